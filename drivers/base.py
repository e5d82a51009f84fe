"""The driver interface: what every robot driver offers, the state it reads, and the errors it raises.

A driver executes a :class:`planner.PlannedJob` (its :class:`planner.Trajectory`) on a robot or a simulated
one. Errors are :class:`DriverError` subclasses that carry the robot's own reason and, where the failure
happened during a job, the job's time (s), the planned TCP pose p[x, y, z, rx, ry, rz] (m, rad) and the
source line being carried out.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from drivers.report import ExecutionReport

#: Progress callback: (stage, done, total), the same the CLI and the service use.
ProgressCallback = Callable[[str, int, int], None]

#: The execution modes: "program" (the job's URScript program, run by the controller) and "stream" (servoJ targets
#: sent by this machine every control period).
Mode = Literal["program", "stream"]
MODES: tuple[Mode, ...] = ("program", "stream")
#: The execution mode every front end offers by default (``planner run``, the REST API's executions and its robots
#: listing, the page) and the drivers' default: program mode runs in the controller and does not depend on this
#: machine's scheduling; a stream on a loaded machine misses control periods (bench/bench_modes.py measures both).
DEFAULT_MODE: Mode = "program"


class DriverError(RuntimeError):
    """The robot refused or failed.

    Attributes
    ----------
    reason : str
        The robot's (or the connection's) reason, as reported.
    t : float or None
        Job time at the failure, s (None outside a job).
    pose : tuple (6,) or None
        Planned TCP pose at that time, p[x, y, z, rx, ry, rz] (m, rotation vector).
    line : int or None
        Source line of the toolpath record being carried out.
    """

    kind = "failure"

    def __init__(self, reason: str, *, t: float | None = None, pose=None, line: int | None = None):
        self.reason = str(reason)
        self.t = None if t is None else float(t)
        self.pose = None if pose is None else tuple(float(x) for x in np.asarray(pose, dtype=float).ravel())
        self.line = None if line is None else int(line)
        super().__init__(self._message())

    def _message(self) -> str:
        where = []
        if self.t is not None:
            where.append(f"at t = {self.t:.3f} s")
        if self.line is not None:
            where.append(f"source line {self.line}")
        if self.pose is not None:
            p = self.pose
            where.append("pose p[" + ", ".join(f"{x:.4f}" for x in p) + "]")
        return self.reason + (f" ({', '.join(where)})" if where else "")

    def located(self, t: float | None, pose, line: int | None) -> DriverError:
        """A copy of this error with the job's time, pose and line (same class, same reason)."""
        err = type(self)(self.reason, t=t, pose=pose, line=line)
        err.__cause__ = self.__cause__ or self
        return err

    def __reduce__(self):
        return (_rebuild, (type(self), self.reason, self.t, self.pose, self.line))


def _rebuild(cls, reason, t, pose, line):
    return cls(reason, t=t, pose=pose, line=line)


class NotReadyError(DriverError):
    """The robot cannot move: not in remote control, powered off, brakes locked, or another program running."""

    kind = "not ready"


class ProtectiveStopError(DriverError):
    """The controller made a protective stop (e.g. an unreachable or too-fast target, a collision)."""

    kind = "protective stop"


class EmergencyStopError(DriverError):
    """An emergency stop (robot or system) stopped the arm."""

    kind = "emergency stop"


class ConnectionLostError(DriverError):
    """The connection to the controller dropped (RTDE, script or dashboard)."""

    kind = "connection lost"


class PeriodOverrunError(DriverError):
    """The streaming loop missed its control period (the command came later than the controller needed it)."""

    kind = "period overrun"


class CancelledError(DriverError):
    """The caller cancelled the run or stopped the robot (cancel event, :meth:`RobotDriver.stop`, dashboard stop)."""

    kind = "cancelled"


@dataclass(frozen=True)
class RobotState:
    """A snapshot of the robot as the controller reports it.

    joints (6,) rad; tcp_pose (6,) p[x, y, z, rx, ry, rz] m, rad; robot_mode (UR robot mode, 7 = RUNNING),
    safety_mode (1 = NORMAL, 3 = PROTECTIVE_STOP, ...), runtime_state (1 = STOPPED, 2 = PLAYING, ...);
    digital_out: actual digital output bits (standard 0-7, configurable 8-15, tool 16-17).
    """

    joints: tuple
    tcp_pose: tuple
    robot_mode: int
    safety_mode: int
    runtime_state: int
    protective_stop: bool
    emergency_stop: bool
    program_running: bool
    digital_out: int

    #: UR robot modes.
    ROBOT_MODE_POWER_OFF = 3
    ROBOT_MODE_IDLE = 5
    ROBOT_MODE_RUNNING = 7

    @property
    def ready(self) -> bool:
        """Powered, brakes released, no stop: the arm can move."""
        return (self.robot_mode == self.ROBOT_MODE_RUNNING and not self.protective_stop
                and not self.emergency_stop)


@runtime_checkable
class RobotDriver(Protocol):
    """One way to execute a planned job on a robot (URDriver on ur_rtde, SimDriver in-process)."""

    def connect(self) -> None:
        """Connect to the robot (only the host given to the driver). NotReadyError / ConnectionLostError."""

    def close(self) -> None:
        """Disconnect; the arm is left stopped."""

    def state(self) -> RobotState:
        """The robot's current state."""

    def move_to_start(self, job, *, speed: float = 0.5, acceleration: float = 0.5) -> None:
        """A joint move (rad/s, rad/s^2) onto ``job.start_joints``, the arm configuration the planner chose."""

    def execute(self, job, *, mode: str = DEFAULT_MODE, progress=None,
                cancel: threading.Event | None = None) -> ExecutionReport:
        """Execute the job ("program", the default: its URScript program; "stream": servoJ with the planner's
        joints).
        ``progress(stage, done, total)``; ``cancel`` set from another thread ends the run with the arm stopped.
        Returns the report; a failure is in ``report.failure`` (and ``report.ok`` is False)."""

    def pause(self) -> None:
        """Hold the arm on the path (decelerate to rest); :meth:`resume` continues."""

    def resume(self) -> None:
        """Continue after :meth:`pause`."""

    def stop(self) -> None:
        """Stop the run now (controlled stop); the run ends with a CancelledError in its report."""
