"""The Python API refuses bad arguments with a PlannerError naming the argument (issue 17).

Every public function of planner.curves, .frames, .motion, .kinematics, .export, planner.budget, the readers
(planner.io) and plan() is called
with a valid set of arguments, then with each argument in turn replaced by a bad value: NaN, inf, strings,
complex numbers, None, an arbitrary object, wrong shapes, empty arrays, arrays holding NaN / inf / strings /
complex numbers, zero and negative sizes. The contract: either a :class:`planner.errors.PlannerError` (a
``ValueError``) or, for a value that can be meant (zero, a negative number, None for an optional argument), a
normal return; never a plain ValueError/TypeError/IndexError from numpy or scipy, and never a silent NaN in the
result of a NaN argument.
"""

from __future__ import annotations

import math
import re
import traceback
import warnings
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from planner.errors import NumericalError, PlannerError
from tests.test_fuzz import Hang as _Hang
from tests.test_fuzz import deadline as _deadline


# ---------------------------------------------------------------------------------------------- valid objects
@cache
def waypoints() -> np.ndarray:
    t = np.linspace(0.0, 2.0, 9)
    return np.column_stack((0.1 * np.cos(t), 0.1 * np.sin(t), 0.02 * t))


@cache
def spline():
    from planner.curves import fit_ph_spline

    return fit_ph_spline(waypoints())


@cache
def quintic():
    from planner.curves import PHQuintic

    return PHQuintic.hermite([0, 0, 0], [1, 0, 0], [1, 1, 0], [1, -1, 0.5])


@cache
def limits():
    from planner.motion import MotionLimits

    return MotionLimits(speed=0.5, acceleration=2.0, jerk=30.0)


@cache
def orientation():
    from planner.frames import frame_field
    from planner.motion import tool_orientation

    return tool_orientation(frame_field(spline(), "rmf"), z_column=2)


@cache
def profile():
    from planner.motion import plan_feed

    return plan_feed(spline(), 0.1, limits())


@cache
def frames_and_reference():
    from planner.frames import path_frames

    u = np.linspace(0.0, spline().knots[-1], 20)
    return path_frames(spline(), u, "rmf"), path_frames(spline(), u, "double-reflection")


@cache
def trajectory():
    from planner import PlanSettings, plan

    return plan(waypoints(), PlanSettings(rate=50.0)).trajectory()


@cache
def toolpath():
    from planner.io import read_toolpath

    return read_toolpath(Path(__file__).resolve().parents[1] / "examples" / "nx_first_pass.cls")


@cache
def settings():
    from planner import PlanSettings

    return PlanSettings().checked()


@cache
def inputs() -> dict[str, Path]:
    """Small valid files of every input format (in the scratch folder): an APT arc, a G-code arc, CSV and JSON."""
    folder = _scratch() / "inputs"
    folder.mkdir(exist_ok=True)
    texts = {
        "apt": "GOTO/0,0,0,0,0,1\nGOTO/10,0,0\nCIRCLE/10,10,0,0,0,1,10\nGOTO/20,10,0\n",
        "nc": "G21 G90\nG1 X0 Y0 Z0 F600\nG1 X10\nG3 X20 Y10 I0 J10\n",
        "csv": "x,y,z,i,j,k,feed\n0,0,0,0,0,1,600\n10,0,0,0,0,1,\n20,10,0,0,0,1,\n30,10,5,0,0,1,\n",
        "json": '[{"x": 0, "y": 0, "z": 0, "i": 0, "j": 0, "k": 1}, {"x": 10, "y": 0, "z": 0}, {"x": 20, "y": 10, '
                '"z": 0}]',
    }
    paths = {}
    for fmt, text in texts.items():
        paths[fmt] = folder / f"p.{fmt}"
        paths[fmt].write_text(text)
    return paths


def _progress(stage, done, total):
    """A valid progress callback for plan()."""


def _q():
    return np.array([0.1, -1.2, 1.3, -1.6, -1.5, 0.2])


def _poses(n=5):
    from planner.kinematics import forward

    q = _q() + np.linspace(0.0, 0.1, n)[:, None]
    return forward("ur5e", q)


