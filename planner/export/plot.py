"""One picture of a planned job for every mode (matplotlib, PNG): the paths and tool axes in 3D at equal
scale, the tool frames' figure for the chosen options, the TCP speed envelope, the joints against their limits,
and the fit of the path.

The frame panel shows what the options make worth seeing: with the tool normal to the path and a method
other than the exact RMF, its twist against the exact RMF along the cut; with tool axes, the spin about the
tool axis per pass against slerping the orientations, and the axes' distance from the great circles between
the given axes. Where there is nothing of the frames to plot (the exact RMF about the path; tool axes constant
along every pass) the 3D panel takes the frame panel's place and its title says why. The fit panel shows the
distance from the polyline against the tolerance ("cam") or how far the interpolating spline bows from the
chords ("interpolate").

A whole job is millions of poses. The trajectory is read once, chunk by chunk (:func:`digest`): the speed
panel keeps the lowest and highest TCP speed of each time bin, the joint panel every k-th sample (and each
move's last), so memory stays bounded whatever the length of the job. The 3D panel draws the planned paths
themselves (a few points per PH segment).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from planner.errors import PlannerError
from planner.wording import counted

#: Image types the plot writes (by the target's suffix).
PLOT_SUFFIXES = (".png", ".svg", ".pdf")


def check_plot_target(target, *inputs) -> None:
    """PlannerError unless ``target`` names an image type the plot writes and a file it may replace (a regular
    file or a new one, through symbolic links; none of the ``inputs``): checked before any work."""
    from planner.export.files import check_output

    suffix = os.path.splitext(os.fspath(target))[1].lower()
    if suffix not in PLOT_SUFFIXES:
        raise PlannerError(f"--plot {os.fspath(target)}: unknown image type {suffix or '(none)'!r} "
                           f"(use {', '.join(PLOT_SUFFIXES)})")
    try:
        check_output(target, *inputs)
    except PlannerError as exc:
        raise PlannerError(f"--plot {exc}") from None


def new_figure(title: str, size: tuple[float, float] = (13, 9.5)):
    """A matplotlib figure on the Agg backend (no display needed) with a title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=size)
    fig.suptitle(title, fontsize=13)
    return fig


def save(fig, target, dpi: int = 110, image_format: str | None = None) -> None:
    """Lay out, write the picture atomically (its type from the suffix) and release the figure; a binary file
    object gets ``image_format`` ("png", "svg" or "pdf"; default PNG)."""
    import io

    import matplotlib.pyplot as plt

    from planner.export.files import write_bytes_atomic

    fig.tight_layout()
    buf = io.BytesIO()
    stream = hasattr(target, "write")
    kind = (image_format or "png") if stream else os.path.splitext(os.fspath(target))[1].lower().lstrip(".")
    fig.savefig(buf, dpi=dpi, format=kind)
    plt.close(fig)
    if stream:  # a binary file object (e.g. an HTTP response body)
        target.write(buf.getvalue())
    else:
        write_bytes_atomic(target, buf.getvalue())


def tool_axes(ax, points: np.ndarray, frames: np.ndarray, scale: float) -> None:
    """Tool z (red) and tool x (green) arrows of ``frames`` (n, 3, 3) at ``points`` (n, 3) on a 3D axes."""
    q, F = points, frames
    ax.quiver(q[:, 0], q[:, 1], q[:, 2], *(F[:, :, 2].T * scale), color="tab:red", lw=0.8, label="tool z")
    ax.quiver(q[:, 0], q[:, 1], q[:, 2], *(F[:, :, 0].T * scale * 0.6), color="tab:green", lw=0.6, label="tool x")


def label_path_axes(ax, title: str) -> None:
    """Axis labels (mm), plain tick labels (no offset notation), title and legend of a 3D path panel."""
    from matplotlib.ticker import MaxNLocator, ScalarFormatter

    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        fmt = ScalarFormatter(useOffset=False)
        fmt.set_scientific(False)
        axis.set_major_formatter(fmt)
        axis.set_major_locator(MaxNLocator(5))
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    ax.set_title(title)
    ax.legend(loc="upper left", fontsize=8)


