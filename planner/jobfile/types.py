"""The stored types of the planning core: each name in the file, its class, its fields and what is checked.

The job's own types (``PlannedJob``, ``PlannedMove``, ``PassReport``) are declared beside them in
:mod:`planner.job`. A check raises :class:`~planner.errors.PlannerError` for what the field kinds cannot see:
sizes that must agree between fields, parameters that must increase, indices that must lie in range. The
checks are what a reader relies on: after them, evaluating the object cannot index out of range or loop on
bad data.
"""

from __future__ import annotations

import numpy as np

from planner.cam.axes import AxisField
from planner.cam.fidelity import PassFit
from planner.cam.moves import Reconfiguration, TurningFrames
from planner.cam.passes import CutPass, Dwell, RapidMove, Reorientation, Segmentation, Skipped
from planner.cam.placement import Placement
from planner.cam.spin import SpunFrames
from planner.curves.spline import PHSpline
from planner.errors import PlannerError
from planner.frames.juttler import R2_WEIGHTS
from planner.frames.path import MotionFrames, PathFrames
from planner.frames.piecewise_motion import PiecewiseArcMotion
from planner.frames.rmf_batch import PathRMFAngles
from planner.frames.tool_field import PathToolField, SampledFrames
from planner.io.toolpath import EVENT_KINDS, Arc, Event, Nurbs, Toolpath
from planner.jobfile.codec import Arr, Bool, Float, Inline, Int, Map, Opt, Ref, Seq, StoredType, Str
from planner.motion.caps import CapWindow
from planner.motion.limits import MotionLimits
from planner.motion.profile import FeedProfile

N = None  # any size
#: Non-negative integers (source lines, counts, indices).
COUNT = Int(0)
LINE = Int(-1)
VEC3 = Arr("f8", (3,))
FRAME = Arr("f8", (3, 3))
NAN = Float(finite=False)


def need(ok, message: str) -> None:
    """PlannerError(message) unless ``ok``."""
    if not ok:
        raise PlannerError(message)


def increasing(a: np.ndarray, name: str, strict: bool = True) -> None:
    ok = (a[1:] > a[:-1]) if strict else (a[1:] >= a[:-1])
    need(ok.all(), f"{name} must {'strictly ' * strict}increase")


def indices(a: np.ndarray, size: int, name: str) -> None:
    need(a.size == 0 or (a.min() >= 0 and a.max() < size), f"{name} must index 0..{size - 1}")


def _spline(s) -> None:
    n = s["A"].shape[0]
    need(n >= 1, "a spline needs a segment")
    need(s["starts"].shape[0] == n and s["knots"].shape[0] == n + 1,
         f"{n} segments need {n} starts and {n + 1} knots, got {s['starts'].shape[0]} and {s['knots'].shape[0]}")
    increasing(s["knots"], "knots")
    if s["waypoint_index"] is not None:
        indices(s["waypoint_index"], n + 1, "waypoint_index")
        increasing(s["waypoint_index"], "waypoint_index")
        need(s["waypoint_index"].size >= 2, "waypoint_index needs 2 entries")


def _points_of(s, names: tuple, n: int) -> None:
    for k in names:
        need(s[k] is None or s[k].shape[0] == n, f"{k} has {0 if s[k] is None else s[k].shape[0]} rows, not {n}")


def _cut(s) -> None:
    n = s["points"].shape[0]
    need(n >= 2, "a pass needs 2 points")
    _points_of(s, ("axes", "axis_given", "feeds", "lines", "source_index"), n)
    need((s["axes"] is None) == (s["axis_given"] is None), "axes and axis_given go together")


def _fit(s) -> None:
    need(s["points"].shape[0] >= 2, "a fit needs 2 points")


def _profile(s) -> None:
    p = s["j"].shape[0]
    need(p >= 1, "a profile needs a phase")
    need(s["t"].shape[0] == p + 1 and all(s[k].shape[0] == p for k in ("s0", "v0", "a0")),
         f"{p} phases need {p + 1} times and {p} starts")
    need(s["t"][0] == 0.0, "the profile must start at t = 0")
    increasing(s["t"], "t", strict=False)
    m = s["commanded"].shape[0]
    need(m >= 1 and s["level_bounds"].shape[0] == m + 1 and s["cruise"].shape[0] == m,
         f"{m} feed levels need {m + 1} bounds and {m} cruise speeds")
    increasing(s["level_bounds"], "level_bounds", strict=False)
    need(s["length"] >= 0.0, "the length must be >= 0")


def _turning(s) -> None:
    need(s["span"] > 0.0, "span must be > 0")