# ----------------------------------------------------------------------------------------------- the calls
@dataclass
class Call:
    """``fn(*args, **kwargs)``: valid arguments; ``fixed`` names the arguments not to spoil."""

    name: str
    fn: object
    args: tuple = ()
    kwargs: dict = field(default_factory=dict)
    fixed: tuple = ()
    #: arguments that may legitimately be None (optional)
    optional: tuple = ()
    #: arguments where NaN elements mean something (a feed of NaN: the job's feed)
    nan_ok: tuple = ()
    #: arguments that take a batch: one more axis is a batch of one
    batch_ok: tuple = ()
    #: arguments where a string is valid (a file name, a program's text)
    str_ok: tuple = ()


def _calls() -> list[Call]:
    from planner import PlanSettings, budget
    from planner import curves as cv
    from planner import export as ex
    from planner import frames as fr
    from planner import io as pio
    from planner import kinematics as kin
    from planner import motion as mo
    from planner import plan as plan_fn

    wp = waypoints
    t9 = lambda: np.linspace(0.0, 1.0, 9)  # noqa: E731
    return [
        # curves
        Call("fit_ph_spline", cv.fit_ph_spline, (wp,), {"continuity": "C2"}),
        Call("fit_ph_spline C1", cv.fit_ph_spline, (wp,), {"continuity": "C1", "angles": (0.1, 0.2)},
             optional=("angles",)),
        Call("fit_ph_spline tangents", cv.fit_ph_spline, (wp, lambda: np.gradient(waypoints(), axis=0)),
             {"continuity": "C1"}),
        Call("fit_ph_cubic_spline", cv.fit_ph_cubic_spline, (wp,), {"max_splits": 12}),
        Call("fit_planar_ph_spline", cv.fit_planar_ph_spline, (lambda: waypoints()[:, :2],),
             {"max_depth": 8, "max_length_ratio": 2.0}),
        Call("PHQuintic.hermite", cv.PHQuintic.hermite, ([0, 0, 0], [1, 0, 0], [1, 1, 0], [1, -1, 0.5])),
        Call("PHCubic.hermite", cv.PHCubic.hermite, ([0, 0, 0], [1, 0, 0], [1, 0.2, 0], [1, -0.2, 0.1])),
        Call("dp_ph_hermite", cv.dp_ph_hermite, ([0, 0], [1, 1], [3, 0], [1, -1])),
        Call("class3", cv.class3, (0.0, 3.0, 2.0, 1.0)),
        Call("class4", cv.class4, ([1.0, 0.5, 0.2, 0.1], 0.3, 0.4)),
        Call("class5", cv.class5, ([1.0, 0.5, 0.2, 0.1], 0.3, 0.4)),
        Call("spline.points", lambda t: spline().points(t), (t9,)),
        Call("spline.tangent", lambda t: spline().tangent(t), (t9,)),
        Call("spline.interpolation_errors", lambda p: spline().interpolation_errors(p), (wp,)),
        Call("spline.parameter_at_length", lambda s: spline().parameter_at_length(s),
             (lambda: np.linspace(0.0, spline().length, 5),)),
        Call("quintic.points", lambda t: quintic().points(t), (t9,)),
        # frames
        Call("frame_field", fr.frame_field, (spline, "rmf")),
        Call("path_frames", fr.path_frames, (spline, lambda: np.linspace(0.0, spline().knots[-1], 7), "rmf")),
        Call("rmf_frames", fr.rmf_frames, (quintic, t9)),
        Call("er_frames", fr.er_frames, (quintic, t9)),
        Call("double_reflection_frames", fr.double_reflection_frames,
             (wp, lambda: np.gradient(waypoints(), axis=0))),
        Call("grm", fr.grm, (quintic,), {"grid": 11}),
        Call("tool_frames", fr.tool_frames, (spline, lambda: np.tile([0.0, 0.0, 1.0], (9, 1)))),
        Call("slerp_frames", fr.slerp_frames, (lambda: np.eye(3), lambda: np.eye(3)[[1, 0, 2]] * [1, 1, -1],
                                                lambda: np.linspace(0, 1, 5))),
        Call("twist_angles", fr.twist_angles, (lambda: frames_and_reference()[0], lambda: frames_and_reference()[1])),
        Call("max_twist_deg", fr.max_twist_deg, (lambda: frames_and_reference()[0],
                                                 lambda: frames_and_reference()[1])),
        Call("frenet_frames", fr.frenet_frames, (lambda: np.array([[1.0, 0, 0], [1, 0.1, 0]]),
                                                 lambda: np.array([[0.0, 1, 0], [0, 1, 0.1]]))),
        Call("exact_arc_motion", fr.exact_arc_motion, (0.5, 0.7)),
        Call("rmm_arc", fr.rmm_arc, (0.5, 0.7)),
        Call("arc_motion", fr.arc_motion, ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0], 0.8)),
        Call("fit_spherical_biarcs", fr.fit_spherical_biarcs,
             (lambda: (lambda t: np.stack((np.sin(t), 0 * t, np.cos(t)), axis=-1)),), {"tol": 1e-4}),
        # motion
        Call("MotionLimits", mo.MotionLimits, (0.5, 2.0, 30.0)),
        Call("plan_feed", mo.plan_feed, (spline, 0.1, limits)),
        Call("plan_feed span_feeds", mo.plan_feed, (spline, 0.1, limits),
             {"span_feeds": lambda: np.full(8, 0.05)}, optional=("span_feeds",), nan_ok=("span_feeds",)),
        Call("sample_poses", mo.sample_poses, (spline, profile, orientation), {"rate": 125.0, "chunk": 64}),
        Call("tool_orientation", mo.tool_orientation, (lambda: fr.frame_field(spline(), "rmf"),), {"z_column": 2}),
        Call("io_window", mo.io_window, (0.01, 0.05, 1)),
        Call("continuous_rotvec", mo.continuous_rotvec, (lambda: np.stack([np.eye(3)] * 4),)),
        Call("rotvec_from_quaternions", mo.rotvec_from_quaternions, (lambda: np.tile([1.0, 0, 0, 0], (4, 1)),)),
        Call("span_feeds_from_point_feeds", mo.span_feeds_from_point_feeds, (lambda: np.array([0.1, 0.2, 0.1]),),
             nan_ok=("arg0",)),
        Call("poses_at_length", mo.poses_at_length, (spline, orientation, lambda: np.linspace(0.0, 0.05, 4))),
        Call("span_bounds", mo.span_bounds, (spline,)),
        Call("evaluator_for", mo.evaluator_for, (spline,)),
        # kinematics
        Call("get_model", kin.get_model, ("ur5e",)),
        Call("forward", kin.forward, ("ur5e", _q), batch_ok=("arg1",)),
        Call("forward_matrix", kin.forward_matrix, ("ur5e", _q), batch_ok=("arg1",)),
        Call("forward tcp", kin.forward, ("ur5e", _q), {"tcp": [0, 0, 0.1, 0, 0, 0]}, optional=("tcp",),
             batch_ok=("arg1",)),
        Call("inverse", kin.inverse, ("ur5e", lambda: _poses(1)[0])),
        Call("inverse_batch", kin.inverse_batch, ("ur5e", _poses)),
        Call("inverse_nearest", kin.inverse_nearest, ("ur5e", lambda: _poses(1)[0], _q)),
        Call("inverse_path", kin.inverse_path, ("ur5e", _poses), {"q_start": _q}, optional=("q_start",)),
        Call("pose_to_matrix", kin.pose_to_matrix, ([0.1, 0.2, 0.3, 0.0, 0.1, 0.0],), batch_ok=("arg0",)),
        Call("matrix_to_pose", kin.matrix_to_pose, (lambda: np.eye(4),), batch_ok=("arg0",)),
        Call("as_transform", kin.as_transform, ([0.1, 0.2, 0.3, 0.0, 0.1, 0.0], "pose"), fixed=("arg1",)),
        Call("wrap_angle", kin.wrap_angle, (lambda: np.array([0.1, 7.0]),), nan_ok=("arg0",), batch_ok=("arg0",)),
        Call("joint_speeds", kin.joint_speeds, (lambda: np.tile(_q(), (5, 1)) + np.arange(5)[:, None] * 0.01,
                                                lambda: np.arange(5) * 0.1)),
        Call("check_reachability", kin.check_reachability,
             ("ur5e", lambda: np.tile(_q(), (5, 1)), lambda: np.arange(5) * 0.1)),
        Call("feed_scale", kin.feed_scale, ("ur5e", lambda: np.tile(_q(), (5, 1)), lambda: np.arange(5) * 0.1)),
        Call("speed_ratios", kin.speed_ratios, ("ur5e", lambda: np.tile(_q(), (5, 1)), lambda: np.arange(5) * 0.1)),
        Call("link_frames", kin.link_frames, ("ur5e", _q), batch_ok=("arg1",)),
        Call("check_poses", kin.check_poses, ("ur5e", _poses, lambda: np.arange(5) * 0.1)),
        # export
        Call("csv_text", lambda tr, parameters=None: "".join(ex.csv_text(tr, parameters=parameters)), (trajectory,),
             {"parameters": {"a": 1}}, optional=("parameters",)),
        Call("json_text", lambda tr: "".join(ex.json_text(tr)), (trajectory,)),
        Call("check_output", ex.check_output, ("out.csv",), str_ok=("arg0",)),
        Call("write_bytes_atomic", lambda data: ex.write_bytes_atomic(_scratch() / "b.bin", data), (b"abc",)),
        Call("write_script", lambda program: ex.write_script(program, _scratch() / "p.script"),
             ("def p():\n  textmsg(1)\nend\n",), str_ok=("arg0",)),
        Call("write_csv", lambda target: ex.write_csv(trajectory(), target), (lambda: _scratch() / "t.csv",),
             str_ok=("arg0",)),
        Call("write_json", lambda target: ex.write_json(trajectory(), target), (lambda: _scratch() / "t.json",),
             str_ok=("arg0",)),
        Call("export", lambda fmt, parameters=None: ex.export(trajectory().job, fmt, parameters=parameters), ("csv",),
             {"parameters": {"a": 1}}, optional=("parameters",)),
        Call("export job", lambda job: ex.export(job, "json"), (lambda: trajectory().job,)),
        Call("write", lambda target: ex.write(trajectory().job, target), (lambda: _scratch() / "w.csv",),
             str_ok=("arg0",)),
        Call("format_of", ex.format_of, ("out.script",), str_ok=("arg0",)),
        # budget
        Call("check_budget", budget.check_budget, (toolpath, settings)),
        Call("estimate", budget.estimate, (toolpath, settings)),
        # readers (the file is fixed: a string there is a file name, a missing one an OSError)
        Call("read_toolpath", pio.read_toolpath, (lambda: inputs()["apt"],),
             {"format": "apt", "units": "mm", "arc_tolerance": 1e-5}, fixed=("arg0",),
             optional=("format", "arc_tolerance")),
        Call("read_apt", pio.read_apt, (lambda: inputs()["apt"],),
             {"units": "mm", "frames": "auto", "arc_tolerance": 1e-5, "axis_tolerance": 1e-3, "source": "part.apt",
              "peck_clearance": 5e-4}, fixed=("arg0",), optional=("arc_tolerance", "source"), str_ok=("source",)),
        Call("read_gcode", pio.read_gcode, (lambda: inputs()["nc"],),
             {"machine": "haas-umc-750", "units": "mm", "arc_tolerance": 1e-5, "source": "part.nc", "dialect": "iso",
              "peck_clearance": 5e-4}, fixed=("arg0",), optional=("machine", "arc_tolerance", "source"),
             str_ok=("source",)),
        Call("read_csv", pio.read_csv, (lambda: inputs()["csv"],),
             {"units": "mm", "feed_units": "mm/min", "delimiter": ",", "axis_tolerance": 1e-3, "normalize_axes": False,
              "source": "part.csv"}, fixed=("arg0",), optional=("feed_units", "delimiter", "source"),
             str_ok=("source",)),
        Call("read_json", pio.read_json, (lambda: inputs()["json"],),
             {"units": "mm", "feed_units": "mm/min", "axis_tolerance": 1e-3, "normalize_axes": True,
              "source": "part.json"}, fixed=("arg0",), optional=("units", "feed_units", "source"), str_ok=("source",)),
        Call("linearize_arcs", pio.linearize_arcs, (lambda: pio.read_apt(inputs()["apt"]), 1e-5)),
        Call("machine_kinematics", pio.machine_kinematics, ("haas-umc-750",)),
        # plan() (a string source is a file name: the waypoints are fixed, spoiled through fit_ph_spline above)
        Call("plan waypoints", plan_fn, (wp,), {"settings": lambda: PlanSettings(rate=50.0),
                                               "axes": lambda: np.tile([0.0, 0.0, 1.0], (9, 1)),
                                               "feeds": lambda: np.full(9, 0.05), "progress": _progress},
             fixed=("arg0",), optional=("settings", "axes", "feeds", "progress"), nan_ok=("feeds",)),
        Call("plan file", plan_fn, (lambda: inputs()["csv"],), {"settings": lambda: PlanSettings(rate=50.0),
                                                                 "read_options": {"units": "mm"},
                                                                 "progress": _progress},
             fixed=("arg0",), optional=("settings", "read_options", "progress")),
    ]