def joints_panel(ax, t: np.ndarray, joints: np.ndarray, robot: str, ok: bool) -> None:
    """Joint positions (n, 6) in degrees against time (n,), with the model's position limits."""
    from planner.kinematics import get_model

    m = get_model(robot)
    for j in range(6):
        ax.plot(t, np.degrees(joints[:, j]), lw=1.0, label=f"q{j + 1}")
    lo, hi = np.degrees(np.min(m.q_min)), np.degrees(np.max(m.q_max))
    ax.axhline(lo, color="k", ls=":", lw=0.8)
    ax.axhline(hi, color="k", ls=":", lw=0.8, label="limits")
    ax.set_ylabel("joint [deg]")
    ax.set_title(f"{robot} joints ({'within limits' if ok else 'LIMITS VIOLATED'})")
    ax.legend(fontsize=7, ncol=4)
    ax.set_xlabel("time [s]")
    ax.grid(alpha=0.3)


@dataclass(frozen=True, eq=False)
class StreamDigest:
    """What the plot keeps of a job's pose stream.

    Attributes
    ----------
    edges : ndarray (B + 1,)
        Time bins of the speed envelope, s.
    speed : dict
        "cut" and "other" (rapids, turns) -> (lowest, highest) TCP speed per bin (B,), m/s; NaN in
        bins without samples of that kind.
    times : ndarray (m,)
        Times of the kept poses, s (every ``step``-th sample and each move's last).
    poses : ndarray (m, 6)
        The kept poses (base frame).
    joints : ndarray (m, 6) or None
        The robot's joint positions at the kept poses (rad), on one branch over the job.
    step : int
        Sample step of the kept poses.
    samples : int
        Poses in the whole stream.
    """

    edges: np.ndarray
    speed: dict
    times: np.ndarray
    poses: np.ndarray
    joints: np.ndarray | None
    step: int
    samples: int


