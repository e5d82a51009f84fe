"""One-page picture of a planned job (matplotlib, written to PNG): path and tool axes, twist of the
chosen frame against the exact RMF, TCP speed, joint positions against their limits.

The panel helpers (:func:`new_figure`, :func:`tool_axes`, :func:`label_path_axes`, :func:`joints_panel`,
:func:`save`) also draw the whole-job picture (:mod:`planner.plot_cam`).
"""

from __future__ import annotations

import numpy as np


def new_figure(title: str, size: tuple[float, float] = (13, 9.5)):
    """A matplotlib figure on the Agg backend (no display needed) with a title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=size)
    fig.suptitle(title, fontsize=13)
    return fig


def save(fig, target, dpi: int = 110) -> None:
    """Lay out, write the PNG and release the figure."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(target, dpi=dpi)
    plt.close(fig)


def tool_axes(ax, points: np.ndarray, frames: np.ndarray, scale: float) -> None:
    """Tool z (red) and tool x (green) arrows of ``frames`` (n, 3, 3) at ``points`` (n, 3) on a 3D axes."""
    q, F = points, frames
    ax.quiver(q[:, 0], q[:, 1], q[:, 2], *(F[:, :, 2].T * scale), color="tab:red", lw=0.8, label="tool z")
    ax.quiver(q[:, 0], q[:, 1], q[:, 2], *(F[:, :, 0].T * scale * 0.6), color="tab:green", lw=0.6, label="tool x")


def label_path_axes(ax, title: str) -> None:
    """Axis labels (mm), title and legend of a 3D path panel."""
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    ax.set_title(title)
    ax.legend(loc="upper left", fontsize=8)


def joints_panel(ax, t: np.ndarray, joints: np.ndarray | None, robot: str | None, ok: bool) -> None:
    """Joint positions (n, 6) in degrees against time (n,), with the model's position limits.

    Without joints the panel says the job was planned without robot kinematics.
    """
    if joints is None:
        ax.text(0.5, 0.5, "planned without robot kinematics", ha="center", va="center")
        ax.set_axis_off()
        return
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


def plot_job(job, target, *, title: str | None = None, axes_shown: int = 40) -> None:
    """Write a 2 x 2 figure of ``job`` (a :class:`planner.job.Job`) to ``target`` (PNG path)."""
    stream = job.stream
    fig = new_figure(title or "PH path job")

    ax = fig.add_subplot(2, 2, 1, projection="3d")
    p = job.path.points(np.linspace(job.path.knots[0], job.path.knots[-1], 1500)) * 1e3
    ax.plot(p[:, 0], p[:, 1], p[:, 2], color="tab:blue", lw=1.5, label="PH path")
    w = job.waypoints * 1e3
    ax.scatter(w[:, 0], w[:, 1], w[:, 2], s=8, color="k", label="waypoints")
    s = np.linspace(0.0, job.path.length, axes_shown)
    q = job.path.points(job.path.parameter_at_length(s)) * 1e3
    tool_axes(ax, q, job.frames.at_length(s), 0.06 * max(np.ptp(p, axis=0).max(), 1e-9))
    label_path_axes(ax, "path (part frame) and tool axes")

    ax = fig.add_subplot(2, 2, 2)
    ax.plot(job.twist_s * 1e3, job.twist_curve_deg, color="tab:purple")
    ax.set_xlabel("arc length [mm]")
    ax.set_ylabel("twist [deg]")
    ax.set_title(f"frame '{job.settings.frame}' against the exact RMF (max {job.twist_deg:.3g} deg)")
    ax.grid(alpha=0.3)

    ax = fig.add_subplot(2, 2, 3)
    t = stream.times
    ax.plot(t, job.profile.v(t) * 1e3, color="tab:blue", label="planned feed")
    d = np.linalg.norm(np.diff(stream.positions, axis=0), axis=1) / np.diff(t)
    ax.plot(0.5 * (t[1:] + t[:-1]), d * 1e3, color="tab:orange", lw=0.8, ls="--", label="sampled TCP speed")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("speed [mm/s]")
    ax.set_title(f"TCP speed ({stream.times.size} poses at {job.settings.rate:g} Hz)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)

    ax = fig.add_subplot(2, 2, 4)
    ok = job.reachability.ok if job.reachability is not None else True
    joints_panel(ax, t, job.joints, job.settings.robot, ok)
    save(fig, target)
