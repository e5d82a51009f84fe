"""The free spin about an axisymmetric tool: frames turned about their own tool axis by a smooth angle psi(x).

A nozzle, a glue needle or a spindle is symmetric about its axis, so the rotation about the tool axis is free:
``spin="reach"`` (:mod:`planner.cam.spin_choice`) chooses an angle function psi along every move and the move's
rotation-minimizing frames F(x) become F(x) Rz(psi(x)): only the columns x and y turn about column z (the tool
axis), which with the position stays exactly as planned. :class:`SpunFrames` is that frame provider, over the
move's own frames (an :class:`~planner.cam.axes.AxisField` along a cut, a
:class:`~planner.cam.moves.TurningFrames` of a rapid or a turn in place); psi is a :class:`SpinCurve`, a clamped
cubic B-spline (C2) of the move's coordinate (arc length along a cut or a rapid, the angle turned in a turn in
place), constant beyond its ends. The trajectory, the exports, the program and the drivers read it like any frame
provider.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.interpolate import BSpline

from planner import quaternion as qt

#: Degree of the spin's B-spline (cubic: C2 in the move's coordinate).
SPIN_DEGREE = 3


def rz(psi: np.ndarray) -> np.ndarray:
    """Rotations (n, 3, 3) about z by angles psi (n,), radians."""
    c, s = np.cos(psi), np.sin(psi)
    R = np.zeros(psi.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


def spun(F: np.ndarray, psi) -> np.ndarray:
    """Frames F (n, 3, 3) turned about their own column 2 by psi (n,) (F Rz(psi)); column 2 is kept bit for bit."""
    psi = np.asarray(psi, dtype=float)
    c, s = np.cos(psi)[..., None], np.sin(psi)[..., None]
    out = np.array(F, dtype=float, copy=True)
    out[..., :, 0] = c * F[..., :, 0] + s * F[..., :, 1]
    out[..., :, 1] = c * F[..., :, 1] - s * F[..., :, 0]
    return out


@dataclass(frozen=True, eq=False)
class SpinCurve:
    """The spin psi(x) (radians) of one move: a clamped cubic B-spline, constant beyond its first and last knot.

    Attributes
    ----------
    knots : ndarray (k + 4,)
        The clamped knot vector (4 equal knots at each end), in the move's coordinate (m, or rad for a turn).
    coeffs : ndarray (k,)
        The B-spline coefficients, radians.
    """

    knots: np.ndarray
    coeffs: np.ndarray

    @classmethod
    def constant(cls, value: float, end: float = 1.0) -> SpinCurve:
        """psi = value everywhere."""
        return cls(np.array([0.0] * 4 + [max(float(end), 1e-300)] * 4), np.full(4, float(value)))

    @classmethod
    def transition(cls, a: float, b: float, end: float) -> SpinCurve:
        """From a at x = 0 to b at x = ``end``, with zero first and second derivatives at both ends (C2)."""
        e = max(float(end), 1e-300)
        knots = np.array([0.0] * 4 + [0.5 * e] + [e] * 4)
        return cls(knots, np.array([a, a, 0.5 * (a + b), b, b], dtype=float))

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"knots": self.knots, "coeffs": self.coeffs}

    @classmethod
    def from_state(cls, state: dict) -> SpinCurve:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    @cached_property
    def _spline(self) -> BSpline:
        return BSpline(self.knots, self.coeffs, SPIN_DEGREE, extrapolate=False)

    @cached_property
    def _derivatives(self) -> tuple[BSpline, BSpline]:
        """psi' and psi'' (built when first asked: most curves are only evaluated, at a move's ends)."""
        return self._spline.derivative(1), self._spline.derivative(2)

    @cached_property
    def is_constant(self) -> bool:
        """psi is one value everywhere."""
        return bool(np.all(self.coeffs == self.coeffs[0]))

    @property
    def is_zero(self) -> bool:
        """psi is 0 everywhere (the move keeps its frames exactly)."""
        return not np.any(self.coeffs)

    def __call__(self, x, nu: int = 0) -> np.ndarray:
        """psi (nu = 0), dpsi/dx (1) or d2psi/dx2 (2) at x (n,); beyond the ends psi is constant."""
        x = np.atleast_1d(np.asarray(x, dtype=float))
        if self.is_constant:
            return np.full(x.shape, float(self.coeffs[0]) if nu == 0 else 0.0)
        lo, hi = float(self.knots[0]), float(self.knots[-1])
        inside = (x >= lo) & (x <= hi)
        out = (self._spline if nu == 0 else self._derivatives[nu - 1])(np.clip(x, lo, hi))
        return out if nu == 0 else np.where(inside, out, 0.0)



@dataclass(frozen=True, eq=False)
class SpinFigures:
    """What the spin of one run of passes bought, rated on the same samples with the RMM spin and with it.

    Attributes
    ----------
    samples : int
        Poses rated along the run.
    branch : int
        The inverse-kinematics branch the spin was chosen for (``IKSolutions``: 4 shoulder + 2 wrist + elbow).
    rmm, reach : ndarray (5,)
        With the RMM spin and with the chosen spin: least singularity margin (min of |sin q3|, |sin q5| and the
        shoulder factor, as :mod:`planner.cam.placement`), least joint-limit margin (rad) of the joints that do
        not turn whole turns, sample steps faster than a joint's speed limit, samples out of reach on the branch,
        wrist travel (|dq4| + |dq6|, rad) along the run; the RMM's on its best branch.
    """

    samples: int
    branch: int
    rmm: np.ndarray
    reach: np.ndarray

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"samples": self.samples, "branch": self.branch, "rmm": self.rmm, "reach": self.reach}

    @classmethod
    def from_state(cls, state: dict) -> SpinFigures:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)


@dataclass(frozen=True, eq=False)
class SpunFrames:
    """A move's frames turned about their own tool axis (column 2) by :class:`SpinCurve` psi of the move's
    coordinate: F(x) Rz(psi(x)). A frame provider (``frames(u)``, ``quaternions(u)``, ``at_length(s)``, ``path``).

    Attributes
    ----------
    base : AxisField or TurningFrames
        The move's rotation-minimizing frames (a cut's, parameter u of its path) or turning frames (a rapid's,
        parameter the arc length; a turn in place's, parameter the angle turned).
    spin : SpinCurve
        psi of arc length along a cut or a rapid, of the angle turned in a turn in place, radians.
    figures : SpinFigures or None
        On the first cut of a run of passes: what the run's spin bought.
    """

    base: object
    spin: SpinCurve
    figures: SpinFigures | None = None

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"base": self.base, "spin": self.spin.to_state(),
                "figures": None if self.figures is None else self.figures.to_state()}

    @classmethod
    def from_state(cls, state: dict) -> SpunFrames:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        figures = state["figures"]
        return cls(state["base"], SpinCurve.from_state(state["spin"]),
                   None if figures is None else SpinFigures.from_state(figures))

    # the geometry of the base frames that the spin does not change
    @property
    def path(self):
        return self.base.path  # type: ignore[attr-defined]

    @property
    def angle(self) -> float:
        return self.base.angle  # type: ignore[attr-defined]

    @property
    def n(self) -> np.ndarray:
        return self.base.n  # type: ignore[attr-defined]

    @property
    def span(self) -> float:
        return self.base.span  # type: ignore[attr-defined]

    @property
    def axes(self) -> np.ndarray:
        return self.base.axes  # type: ignore[attr-defined]

    @property
    def motion(self):
        return getattr(self.base, "motion", None)

    def axis(self, u) -> np.ndarray:
        """Tool axis (n, 3) at u: the base's (the spin turns about it)."""
        return self.base.axis(u)  # type: ignore[attr-defined]

    def axis_errors(self) -> np.ndarray:
        return self.base.axis_errors()  # type: ignore[attr-defined]

    def coordinate(self, u) -> np.ndarray:
        """The spin's coordinate x (n,) at the base's parameters u (n,): arc length along a cut (the path's exact
        arc length), u itself on a rapid (parameter = arc length) or a turn (angle)."""
        u = np.atleast_1d(np.asarray(u, dtype=float))
        if type(self.base).__name__ == "AxisField":
            return np.asarray(self.path.arc_length(u), dtype=float)
        return u

    def psi(self, u) -> np.ndarray:
        """psi (n,) at the base's parameters u (n,), radians."""
        return self.spin(self.coordinate(u))

    def frames(self, u) -> np.ndarray:
        """Tool frames (n, 3, 3) at the base's parameters u (n,)."""
        u = np.atleast_1d(np.asarray(u, dtype=float))
        return spun(self.base.frames(u), self.psi(u))  # type: ignore[attr-defined]

    def quaternions(self, u) -> np.ndarray:
        """Unit quaternions (n, 4) (scalar first) of the frames at u (n,), signs continuous where the base's are."""
        u = np.atleast_1d(np.asarray(u, dtype=float))
        half = 0.5 * self.psi(u)
        z = np.zeros((u.size, 4))
        z[:, 0], z[:, 3] = np.cos(half), np.sin(half)
        return qt.mul(self.base.quaternions(u), z)  # type: ignore[attr-defined]

    def at_length(self, s) -> np.ndarray:
        """Tool frames (n, 3, 3) at arc lengths s (n,) (the angle of a turn in place)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        return spun(self.base.at_length(s), self.spin(s))  # type: ignore[attr-defined]

    @property
    def start(self) -> np.ndarray:
        """Frame (3, 3) at the start of the move."""
        return spun(self.base.start[None], self.spin(0.0))[0]  # type: ignore[attr-defined]

    @property
    def end(self) -> np.ndarray:
        """Frame (3, 3) at the end of the move."""
        return spun(self.base.end[None], self.spin(self.end_coordinate))[0]  # type: ignore[attr-defined]

    @property
    def end_coordinate(self) -> float:
        """The spin's coordinate at the end of the move (a cut's length, a rapid's length, a turn's angle)."""
        if type(self.base).__name__ == "AxisField":
            return float(self.path.length)
        return float(self.base.span)  # type: ignore[attr-defined]
