"""Universal Robots e-Series arm models: DH parameters, joint position limits, joint speed limits.

Sources
-------
DH parameters (standard Denavit-Hartenberg, T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i), with
alpha = (pi/2, 0, 0, pi/2, -pi/2, 0) and a1 = a4 = a5 = a6 = d2 = d3 = 0 for every model):
  Universal Robots, "DH Parameters for calculations of kinematics and dynamics",
  https://www.universal-robots.com/articles/ur/application-installation/dh-parameters-for-calculations-of-kinematics-and-dynamics/
  (UR3e, UR5e, UR10e, UR16e in the table; UR20 in the file linked from the same article).
  The controller's base frame is DH frame 0 and its tool flange frame is DH frame 6, so a pose
  computed from these tables is what ``get_actual_tcp_pose()`` reports with a zero TCP offset.

Joint limits: the e-Series user manuals (UR3e/UR5e/UR10e/UR16e manual version 5.8, UR20 manual 5.14,
"Technical specifications": working range of every joint +-360 deg), as transcribed with the manual
references in Universal Robots' own ROS description package (UniversalRobots/
Universal_Robots_ROS2_Description, ``config/<model>/joint_limits.yaml``). Joint speeds (deg/s):
  UR3e  base/shoulder/elbow 180, wrists 360
  UR5e  all joints 180
  UR10e base/shoulder 120, elbow and wrists 180
  UR16e base/shoulder 120, elbow and wrists 180
  UR20  base/shoulder 120, elbow 150, wrists 210
Caveats: the elbow cannot physically turn much beyond +-180 deg (the upper arm collides with the
lower arm); the inverse kinematics here produces elbow angles in [-pi, pi] anyway. UR's UR3e data
sheet advertises infinite rotation of wrist 3; we keep the manual's +-360 deg (the conservative
value). Acceleration limits are not published by UR: the controller's bound on every joint is
planner.kinematics.ur_moves.JOINT_ACCEL_MAX.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from planner.errors import PlannerError

__all__ = ["URModel", "UnknownModelError", "MODELS", "model_names", "get_model"]

# Standard DH twist angles of every UR arm, stored as exact (sin, cos) to avoid cos(pi/2) = 6e-17.
DH_ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
DH_SIN_ALPHA = (1.0, 0.0, 0.0, 1.0, -1.0, 0.0)
DH_COS_ALPHA = (0.0, 1.0, 1.0, 0.0, 0.0, 1.0)

JOINT_NAMES = ("base", "shoulder", "elbow", "wrist 1", "wrist 2", "wrist 3")

_TWO_PI = 2.0 * math.pi


class UnknownModelError(PlannerError):
    """The robot model name is not one of the supported UR arms."""


@dataclass(frozen=True)
class URModel:
    """One UR arm: its standard DH lengths (m) and joint limits.

    Attributes
    ----------
    name : str
        Model name as accepted by :func:`get_model` (lower case, e.g. ``"ur5e"``).
    d1, a2, a3, d4, d5, d6 : float
        The non-zero DH lengths in metres (a2, a3 are negative as UR publishes them).
    q_min, q_max : tuple of 6 floats
        Joint position limits in rad.
    qd_max : tuple of 6 floats
        Joint speed limits in rad/s.
    """

    name: str
    d1: float
    a2: float
    a3: float
    d4: float
    d5: float
    d6: float
    q_min: tuple[float, ...]
    q_max: tuple[float, ...]
    qd_max: tuple[float, ...]

    def __post_init__(self) -> None:
        for field in ("q_min", "q_max", "qd_max"):
            value = getattr(self, field)
            if len(value) != 6:
                raise PlannerError(f"URModel {self.name!r}: {field} needs 6 values, got {len(value)}")
        for j in range(6):
            if not self.q_min[j] < self.q_max[j]:
                raise PlannerError(f"URModel {self.name!r}: joint {j} has q_min >= q_max")
            if not self.qd_max[j] > 0:
                raise PlannerError(f"URModel {self.name!r}: joint {j} speed limit must be > 0")

    @property
    def a(self) -> np.ndarray:
        """DH link lengths a_1..a_6 in m, shape (6,)."""
        return np.array([0.0, self.a2, self.a3, 0.0, 0.0, 0.0])

    @property
    def d(self) -> np.ndarray:
        """DH link offsets d_1..d_6 in m, shape (6,)."""
        return np.array([self.d1, 0.0, 0.0, self.d4, self.d5, self.d6])

    @property
    def lower(self) -> np.ndarray:
        """Joint position lower limits in rad, shape (6,)."""
        return np.array(self.q_min, dtype=float)

    @property
    def upper(self) -> np.ndarray:
        """Joint position upper limits in rad, shape (6,)."""
        return np.array(self.q_max, dtype=float)

    @property
    def speed_limits(self) -> np.ndarray:
        """Joint speed limits in rad/s, shape (6,)."""
        return np.array(self.qd_max, dtype=float)

    @property
    def multiturn(self) -> np.ndarray:
        """Boolean mask (6,): joints whose range exceeds 2 pi (unwrapped along paths)."""
        return (self.upper - self.lower) > _TWO_PI

    @property
    def reach(self) -> float:
        """A bound on the flange distance from the shoulder, in m (used for tolerances)."""
        return abs(self.a2) + abs(self.a3) + self.d4 + self.d5 + self.d6


def _deg(*values: float) -> tuple[float, ...]:
    return tuple(math.radians(v) for v in values)


_FULL_TURN = _deg(*([360.0] * 6))
_MINUS_FULL_TURN = tuple(-v for v in _FULL_TURN)


def _ur(name, d1, a2, a3, d4, d5, d6, speeds_deg) -> URModel:
    return URModel(name, d1, a2, a3, d4, d5, d6, _MINUS_FULL_TURN, _FULL_TURN, _deg(*speeds_deg))


# DH lengths in m from the UR article cited in the module docstring: (d1, a2, a3, d4, d5, d6).
MODELS = MappingProxyType(
    {
        "ur3e": _ur("ur3e", 0.15185, -0.24355, -0.2132, 0.13105, 0.08535, 0.0921,
                    (180, 180, 180, 360, 360, 360)),
        "ur5e": _ur("ur5e", 0.1625, -0.425, -0.3922, 0.1333, 0.0997, 0.0996,
                    (180, 180, 180, 180, 180, 180)),
        "ur10e": _ur("ur10e", 0.1807, -0.6127, -0.57155, 0.17415, 0.11985, 0.11655,
                     (120, 120, 180, 180, 180, 180)),
        "ur16e": _ur("ur16e", 0.1807, -0.4784, -0.36, 0.17415, 0.11985, 0.11655,
                     (120, 120, 180, 180, 180, 180)),
        "ur20": _ur("ur20", 0.2363, -0.862, -0.7287, 0.201, 0.1593, 0.1543,
                    (120, 120, 150, 210, 210, 210)),
    }
)


def model_names() -> tuple[str, ...]:
    """Names of the supported models, e.g. ``("ur3e", "ur5e", ...)``."""
    return tuple(MODELS)


def get_model(model: str | URModel) -> URModel:
    """Look a model up by name (case-insensitive); a :class:`URModel` is returned unchanged.

    Raises
    ------
    UnknownModelError
        If the name is not a supported model; the message lists the valid names.
    """
    if isinstance(model, URModel):
        return model
    if not isinstance(model, str):
        raise UnknownModelError(
            f"robot model must be a name or a URModel, got {type(model).__name__}; "
            f"valid names: {', '.join(MODELS)}"
        )
    key = model.strip().lower().replace("-", "").replace("_", "")
    try:
        return MODELS[key]
    except KeyError:
        raise UnknownModelError(
            f"unknown robot model {model!r}; valid names: {', '.join(MODELS)}"
        ) from None
