"""The trajectory of a planned job at the controller rate: the one stream every consumer reads.

Exports (CSV, JSON, URScript), the plot, the drivers, the simulator and the service take a
:class:`Trajectory` (``job.trajectory()``) and read it chunk by chunk: one :class:`Chunk` per moving move
(cut, rapid, turn, change of arm configuration) or dwell with, per sample, the time, the TCP pose, the
robot's joints (with a robot), the tool I/O state, and the move, pass and source line it carries out. Memory is
bounded by one move's samples: a whole NX job is millions of poses.

Every move starts and ends at rest. Move k is sampled at its local times 0, 1/rate, ...,
(n_k - 1)/rate with n_k = ceil(duration_k * rate): the first sample at or after its end is the first
sample of the next move (the same pose), so the tool rests less than one sample period at each move
boundary and the job clock ticks uniformly. A dwell is a move like the others whose poses all equal the
pose where the move before it ended: ceil(seconds * rate) sample periods at rest (the output of
``cut_output`` is off there: it is on during cuts only). The rotation vectors are continuous over the whole
job. The joints follow one inverse-kinematics branch from one change of the arm configuration to the next (the one
the planner's reachability check chose); a change (a "reconfiguration" move, in a rapid) is a joint move: its
chunk carries its joints, and its poses are their forward kinematics.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

import numpy as np

from planner.errors import PlannerError
from planner.kinematics.poses import as_transform
from planner.kinematics.ur_outputs import (
    IO_BIT_OFFSET,  # noqa: F401  (importable from here, as before)
    output_bit,
)
from planner.motion import sample_poses, tool_orientation
from planner.motion.rotvec import continuous_rotvec
from planner.rotations import rotvec_to_quaternion


@dataclass(frozen=True, eq=False)
class Chunk:
    """The samples of one move.

    Attributes
    ----------
    move : int
        Index of the move in ``PlannedJob.moves``.
    kind : str
        "cut", "rapid", "reorientation", "reconfiguration" or "dwell" (the tool at rest: every pose the same).
    pass_index : int
        Pass number of a cut, -1 otherwise.
    times : ndarray (k,)
        Sample times on the job clock, s.
    poses : ndarray (k, 6)
        TCP poses p[x, y, z, rx, ry, rz] in the robot base frame (m, rotation vector, continuous).
    lines : ndarray (k,) of int
        Source line of the record each sample carries out (of a reconfiguration: its rapid's record; for
        waypoint arrays: the waypoint index).
    joints : ndarray (k, 6) or None
        Joint positions (rad) with a robot (rows of NaN where a pose has no inverse-kinematics solution; the
        job's ``problems`` name them); None without a robot or when not asked for.
    io : ndarray (k,) of int64
        Digital output bits set at each sample (the 18-bit word of :mod:`planner.kinematics.ur_outputs`;
        ``PlanSettings.cut_output`` is on during cuts), 0 when the job switches nothing.
    final : bool
        Whether this is the move's last chunk (a move of more than :data:`CHUNK_SAMPLES` samples comes in
        several).
    """

    move: int
    kind: str
    pass_index: int
    times: np.ndarray
    poses: np.ndarray
    lines: np.ndarray
    joints: np.ndarray | None = None
    io: np.ndarray | None = None
    final: bool = True

    def __len__(self) -> int:
        return self.times.size

    def every(self, step: int, offset: int = 0) -> Chunk:
        """The samples whose job-wide number is a multiple of ``step``, and the chunk's last sample (for
        plots of long jobs: every move keeps at least its last pose). ``offset``: the job-wide number of
        the chunk's first sample."""
        n = self.times.size
        first = (-offset) % step
        keep = np.union1d(np.arange(first, n, step), [n - 1]) if n else np.zeros(0, dtype=np.int64)
        return replace(self, times=self.times[keep], poses=self.poses[keep], lines=self.lines[keep],
                       joints=None if self.joints is None else self.joints[keep],
                       io=None if self.io is None else self.io[keep])


