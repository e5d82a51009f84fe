"""What every driver checks of a job before it moves, and the small rules every run shares.

- :func:`check_job`: the job was planned for this robot model, has no unreachable pose and has start joints;
- :func:`output_mask`: the digital output bits a job switches (cleared before a run, switched off after a failure);
- :func:`stop_requested`: the caller's cancel event or the driver's stop, as the run's :class:`CancelledError`.
"""

from __future__ import annotations

import threading

import numpy as np

from drivers.base import CancelledError, DriverError


def check_job(job, model: str, robot_name: str = "the driver drives") -> None:
    """DriverError unless ``job`` can run on a ``model`` robot: planned with a robot of that model, no move the
    robot cannot make, start joints chosen (:attr:`planner.job.PlannedJob.not_executable`). ``robot_name`` words the
    model mismatch ("the driver drives a ur5e")."""
    robot = job.settings.robot
    if robot is not None:
        from planner.kinematics import get_model

        if get_model(robot).name != model:
            raise DriverError(f"the job was planned for {robot}, {robot_name} a {model}")
    reason = job.not_executable
    if reason is not None:
        raise DriverError(reason)


def output_mask(io: np.ndarray) -> int:
    """The union of the output bits in a trajectory's I/O column (n,) int: the bits the job switches."""
    m = 0
    for v in np.unique(np.asarray(io, dtype=np.int64)):
        m |= int(v)
    return m


def stop_requested(cancel: threading.Event | None, stop: threading.Event) -> DriverError | None:
    """The run's CancelledError if the caller set ``cancel`` or called the driver's stop() (``stop``), else None."""
    if cancel is not None and cancel.is_set():
        return CancelledError("cancelled by the caller")
    if stop.is_set():
        return CancelledError("stopped by the caller (driver.stop())")
    return None