def _bin_extremes(b: np.ndarray, v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """Fold values v into per-bin minima lo and maxima hi (b sorted ascending, same length as v)."""
    if v.size == 0:
        return
    starts = np.concatenate(([0], np.flatnonzero(np.diff(b)) + 1))
    at = b[starts]
    lo[at] = np.fmin(lo[at], np.minimum.reduceat(v, starts))
    hi[at] = np.fmax(hi[at], np.maximum.reduceat(v, starts))


def digest(trajectory, *, bins: int = 1500, max_points: int = 20_000) -> StreamDigest:
    """Read a trajectory once: the TCP speed envelope in ``bins`` time bins and about ``max_points`` samples
    (with the robot's joints when the job has a robot)."""
    job, rate = trajectory.job, trajectory.rate
    total = trajectory.n_samples
    step = max(1, math.ceil(total / max_points))
    edges = np.linspace(0.0, max(job.duration, 1.0 / rate), bins + 1)
    speed = {k: (np.full(bins, np.nan), np.full(bins, np.nan)) for k in ("cut", "other")}
    kept: list = []
    offset, p_last = 0, None

    def thinned():
        nonlocal offset, p_last
        for c in trajectory.chunks(joints=False):
            p = c.poses[:, :3] if p_last is None else np.vstack((p_last, c.poses[:, :3]))
            t = c.times if p_last is None else np.concatenate((c.times[:1] - 1.0 / rate, c.times))
            v = np.linalg.norm(np.diff(p, axis=0), axis=1) * rate
            b = np.clip(np.searchsorted(edges, 0.5 * (t[1:] + t[:-1]), side="right") - 1, 0, bins - 1)
            _bin_extremes(b, v, *speed["cut" if c.kind == "cut" else "other"])
            p_last = c.poses[-1, :3]
            yield c.every(step, offset)
            offset += c.times.size

    if job.settings.robot is not None:
        from planner.trajectory import track_joints

        kept = [(c, c.joints) for c in track_joints(job, thinned())]
    else:
        kept = [(c, None) for c in thinned()]
    times = np.concatenate([c.times for c, _ in kept]) if kept else np.zeros(0)
    poses = np.concatenate([c.poses for c, _ in kept]) if kept else np.zeros((0, 6))
    joints = np.concatenate([q for _, q in kept]) if kept and job.settings.robot is not None else None
    return StreamDigest(edges, speed, times, poses, joints, step, total)


def _path_lines(job, per_segment: int = 4):
    """Polylines (part frame, mm) of every cut and of the rapids: (list of (n, 3) per pass, (m, 3) with
    NaN rows between rapids)."""
    cuts, rapids = [], []
    for m in job.moves:
        if m.path is None:
            continue
        k = np.asarray(m.path.knots, dtype=float)
        u = np.append((k[:-1, None] + np.diff(k)[:, None] * np.arange(per_segment) / per_segment).ravel(), k[-1])
        p = m.path.points(u) * 1e3
        if m.kind == "cut":
            cuts.append(p)
        else:
            rapids += [p[[0, -1]], np.full((1, 3), np.nan)]
    return cuts, (np.vstack(rapids) if rapids else np.zeros((0, 3)))


def _axis_stations(job, n: int):
    """Points (n, 3) in mm and tool frames (n, 3, 3) evenly spaced along the total cut length (part frame)."""
    from planner.motion import poses_at_length, tool_orientation

    cuts = [m for m in job.moves if m.kind == "cut"]
    if not cuts:
        return np.zeros((0, 3)), np.zeros((0, 3, 3))
    lengths = np.array([m.path.length for m in cuts])
    cum = np.concatenate(([0.0], np.cumsum(lengths)))
    g = np.linspace(0.0, cum[-1], n)
    which = np.clip(np.searchsorted(cum, g, side="right") - 1, 0, len(cuts) - 1)
    pts, frames = [], []
    for i in np.unique(which):
        m = cuts[i]
        s = np.clip(g[which == i] - cum[i], 0.0, m.path.length)
        p, R, _ = poses_at_length(m.path, tool_orientation(m.frames), s)
        pts.append(p * 1e3)
        frames.append(R)
    return np.vstack(pts), np.concatenate(frames)


def plot_job(job, target, *, rate: float | None = None, title: str | None = None, axes_shown: int = 60,
             bins: int = 1500, max_points: int = 20_000, execution=None, image_format: str | None = None
             ) -> StreamDigest:
    """Write the picture of a planned job (:class:`planner.PlannedJob`) to ``target`` (a path ending in .png,
    .svg or .pdf, written atomically; or a binary file object, which gets a PNG).

    Parameters
    ----------
    job : PlannedJob
    target : path or binary file object
    rate : float, optional
        Rate of the trajectory read for the speed and joint panels, Hz (default the job's).
    title : str, optional
    axes_shown : int
        Tool frames drawn, evenly spaced along the total cut length.
    bins, max_points : int
        Time bins of the speed envelope and samples kept for the joint panel (:func:`digest`).
    execution : execution report, optional
        How a run of the job went (duck-typed, e.g. ``drivers.report.ExecutionReport``: ``trace`` with ``t``
        (n,) s, ``xyz`` (n, 3) m base frame, ``speed`` (n,) m/s, ``io`` (n,) output bits; ``io_events`` with
        ``bit``, ``value``, ``planned_t``, ``actual_t``, ``distance_mm``; ``mode``, ``ok``, ``reason``,
        ``max_path_error`` m). Drawn over the plan: the actual TCP path in the 3D panel with the planned
        stations and the actual switches, the actual TCP speed over the planned envelope, and a panel of the
        outputs planned against the outputs switched.
    image_format : {"png", "svg", "pdf"}, optional
        The image type written to a file object (default PNG); a path's type is its suffix.

    Returns
    -------
    StreamDigest
        What was drawn from the trajectory.
    """
    import matplotlib
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    if not hasattr(target, "write"):
        check_plot_target(target)
    elif image_format not in (None, *(sfx.lstrip(".") for sfx in PLOT_SUFFIXES)):
        raise PlannerError(f"image_format must be one of {', '.join(sfx.lstrip('.') for sfx in PLOT_SUFFIXES)}, "
                           f"got {image_format!r}")
    dg = digest(job.trajectory(rate), bins=bins, max_points=max_points)
    rate = float(rate or job.settings.rate)
    s = job.summary()
    st = job.settings
    run = _execution_view(job, execution, dg) if execution is not None else None
    head = title or f"{job.source}: {counted(s['passes'], 'pass')}"
    if run is not None:
        head += "\n" + run["title"]
    fig = new_figure(head, size=(17, 14 if run is not None else 10))
    grid = fig.add_gridspec(3, 3, height_ratios=(1.0, 1.0, 0.55)) if run is not None else fig.add_gridspec(2, 3)

    note = _frames_note(job)  # nothing to plot about the frames: the path panel takes the whole row
    ax = fig.add_subplot(grid[0, 0:3] if note else grid[0, 0:2], projection="3d")
    cuts, rapids = _path_lines(job)
    cmap = matplotlib.colormaps["viridis"]
    if cuts:
        colors = cmap(np.linspace(0.0, 1.0, len(cuts)))
        ax.add_collection3d(Line3DCollection(cuts, colors=colors, linewidths=1.0))
        ax.plot([], [], color=cmap(0.5), label=f"{counted(len(cuts), 'pass')} (colour: order)")
    if rapids.size:
        ax.plot(rapids[:, 0], rapids[:, 1], rapids[:, 2], color="0.45", lw=0.7, ls="--", label="rapids")
    allp = np.vstack([*cuts, rapids[np.isfinite(rapids).all(axis=1)]]) if cuts or rapids.size else np.zeros((1, 3))
    q, F = _axis_stations(job, axes_shown)
    scale = 0.05 * max(float(np.ptp(allp, axis=0).max()), 1e-6)
    allp = np.vstack((allp, q + scale * F[:, :, 2]))  # room for the tool axes
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    span = np.maximum(hi - lo, 0.3 * max(float((hi - lo).max()), 1e-6))  # equal scale, flat jobs thickened
    mid = 0.5 * (lo + hi)
    ax.set_xlim(mid[0] - 0.5 * span[0], mid[0] + 0.5 * span[0])
    ax.set_ylim(mid[1] - 0.5 * span[1], mid[1] + 0.5 * span[1])
    ax.set_zlim(mid[2] - 0.5 * span[2], mid[2] + 0.5 * span[2])
    ax.set_box_aspect(span, zoom=1.15)
    if len(q):
        tool_axes(ax, q, F, scale)
    if run is not None:
        _execution_path(ax, run)
    label_path_axes(ax, f"paths (part frame, {st.path}): {s['cut_length_mm']:.0f} mm of cut, "
                        f"{counted(s['rapids'], 'rapid')}, {counted(s['reorientations'], 'turn')} in place"
                        + (f"; {note}" if note else ""))
    if not note:
        _frames_panel(fig.add_subplot(grid[0, 2]), job, s)

    ax = fig.add_subplot(grid[1, 0] if st.robot is not None else grid[1, 0:2])  # no empty joint panel
    t_mid = 0.5 * (dg.edges[1:] + dg.edges[:-1])
    for kind, color, label in (("other", "0.5", "rapids"), ("cut", "tab:blue", "cuts")):
        v_lo, v_hi = (1e3 * a for a in dg.speed[kind])
        if np.isfinite(v_hi).any():
            ax.fill_between(t_mid, np.where(v_lo > 0, v_lo, np.nan), v_hi, color=color, alpha=0.3, lw=0)
            ax.plot(t_mid, v_hi, color=color, lw=0.8, label=f"{label}: highest speed per bin")
    if run is not None:
        v = 1e3 * run["speed"]
        ax.plot(run["t"], np.where(v > 0, v, np.nan), color="tab:red", lw=0.6, alpha=0.8,
                label=f"actual ({run['mode']} run)")
    ax.set_yscale("log")
    peaks = 1e3 * np.concatenate([v_hi for _, v_hi in dg.speed.values()])
    peaks = peaks[np.isfinite(peaks) & (peaks > 0)]
    if peaks.size:  # the lows reach 0 at every stop: show a decade below the usual speeds
        ax.set_ylim(0.1 * float(np.percentile(peaks, 5)), 2.0 * float(peaks.max()))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("TCP speed [mm/s]")
    ax.set_title(f"TCP speed, {dg.samples} poses at {rate:g} Hz ({s['duration_s']:.1f} s)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")

    if st.robot is not None:
        ax = fig.add_subplot(grid[1, 1])
        assert dg.joints is not None  # a job with a robot: the digest tracked its joints
        joints_panel(ax, dg.times, dg.joints, st.robot, not job.problems)
        ax.set_title(f"{st.robot} joints, 1 pose in {dg.step} "
                     f"({'within limits' if not job.problems else f'{len(job.problems)} move(s) with problems'})")

    _fit_panel(fig.add_subplot(grid[1, 2]), job, s)
    if run is not None:
        _execution_io_panel(fig.add_subplot(grid[2, 0:3]), run)
    save(fig, target, image_format=image_format)
    return dg


def _execution_view(job, execution, dg: StreamDigest) -> dict:
    """What the plot draws of a run (see plot_job's ``execution``), in the part frame, mm."""
    from planner.kinematics.poses import as_transform

    tr = getattr(execution, "trace", None)
    if tr is None:
        raise PlannerError("execution= needs a report with a trace of the run (its 'trace' is missing)")
    t = np.asarray(tr.t, dtype=float).reshape(-1)
    xyz = np.asarray(tr.xyz, dtype=float).reshape(-1, 3)
    speed = np.asarray(tr.speed, dtype=float).reshape(-1)
    io = np.asarray(tr.io, dtype=np.int64).reshape(-1)
    if not (xyz.shape[0] == speed.size == io.size == t.size):
        raise PlannerError(f"execution trace: t, xyz, speed and io differ in length ({t.size}, {xyz.shape[0]}, "
                           f"{speed.size}, {io.size})")
    Tb = as_transform(job.settings.part_frame, "part_frame")
    Rb, pb = Tb[:3, :3], Tb[:3, 3]
    part = (xyz - pb) @ Rb * 1e3  # base frame (m) -> part frame (mm)
    events = list(getattr(execution, "io_events", ()))
    # planned stations: the planned pose at each planned switch time (the digest's kept poses, nearest in time)
    planned_at = []
    for e in events:
        if dg.times.size and math.isfinite(e.planned_t):
            k = int(np.clip(np.searchsorted(dg.times, e.planned_t), 0, dg.times.size - 1))
            planned_at.append((dg.poses[k, :3] - pb) @ Rb * 1e3)
    change = np.flatnonzero(io[1:] != io[:-1]) + 1
    ok = bool(getattr(execution, "ok", True))
    err = float(getattr(execution, "max_path_error", math.nan))
    done = [e.distance_mm for e in events if math.isfinite(e.distance_mm)]
    head = (f"run ({getattr(execution, 'mode', 'run')}): {'ok' if ok else 'FAILED: ' + str(execution.reason)}, "
            f"actual TCP within {1e3 * err:.3f} mm of the planned path")
    if events:
        head += f", {len(done)} of {len(events)} switches made" + (
            f" within {max(done):.3f} mm of their stations" if done else "")
    return {"t": t, "xyz": part, "speed": speed, "io": io, "events": events, "switch_xyz": part[change],
            "planned_xyz": np.asarray(planned_at).reshape(-1, 3), "mode": getattr(execution, "mode", "run"),
            "title": head}


def _execution_path(ax, run: dict) -> None:
    p = run["xyz"]
    if p.shape[0]:
        ax.plot(p[:, 0], p[:, 1], p[:, 2], color="tab:red", lw=0.8, alpha=0.9, label="actual TCP path (run)")
    if run["planned_xyz"].shape[0]:
        q = run["planned_xyz"]
        ax.scatter(q[:, 0], q[:, 1], q[:, 2], marker="o", s=40, facecolors="none", edgecolors="k",
                   label="I/O stations (planned)")
    if run["switch_xyz"].shape[0]:
        q = run["switch_xyz"]
        ax.scatter(q[:, 0], q[:, 1], q[:, 2], marker="x", s=40, color="tab:red", label="I/O switched (run)")


def _execution_io_panel(ax, run: dict) -> None:
    """The outputs the plan switches (step lines from the planned switch times) against the ones the run
    switched (the trace's output bits), one row per output bit."""
    from planner.kinematics.ur_outputs import DIGITAL_BITS, bit_name

    events = run["events"]
    bits = sorted({int(e.bit) for e in events} | {b for b in range(DIGITAL_BITS) if np.any((run["io"] >> b) & 1)})
    t = run["t"]
    t_end = float(t[-1]) if t.size else 1.0
    for row, b in enumerate(bits):
        ev = sorted((e for e in events if int(e.bit) == b and math.isfinite(e.planned_t)), key=lambda e: e.planned_t)
        tp = [0.0] + [float(e.planned_t) for e in ev] + [t_end]
        vp = [0.0] + [float(bool(e.value)) for e in ev]
        ax.step(tp, [row + 0.8 * v for v in vp] + [row + 0.8 * vp[-1]], where="post", color="k", lw=1.0,
                label="planned" if row == 0 else None)
        if t.size:
            ax.step(t, row + 0.8 * ((run["io"] >> b) & 1) + 0.04, where="post", color="tab:red", lw=1.0,
                    label="switched (run)" if row == 0 else None)
        for e in ev:
            if math.isfinite(e.actual_t):
                ax.annotate(f"{e.distance_mm:.3f} mm", (float(e.actual_t), row + 0.4), fontsize=7,
                            xytext=(3, 0), textcoords="offset points")
    ax.set_yticks([row + 0.4 for row in range(len(bits))], [bit_name(b) for b in bits])
    ax.set_xlabel("time [s]")
    ax.set_title("digital outputs: planned against switched in the run (distance of each switch from its station)")
    if bits:
        ax.legend(fontsize=8, loc="upper right")
    ax.grid(alpha=0.3)


def _frames_note(job) -> str | None:
    """Why the job has no tool frames' figure (the path panel takes its place and says so), or None."""
    if job.settings.axes == "path":
        return "exact RMF about the tangent: no twist" if job.settings.frame == "rmf" else None
    if _spin_figures(job) is not None:
        return None
    if all(max(abs(p.slerp_spin_deg), abs(p.spin_deg), abs(p.max_axis_departure_deg)) < 1e-9 for p in job.passes):
        return "tool axis constant along every pass: no spin"
    return None


def _frames_panel(ax, job, s: dict) -> None:
    """The tool frames' figure for the chosen options (see the module doc; a job with :func:`_frames_note` has
    none)."""
    idx = np.array([p.index for p in job.passes])
    if _spin_figures(job) is not None:
        _spin_panel(ax, job, s["spin"])
        return
    if job.settings.axes == "path":
        offset = 0.0
        for m in job.moves:
            if m.kind != "cut":
                continue
            sv, ang = m.frames.twist_curve(401)
            ax.plot(1e3 * (offset + sv), ang, lw=0.9, color="tab:purple")
            offset += float(m.path.length)
        ax.set_xlabel("arc length along the cuts [mm]")
        ax.set_ylabel("twist against the exact RMF [deg]")
        ax.set_title(f"{job.settings.frame}: largest twist {s['max_twist_vs_exact_rmf_deg']:.3g} deg")
        ax.grid(alpha=0.3)
        return
    ax.plot(idx, [p.slerp_spin_deg for p in job.passes], ".", ms=4, color="tab:orange",
            label=f"orientations slerped point to point (total {s['slerp_spin_deg']:.4g} deg)")
    ax.plot(idx, [p.spin_deg for p in job.passes], ".", ms=4, color="tab:purple",
            label=f"planned frames (total {s['spin_deg']:.3g} deg)")
    ax.plot(idx, [p.max_axis_departure_deg for p in job.passes], "x", ms=4, color="tab:cyan",
            label=f"axis distance from the great circles (largest {s['max_axis_departure_deg']:.3g} deg)")
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.set_xlabel("pass")
    ax.set_ylabel("[deg]")
    ax.set_title("tool axes: spin about them and distance from their great circles")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)


