"""One-page picture of a whole CAM job (matplotlib, PNG): every pass and rapid in 3D with tool axes, the
spin about the tool axis and the fit deviation per pass, the TCP speed over the whole job, and the
joints against their limits.

A whole job is millions of poses. The stream is read once, move by move (:func:`digest_stream`): the
speed panel keeps the lowest and highest TCP speed of each time bin, the joint panel the inverse
kinematics of every k-th pose (and of each move's last pose), so memory stays bounded whatever the
length of the job. The 3D panel draws the planned paths themselves (a few points per PH segment).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.plot import joints_panel, label_path_axes, new_figure, save, tool_axes


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


def digest_stream(job, rate: float, *, bins: int = 1500, max_points: int = 20_000) -> StreamDigest:
    """Read a job's stream once: the TCP speed envelope in ``bins`` time bins and about ``max_points`` poses
    (with the robot's joints when the job has a robot)."""
    from planner.cam.stream import thin_chunk, track_joints

    total = job.n_samples(rate)
    step = max(1, math.ceil(total / max_points))
    edges = np.linspace(0.0, max(job.duration, 1.0 / rate), bins + 1)
    speed = {k: (np.full(bins, np.nan), np.full(bins, np.nan)) for k in ("cut", "other")}
    kept: list = []
    offset, p_last = 0, None

    def thinned():
        nonlocal offset, p_last
        for c in job.iter_stream(rate):
            p = c.poses[:, :3] if p_last is None else np.vstack((p_last, c.poses[:, :3]))
            t = c.times if p_last is None else np.concatenate((c.times[:1] - 1.0 / rate, c.times))
            v = np.linalg.norm(np.diff(p, axis=0), axis=1) * rate
            b = np.clip(np.searchsorted(edges, 0.5 * (t[1:] + t[:-1]), side="right") - 1, 0, bins - 1)
            _bin_extremes(b, v, *speed["cut" if c.kind == "cut" else "other"])
            p_last = c.poses[-1, :3]
            yield thin_chunk(c, step, offset)
            offset += c.times.size

    if job.settings.robot is not None:
        for c, q in track_joints(job, thinned()):
            kept.append((c, q))
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


def plot_cam_job(job, target, *, rate: float | None = None, title: str | None = None, axes_shown: int = 60,
                 bins: int = 1500, max_points: int = 20_000) -> StreamDigest:
    """Write the picture of a whole CAM job (:class:`planner.cam.CamJob`) to ``target`` (PNG path).

    Parameters
    ----------
    job : CamJob
    target : path
    rate : float, optional
        Rate of the stream read for the speed and joint panels, Hz (default the job's).
    title : str, optional
    axes_shown : int
        Tool frames drawn, evenly spaced along the total cut length.
    bins, max_points : int
        Time bins of the speed envelope and poses kept for the joint panel (:func:`digest_stream`).

    Returns
    -------
    StreamDigest
        What was drawn from the stream.
    """
    import matplotlib
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    rate = float(rate or job.settings.rate)
    digest = digest_stream(job, rate, bins=bins, max_points=max_points)
    s = job.summary()
    fig = new_figure(title or f"{job.source}: whole job", size=(17, 10))
    grid = fig.add_gridspec(2, 3)

    ax = fig.add_subplot(grid[0, 0:2], projection="3d")
    cuts, rapids = _path_lines(job)
    cmap = matplotlib.colormaps["viridis"]
    if cuts:
        colors = cmap(np.linspace(0.0, 1.0, len(cuts)))
        ax.add_collection3d(Line3DCollection(cuts, colors=colors, linewidths=1.0))
        ax.plot([], [], color=cmap(0.5), label=f"{len(cuts)} passes (colour: order)")
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
    label_path_axes(ax, f"paths (part frame): {s['cut_length_mm']:.0f} mm of cut, {s['rapids']} rapids, "
                        f"{s['reorientations']} turns in place")

    ax = fig.add_subplot(grid[0, 2])
    idx = np.array([p.index for p in job.passes])
    ax.plot(idx, [p.slerp_spin_deg for p in job.passes], ".", ms=3, color="tab:orange",
            label=f"CAM orientations slerped (total {s['slerp_spin_deg']:.4g} deg)")
    ax.plot(idx, [p.spin_deg for p in job.passes], ".", ms=3, color="tab:purple",
            label=f"planned frames (total {s['spin_deg']:.3g} deg)")
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.set_xlabel("pass")
    ax.set_ylabel("spin about the tool axis [deg]")
    ax.set_title("spin about the tool axis per pass")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)

    ax = fig.add_subplot(grid[1, 0])
    t_mid = 0.5 * (digest.edges[1:] + digest.edges[:-1])
    for kind, color, label in (("other", "0.5", "rapids"), ("cut", "tab:blue", "cuts")):
        v_lo, v_hi = (1e3 * a for a in digest.speed[kind])
        if np.isfinite(v_hi).any():
            ax.fill_between(t_mid, np.where(v_lo > 0, v_lo, np.nan), v_hi, color=color, alpha=0.3, lw=0)
            ax.plot(t_mid, v_hi, color=color, lw=0.8, label=f"{label}: highest speed per bin")
    ax.set_yscale("log")
    peaks = 1e3 * np.concatenate([v_hi for _, v_hi in digest.speed.values()])
    peaks = peaks[np.isfinite(peaks) & (peaks > 0)]
    if peaks.size:  # the lows reach 0 at every stop: show a decade below the usual speeds
        ax.set_ylim(0.1 * float(np.percentile(peaks, 5)), 2.0 * float(peaks.max()))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("TCP speed [mm/s]")
    ax.set_title(f"TCP speed, {digest.samples} poses at {rate:g} Hz ({s['duration_s']:.1f} s)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")

    ax = fig.add_subplot(grid[1, 1])
    joints_panel(ax, digest.times, digest.joints, job.settings.robot, not job.problems)
    if digest.joints is not None:
        ax.set_title(f"{job.settings.robot} joints, 1 pose in {digest.step} "
                     f"({'within limits' if not job.problems else f'{len(job.problems)} move(s) with problems'})")

    ax = fig.add_subplot(grid[1, 2])
    ax.plot(idx, [1e3 * p.max_deviation for p in job.passes], ".", ms=3, color="tab:green",
            label="largest deviation of the PH path")
    ax.axhline(s["tolerance_mm"], color="tab:red", ls="--", lw=0.8, label=f"tolerance {s['tolerance_mm']:g} mm")
    ax.set_xlabel("pass")
    ax.set_ylim(0.0, 1.15 * max(s["tolerance_mm"], s["max_deviation_mm"]))
    ax.set_ylabel("distance from the CAM polyline [mm]")
    ax.set_title(f"fit per pass (largest {s['max_deviation_mm']:.4f} mm)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    save(fig, target)
    return digest