def _axis_field(s) -> None:
    m = s["axes"].shape[0]
    need(m == s["path"].waypoint_knots.size, f"{m} axes for {s['path'].waypoint_knots.size} CAM points")
    need((np.linalg.norm(s["axes"], axis=1) > 0.5).all(), "the axes must be unit vectors")
    if s["motion"] is not None:
        _spin_table(s["motion"])


def _spin_table(s) -> None:
    p, k = s["bases"].shape[0], s["coeffs"].shape[0]
    need(p >= 1 and k >= 1, "a spin table needs a piece and a panel")
    need(s["pieces"].shape[0] == p + 1 and s["base_quaternions"].shape[0] == p, f"{p} pieces: sizes disagree")
    need(s["panels"].shape[0] == k + 1 and s["panel_piece"].shape[0] == k and s["spin_start"].shape[0] == k,
         f"{k} panels: sizes disagree")
    increasing(s["panels"], "panels")
    indices(s["panel_piece"], p, "panel_piece")


def _spin_curve(s) -> None:
    k = s["coeffs"].shape[0]
    need(k >= 4 and s["knots"].shape[0] == k + 4, f"a cubic spin of {k} coefficients needs {k + 4} knots (and >= 4)")
    increasing(s["knots"], "knots", strict=False)
    need(s["knots"][-1] > s["knots"][0], "the spin's knots must span an interval")
    need(np.all(s["knots"][:4] == s["knots"][0]) and np.all(s["knots"][-4:] == s["knots"][-1]),
         "the spin's knots must be clamped (4 equal at each end)")


def _rmf_angles(s) -> None:
    n = s["panels"].shape[0]
    need(n >= 1 and (s["panels"] >= 1).all() and (s["panels"] <= 4096).all(), "panels must be 1..4096 per segment")
    need(s["offsets"].shape[0] == n + 1 and s["q"].shape[0] == n and s["sig"].shape[0] == n,
         f"{n} segments: sizes disagree")
    need(np.array_equal(s["offsets"], np.concatenate(([0], np.cumsum(s["panels"] + 1)))),
         "offsets must count the panel edges")
    need(s["cum"].shape[0] == s["offsets"][-1], f"cum must have {s['offsets'][-1]} entries")


def _path_frames(s) -> None:
    path, method = s["path"], s["method"]
    n = path.n_segments
    need(s["offsets"].shape[0] == n, f"{n} segments need {n} offsets")
    need(s["stations"].shape == s["corrections"].shape, "stations and corrections differ in size")
    increasing(s["stations"], "stations", strict=False)
    need((method == "rmf") == (s["panels"] is not None), "the exact RMF (and only it) has panels")
    need((method == "grm") == (s["grm_frames"] is not None), "GRM frames (and only they) have GRM solutions")
    if s["panels"] is not None:
        need(s["panels"].panels.size == n, f"panels of {s['panels'].panels.size} segments on a path of {n}")
    if s["grm_frames"] is not None:
        need(path.degree == 5 and len(s["grm_frames"]) == n, "GRM frames need one solution per PH quintic segment")


def _motion_frames(s) -> None:
    need((s["method"] == "juttler") == (s["motion"] is not None), "Juttler's frames (and only they) have a motion")
    if s["motion"] is not None:
        need(s["path"].degree == 3, "Juttler's frames are on a PH cubic spline")


def _arc_motion(s) -> None:
    m = s["phi"].shape[0]
    need(m >= 1 and s["knots"].shape[0] == m + 1, f"{m} arcs need {m + 1} knots")
    need(all(s[k].shape[0] == m for k in ("psi", "rho", "w0", "w1", "left")), f"{m} arcs: sizes disagree")
    increasing(s["knots"], "knots")


def _sampled(s) -> None:
    need(s["u"].shape[0] >= 2 and s["grid_quaternions"].shape[0] == s["u"].shape[0], "one quaternion per grid point")
    increasing(s["u"], "u")
    need((np.linalg.norm(s["grid_quaternions"], axis=1) > 0.5).all(), "the quaternions must be unit")


def _tool_field(s) -> None:
    need(s["field"].path is s["path"] and s["reference"].path is s["path"], "the fields must be on the same path")


def _segmentation(s) -> None:
    need(all(isinstance(v, int) for v in s["counts"].values()), "counts must be integers")


def _toolpath(s) -> None:
    n = s["points"].shape[0]
    _points_of(s, ("axes", "axis_given", "feeds", "rapid", "lines", "rotary"), n)


def _nurbs(s) -> None:
    need(1 <= s["degree"] <= 30, "degree must be 1..30")
    increasing(s["knots"], "knots", strict=False)