def _spin_figures(job) -> dict | None:
    """The summary's spin figures of a job planned with ``spin="reach"`` and a robot (None otherwise)."""
    if job.settings.spin != "reach" or job.settings.robot is None:
        return None
    from planner.cam.spin_choice import spin_summary

    return spin_summary(job.moves)


def _spin_panel(ax, job, sp: dict) -> None:
    """spin="reach": the chosen spin from the RMM spin along the cuts, and what it bought against the RMM spin."""
    from planner.cam.spin import SpunFrames

    offset = 0.0
    for m in job.moves:
        if m.kind != "cut":
            continue
        L = float(m.path.length)
        if isinstance(m.frames, SpunFrames):
            x = np.linspace(0.0, L, 65)
            ax.plot(1e3 * (offset + x), np.degrees(m.frames.spin(x)), lw=0.9, color="tab:purple")
        offset += L
    a, b = sp["rmm"], sp["reach"]
    ax.set_xlabel("arc length along the cuts [mm]")
    ax.set_ylabel("spin from the RMM spin [deg]")
    ax.set_title(f"spin reach: {sp['spun_runs']}/{sp['runs']} runs spun, at most {sp['max_spin_rate_deg_s']:.3g} "
                 f"deg/s\nsingularity margin {b['singularity_margin']:.3f} (RMM {a['singularity_margin']:.3f}), out "
                 f"of reach {b['out_of_reach_samples']} (RMM {a['out_of_reach_samples']}) samples", fontsize=10)
    ax.grid(alpha=0.3)