class Trajectory:
    """A planned job sampled at a controller rate, produced lazily chunk by chunk (bounded memory).

    Parameters
    ----------
    job : PlannedJob
    rate : float
        Samples per second, Hz (500 for UR e-Series, 125 for CB-Series).

    Iterating gives the :class:`Chunk` s with joints (when the job has a robot); :meth:`chunks` chooses.
    """

    def __init__(self, job, rate: float):
        try:
            r = float(rate)
        except (TypeError, ValueError):
            raise PlannerError(f"rate must be a positive number of Hz, got {rate!r}") from None
        if not (np.isfinite(r) and 0.0 < r <= 10_000.0):
            raise PlannerError(f"rate must be in (0, 10000] Hz, got {rate!r}")
        self.job = job
        self.rate = r

    @property
    def robot(self) -> str | None:
        """The UR model the job was planned for (None: no joints)."""
        return self.job.settings.robot

    @property
    def n_samples(self) -> int:
        """Number of samples (poses) of the whole trajectory."""
        return int(sample_counts(self.job.moves, self.rate).sum()) + 1

    @property
    def duration(self) -> float:
        """Time of the last sample, s: (n_samples - 1) / rate. Each move is rounded up to the sample grid, so
        this exceeds the job's planned motion time (``job.duration``) by less than one period per move."""
        return (self.n_samples - 1) / self.rate

    def __len__(self) -> int:
        return self.n_samples

    def __iter__(self) -> Iterator[Chunk]:
        return self.chunks()

    def chunks(self, *, joints: bool | None = None, progress: Callable[[str, int, int], None] | None = None,
               ) -> Iterator[Chunk]:
        """One :class:`Chunk` per moving move (several for a move of more than :data:`CHUNK_SAMPLES` samples), in order.

        ``joints``: add the robot's joints (default: when the job has a robot; True without a robot is an
        error). ``progress(stage, done, total)`` is called with the samples produced ("samples").

        Examples
        --------
        >>> import numpy as np
        >>> from planner import PlanSettings, plan
        >>> t = np.linspace(0.0, 1.0, 9)
        >>> bead = np.c_[0.2 * t, 0.03 * np.sin(2 * np.pi * t), np.zeros_like(t)]
        >>> job = plan(bead, PlanSettings(feed=0.02, robot="ur5e", part_frame=(0.4, -0.1, 0.2, 0, 0, 0)))
        >>> for chunk in job.trajectory().chunks():   # 500 Hz: time (n,) s, poses (n, 6) m and rad, joints (n, 6)
        ...     print(chunk.kind, chunk.times.shape, chunk.poses.shape, chunk.joints.shape, chunk.io.shape)
        cut (6036,) (6036, 6) (6036, 6) (6036,)
        """
        want = self.robot is not None if joints is None else bool(joints)
        if want and self.robot is None:
            raise PlannerError("joint positions need a robot: the job was planned without one (robot=None)")
        chunks = _pose_chunks(self.job, self.rate)
        if want:
            chunks = track_joints(self.job, chunks)
        chunks = _with_io(self.job, chunks)
        if progress is None:
            return chunks
        return _counted(chunks, self.n_samples, progress)

    def collect(self, *, joints: bool | None = None, max_samples: int = 20_000_000) -> Chunk:
        """The whole trajectory as one :class:`Chunk` (its move, kind and pass_index are the first move's: read
        :meth:`chunks` for them per move). PlannerError beyond ``max_samples`` samples."""
        n = self.n_samples
        if n > max_samples:
            raise PlannerError(f"the trajectory is {n} poses at {self.rate:g} Hz (more than max_samples = "
                               f"{max_samples}); read it chunk by chunk with Trajectory.chunks()")
        parts = list(self.chunks(joints=joints))
        if not parts:
            return Chunk(-1, "", -1, np.zeros(0), np.zeros((0, 6)), np.zeros(0, np.int64), None, np.zeros(0, np.int64))
        q = None if parts[0].joints is None else np.concatenate([c.joints for c in parts])
        return Chunk(parts[0].move, parts[0].kind, parts[0].pass_index, np.concatenate([c.times for c in parts]),
                     np.concatenate([c.poses for c in parts]), np.concatenate([c.lines for c in parts]), q,
                     np.concatenate([c.io for c in parts]))

    def moves(self) -> list[dict]:
        """One dict per move of the job: move, kind, pass, operation, first_line, last_line, t_start (s),
        duration_s, samples (that the move starts in the trajectory; 0 for skipped records); a change of the
        arm configuration adds for_pass (the first pass made on it) and q_from, q_to (rad)."""
        job = self.job
        counts = sample_counts(job.moves, self.rate)
        starts = np.concatenate(([0], np.cumsum(counts)))[:-1] / self.rate
        out = []
        for k, m in enumerate(job.moves):
            item = m.item
            last = getattr(item, "last_line", None)
            out.append({
                "move": k, "kind": m.kind, "pass": int(m.pass_index), "operation": getattr(item, "operation", ""),
                "first_line": int(m.line), "last_line": int(m.line if last is None else last),
                "t_start": float(starts[k]), "duration_s": m.duration, "samples": int(counts[k]),
            })
            if m.kind == "reconfiguration":
                out[-1].update({"for_pass": int(item.pass_index), "q_from": [float(x) for x in item.q_from],
                                "q_to": [float(x) for x in item.q_to]})
        if out and counts.any():
            out[int(np.flatnonzero(counts)[-1])]["samples"] += 1  # the job's final pose
        return out


