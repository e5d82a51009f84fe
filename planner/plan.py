"""``plan(...)``: the one entry point of the planner, from a toolpath file or waypoints to a PlannedJob.

A list of waypoints is a toolpath with one pass; a single pass is a job with one cut. For every input:

1. read (a file, with :func:`planner.io.read_toolpath`) and resolve the settings (:class:`PlanSettings`):
   the path model and the source of the tool axes (printed in the summary);
2. arcs linearised to ``arc_tolerance`` (:func:`planner.io.linearize_arcs`);
3. the split into cutting passes, rapid moves and reorientations at rapids, sharp corners and tool-axis
   jumps (:mod:`planner.cam.passes`), in both path models;
4. every pass's PH path: a C2 PH quintic spline through its points ("interpolate"; a G1 PH cubic spline for
   Jüttler's frames) or a C1 PH quintic spline within ``tolerance`` of its polyline ("cam",
   :mod:`planner.cam.fidelity`);
5. the tool frames of every move, each starting from the previous move's end frame: about the tool axes
   (the file's, or the CAM default +Z) interpolated on great circles without overshoot, spin exactly
   rotation-minimizing (:func:`planner.cam.axis_field`); or, with the tool normal to the path, the frame
   field of the chosen method (:func:`planner.frames.frame_field`), with its twist against the exact RMF;
6. the jerk-limited time law of every move along the exact arc length (cuts at the input's feeds, rapids at
   rapid speed, turns at the turning speed), starting and ending at rest;
7. with ``spin="reach"``: the spin about the tool axis chosen for the arm along every run of passes
   (:mod:`planner.cam.spin_choice`);
8. with a robot: inverse kinematics along every move, problems named by pass and source line, the feed
   lowered locally where a joint would be too fast, and the arm configuration of every run of passes,
   changed by a joint move in a rapid where needed (:mod:`planner.cam.reach`, :mod:`planner.cam.configure`).

The trajectory at the controller rate is produced on demand, move by move
(:meth:`PlannedJob.trajectory`, :mod:`planner.trajectory`).
"""

from __future__ import annotations

import math
import operator
import os
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np

from planner.cam.axes import (
    AxisField,
    axis_departure,
    axis_field,
    frame_with_axis,
    spin_about_axis,
    transport,
    travel_spin,
)
from planner.cam.fidelity import PassFit, fit_passes
from planner.cam.moves import rapid_frames, straight_path, turn_frames, turn_profile
from planner.cam.passes import CutPass, Dwell, RapidMove, Reorientation, Segmentation, split_passes
from planner.errors import PlannerError
from planner.frames.tool_field import PathToolField, path_tool_field
from planner.job import PassReport, PlannedJob, PlannedMove, PlannedPiece
from planner.motion import MotionLimits, plan_feed, tool_orientation
from planner.settings import PlanSettings
from planner.validation import ArgumentError, _described, as_floats

#: The CAM default tool axis (APT: +Z, from the tip towards the spindle).
CAM_DEFAULT_AXIS = np.array([0.0, 0.0, 1.0])
#: Input formats whose points are CAD waypoints (interpolated by default); the others are CAM polylines.
WAYPOINT_FORMATS = ("csv", "json", "waypoints")

#: CAM chords fitted in one batch at most (the batched fit needs about 5 kB per chord while it runs).
FIT_BATCH_SPANS = 8192

#: A progress callback: (stage, done, total), counted in cutting passes at every stage of planning: "fit" (passes
#: fitted), "plan" (passes given their tool frames and time law), "place" and "reach" (the whole job placed and
#: checked on the robot: 0 of the passes, then all), e.g. ("plan", 12, 40). The CLI draws it with tqdm; the service
#: shows it as passes planned of passes.
Progress = Callable[[str, int, int], None]


def waypoints_toolpath(waypoints, axes=None, feeds=None, *, source: str = "<waypoints>"):
    """A :class:`planner.io.Toolpath` of one pass from arrays (m, part frame).

    Parameters
    ----------
    waypoints : array_like (N, 3)
        Tool tip positions, m.
    axes : array_like (N, 3), optional
        Tool axes in the CAM convention (from the tool tip towards the spindle); see ``PlanSettings.axes``.
    feeds : array_like (N,), optional
        Feed into each waypoint, m/s (NaN: the job's feed; the first is unused).

    The "source line" of waypoint i is i (its index), so every message names the waypoint.
    """
    from planner.io.toolpath import Toolpath
    from planner.validation import check_waypoints

    pts = check_waypoints(waypoints, min_count=2)
    n = len(pts)
    ax = given = None
    if axes is not None:
        ax = _finite_rows(axes, "axes", n)
        bad = np.flatnonzero(np.linalg.norm(ax, axis=1) < 1e-12)
        if bad.size:
            raise ArgumentError(f"axes[{int(bad[0])}]", f"the tool axis is zero (waypoint {int(bad[0])})")
        ax = ax / np.linalg.norm(ax, axis=1, keepdims=True)
        given = np.ones(n, bool)
    f = np.full(n, np.nan)
    if feeds is not None:
        f = as_floats(feeds, "feeds")
        if f.shape != (n,):
            raise ArgumentError("feeds", f"expected one feed per waypoint, shape ({n},), got {f.shape}")
        bad = np.flatnonzero(~np.isnan(f) & ~(np.isfinite(f) & (f > 0.0)))
        if bad.size:
            raise ArgumentError(f"feeds[{int(bad[0])}]", f"a feed must be > 0 m/s (or NaN for the job's feed), "
                                                         f"got {float(f[bad[0]])!r}")
    return Toolpath(pts, ax, given, f, np.zeros(n, bool), np.arange(n, dtype=np.int64), (), "m", source)