def _fit_panel(ax, job, s: dict) -> None:
    """Distance of the path from every chord of the polyline along the cut length (against the tolerance of
    the "cam" model; how far the interpolating spline bows from the chords for "interpolate")."""
    x0, xs, ds = 0.0, [], []
    for m in job.moves:
        if m.kind != "cut" or m.fit is None:
            continue
        chord = np.linalg.norm(np.diff(m.fit.points, axis=0), axis=1)
        xs.append(1e3 * (x0 + np.cumsum(chord) - 0.5 * chord))
        ds.append(1e3 * np.asarray(m.fit.span_deviation))
        x0 += float(chord.sum())
    x = np.concatenate(xs) if xs else np.zeros(0)
    d = np.concatenate(ds) if ds else np.zeros(0)
    if job.settings.path == "cam":
        ax.plot(x, d, ".", ms=2, color="tab:green", label="largest distance of the PH path from each chord")
        ax.axhline(s["tolerance_mm"], color="tab:red", ls="--", lw=0.8, label=f"tolerance {s['tolerance_mm']:g} mm")
        ax.set_ylim(0.0, 1.15 * max(s["tolerance_mm"], s["max_deviation_mm"]))
        ax.set_title(f"fit to the CAM polyline (largest {s['max_deviation_mm']:.4f} mm)")
    else:
        ax.plot(x, d, ".", ms=3, color="tab:green", label="largest distance of the spline from each chord")
        ax.set_title(f"through every point ({s['max_waypoint_error_mm']:.0e} mm), bow up to "
                     f"{s['max_deviation_mm']:.3f} mm")
    ax.set_xlabel("polyline length along the cuts [mm]")
    ax.set_ylabel("distance from the chord [mm]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