def _counted(chunks, total: int, progress):
    done = 0
    for c in chunks:
        yield c
        done += c.times.size
        progress("samples", done, total)


def _with_io(job, chunks):
    """The chunks with their digital output bits (``cut_output`` on during cuts). The last sample of a cut is
    the first of the next move: the output is off there unless that move is a cut too (two passes joined at a
    corner), so the output never blinks off for one sample between them. One chunk is held back to see the
    next one's kind."""
    out = job.settings.cut_output
    bit = 0 if out is None else 1 << output_bit(*out)
    held = None
    for c in chunks:
        if held is not None:
            yield _io_of(held, bit, c.kind == "cut")
        held = c
    if held is not None:
        yield _io_of(held, bit, False)


def _io_of(c, bit: int, next_is_cut: bool):
    n = c.times.size
    on = bit if c.kind == "cut" else 0
    if on and n:
        io = np.full(n, on, dtype=np.int64)
        if c.final and not next_is_cut:
            io[-1] = 0
        return replace(c, io=io)
    return replace(c, io=np.zeros(n, dtype=np.int64))


def sample_counts(moves, rate: float) -> np.ndarray:
    """Sample intervals (n_k,) each move takes at ``rate``: ceil(duration * rate), 0 for no motion."""
    d = np.array([m.duration for m in moves], dtype=float)
    return np.where(d > 0.0, np.ceil(d * rate - 1e-9), 0.0).astype(np.int64)


@dataclass(frozen=True, eq=False)
class SamplePlace:
    """Where in the job a trajectory sample lies: its job time ``t`` (s), the move's kind ("cut", "rapid", ...),
    its pass (``pass_index``, -1 for a move between passes) and the source line of the move's first record."""

    t: float
    kind: str
    pass_index: int
    line: int


class SamplePlaces:
    """The moves' places along a job's trajectory at ``rate`` Hz: :meth:`at` gives a sample's (a driver's progress
    counts samples) job time, move, pass and source line. ``duration``: the last sample's job time, s."""

    def __init__(self, job, rate: float) -> None:
        counts = sample_counts(job.moves, rate)
        self.rate = float(rate)
        self.first = np.concatenate(([0], np.cumsum(counts)[:-1])) if counts.size else np.zeros(0, np.int64)
        self.n = int(counts.sum()) + 1
        self.duration = (self.n - 1) / self.rate
        self._moves = [(m.kind, int(m.pass_index), int(m.line)) for m in job.moves]
        self._moving = counts > 0

    def at(self, k: int) -> SamplePlace:
        """Sample ``k``'s place (clipped to the trajectory): the moving move it lies in (the last one for the last
        sample)."""
        k = min(max(int(k), 0), self.n - 1)
        t = k / self.rate
        if not self._moves:
            return SamplePlace(t, "", -1, -1)
        candidates = np.flatnonzero(self._moving & (self.first <= k))
        m = int(candidates[-1]) if candidates.size else 0
        kind, pass_index, line = self._moves[m]
        return SamplePlace(t, kind, pass_index, line)


#: Samples per chunk at most: a move longer than this comes in several chunks (bounded memory: a slow pass of
#: an hour is 1.8 million samples at 500 Hz).
CHUNK_SAMPLES = 65_536