_SCRATCH: list[Path] = []


def _scratch() -> Path:
    import tempfile

    if not _SCRATCH:
        _SCRATCH.append(Path(tempfile.mkdtemp(prefix="fuzz-api-")))
    return _SCRATCH[0]


def _materialize(v):
    return v() if callable(v) and getattr(v, "__name__", "") in ("<lambda>", "waypoints", "spline", "quintic",
                                                                  "limits", "orientation", "profile", "trajectory",
                                                                  "toolpath", "settings", "_q", "_poses") else v


#: Bad values that must be refused (a PlannerError): (label, value or a function of the valid value).
MUST_REFUSE = {
    "nan": math.nan,
    "inf": math.inf,
    "string": "abc",
    "complex": 1 + 2j,
    "object": object(),
    "nan inside": lambda v: _spoil(v, math.nan),
    "inf inside": lambda v: _spoil(v, math.inf),
    "strings inside": lambda v: _as_kind(v, "U"),
    "complex inside": lambda v: _as_kind(v, "c"),
    "one more axis": lambda v: None if np.ndim(v) == 0 else np.asarray(v, dtype=float)[None],
    "list of strings": ["a", "b", "c"],
}
#: Bad values that may be meant (then a normal return is fine), or refused by a PlannerError.
MAY_PASS = {
    "None": None,
    "zero": 0,
    "negative": -1.0,
    "True": True,
    "huge": 1e308,
    "huge int": 10**400,
    "empty": lambda v: None if np.ndim(v) == 0 else np.zeros((0,) + np.shape(v)[1:]),
    "one row": lambda v: None if np.ndim(v) < 2 else np.asarray(v, dtype=float)[:1],
    "last column dropped": lambda v: None if np.ndim(v) < 1 or np.shape(v)[-1] < 2 else np.asarray(v)[..., :-1],
}