def _finite_rows(a, name: str, n: int) -> np.ndarray:
    """``a`` as finite rows (n, 3), one per waypoint; else ArgumentError naming ``name`` (and the row)."""
    arr = as_floats(a, name)
    if arr.shape != (n, 3):
        raise ArgumentError(name, f"expected shape ({n}, 3) (one per waypoint), got {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if bad.size:
        raise ArgumentError(f"{name}[{int(bad[0])}]", f"not a finite vector (waypoint {int(bad[0])})")
    return arr


def _check_plan_arguments(settings, read_options, progress) -> None:
    """plan()'s own arguments, before any work: ArgumentError naming the first bad one."""
    if not isinstance(settings, PlanSettings):
        raise PlannerError(f"settings must be a PlanSettings, got {_described(settings)}")
    if progress is not None and not callable(progress):
        raise ArgumentError("progress", f"must be a function (stage, done, total) or None, got {_described(progress)}")
    if read_options is not None:
        if not isinstance(read_options, Mapping):
            raise ArgumentError("read_options", f"must be a dict of reader options such as {{'units': 'mm'}}, got "
                                                f"{_described(read_options)}")
        bad = [k for k in read_options if not isinstance(k, str)]
        if bad:
            raise ArgumentError("read_options", f"option names must be strings, got {_described(bad[0])}")


def resolve(settings: PlanSettings, fmt: str, has_axes: bool) -> PlanSettings:
    """``settings`` checked, with ``path`` and ``axes`` resolved for an input of format ``fmt``.

    Raises PlannerError for combinations that do not apply (naming the option), never ignores one.
    """
    s = settings.checked()
    path = s.path if s.path != "auto" else ("interpolate" if fmt in WAYPOINT_FORMATS else "cam")
    axes = s.axes
    if axes == "auto":
        axes = "file" if has_axes else ("path" if path == "interpolate" else "fixed")
    if axes in ("file", "approach") and not has_axes:
        raise PlannerError(f"axes={axes!r}: the input has no tool axes (use axes='fixed' for the CAM default +Z "
                           "or axes='path' for the tool normal to the path)", field="axes", value=s.axes)
    if s.frame != "rmf" and axes != "path":
        raise PlannerError(f"frame={s.frame!r} sets the spin about the path tangent and needs the tool normal to the "
                           f"path (axes='path'); with tool axes ({axes}) the spin about them is the exact "
                           "rotation-minimizing motion: frame='rmf'", field="frame", value=s.frame)
    if s.spin == "reach" and axes == "path":
        raise PlannerError("spin='reach' turns the tool about the tool axes of the input (axes file, approach or "
                           "fixed); with the tool normal to the path (axes='path') the spin is the frame method's",
                           field="spin", value=s.spin)
    if s.frame == "juttler" and path != "interpolate":
        raise PlannerError("frame='juttler' needs a G1 PH cubic spline through the points (path='interpolate'); "
                           "a CAM polyline fit is a PH quintic spline", field="frame", value=s.frame)
    return replace(s, path=path, axes=axes)


def plan(source, settings: PlanSettings | None = None, *, axes=None, feeds=None, read_options: dict | None = None,
         progress: Progress | None = None, fits: Sequence[PassFit] | None = None,
         pieces: Sequence[PlannedPiece] | None = None) -> PlannedJob:
    """Plan a toolpath file, a :class:`planner.io.Toolpath`, or waypoints: every pass, rapid and turn.

    Parameters
    ----------
    source : str, os.PathLike, planner.io.Toolpath or array_like (N, 3)
        A file to read (:func:`planner.io.read_toolpath`, with ``read_options`` such as
        ``{"units": "mm"}`` or ``{"machine": "haas-umc-750"}``), a reader's output, or waypoints in
        metres (a toolpath of one pass; with ``axes`` and ``feeds`` per waypoint, see
        :func:`waypoints_toolpath`).
    settings : PlanSettings, optional
        Default ``PlanSettings()``.
    progress : callable (stage, done, total), optional
        Called as the work advances, in cutting passes done of the job's passes (stages "fit", "plan", "place",
        "reach": :data:`Progress`).
    fits : sequence of PassFit, optional
        The fitted paths of every cutting pass, made apart (a large job fitted in pieces on several machines:
        :func:`fit_batches`, :func:`fit_passes_of`); the job is then the one this call would plan, export for
        export. PlannerError if they are not this input's passes.
    pieces : sequence of PlannedPiece, optional
        All the moves of the job planned apart, in consecutive pieces (a large job planned in pieces on several
        machines: :func:`fit_batches`, :func:`plan_piece`): joined, and what needs the whole sequence done here
        (placement, spin, the robot check and the arm configurations along all of it); the job is the one this
        call would plan, export for export. PlannerError if they are not this input's moves.

    Returns
    -------
    PlannedJob
        Its ``trajectory()`` streams the poses; ``summary()`` and ``describe()`` give the figures.

    Raises
    ------
    PlannerError
        Bad settings (naming the option), a file that cannot be read (naming file, line and field), a pass
        that cannot be planned (naming the file's lines or the waypoints).
    planner.errors.NumericalError
        A numerical failure of the planner itself (not the input's fault).

    Examples
    --------
    A glue bead through nine waypoints (m), at 20 mm/s: a C2 PH spline through them, one pass.

    >>> import numpy as np
    >>> from planner import PlanSettings, plan
    >>> t = np.linspace(0.0, 1.0, 9)
    >>> bead = np.c_[0.2 * t, 0.03 * np.sin(2 * np.pi * t), np.zeros_like(t)]
    >>> job = plan(bead, PlanSettings(feed=0.02))
    >>> s = job.summary()
    >>> s["path_model"], s["passes"], round(s["cut_length_mm"], 3), s["max_waypoint_error_mm"] < 1e-9
    ('interpolate', 1, 238.857, True)
    >>> round(job.duration, 2)   # s: jerk-limited, along the exact arc length
    12.07
    """
    settings = PlanSettings() if settings is None else settings
    _check_plan_arguments(settings, read_options, progress)
    timings: dict[str, float] = {}
    caught: list[str] = []
    tp, seg, s = _prepared(source, settings, axes, feeds, read_options, timings, caught)
    t_plan = timings.pop("_start")
    if fits is not None and pieces is not None:
        raise PlannerError("fits and pieces: give the fits of the passes or the planned pieces, not both")
    cuts = seg.passes
    n_cuts = len(cuts)
    joined: list[str] = []  # the pieces' warnings
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        if pieces is not None:
            moves, reports, joined = _joined(tp.source, seg, s, pieces, timings)
        else:
            tic = time.perf_counter()
            if progress is not None:
                progress("fit", 0, n_cuts)
            if fits is None:
                fits = _fit(tp.source, cuts, s, progress)
            else:
                fits = _given_fits(tp.source, cuts, fits)
            fit_time = time.perf_counter() - tic
            timings["fit"] = fit_time
            if progress is not None:
                progress("fit", n_cuts, n_cuts)
            spans_total = max(sum(len(p) - 1 for p in cuts), 1)
            moves, reports = _plan_moves(tp, seg, fits, s, fit_time / spans_total, timings, progress)
        moves, reports = _whole_sequence(moves, reports, s, timings)
    caught += joined + [str(x.message) for x in w]
    if progress is not None:
        progress("plan", n_cuts, n_cuts)
    timings["plan"] = time.perf_counter() - t_plan
    placement = None
    if isinstance(s.part_frame, str):  # "auto": the part placed for the robot, then checked like any frame
        from planner.cam.placement import place_part

        assert s.robot is not None  # PlanSettings.checked() refuses "auto" without a robot
        if progress is not None:
            progress("place", 0, n_cuts)
        tic = time.perf_counter()
        placement = place_part(moves, s.robot, s.tcp, source=tp.source)
        timings["place"] = time.perf_counter() - tic
        if progress is not None:
            progress("place", n_cuts, n_cuts)
        s = replace(s, part_frame=placement.part_frame)
    if s.spin == "reach":  # the spin about the tool axis chosen for the arm, at the part frame (given or placed)
        from planner.cam.spin_choice import choose_spin

        if progress is not None:
            progress("spin", 0, 1)
        choice = choose_spin(moves, s)
        moves = choice.moves
        timings["spin"] = choice.seconds
    job = PlannedJob(tp.source, s, tp, seg, tuple(moves), tuple(reports), timings, warnings=tuple(caught),
                     placement=placement)
    if s.robot is not None:
        from planner.cam.reach import check_job

        if progress is not None:
            progress("reach", 0, n_cuts)
        tic = time.perf_counter()
        reach = check_job(job)
        timings["reach"] = time.perf_counter() - tic
        # moves whose feed was lowered locally for the joint speed limits take their new time law
        moves = [replace(m, profile=reach.profiles[k]) if k in reach.profiles else m for k, m in enumerate(moves)]
        caps = {m.pass_index: reach.windows[k] for k, m in enumerate(moves) if m.kind == "cut" and k in reach.windows}
        duration = {m.pass_index: m.duration for m in moves if m.kind == "cut"}
        reports = [replace(r, reachable=reach.passes.get(r.index) is None, reach_message=reach.passes.get(r.index, ""),
                           feed_caps=caps.get(r.index, ()), duration=duration[r.index]) for r in reports]
        moves = _with_reconfigurations(moves, reach.reconfigurations, s)
        job = PlannedJob(tp.source, s, tp, seg, tuple(moves), tuple(reports), timings, tuple(reach.problems),
                         tuple(reach.slowed), reach.start_joints, reach.start_note, tuple(caught), placement)
        if progress is not None:
            progress("reach", n_cuts, n_cuts)
    return job


def _prepared(source, settings: PlanSettings, axes, feeds, read_options, timings: dict, caught: list):
    """The input read, the settings resolved for it, and its moves split: (toolpath, segmentation, settings); the
    planning clock's start in ``timings["_start"]``."""
    from planner.io import Toolpath, detect_format, linearize_arcs, read_toolpath

    if isinstance(source, str | os.PathLike):
        if axes is not None or feeds is not None:
            raise PlannerError("axes and feeds are for waypoint arrays; a file gives its own")
        tic = time.perf_counter()
        fmt = detect_format(source)
        check_read_options(fmt, read_options or {})
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            toolpath = read_toolpath(source, format=fmt, **(read_options or {}))
        caught += [str(x.message) for x in w]
        timings["parse"] = time.perf_counter() - tic
    else:
        if read_options:
            raise PlannerError("read_options are for a file name; the toolpath is already read")
        if isinstance(source, Toolpath):
            if axes is not None or feeds is not None:
                raise PlannerError("axes and feeds are for waypoint arrays; a Toolpath carries its own")
            toolpath = source
            fmt = getattr(source, "format", "") or _format_of(source.source)
        else:
            toolpath, fmt = waypoints_toolpath(source, axes, feeds), "waypoints"
    s = resolve(settings, fmt, toolpath.axes is not None)
    from planner.budget import check_budget

    check_budget(toolpath, s)  # before any fitting or sampling: refuses absurd work in well under a second
    timings["_start"] = time.perf_counter()
    assert s.arc_tolerance is not None  # filled in by PlanSettings.checked()
    tp = linearize_arcs(toolpath, s.arc_tolerance)
    if s.axes in ("fixed", "path") and tp.axes is not None:
        tp = replace(tp, axes=None, axis_given=None)  # the file's axes are not used: no reorientations either
    tic = time.perf_counter()
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        seg = split_passes(tp, corner_deg=s.corner_deg, axis_jump_deg=s.axis_jump_deg)
        if s.passes is not None:
            tp = _select_passes(tp, seg, s.passes)
            seg = split_passes(tp, corner_deg=s.corner_deg, axis_jump_deg=s.axis_jump_deg)
        if not seg.passes:
            raise PlannerError(f"{tp.source}: no cutting motion with at least two points")
    caught += [str(x.message) for x in w]
    timings["split"] = time.perf_counter() - tic
    return tp, seg, s


def _batch_ranges(cuts, s: PlanSettings) -> list[tuple[int, int]]:
    """The (start, stop) pass ranges :func:`_fit` fits together: CAM fits in batches of FIT_BATCH_SPANS chords, the
    others pass by pass."""
    if s.path != "cam":
        return [(k, k + 1) for k in range(len(cuts))]
    out, start, spans = [], 0, 0
    for k, p in enumerate(cuts):
        spans += len(p) - 1
        if spans >= FIT_BATCH_SPANS:
            out.append((start, k + 1))
            start, spans = k + 1, 0
    return out + ([(start, len(cuts))] if start < len(cuts) else [])


def fit_batches(source, settings: PlanSettings | None = None, *, read_options: dict | None = None,
                chords: bool = False) -> list[tuple[int, ...]]:
    """The fitting work of a job in independent pieces: the (start, stop) ranges of its cutting passes that the
    planner fits together (with ``chords``: (start, stop, CAM chords of those passes)): fitted apart
    (:func:`fit_passes_of`, e.g. on several machines) and given back to :func:`plan` (``fits=``), they make the same
    job, export for export."""
    settings = PlanSettings() if settings is None else settings
    _check_plan_arguments(settings, read_options, None)
    tp, seg, s = _prepared(source, settings, None, None, read_options, {}, [])
    ranges = _batch_ranges(seg.passes, s)
    if not chords:
        return list(ranges)
    spans = np.cumsum([0] + [len(p) - 1 for p in seg.passes])
    return [(a, b, int(spans[b] - spans[a])) for a, b in ranges]


def fit_passes_of(source, settings: PlanSettings | None, start: int, stop: int, *,
                  read_options: dict | None = None) -> list[PassFit]:
    """The fits of cutting passes ``start`` .. ``stop - 1`` (whole batches of :func:`fit_batches`, one after the
    other), as :func:`plan` fits them."""
    settings = PlanSettings() if settings is None else settings
    _check_plan_arguments(settings, read_options, None)
    tp, seg, s = _prepared(source, settings, None, None, read_options, {}, [])
    _check_batches(tp.source, seg, s, start, stop)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (plan() reports them)
        return _fit(tp.source, seg.passes[start:stop], s)


def _check_batches(source: str, seg: Segmentation, s: PlanSettings, start: int, stop: int) -> list[tuple[int, int]]:
    """The job's fit batches; PlannerError unless passes ``start`` .. ``stop - 1`` are whole ones."""
    ranges = _batch_ranges(seg.passes, s)
    bounds = {0} | {b for r in ranges for b in r}
    if not (0 <= start < stop <= len(seg.passes)) or start not in bounds or stop not in bounds:
        raise PlannerError(f"{source}: passes {start}..{stop - 1} are not whole fit batches of its "
                           f"{len(seg.passes)} passes (see fit_batches)")
    return ranges


def _piece_moves(seg: Segmentation, start: int, stop: int) -> tuple[int, int]:
    """The moves (first, stop) of the piece of cutting passes ``start`` .. ``stop - 1``: from the move after pass
    ``start - 1`` (the job's first move for the first piece) to pass ``stop - 1`` (to the job's last move for the
    last piece): the rapids, turns and dwells before a pass are its piece's."""
    at = {m.index: k for k, m in enumerate(seg.moves) if isinstance(m, CutPass)}
    return (0 if start == 0 else at[start - 1] + 1), (len(seg.moves) if stop == len(seg.passes) else at[stop - 1] + 1)


#: What planning a piece costs per CAM chord (:func:`plan_pieces`), against a chord of a pass whose tool axis varies
#: (its rotation-minimizing frames, the angular speed caps of its time law: 0.76 ms on the NX job): (planning it,
#: chaining it for a later piece (its fit and frames, no time law)) for a pass whose tool axis varies, and for one
#: whose axis is constant (frames and time law on the bare length: 0.087 ms; chained: its fit, 0.037 ms).
PIECE_COST = {"varying": (1.0, 0.23), "constant": (0.115, 0.05)}


def plan_pieces(source, settings: PlanSettings | None = None, n: int = 2, *, read_options: dict | None = None
                ) -> list[tuple[int, int, int, int]]:
    """A job's cutting passes in at most ``n`` consecutive pieces for :func:`plan_piece` on ``n`` machines, (start,
    stop, CAM chords, work) each, balanced for their cost (:data:`PIECE_COST`): a piece's passes planned and the
    passes before it chained (the later pieces have fewer passes). Fewer pieces when the job has fewer passes.

    A piece's work is the cost of planning its passes in CAM chords of a pass whose tool axis varies (a chord of a
    constant axis counts 0.115): what says whether splitting a job pays."""
    settings = PlanSettings() if settings is None else settings
    _check_plan_arguments(settings, read_options, None)
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise ArgumentError("n", f"must be a whole number of pieces >= 1, got {_described(n)}")
    tp, seg, s = _prepared(source, settings, None, None, read_options, {}, [])
    chords = np.array([len(p) - 1 for p in seg.passes])
    if s.axes == "path":  # frames about the path tangent: every pass alike, chained from the one before only
        plan_cost, chain_cost = chords.astype(float), np.zeros(len(chords))
    else:
        varying = np.array([p.axes is not None and np.ptp(p.axes, axis=0).max() > 0.0 for p in seg.passes], bool)
        (pv, cv), (pc, cc) = PIECE_COST["varying"], PIECE_COST["constant"]
        plan_cost, chain_cost = chords * np.where(varying, pv, pc), chords * np.where(varying, cv, cc)
    return [(a, b, int(chords[a:b].sum()), int(round(plan_cost[a:b].sum())))
            for a, b in balanced_pieces(plan_cost, chain_cost, n)]


def balanced_pieces(cost: np.ndarray, chain: np.ndarray, n: int) -> list[tuple[int, int]]:
    """Passes in at most ``n`` consecutive pieces (start, stop) of the least largest cost: a piece's cost the sum of
    ``cost`` (k,) over its passes plus the sum of ``chain`` (k,) over the passes before it."""
    C = np.concatenate(([0.0], np.cumsum(cost)))
    H = np.concatenate(([0.0], np.cumsum(chain)))

    def cut(most: float) -> list[tuple[int, int]]:
        out, a = [], 0
        while a < len(cost):  # each piece as long as its cost stays within ``most`` (at least one pass)
            b = max(int(np.searchsorted(C, C[a] - H[a] + most, side="right")) - 1, a + 1)
            out.append((a, b))
            a = b
        return out

    lo, hi = 0.0, float(C[-1] + H[-1]) + 1.0
    for _ in range(64):  # bisection on the largest cost
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if len(cut(mid)) <= n else (mid, hi)
    return cut(hi)


def plan_piece(source, settings: PlanSettings | None, start: int, stop: int, *,
               read_options: dict | None = None) -> PlannedPiece:
    """The moves of cutting passes ``start`` .. ``stop - 1`` planned as :func:`plan` plans them, with the rapids,
    turns and dwells before each (after the last pass of the job: those after it too): a piece of a job split across
    machines (:func:`plan_pieces`), joined by ``plan(..., pieces=...)`` into the job :func:`plan` makes, export for
    export.

    Its first move starts from the end frame of the move before it, bit for bit: the moves before it are chained
    here (their passes fitted and given their tool frames, no time law; with the tool normal to the path only the
    pass just before, whose frames do not depend on the move before it): :data:`PIECE_COST`. Passes are fitted in
    the job's fit batches (:func:`fit_batches`), whole, as :func:`plan` fits them.
    """
    tic = time.perf_counter()
    settings = PlanSettings() if settings is None else settings
    _check_plan_arguments(settings, read_options, None)
    tp, seg, s = _prepared(source, settings, None, None, read_options, {}, [])
    try:
        start, stop = operator.index(start), operator.index(stop)
    except TypeError:
        raise ArgumentError("start, stop", f"must be whole pass numbers, got {_described(start)} and "
                                           f"{_described(stop)}") from None
    if not 0 <= start < stop <= len(seg.passes):
        raise PlannerError(f"{tp.source}: passes {start}..{stop - 1} are not a range of its {len(seg.passes)} "
                           "passes")
    first, last = _piece_moves(seg, start, stop)
    # the passes fitted: this piece's, and those whose frames are chained to its first move (all before it; with
    # the tool normal to the path, the one before it), in whole fit batches
    need = 0 if s.axes != "path" else max(start - 1, 0)
    timings: dict[str, float] = {}
    fits: dict[int, PassFit] = {}
    fit_warnings: list[str] = []
    t_fit = time.perf_counter()
    for a, b in _batch_ranges(seg.passes, s):
        if b <= need or a >= stop:
            continue
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            fits.update(zip(range(a, b), _fit(tp.source, seg.passes[a:b], s), strict=True))
        if start <= a:  # a batch's warnings are the piece's that holds its first pass
            fit_warnings += [str(x.message) for x in w]
    timings["fit"] = time.perf_counter() - t_fit
    frame = None
    if first > 0:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (the pieces that plan those moves report them)
            chain_from = 0 if need == 0 else _piece_moves(seg, need, start)[1] - 1
            frame = _plan_moves(tp, seg, fits, s, 0.0, {}, first=chain_from, stop=first, chain=True)
    timings["chain"] = time.perf_counter() - t_fit - timings["fit"]
    spans = max(sum(len(p) - 1 for p in seg.passes), 1)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        moves, reports = _plan_moves(tp, seg, fits, s, timings["fit"] / spans, timings, first=first, stop=last,
                                     frame=frame)
    timings["piece"] = time.perf_counter() - tic
    return PlannedPiece(first, last, tuple(moves), tuple(reports), tuple(fit_warnings),
                        tuple(str(x.message) for x in w), timings, _settings_text(s))


def _settings_text(s: PlanSettings) -> str:
    """Resolved settings as JSON text (what a piece was planned with)."""
    import json

    return json.dumps(s.to_dict(), sort_keys=True, default=str)


def _joined(source: str, seg: Segmentation, s: PlanSettings, pieces: Sequence[PlannedPiece], timings: dict
            ) -> tuple[list, list, list[str]]:
    """The moves, pass reports and warnings (fitting's, then planning's) of pieces planned apart, checked to be
    those of ``seg`` (consecutive, whole, the same records); sums of their timings in ``timings``."""
    pieces = list(pieces)
    if not pieces or not all(isinstance(p, PlannedPiece) for p in pieces):
        raise PlannerError(f"{source}: pieces: expected planned pieces (plan_piece), got "
                           f"{_described(pieces[0] if pieces else pieces)}")
    at = 0
    settings = _settings_text(s)
    for k, p in enumerate(pieces):
        if p.settings != settings:
            raise PlannerError(f"{source}: pieces: piece {k} was planned with other settings than these")
        if p.first != at:
            raise PlannerError(f"{source}: pieces: piece {k} starts at move {p.first}, not {at} (the pieces are not "
                               "consecutive, in order)")
        at = p.stop
    if at != len(seg.moves):
        raise PlannerError(f"{source}: pieces: they end at move {at} of the job's {len(seg.moves)}")
    moves = [m for p in pieces for m in p.moves]
    for k, (m, item) in enumerate(zip(moves, seg.moves, strict=True)):
        same = type(m.item) is type(item) and (not isinstance(item, CutPass) or (
            m.item.index == item.index and np.array_equal(m.item.points, item.points)))
        if not same:
            raise PlannerError(f"{source}: pieces: move {k} is not this job's ({_where(source, item)})")
    # the job's own records (a saved job stores each once: a move's record is its segmentation's, a fit's points
    # its pass's)
    moves = [replace(m, item=item, fit=None if m.fit is None else replace(m.fit, points=item.points))
             for m, item in zip(moves, seg.moves, strict=True)]
    reports = [r for p in pieces for r in p.passes]
    if [r.index for r in reports] != [c.index for c in seg.passes]:
        raise PlannerError(f"{source}: pieces: their pass reports are not those of the job's {len(seg.passes)} passes")
    for name in ("fit", "frames", "time_law"):
        timings[name] = sum(float(p.timings.get(name, 0.0)) for p in pieces)
    return moves, reports, [x for p in pieces for x in p.fit_warnings] + [x for p in pieces for x in p.warnings]


def _given_fits(source: str, cuts, fits: Sequence[PassFit]) -> list[PassFit]:
    """Fits made apart, checked to be those of ``cuts`` (same passes, same points)."""
    fits = list(fits)
    if len(fits) != len(cuts) or not all(isinstance(f, PassFit) for f in fits):
        raise PlannerError(f"{source}: fits: {len(fits)} given for {len(cuts)} cutting passes")
    for k, (f, c) in enumerate(zip(fits, cuts, strict=True)):
        if f.points.shape != c.points.shape or not np.array_equal(f.points, c.points):
            raise PlannerError(f"{source}: fits: fit {k} is not of pass {k} (other points)")
    return fits


def _select_passes(tp, seg: Segmentation, passes):
    """The toolpath of the selected cutting passes only (each starting with a rapid after the first)."""
    cuts = seg.passes
    if not cuts:
        raise PlannerError(f"{tp.source}: no cutting motion with at least two points")
    if passes == "longest":
        passes = (int(np.argmax([np.linalg.norm(np.diff(c.points, axis=0), axis=1).sum() for c in cuts])),)
    bad = [k for k in passes if k >= len(cuts)]
    if bad:
        raise PlannerError(f"passes: {tp.source} has passes 0..{len(cuts) - 1}, not {bad[0]}")
    rows = np.concatenate([np.arange(cuts[k].source_index[0], cuts[k].source_index[-1] + 1) for k in passes])
    rapid = tp.rapid[rows].copy()
    starts = np.cumsum([0] + [cuts[k].source_index[-1] - cuts[k].source_index[0] + 1 for k in passes])[:-1]
    rapid[starts] = True
    rapid[0] = False
    def sub(a):
        return (None if a is None else a[rows])
    # the dwells at the selected points stay (the tool waits there as in the whole job)
    at = {int(r): k for k, r in enumerate(rows)}
    dwells = tuple(replace(e, index=at[e.index - 1] + 1) for e in tp.events
                   if e.kind == "dwell" and e.index - 1 in at)
    return type(tp)(tp.points[rows], sub(tp.axes), sub(tp.axis_given), tp.feeds[rows], rapid, tp.lines[rows],
                    dwells, tp.units, tp.source, sub(tp.rotary))


def check_read_options(fmt: str, options) -> None:
    """PlannerError (a :class:`planner.io.options.ReaderArgumentError`) naming the first reader option that does not
    apply to files of format ``fmt``."""
    from planner.io.dispatch import check_options

    check_options(fmt, options)


def _format_of(name: str) -> str:
    from planner.io.dispatch import SUFFIXES

    for suffix in reversed(os.path.splitext(name)[1:]):
        if suffix.lower() in SUFFIXES:
            return SUFFIXES[suffix.lower()]
    return ""


def _fit(source: str, cuts, s: PlanSettings, progress: Progress | None = None) -> list[PassFit]:
    """The PH path of every pass: within tolerance of the polyline ("cam") or through the points ("interpolate");
    ``progress("fit", passes fitted, passes)`` after each batch (cam) or pass."""
    n = len(cuts)
    if s.path == "cam":  # batched over passes, in groups of bounded size (memory grows with the spans fitted at once)
        out: list[PassFit] = []
        group: list = []
        spans = 0
        for p in cuts:
            group.append(p.points)
            spans += len(p) - 1
            if spans >= FIT_BATCH_SPANS:
                out += fit_passes(group, s.tolerance)
                group, spans = [], 0
                if progress is not None:
                    progress("fit", len(out), n)
        return out + (fit_passes(group, s.tolerance) if group else [])
    from planner.curves import fit_ph_cubic_spline, fit_ph_spline

    out = []
    for p in cuts:
        try:
            path = fit_ph_cubic_spline(p.points) if s.frame == "juttler" else fit_ph_spline(p.points)
        except PlannerError as exc:
            raise PlannerError(f"{_where(source, p)}: {exc}") from exc
        dev = _chord_deviation(path, p.points)
        out.append(PassFit(path, p.points, float(dev.max()), dev, 0, 0, 0))
        if progress is not None:
            progress("fit", len(out), n)
    return out


def _chord_deviation(path, points: np.ndarray, samples: int = 16) -> np.ndarray:
    """Largest distance (m - 1,) of the path from each chord between consecutive points (sampled)."""
    k = path.waypoint_knots
    u = k[:-1, None] + np.diff(k)[:, None] * np.linspace(0.0, 1.0, samples + 1)[None, 1:-1]
    P = path.points(u.ravel()).reshape(u.shape + (3,))
    a, d = points[:-1, None, :], np.diff(points, axis=0)[:, None, :]
    lam = np.clip(np.einsum("mki,mki->mk", P - a, d) / np.maximum(np.einsum("mki,mki->mk", d, d), 1e-300), 0.0, 1.0)
    dist = np.linalg.norm(P - (a + lam[..., None] * d), axis=-1)
    return dist.max(axis=1) if dist.shape[1] else np.zeros(len(points) - 1)


def _tool_z(axes: np.ndarray | None, n: int, source: str) -> np.ndarray:
    """Unit tool approach axes (tool z) (n, 3): the one owner of the tool-axis sign.

    Files give CAM vectors (from the tip towards the spindle): tool z is their negative ("file"); with
    ``axes="approach"`` the vectors are tool z already; without axes, the CAM default +Z (tool z = -Z).
    """
    if axes is None:
        return np.broadcast_to(-CAM_DEFAULT_AXIS, (n, 3)).copy()
    a = np.asarray(axes, dtype=float)
    sign = 1.0 if source == "approach" else -1.0
    return sign * a / np.linalg.norm(a, axis=-1, keepdims=True)  # files write 7 digits: |v| = 1 +- 1e-7


def _where(source: str, item) -> str:
    if isinstance(item, CutPass):
        return f"{source} lines {item.first_line}-{item.last_line} ({item.describe()})"
    if isinstance(item, RapidMove | Reorientation | Dwell):
        return f"{source} line {item.line} ({item.kind})"
    return source


def _with_reconfigurations(moves: list, changes: list, s: PlanSettings) -> list:
    """The moves with a joint move inserted before move k for every (k, Reconfiguration) in ``changes``."""
    from planner.cam.moves import joint_move_profile
    from planner.kinematics import get_model

    out = list(moves)
    assert s.robot is not None  # changes of configuration come from the robot check
    speeds = get_model(s.robot).speed_limits
    for k, r in sorted(changes, key=lambda c: c[0], reverse=True):
        F = moves[k].start_frame
        profile = joint_move_profile(r.q_from, r.q_to, s.joint_limits, speeds)
        out.insert(k, PlannedMove("reconfiguration", r, None, None, profile, F, F, r.point.copy()))
    return out


class _PathFields(dict):
    """With the tool normal to the path: every pass's frame field (method ``s.frame``, starting nearest -Z), made
    when first asked for (a piece of a split job needs only its own passes' and the one before)."""

    def __init__(self, fits, s: PlanSettings):
        super().__init__()
        self.fits, self.frame = fits, s.frame

    def __missing__(self, index: int) -> PathToolField:
        self[index] = field = path_tool_field(self.fits[index].path, self.frame)
        return field


def _next_cut_z(seg: Segmentation, k: int, fields: dict) -> np.ndarray | None:
    """Tool z at the start of the first cut after move k (tool normal to the path), None if there is none."""
    for item in seg.moves[k + 1:]:
        if isinstance(item, CutPass):
            return fields[item.index].start[:, 2]
    return None


def _plan_moves(tp, seg: Segmentation, fits, s: PlanSettings, fit_share: float, timings: dict, progress=None, *,
                first: int = 0, stop: int | None = None, frame: np.ndarray | None = None, chain: bool = False):
    """Frames and time laws of moves ``first`` .. ``stop - 1`` (default: all), in order, each starting from the
    previous end frame (``frame``: the end frame of move ``first - 1``; None before any motion).

    With ``chain``: only the frames the moves pass on (no time law of a cut, no pass reports), to find a later
    move's start frame; returns that end frame (3, 3) or None. Else (moves, pass reports).
    """
    moves: list[PlannedMove] = []
    reports: list[PassReport] = []
    t_frames = t_law = 0.0
    cut_limits = MotionLimits(s.limits.speed, s.limits.acceleration, s.limits.jerk)
    on_path = s.axes == "path"
    fields = _PathFields(fits, s)
    n_cuts = len(seg.passes)
    for n_done in range(first, len(seg.moves) if stop is None else stop):
        item = seg.moves[n_done]
        if progress is not None and isinstance(item, CutPass):
            progress("plan", len(reports), n_cuts)  # passes given their frames and time law so far
        try:
            if isinstance(item, CutPass):
                tic = time.perf_counter()
                fit = fits[item.index]
                field: PathToolField | AxisField
                if on_path:
                    field = fields[item.index]
                    z = field.start[None, :, 2]
                else:
                    z = _tool_z(item.axes, len(item), s.axes)
                    field = axis_field(fit.path, z, start=frame)
                t1 = time.perf_counter()
                t_frames += t1 - tic
                if chain:
                    frame = field.end
                    continue
                feeds = item.feeds[1:] * s.feed_override
                job_feed = s.feed * s.feed_override
                capped = s.limits.angular_speed is not None and _turns_fast(field, feeds, job_feed, s.limits)
                f = np.where(np.isnan(feeds), job_feed, feeds)
                if not capped and (f == f[0]).all():  # one feed: plan on the bare length (same profile)
                    profile = plan_feed(float(fit.path.length), float(f[0]), cut_limits)
                else:
                    profile = plan_feed(fit.path, job_feed, s.limits if capped else cut_limits,
                                        span_feeds=None if np.isnan(feeds).all() else feeds,
                                        orientation=tool_orientation(field) if capped else None)
                t2 = time.perf_counter()
                end = field.end
                moves.append(PlannedMove("cut", item, fit.path, field, profile, field.start, end,
                                         item.points[0], item.index, fit))
                reports.append(_pass_report(item, fit, field, profile, t2 - tic + fit_share * (len(item) - 1)))
                t_law += t2 - t1
                frame = end
            elif isinstance(item, RapidMove):
                tic = time.perf_counter()
                if on_path:  # the tool keeps its axis, then turns onto the next pass's start axis
                    z0 = frame[:, 2] if frame is not None else _tool_z(None, 1, s.axes)[0]
                    z1 = _next_cut_z(seg, n_done, fields)
                    z1 = z0 if z1 is None else z1
                else:
                    z0 = _tool_z(None if item.start_axis is None else item.start_axis[None], 1, s.axes)[0]
                    z1 = _tool_z(None if item.end_axis is None else item.end_axis[None], 1, s.axes)[0]
                start = frame_with_axis(z0, item.end - item.start) if frame is None else transport(frame, z0)
                path = straight_path(item.start, item.end)
                fr = rapid_frames(path, start, z1)
                frame = transport(fr.end, z1)  # column 2 exactly z1 (the rotation leaves round-off)
                if chain:
                    continue
                v = s.rapid_speed
                if fr.angle > 0.0 and s.limits.angular_speed is not None:  # the axis turns at angle / L rad/m
                    v = min(v, s.limits.angular_speed * path.length / fr.angle)
                profile = plan_feed(float(path.length), v, MotionLimits(v, s.limits.acceleration, s.limits.jerk))
                moves.append(PlannedMove("rapid", item, path, fr, profile, start, frame, item.start.copy()))
                t_law += time.perf_counter() - tic
            elif isinstance(item, Reorientation):
                z0, z1 = _tool_z(np.vstack((item.axis_from, item.axis_to)), 2, s.axes)
                start = frame_with_axis(z0, np.array([1.0, 0.0, 0.0])) if frame is None else transport(frame, z0)
                fr = turn_frames(start, z1)
                frame = transport(fr.end, z1)
                if not chain:
                    turn = turn_profile(fr.angle, s.turn_limits) if fr.angle > 0.0 else None
                    moves.append(PlannedMove("reorientation", item, None, fr, turn, start, frame, item.point.copy()))
            elif not chain:  # a dwell: the tool at rest where the previous move ended, for the dwell's time (before
                # any motion: it takes the first move's start frame, :func:`_leading_dwells`); else Skipped
                F = frame if frame is not None else frame_with_axis(-CAM_DEFAULT_AXIS, np.array([1.0, 0.0, 0.0]))
                kind = "dwell" if isinstance(item, Dwell) else "skipped"
                moves.append(PlannedMove(kind, item, None, None, None, F, F, item.point.copy()))
        except PlannerError as exc:
            raise PlannerError(f"{_where(tp.source, item)}: {exc}") from exc
    timings["frames"] = timings.get("frames", 0.0) + t_frames
    timings["time_law"] = timings.get("time_law", 0.0) + t_law
    if chain:
        return frame
    return moves, reports


def _whole_sequence(moves: list, reports: list, s: PlanSettings, timings: dict) -> tuple[list, list]:
    """What the planned moves need from the whole sequence: the dwells before any motion in the first move's start
    frame, and every pass's spin of the naive CAM orientations (``slerp_spin_deg``)."""
    first = next((m for m in moves if m.kind not in ("dwell", "skipped")), None)
    if first is not None:
        moves = [replace(m, start_frame=first.start_frame, end_frame=first.start_frame) if m.kind == "dwell" else m
                 for m in moves[:moves.index(first)]] + moves[moves.index(first):]
    tic = time.perf_counter()
    cut_items = [m.item for m in moves if isinstance(m.item, CutPass)]
    if s.axes == "path":
        slerp = np.full(len(cut_items), math.nan)
    else:
        slerp = np.degrees(travel_spin([c.points for c in cut_items],
                                       [_tool_z(c.axes, len(c), s.axes) for c in cut_items]))
    reports = [replace(r, slerp_spin_deg=float(v)) for r, v in zip(reports, slerp, strict=True)]
    timings["frames"] = timings.get("frames", 0.0) + time.perf_counter() - tic
    return moves, reports


def _turns_fast(field, feeds: np.ndarray, job_feed: float, limits: MotionLimits) -> bool:
    """Whether the angular speed limit can matter on a pass: the tool axis turns by |dz/ds| rad/m
    (the rotation-minimizing frames turn only with the axis), sampled 8 times per span, times the
    fastest feed exceeds half the limit (the margin covers peaks between samples). Frames about the
    path tangent turn with its curvature: always capped."""
    if isinstance(field, PathToolField):
        return True
    if field.motion is None:
        return False
    k = field.path.waypoint_knots
    u = (k[:-1, None] + np.diff(k)[:, None] * np.linspace(0.0, 1.0, 9)).ravel()
    rate = np.linalg.norm(field.motion.dz(u), axis=1) / field.path.speed(u)  # |dz/ds| = |dz/du| / |dr/du|
    v = min(float(np.max(np.where(np.isnan(feeds), job_feed, feeds))), limits.speed)
    return limits.angular_speed is not None and float(rate.max()) * v > 0.5 * limits.angular_speed


def _pass_report(item: CutPass, fit: PassFit, field, profile, elapsed: float) -> PassReport:
    path = fit.path
    k = path.knots
    u = np.append((k[:-1, None] + np.diff(k)[:, None] * np.linspace(0.0, 1.0, 5)[:-1]).ravel(), k[-1])
    if isinstance(field, PathToolField):
        spin = spin_about_axis(field.frames(u))
        axis_error = departure = math.nan
        twist = field.max_twist_deg()
    else:
        twist = math.nan
        # frames at every knot and 4 points per segment, slerped between (the RMM's spin is 0)
        spin = 0.0 if field.motion is None else spin_about_axis(field.frames(u))
        axis_error = float(np.degrees(field.axis_errors().max()))
        departure = float(np.degrees(axis_departure(field)))
    return PassReport(
        index=item.index, operation=item.operation, first_line=item.first_line, last_line=item.last_line,
        points=len(item), length=path.length, max_deviation=fit.max_deviation,
        max_axis_error_deg=axis_error, max_axis_departure_deg=departure, knots_added=fit.knots_added,
        start_reason=item.start_reason, end_reason=item.end_reason, start_corner_deg=item.start_corner_deg,
        duration=float(profile.duration), spin_deg=float(np.degrees(spin)), slerp_spin_deg=math.nan,
        planning_time=elapsed, merged=item.merged, max_twist_deg=twist,
        max_waypoint_error=float(path.interpolation_errors(item.points).max()),
    )