def _pose_chunks(job, rate: float, piece: int = CHUNK_SAMPLES):
    """Chunks of poses (no joints, no I/O) of every moving move of the job, in order, at most ``piece``
    samples each (``Chunk.final`` marks a move's last chunk)."""
    moves = job.moves
    counts = sample_counts(moves, rate)
    offsets = np.concatenate(([0], np.cumsum(counts)))
    moving = np.flatnonzero(counts > 0)
    last_move = int(moving[-1]) if moving.size else -1
    Tb = as_transform(job.settings.part_frame, "part_frame")
    Rb, pb = Tb[:3, :3], Tb[:3, 3]
    r_prev = None
    for k in moving:
        m = moves[k]
        n = int(counts[k]) + (1 if k == last_move else 0)
        orientation = tool_orientation(m.frames) if m.kind in ("cut", "rapid") else None
        state = None
        for a in range(0, n, piece):
            b = min(a + piece, n)
            r = q = None
            if m.kind == "reconfiguration":  # a joint move: its poses are the forward kinematics of its joints
                from planner.kinematics import forward_matrix

                q = m.item.joints(m.profile.s(np.arange(a, b) / rate))
                T = forward_matrix(job.settings.robot, q, tcp=job.settings.tcp)
                pos, R = T[:, :3, 3], T[:, :3, :3]
                lines = np.full(b - a, m.item.line)
            elif m.kind in ("cut", "rapid"):
                ps = sample_poses(m.path, m.profile, orientation, rate=rate, base=Tb, window=(a, b - a),
                                  previous=state)
                state = ps.state
                pos, R = ps.positions, ps.rotations
                r = ps.poses[:, 3:]  # continuous within the move; checked against the previous move below
                if m.kind == "cut":
                    lines = m.item.lines[np.minimum(ps.span + 1, len(m.item) - 1)]
                else:
                    lines = np.full(b - a, m.item.line)
            elif m.kind == "dwell":  # the tool at rest: the job clock advances, the pose stays
                R = np.broadcast_to(Rb @ m.start_frame, (b - a, 3, 3))
                pos = np.broadcast_to(Rb @ m.point + pb, (b - a, 3))
                lines = np.full(b - a, m.item.line)
            else:  # a turn in place
                angle = m.profile.s(np.arange(a, b) / rate)
                R = np.matmul(Rb, m.frames.frames(angle))
                pos = np.broadcast_to(Rb @ m.point + pb, (b - a, 3))
                lines = np.full(b - a, m.item.line)
            if r is None or (r_prev is not None and np.abs(r[0] - r_prev).max() > 1e-6):
                r, _ = continuous_rotvec(R, None if r_prev is None else rotvec_to_quaternion(r_prev), r_prev)
            r_prev = r[-1]
            yield Chunk(int(k), m.kind, m.pass_index, (offsets[k] + np.arange(a, b)) / rate,
                        np.hstack((pos, r)), np.asarray(lines, dtype=np.int64), q, final=b == n)


def track_joints(job, chunks, q_start=None):
    """The chunks with the robot's joint positions (k, 6), rad, on one continuous inverse-kinematics branch
    between the changes of the arm configuration (:func:`planner.kinematics.inverse_path`, the job's TCP).

    Each chunk starts from the last reachable joint vector of the previous one (the first from the job's
    ``start_joints``, the configuration its reachability check chose); a reconfiguration chunk carries its
    joints. Poses without a solution are rows of NaN. Bounded memory: one chunk at a time.
    """
    from planner.kinematics import inverse_path

    robot, tcp = job.settings.robot, job.settings.tcp
    if q_start is None:
        q_start = getattr(job, "start_joints", None)
    q_prev = None if q_start is None else np.asarray(q_start, dtype=float)
    for c in chunks:
        if c.times.size == 0:
            yield replace(c, joints=np.zeros((0, 6)))
            continue
        if c.joints is not None:  # a joint move: the configuration changes here
            q_prev = c.joints[-1]
            yield c
            continue
        q = inverse_path(robot, c.poses, q_prev, tcp=tcp, allow_unreachable=True)
        ok = np.flatnonzero(np.isfinite(q).all(axis=1))
        if ok.size:
            q_prev = q[ok[-1]]
        yield replace(c, joints=q)