def _numeric(v) -> bool:
    try:
        a = np.asarray(v)
    except Exception:  # noqa: BLE001
        return False
    return a.dtype.kind in "fiu" and a.size > 0


def _spoil(v, x):
    if not _numeric(v):
        return None
    a = np.array(v, dtype=float)
    a.flat[a.size // 2] = x
    return a


def _as_kind(v, kind):
    if not _numeric(v):
        return None
    a = np.asarray(v, dtype=float)
    return a.astype(str) if kind == "U" else a + 1j


def _cases():
    """(call, argument, bad value) for every argument and every bad value that applies to it (the array spoilers
    only to array arguments)."""
    for call in _calls():
        valid = {f"arg{i}": a for i, a in enumerate(call.args)} | call.kwargs
        for name, value in valid.items():
            if name in call.fixed:
                continue
            for table, must in ((MUST_REFUSE, True), (MAY_PASS, False)):
                for label, bad in table.items():
                    if callable(bad) and not isinstance(bad, type) and bad(_materialize(value)) is None:
                        continue
                    yield pytest.param(call.name, name, label, must, id=f"{call.name}-{name}-{label}")


def _run(call_name: str, arg: str, label: str):
    call = next(c for c in _calls() if c.name == call_name)
    args = [_materialize(a) for a in call.args]
    kwargs = {k: _materialize(v) for k, v in call.kwargs.items()}
    valid = args[int(arg[3:])] if arg.startswith("arg") else kwargs[arg]
    bad = {**MUST_REFUSE, **MAY_PASS}[label]
    if callable(bad) and not isinstance(bad, type):
        bad = bad(valid)
    if arg.startswith("arg"):
        args[int(arg[3:])] = bad
    else:
        kwargs[arg] = bad
    return call, bad, args, kwargs


@pytest.fixture(autouse=True)
def _in_scratch(monkeypatch):
    """Every call runs in a scratch folder: a bad value that is a valid file name ("abc") writes there."""
    monkeypatch.chdir(_scratch())


@pytest.mark.parametrize("call_name, arg, label, must", list(_cases()))
def test_bad_argument_is_a_planner_error(call_name, arg, label, must):
    call, bad, args, kwargs = _run(call_name, arg, label)
    where = f"{call_name}({arg}={label})"
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"), _deadline(20.0):
            warnings.simplefilter("ignore")
            result = call.fn(*args, **kwargs)
    except PlannerError:
        return
    except NumericalError as exc:
        pytest.fail(f"{where}: bad input reported as our numerical failure: {exc}")
    except _Hang:
        pytest.fail(f"{where}: hangs")
    except Exception as exc:  # noqa: BLE001
        frames = [f for f in traceback.extract_tb(exc.__traceback__) if "/planner/" in f.filename]
        place = f"{Path(frames[-1].filename).name}:{frames[-1].lineno}" if frames else "?"
        pytest.fail(f"{where}: not a PlannerError: {type(exc).__name__}: {exc} (raised past {place})")
    if must and not ((label == "None" and arg in call.optional) or (label in ("nan", "nan inside") and arg in call.nan_ok)
                     or (label == "one more axis" and arg in call.batch_ok)
                     or (label == "string" and arg in call.str_ok)):
        pytest.fail(f"{where}: accepted (returned {type(result).__name__})")


@pytest.mark.parametrize("call_name", [c.name for c in _calls()])
def test_the_valid_call_works(call_name):
    """Each call of the table is valid as given: the bad values above spoil a working call."""
    call = next(c for c in _calls() if c.name == call_name)
    call.fn(*[_materialize(a) for a in call.args], **{k: _materialize(v) for k, v in call.kwargs.items()})


@pytest.mark.parametrize("value, message", [
    ("0.01", "got the string '0.01'"),
    (1j, "got the complex number 1j"),
    (None, "got None"),
    (True, "got the boolean True"),
    (10**400, "an integer of 401 digits, beyond the float range"),
    (math.nan, "be in [1e-06, 10], got nan"),  # the feed range of the command line and the budget (1 um/s)
])
def test_a_setting_is_a_real_number(value, message):
    """PlanSettings' numbers (planner.validation.check_in_range): a numeric string is not parsed, a complex
    number is not truncated to its real part."""
    from planner import PlanSettings

    with pytest.raises(PlannerError, match=f"^feed must .*{re.escape(message)}"):
        PlanSettings(feed=value).checked()
    assert PlanSettings(feed=np.float32(0.25)).checked().feed == pytest.approx(0.25)


@pytest.mark.parametrize("value, message", [
    ([[0.0, 1.0], [2.0, "3"]], "must be numbers, got strings"),
    ([[0.0, 1.0], [2.0]], "rectangular array"),
    ([1.0, 2.0 + 1e-3j], "must be real numbers, got complex numbers"),
    ([1.0, None], "must be numbers, got None"),
    ([1.0, 10**400], "an integer of 401 digits"),
    ([True, False], "must be numbers, got booleans"),
    ("1, 2", "must be numbers, got the string '1, 2'"),
])
def test_as_floats_names_what_is_not_a_number(value, message):
    from planner.validation import ArgumentError, as_floats

    with pytest.raises(ArgumentError, match=re.escape(message)) as info:
        as_floats(value, "q")
    assert info.value.argument == "q" and str(info.value).startswith("q: ")
    assert as_floats([[1, 2], [3, 4]], "q").dtype == np.float64


def test_finite_floats_names_the_index_and_the_shape():
    from planner.validation import ArgumentError, finite_floats

    with pytest.raises(ArgumentError, match=r"^p\[1\]\[2\]: must be finite, got nan$"):
        finite_floats([[0, 0, 0], [1, 1, math.nan]], "p", (None, 3))
    with pytest.raises(ArgumentError, match=r"^p: must have shape \(n, 3\), got \(2, 2\)$"):
        finite_floats([[0, 0], [1, 1]], "p", (None, 3))
    with pytest.raises(ArgumentError, match=r"^t: must have shape \(\) or \(n,\), got \(1, 2\)$"):
        finite_floats([[0.1, 0.2]], "t", ((), (None,)))
    assert finite_floats(0.5, "t", ((), (None,))).shape == ()