#: name -> stored type (the job's own types are added by :mod:`planner.job`).
CORE_TYPES = {t.name: t for t in (
    StoredType("PHSpline", PHSpline, {
        "A": Arr("f8", (N, (2, 3), 4)), "starts": Arr("f8", (N, 3)), "knots": Arr("f8", (N,)),
        "continuity": Str(("G1", "C1", "C2")), "iterations": COUNT, "waypoint_index": Opt(Arr("i8", (N,)))},
        check=_spline),
    StoredType("CutPass", CutPass, {
        "index": COUNT, "points": Arr("f8", (N, 3)), "axes": Opt(Arr("f8", (N, 3), finite=False)),
        "axis_given": Opt(Arr("b1", (N,))), "feeds": Arr("f8", (N,), finite=False), "lines": Arr("i8", (N,)),
        "source_index": Arr("i8", (N,)), "operation": Str(), "tool": NAN, "start_reason": Str(), "end_reason": Str(),
        "start_corner_deg": NAN, "end_corner_deg": NAN, "merged": COUNT}, check=_cut),
    StoredType("RapidMove", RapidMove, {
        "start": VEC3, "end": VEC3, "start_axis": Opt(VEC3), "end_axis": Opt(VEC3), "line": LINE,
        "source_index": LINE, "reason": Str()}),
    StoredType("Reorientation", Reorientation, {
        "point": VEC3, "axis_from": VEC3, "axis_to": VEC3, "line": LINE, "reason": Str()}),
    StoredType("Dwell", Dwell, {"point": VEC3, "seconds": Float(), "line": LINE, "name": Str()},
               check=lambda s: need(s["seconds"] >= 0.0, "seconds must be >= 0")),
    StoredType("Skipped", Skipped, {"point": VEC3, "first_line": LINE, "last_line": LINE, "reason": Str()}),
    StoredType("Segmentation", Segmentation, {
        "moves": Seq(Ref("CutPass", "RapidMove", "Reorientation", "Dwell", "Skipped")), "corners": COUNT,
        "corner_deg": Float(), "axis_jump_deg": Float(), "source": Str(), "counts": Map(Int())}, check=_segmentation),
    StoredType("Reconfiguration", Reconfiguration, {
        "q_from": Arr("f8", (6,)), "q_to": Arr("f8", (6,)), "point": VEC3, "line": LINE, "pass_index": COUNT,
        "passes": Seq(COUNT), "reason": Str(), "change": Str(), "where": Str(), "tcp_excursion": Float()},
        check=lambda s: need(len(s["passes"]) >= 1, "a reconfiguration is made for a pass")),
    StoredType("PassFit", PassFit, {
        "path": Ref("PHSpline"), "points": Arr("f8", (N, 3)), "max_deviation": NAN,
        "span_deviation": Arr("f8", (N,), finite=False), "knots_added": COUNT, "straight_chords": COUNT,
        "rounds": COUNT}, check=_fit),
    StoredType("MotionLimits", MotionLimits, {
        "speed": Float(), "acceleration": Float(), "jerk": Float(), "angular_speed": Opt(Float())}),
    StoredType("FeedProfile", FeedProfile, {
        "t": Arr("f8", (N,)), "s0": Arr("f8", (N,)), "v0": Arr("f8", (N,)), "a0": Arr("f8", (N,)),
        "j": Arr("f8", (N,)), "length": Float(), "limits": Ref("MotionLimits"), "level_bounds": Arr("f8", (N,)),
        "commanded": Arr("f8", (N,)), "cruise": Arr("f8", (N,))}, check=_profile),
    StoredType("CapWindow", CapWindow, {
        "start": Float(), "end": Float(), "factor": Float(), "speed": Float(), "tag": Int(),
        "first_span": Opt(Int()), "last_span": Opt(Int()), "floored": Bool()}),
    StoredType("TurningFrames", TurningFrames, {
        "path": Opt(Ref("PHSpline")), "start": FRAME, "n": VEC3, "angle": Float(), "span": Float()},
        check=_turning),
    StoredType("SpinTable", None, {
        "pieces": Arr("f8", (N,)), "bases": Arr("f8", (N, 3)), "base_quaternions": Arr("f8", (N, 4)),
        "panels": Arr("f8", (N,)), "panel_piece": Arr("i8", (N,)), "spin_start": Arr("f8", (N,)),
        "coeffs": Arr("f8", (N, N))}),
    StoredType("AxisField", AxisField, {
        "path": Ref("PHSpline"), "axes": Arr("f8", (N, 3)), "start": FRAME, "motion": Opt(Inline("SpinTable"))},
        check=_axis_field),
    StoredType("SpinCurve", None, {"knots": Arr("f8", (N,)), "coeffs": Arr("f8", (N,))}, check=_spin_curve),
    StoredType("SpinFigures", None, {
        "samples": COUNT, "branch": Int(0, 7), "rmm": Arr("f8", (5,), finite=False),
        "reach": Arr("f8", (5,), finite=False)}),
    StoredType("SpunFrames", SpunFrames, {
        "base": Ref("AxisField", "TurningFrames"), "spin": Inline("SpinCurve"), "figures": Opt(Inline("SpinFigures"))}),
    StoredType("PathRMFAngles", PathRMFAngles, {
        "panels": Arr("i8", (N,)), "cum": Arr("f8", (N,)), "offsets": Arr("i8", (N,)), "q": Arr("f8", (N, N)),
        "sig": Arr("f8", (N, N))}, check=_rmf_angles),
    StoredType("GRMFrame", None, {
        "a": Arr("f8", (5,)), "b": Arr("f8", (5,)), "weight": Str(), "objective": NAN,
        "constraint_residual": NAN, "max_twist_deg": NAN, "start_angle": Float(), "seconds": NAN}),
    StoredType("PathFrames", PathFrames, {
        "path": Ref("PHSpline"), "method": Str(("rmf", "grm", "er")), "offsets": Arr("f8", (N,)),
        "stations": Arr("f8", (N,)), "corrections": Arr("f8", (N,)), "grm_frames": Opt(Seq(Inline("GRMFrame"))),
        "panels": Opt(Ref("PathRMFAngles"))}, check=_path_frames),
    StoredType("PiecewiseArcMotion", PiecewiseArcMotion, {
        "knots": Arr("f8", (N,)), "phi": Arr("f8", (N,)), "psi": Arr("f8", (N,)), "rho": Arr("f8", (N,)),
        "w0": Arr("f8", (N,)), "w1": Arr("f8", (N,)), "left": Arr("f8", (N, 4)), "right": Arr("f8", (4,)),
        "axis_column": Int(0, 2), "rational": Bool(), "r2_weights": Str(R2_WEIGHTS)}, check=_arc_motion),
    StoredType("MotionFrames", MotionFrames, {
        "path": Ref("PHSpline"), "method": Str(("juttler", "double-reflection")),
        "motion": Opt(Ref("PiecewiseArcMotion")), "start": FRAME}, check=_motion_frames),
    StoredType("SampledFrames", SampledFrames, {
        "path": Ref("PHSpline"), "u": Arr("f8", (N,)), "grid_quaternions": Arr("f8", (N, 4))}, check=_sampled),
    StoredType("PathToolField", PathToolField, {
        "path": Ref("PHSpline"), "method": Str(("rmf", "grm", "er", "juttler", "double-reflection")),
        "field": Ref("PathFrames", "MotionFrames", "SampledFrames"), "reference": Ref("PathFrames")},
        check=_tool_field),
    StoredType("Event", Event, {
        "kind": Str(EVENT_KINDS, "one of planner.io.EVENT_KINDS"), "line": LINE, "index": COUNT, "name": Str(),
        "value": NAN, "text": Str()}),
    StoredType("Arc", Arc, {
        "line": LINE, "index": COUNT, "start": COUNT, "centre": Seq(Float(), 3), "axis": Seq(Float(), 3),
        "radius": NAN}),
    StoredType("Nurbs", Nurbs, {
        "line": LINE, "index": COUNT, "start": COUNT, "degree": COUNT, "knots": Arr("f8", (N,)),
        "control": Arr("f8", (N, 3)), "weights": Arr("f8", (N,)), "axes": Opt(Arr("f8", (N, 3)))}, check=_nurbs),
    StoredType("Toolpath", Toolpath, {
        "points": Arr("f8", (N, 3)), "axes": Opt(Arr("f8", (N, 3), finite=False)),
        "axis_given": Opt(Arr("b1", (N,))), "feeds": Arr("f8", (N,), finite=False), "rapid": Arr("b1", (N,)),
        "lines": Arr("i8", (N,)), "events": Seq(Ref("Event", "Arc", "Nurbs")), "units": Str(), "source": Str(),
        "rotary": Opt(Arr("f8", (N, 2), finite=False))}, check=_toolpath),
    StoredType("Placement", Placement, {
        "part_frame": Seq(Float(), 6), "singularity_margin": NAN, "joint_margin": NAN, "factors": Seq(NAN, 3),
        "branch": Int(0, 7), "poses": COUNT, "ratings": COUNT, "seconds": NAN}),
)}
