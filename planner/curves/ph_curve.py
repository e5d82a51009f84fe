"""The evaluation every spatial PH segment shares, whatever its degree (PH cubics and quintics).

A segment is its quaternion coefficients A (m, 4) (Bernstein form of A(t), r'(t) = A i A*) and its start
point; subclasses fix m and add their constructors (Hermite interpolation differs by degree).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from planner import bernstein
from planner.curves.ph_core import (
    arc_length_coeffs,
    batch_control_points,
    batch_hodograph,
    batch_sigma,
    curvature_torsion,
    invert_arc_length,
)
from planner.errors import PlannerError
from planner.validation import as_int, check_arc_lengths, check_vector, finite_floats


def _params(t) -> np.ndarray:
    """Curve parameters t as a finite float array (n,) (a scalar is one sample); ArgumentError names ``t``."""
    return np.atleast_1d(finite_floats(t, "t", ((), (None,))))


@dataclass(frozen=True, eq=False)
class PHSegment:
    """A spatial PH curve r(t), t in [0, 1], with hodograph r'(t) = A(t) i A*(t).

    Parameters
    ----------
    A : ndarray (m, 4)
        Bernstein coefficients of the quaternion polynomial A(t) (scalar, i, j, k); ``m`` is fixed by
        the subclass (2 for PH cubics, 3 for PH quintics).
    p0 : ndarray (3,)
        Start point r(0) (metres).

    All evaluation methods take parameters t of shape (n,) (or a scalar) and are vectorized.
    """

    A: np.ndarray
    p0: np.ndarray

    #: Number of quaternion coefficients (set by subclasses).
    M = 0
    NAME = "PH curve"

    def __post_init__(self):
        A = np.array(self.A, dtype=float)
        if A.shape != (self.M, 4):
            raise PlannerError(f"{self.NAME}: A must have shape ({self.M}, 4) ({self.M} quaternions), got {A.shape}")
        if not np.isfinite(A).all():
            raise PlannerError(f"{self.NAME}: A must be finite")
        p0 = check_vector(self.p0, "p0").copy()
        A.setflags(write=False)
        p0.setflags(write=False)
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "p0", p0)

    @property
    def degree(self) -> int:
        """Polynomial degree of r(t): 2m - 1."""
        return 2 * self.M - 1

    # -- polynomial data ---------------------------------------------------------------------
    @cached_property
    def hodograph_coeffs(self) -> np.ndarray:
        """Bernstein coefficients (2m - 1, 3) of r'(t)."""
        return batch_hodograph(self.A)

    @cached_property
    def control_points(self) -> np.ndarray:
        """Bezier control points (2m, 3) of r(t)."""
        return batch_control_points(self.A, self.p0)

    @cached_property
    def sigma_coeffs(self) -> np.ndarray:
        """Bernstein coefficients (2m - 1,) of the parametric speed sigma(t) = |r'(t)|."""
        return batch_sigma(self.A)

    @property
    def length(self) -> float:
        """Total arc length (metres), exact: the mean of the speed's Bernstein coefficients."""
        return float(self.sigma_coeffs.mean())

    # -- evaluation --------------------------------------------------------------------------
    def points(self, t) -> np.ndarray:
        """Points r(t), shape (n, 3)."""
        return bernstein.evaluate(self.control_points, _params(t))

    def derivative(self, t, order: int = 1) -> np.ndarray:
        """Derivative of the given order (1..degree) with respect to t, shape (n, 3)."""
        order = as_int(order, "order", 1, self.degree)
        c = self.control_points
        for _ in range(order):
            c = bernstein.derivative(c)
        return bernstein.evaluate(c, _params(t))

    def speed(self, t) -> np.ndarray:
        """Parametric speed sigma(t) = |r'(t)| (metres per unit t), shape (n,); a polynomial."""
        return bernstein.evaluate(self.sigma_coeffs, _params(t))

    def arc_length(self, t0=0.0, t1=1.0):
        """Exact arc length from t0 to t1 (vectorized over either), metres."""
        S = arc_length_coeffs(self.sigma_coeffs)
        a, b = np.broadcast_arrays(finite_floats(t0, "t0"), finite_floats(t1, "t1"))
        val = bernstein.evaluate(S, np.ravel(b)) - bernstein.evaluate(S, np.ravel(a))
        return val.reshape(a.shape) if a.ndim else float(val[0])

    def parameter_at_length(self, s) -> np.ndarray:
        """Parameters t (n,) at arc lengths s (n,) measured from t = 0; s must lie in [0, length]."""
        L = self.length
        s = check_arc_lengths(s, L)
        sig = np.broadcast_to(self.sigma_coeffs, (s.size, self.sigma_coeffs.size))
        return invert_arc_length(sig, s)

    def tangent(self, t) -> np.ndarray:
        """Unit tangent r'/|r'|, shape (n, 3)."""
        return self.derivative(t) / self.speed(t)[:, None]

    def curvature(self, t) -> np.ndarray:
        """Curvature (1/metres), shape (n,)."""
        return curvature_torsion(self.derivative(t), self.derivative(t, 2), self.derivative(t, 3))[0]

    def torsion(self, t) -> np.ndarray:
        """Torsion (1/metres), shape (n,); 0 where the curvature vanishes."""
        return curvature_torsion(self.derivative(t), self.derivative(t, 2), self.derivative(t, 3))[1]

    def quaternion(self, t) -> np.ndarray:
        """The quaternion polynomial A(t), shape (n, 4)."""
        return bernstein.evaluate(self.A, _params(t))
