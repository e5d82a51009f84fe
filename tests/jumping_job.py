"""A planned job whose servo targets jump: the faults tests' way to make the controller refuse a target."""

from __future__ import annotations

from planner.trajectory import Chunk, Trajectory


class JumpingJob:
    """``job`` (a PlannedJob) whose joint targets jump by ``jump`` rad on ``joint`` from ``after_s`` s into each
    cut chunk on, and stay there; everything else is the job's own."""

    def __init__(self, job, *, joint: int, jump: float, after_s: float):
        self._job = job
        self._jump = (joint, jump, after_s)

    def __getattr__(self, name):
        return getattr(self._job, name)

    def trajectory(self, rate=None):
        return _JumpingTrajectory(self._job, self._job.settings.rate if rate is None else rate, self._jump)


class _JumpingTrajectory(Trajectory):
    def __init__(self, job, rate, jump):
        super().__init__(job, rate)
        self._jump = jump

    def chunks(self, *, joints=None, progress=None):
        joint, jump, after_s = self._jump
        k = int(round(after_s * self.rate))
        for c in super().chunks(joints=joints, progress=progress):
            if c.joints is not None and c.kind == "cut":
                q = c.joints.copy()
                q[k:, joint] += jump
                c = Chunk(c.move, c.kind, c.pass_index, c.times, c.poses, c.lines, q, c.io, c.final)
            yield c
