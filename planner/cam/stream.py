"""The pose stream of a whole CAM job at the controller rate: cuts, rapids and turns, move by move.

Every move starts and ends at rest. Move k is sampled at its local times 0, 1/rate, ...,
(n_k - 1)/rate with n_k = ceil(duration_k * rate): the first sample at or after its end is the
first sample of the next move (the same pose), so the tool rests less than one sample period at each
move boundary and the job clock ticks uniformly. The rotation vectors are continuous over the whole
job. A job of hours is millions of poses: :func:`iter_stream` yields them one move at a time;
:func:`collect` concatenates them for jobs that fit in memory; :func:`track_joints` adds the robot's
joint positions, chunk by chunk, on one continuous inverse-kinematics branch between the changes of the
arm configuration. A change (a "reconfiguration" move, in a rapid) is a joint move: its chunk carries
its joints, and its poses are their forward kinematics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.cam.passes import CamInputError
from planner.motion import sample_poses, tool_orientation
from planner.motion.rotvec import continuous_rotvec
from planner.motion.stream import as_transform


@dataclass(frozen=True, eq=False)
class StreamChunk:
    """The poses of one move.

    Attributes
    ----------
    move : int
        Index of the move in ``CamJob.moves``.
    kind : str
        "cut", "rapid", "reorientation" or "reconfiguration".
    pass_index : int
        Pass number of a cut, -1 otherwise.
    times : ndarray (k,)
        Sample times on the job clock, s.
    poses : ndarray (k, 6)
        TCP poses p[x, y, z, rx, ry, rz] in the robot base frame (m, rotation vector, continuous).
    lines : ndarray (k,) of int
        Source line of the record each sample carries out (of a reconfiguration: its rapid's record).
    joints : ndarray (k, 6) or None
        Joint positions (rad) of a reconfiguration (a joint move); None for the Cartesian moves, whose
        joints come from inverse kinematics (:func:`track_joints`).
    """

    move: int
    kind: str
    pass_index: int
    times: np.ndarray
    poses: np.ndarray
    lines: np.ndarray
    joints: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class JobStream:
    """The whole pose stream of a job (see :class:`StreamChunk` for the fields, here per sample)."""

    rate: float
    times: np.ndarray
    poses: np.ndarray
    move: np.ndarray
    pass_index: np.ndarray
    lines: np.ndarray

    def __len__(self) -> int:
        return self.times.size


def sample_counts(moves, rate: float) -> np.ndarray:
    """Sample intervals (n_k,) each move takes at ``rate``: ceil(duration * rate), 0 for no motion."""
    d = np.array([m.duration for m in moves], dtype=float)
    return np.where(d > 0.0, np.ceil(d * rate - 1e-9), 0.0).astype(np.int64)


def iter_stream(job, rate: float):
    """Yield one :class:`StreamChunk` per moving move of the job, in order.

    Parameters
    ----------
    job : CamJob
    rate : float
        Controller rate, Hz.
    """
    rate = float(rate)
    if not (np.isfinite(rate) and rate > 0.0):
        raise CamInputError(f"rate must be a positive number of Hz, got {rate!r}")
    moves = job.moves
    counts = sample_counts(moves, rate)
    offsets = np.concatenate(([0], np.cumsum(counts)))
    moving = np.flatnonzero(counts > 0)
    final = int(moving[-1]) if moving.size else -1
    Tb = as_transform(job.settings.part_frame, "part_frame")
    Rb, pb = Tb[:3, :3], Tb[:3, 3]
    r_prev = None
    for k in moving:
        m = moves[k]
        n = int(counts[k]) + (1 if k == final else 0)
        r = q = None
        if m.kind == "reconfiguration":  # a joint move: its poses are the forward kinematics of its joints
            from planner.kinematics import forward_matrix

            q = m.item.joints(m.profile.s(np.arange(n) / rate))
            T = forward_matrix(job.settings.robot, q, tcp=job.settings.tcp)
            pos, R = T[:, :3, 3], T[:, :3, :3]
            lines = np.full(n, m.item.line)
        elif m.kind in ("cut", "rapid"):
            ps = sample_poses(m.path, m.profile, tool_orientation(m.frames), rate=rate, base=Tb)
            pos, R = ps.positions[:n], ps.rotations[:n]
            r = ps.poses[:n, 3:]  # continuous within the move; checked against the previous move below
            if m.kind == "cut":
                lines = m.item.lines[np.minimum(ps.span[:n] + 1, len(m.item) - 1)]
            else:
                lines = np.full(n, m.item.line)
        else:  # a turn in place
            angle = m.profile.s(np.arange(n) / rate)
            R = np.matmul(Rb, m.frames.frames(angle))
            pos = np.broadcast_to(Rb @ m.point + pb, (n, 3))
            lines = np.full(n, m.item.line)
        if r is None or (r_prev is not None and np.abs(r[0] - r_prev).max() > 1e-6):
            r, _ = continuous_rotvec(R, None if r_prev is None else _rotvec_quaternion(r_prev), r_prev)
        r_prev = r[-1]
        yield StreamChunk(int(k), m.kind, m.pass_index, (offsets[k] + np.arange(n)) / rate,
                          np.hstack((pos, r)), np.asarray(lines, dtype=np.int64), q)


def track_joints(job, chunks, q_start=None):
    """Yield ``(chunk, q)`` for each chunk of a job's stream: q (k, 6) the joint positions (rad) of the robot.

    The joint trajectory follows one inverse-kinematics branch from one change of the arm configuration
    to the next (:func:`planner.kinematics.inverse_path`, with the job's TCP): each chunk starts from the
    last reachable joint vector of the previous one; a reconfiguration chunk carries its joints, and the
    chunks after it continue from them. Poses without a solution are rows of NaN (the job's
    ``problems`` name them by pass and line). Bounded memory: one chunk at a time.

    Parameters
    ----------
    job : CamJob
        Planned with a robot (``job.settings.robot``).
    chunks : iterable of StreamChunk
        The job's stream (``job.iter_stream(rate)``), or a subsequence of it in order (e.g. every k-th
        pose of each chunk, for a plot).
    q_start : array_like (6,), optional
        Joint positions before the first chunk (rad); default: the job's ``start_joints`` (the
        configuration its reachability check chose), else the branch of least joint travel.
    """
    from planner.kinematics import inverse_path

    robot, tcp = job.settings.robot, job.settings.tcp
    if robot is None:
        raise CamInputError("joint positions need a robot: the job was planned without one (robot=None)")
    if q_start is None:
        q_start = getattr(job, "start_joints", None)
    q_prev = None if q_start is None else np.asarray(q_start, dtype=float)
    for c in chunks:
        if c.times.size == 0:
            yield c, np.zeros((0, 6))
            continue
        if c.joints is not None:  # a joint move: the configuration changes here
            q_prev = c.joints[-1]
            yield c, c.joints
            continue
        q = inverse_path(robot, c.poses, q_prev, tcp=tcp, allow_unreachable=True)
        ok = np.flatnonzero(np.isfinite(q).all(axis=1))
        if ok.size:
            q_prev = q[ok[-1]]
        yield c, q


def thin_chunk(chunk: StreamChunk, step: int, offset: int = 0) -> StreamChunk:
    """The samples of a chunk whose job-wide sample number is a multiple of ``step``, and its last sample.

    ``offset`` is the job-wide number of the chunk's first sample. For plots of long jobs: every move
    keeps at least its last pose, so rapids and turns stay visible.
    """
    n = chunk.times.size
    first = (-offset) % step
    keep = np.union1d(np.arange(first, n, step), [n - 1]) if n else np.zeros(0, dtype=np.int64)
    return StreamChunk(chunk.move, chunk.kind, chunk.pass_index, chunk.times[keep], chunk.poses[keep],
                       chunk.lines[keep], None if chunk.joints is None else chunk.joints[keep])


def _rotvec_quaternion(r: np.ndarray) -> np.ndarray:
    """The unit quaternion (4,) whose rotation vector representation is exactly r (any |r|)."""
    th = float(np.linalg.norm(r))
    if th == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate(([np.cos(0.5 * th)], np.sin(0.5 * th) * r / th))


def collect(job, rate: float, max_samples: int = 20_000_000) -> JobStream:
    """The whole pose stream of a job in memory; CamInputError beyond ``max_samples`` poses."""
    n = job.n_samples(rate)
    if n > max_samples:
        raise CamInputError(f"the job is {n} poses at {rate:g} Hz (more than max_samples = {max_samples}); "
                            "stream it with CamJob.iter_stream()")
    chunks = list(iter_stream(job, rate))
    if not chunks:
        return JobStream(rate, np.zeros(0), np.zeros((0, 6)), np.zeros(0, int), np.zeros(0, int), np.zeros(0, int))
    return JobStream(
        rate,
        np.concatenate([c.times for c in chunks]),
        np.concatenate([c.poses for c in chunks]),
        np.concatenate([np.full(c.times.size, c.move) for c in chunks]),
        np.concatenate([np.full(c.times.size, c.pass_index) for c in chunks]),
        np.concatenate([c.lines for c in chunks]),
    )
