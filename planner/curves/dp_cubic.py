"""Planar cubic DP curves and the condition for them to be Pythagorean-hodograph (PH) curves.

A cubic DP curve (seed ``dp-ph-cubic-construction.md``, section 2.1) is

    P(t) = sum_i p_i D_i(t),  [D_0, D_1, D_2, D_3] = [(1-t)^3, t(1-t)(2-t), t(1-t)(1+t), t^3],  t in [0, 1].

Since t(1-t)(2-t) = (2/3) B_1 + (1/3) B_2 and t(1-t)(1+t) = (1/3) B_1 + (2/3) B_2 with the cubic Bernstein
polynomials B_k, the Bezier points of P are b = (p0, (2 p1 + p2)/3, (p1 + 2 p2)/3, p3) and back
p1 = 2 b1 - b2, p2 = 2 b2 - b1 (shared/DESIGN.md, "Checked facts").

The PH condition, derived here from the hodograph (not copied from the seed, whose section 2.3 is wrong)
-----------------------------------------------------------------------------------------------------
Write points as complex numbers and the DP legs as D0 = p1 - p0, D1 = p2 - p1, D2 = p3 - p2. The Bezier legs
are L1 = b1 - b0 = D0 + D1/3, L2 = b2 - b1 = D1/3, L3 = b3 - b2 = D2 + D1/3 (so that
3 (L1 L3 - L2^2) = 3 D0 D2 + D1 (D0 + D2)), and the hodograph is
P'(t) = 3 (L1 (1-t)^2 + 2 L2 (1-t) t + L3 t^2), a complex quadratic p(t). |P'|^2 = p conj(p) is the square of
a real polynomial iff every root of p is real or the roots are a conjugate pair (then p = c q(t) with q real:
a straight line) or p has a double root (p = w(t)^2, w linear). So a planar cubic is PH iff

  (a) it is a straight line (all hodograph coefficients parallel), or
  (b) P'(t) = w(t)^2 with w(t) = w0 (1-t) + w1 t complex linear, i.e. L1 L3 = L2^2 (complex), i.e.

          3 D0 D2 + D1 (D0 + D2) = 0      <=>      1/D0 + 3/D1 + 1/D2 = 0      (all legs nonzero).

In (b) the DP legs are D0 = w0 (w0 - w1)/3, D1 = w0 w1, D2 = w1 (w1 - w0)/3, and |P'(t)| = |w(t)|^2.
Geometrically (conj(1/z) = z/|z|^2): the vectors D0/|D0|^2, 3 D1/|D1|^2, D2/|D2|^2 close a triangle. With side
lengths l_k = |D_k| and turning angles th1 (from D0 to D1), th2 (from D1 to D2) this reads

    l2 sin th1 = l0 sin th2     and     l1 (l2 cos th1 + l0 cos th2) = -3 l0 l2.

The three leg directions must therefore positively span the plane: th1, th2 have one sign and
|th1 + th2| > pi -- the DP polygon of a curved PH cubic always turns by more than a half turn.

The seed instead states 2 |D1 D2| = 3 sqrt(|D0 D1| |D2 D3|) with equal angles th1 = th2 (section 2.3 and eq.
3.x); for a polygon with equal angles our condition forces l0 = l2 and cos th = -3 l0 / (2 l1), so the
seed's pair of conditions only admits the degenerate th = pi: the seed's condition is wrong (tests show it).

"PH" is tested from the definition: ``is_ph`` checks that |P'(t)| equals a polynomial on [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner import bernstein
from planner.errors import NoSolutionError, PlannerError

#: DP control points -> Bezier control points (rows: b0..b3 as combinations of p0..p3).
DP_TO_BEZIER = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 2 / 3, 1 / 3, 0.0], [0.0, 1 / 3, 2 / 3, 0.0], [0.0, 0.0, 0.0, 1.0]]
)
#: Bezier control points -> DP control points (the inverse of DP_TO_BEZIER).
BEZIER_TO_DP = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 2.0, -1.0, 0.0], [0.0, -1.0, 2.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)

#: Relative tolerance of the PH tests (|P'| against its best quadratic fit, condition residuals).
PH_RTOL = 1e-9

_FIT_NODES = 0.5 - 0.5 * np.cos(np.pi * (np.arange(25) + 0.5) / 25)  # Chebyshev nodes on [0, 1]


class NotPHError(NoSolutionError):
    """An operation needs a PH curve (exact arc length, preimage) and the curve is not one."""


def dp_basis(t) -> np.ndarray:
    """The cubic DP basis of the seed (section 2.1) at t (n,), shape (n, 4)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    s = 1.0 - t
    return np.stack((s**3, t * s * (2.0 - t), t * s * (1.0 + t), t**3), axis=-1)


def dp_basis_derivative(t) -> np.ndarray:
    """Derivatives of the cubic DP basis at t (n,), shape (n, 4)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    return np.stack((-3 * (1 - t) ** 2, 2 - 6 * t + 3 * t**2, 1 - 3 * t**2, 3 * t**2), axis=-1)


def _c(v: np.ndarray) -> np.ndarray:
    """Points (..., 2) as complex numbers (...)."""
    return v[..., 0] + 1j * v[..., 1]


def _xy(z) -> np.ndarray:
    """Complex numbers (...) as points (..., 2)."""
    z = np.asarray(z, dtype=complex)
    return np.stack((z.real, z.imag), axis=-1)


def ph_condition(control_points) -> complex:
    """The complex PH condition 3 D0 D2 + D1 (D0 + D2) of a DP control polygon (4, 2), unscaled.

    Zero (for a polygon that is not a straight line) iff the DP cubic is PH; see the module docstring.
    """
    d0, d1, d2 = _c(np.diff(np.asarray(control_points, dtype=float), axis=0))
    return complex(3 * d0 * d2 + d1 * (d0 + d2))


def polygon_geometry(control_points) -> tuple[np.ndarray, np.ndarray]:
    """Side lengths (l0, l1, l2) and signed turning angles (th1, th2) in (-pi, pi] of a DP polygon."""
    d = _c(np.diff(np.asarray(control_points, dtype=float), axis=0))
    return np.abs(d), np.angle(d[1:] / d[:-1])


def ph_polygon_residuals(control_points) -> tuple[float, float]:
    """The PH condition in side lengths and angles, both scale-free (zero iff PH, curved case).

    Returns ``(l2 sin th1 - l0 sin th2) / (l0 + l2)`` and
    ``(l1 (l2 cos th1 + l0 cos th2) + 3 l0 l2) / (l0 l1 + l1 l2 + l0 l2)``.
    """
    (l0, l1, l2), (th1, th2) = polygon_geometry(control_points)
    r1 = (l2 * np.sin(th1) - l0 * np.sin(th2)) / (l0 + l2)
    r2 = (l1 * (l2 * np.cos(th1) + l0 * np.cos(th2)) + 3 * l0 * l2) / (l0 * l1 + l1 * l2 + l0 * l2)
    return float(r1), float(r2)


@dataclass(frozen=True, eq=False)
class DPCubic:
    """A planar cubic DP curve P(t) = sum p_i D_i(t), t in [0, 1] (seed section 2.1).

    Attributes
    ----------
    control_points : ndarray (4, 2)
        DP control points p0..p3 (metres). P(0) = p0, P(1) = p3.
    """

    control_points: np.ndarray

    def __post_init__(self):
        try:
            p = np.array(self.control_points, dtype=float)
        except (TypeError, ValueError):
            raise PlannerError("DP control points must be numeric, shape (4, 2)") from None
        if p.shape != (4, 2):
            raise PlannerError(f"DP control points must have shape (4, 2), got {p.shape}")
        if not np.isfinite(p).all():
            i = int(np.argmax(~np.isfinite(p).all(axis=1)))
            raise PlannerError(f"DP control point {i} is not finite: {p[i].tolist()}")
        p.setflags(write=False)
        object.__setattr__(self, "control_points", p)

    # -- constructors ---------------------------------------------------------------------------
    @classmethod
    def from_bezier(cls, bezier_points) -> DPCubic:
        """The DP cubic with the given Bezier control points (4, 2): p1 = 2 b1 - b2, p2 = 2 b2 - b1."""
        b = np.asarray(bezier_points, dtype=float)
        if b.shape != (4, 2):
            raise PlannerError(f"Bezier control points must have shape (4, 2), got {b.shape}")
        return cls(BEZIER_TO_DP @ b)

    @classmethod
    def from_preimage(cls, w0: complex, w1: complex, p0=(0.0, 0.0)) -> DPCubic:
        """The PH DP cubic with P'(t) = w(t)^2, w(t) = w0 (1-t) + w1 t (complex), starting at p0.

        DP legs p1 - p0 = w0 (w0 - w1)/3, p2 - p1 = w0 w1, p3 - p2 = w1 (w1 - w0)/3 (module docstring).
        """
        w0, w1 = complex(w0), complex(w1)
        start = complex(*np.asarray(p0, dtype=float))
        legs = np.array([w0 * (w0 - w1) / 3, w0 * w1, w1 * (w1 - w0) / 3])
        return cls(_xy(start + np.concatenate(([0.0], np.cumsum(legs)))))

    # -- representation -------------------------------------------------------------------------
    def to_bezier(self) -> np.ndarray:
        """Bezier control points (4, 2) of the same cubic: p0, (2p1 + p2)/3, (p1 + 2p2)/3, p3."""
        return DP_TO_BEZIER @ self.control_points

    @property
    def legs(self) -> np.ndarray:
        """DP control polygon legs D0, D1, D2, shape (3, 2)."""
        return np.diff(self.control_points, axis=0)

    def hodograph(self) -> np.ndarray:
        """Bernstein coefficients (3, 2) of P'(t): 3 (b1 - b0), 3 (b2 - b1), 3 (b3 - b2)."""
        return bernstein.derivative(self.to_bezier())

    # -- evaluation -----------------------------------------------------------------------------
    def points(self, t) -> np.ndarray:
        """Points P(t), shape (n, 2), for t (n,)."""
        return dp_basis(t) @ self.control_points

    def derivative(self, t) -> np.ndarray:
        """Hodograph P'(t), shape (n, 2)."""
        return dp_basis_derivative(t) @ self.control_points

    def speed(self, t) -> np.ndarray:
        """|P'(t)|, shape (n,)."""
        return np.linalg.norm(self.derivative(t), axis=-1)

    def tangent(self, t) -> np.ndarray:
        """Unit tangent P'(t)/|P'(t)|, shape (n, 2)."""
        d = self.derivative(t)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    # -- PH property ----------------------------------------------------------------------------
    def ph_residual(self) -> float:
        """How far |P'(t)| is from a polynomial on [0, 1]: 0 to round-off iff the curve is PH.

        |P'| is sampled at 25 Chebyshev nodes and fitted by the least-squares quadratic (|P'| of a
        PH cubic is a quadratic); the result is the largest deviation divided by max |P'|. A quadratic
        q with |q - sqrt(x'^2 + y'^2)| tiny at 25 nodes forces the quartic q^2 - x'^2 - y'^2 to vanish.
        """
        s = self.speed(_FIT_NODES)
        scale = float(s.max())
        if scale == 0.0:
            return 0.0
        B = bernstein.basis(2, _FIT_NODES)
        coef, *_ = np.linalg.lstsq(B, s, rcond=None)
        return float(np.abs(B @ coef - s).max() / scale)

    def is_ph(self, rtol: float = PH_RTOL) -> bool:
        """True iff |P'(t)| is a polynomial on [0, 1] (to relative tolerance ``rtol``)."""
        return self.ph_residual() <= rtol

    def ph_condition_residual(self) -> float:
        """|3 D0 D2 + D1 (D0 + D2)| / max|D_k|^2: the derived DP-polygon condition (b), scale-free."""
        scale = float(np.max(np.linalg.norm(self.legs, axis=1))) ** 2
        return abs(ph_condition(self.control_points)) / scale if scale > 0 else 0.0

    def is_straight(self, rtol: float = PH_RTOL) -> bool:
        """True iff the hodograph coefficients are parallel (the curve lies on a line)."""
        h = self.hodograph()
        scale = float(np.max(np.linalg.norm(h, axis=1))) ** 2
        cross = h[:, 0, None] * h[None, :, 1] - h[:, 1, None] * h[None, :, 0]
        return bool(np.abs(cross).max() <= rtol * scale)

    def satisfies_ph_condition(self, rtol: float = PH_RTOL) -> bool:
        """The derived necessary and sufficient PH condition on the DP control polygon.

        Either condition (b), 3 D0 D2 + D1 (D0 + D2) = 0, or a straight line whose speed along the line
        keeps its sign on [0, 1] (so that |P'| is a polynomial there).
        """
        if self.ph_condition_residual() <= rtol:
            return True
        if not self.is_straight(rtol):
            return False
        h = self.hodograph()
        e = h[np.argmax(np.linalg.norm(h, axis=1))]
        q = h @ e  # speed along the line, Bernstein coefficients
        _, b, a = bernstein.to_power(q)  # q(t) = c + b t + a t^2
        cand = [0.0, 1.0] + ([-b / (2 * a)] if a != 0 and 0 < -b / (2 * a) < 1 else [])
        vals = bernstein.evaluate(q, np.array(cand))
        tol = rtol * float(np.abs(q).max())
        return bool(vals.min() >= -tol or vals.max() <= tol)

    def preimage(self) -> tuple[complex, complex]:
        """(w0, w1) with P'(t) = w(t)^2, w(t) = w0 (1-t) + w1 t; raises NotPHError if there is none.

        Defined up to a common sign. Uses the Bezier legs: w0^2 = 3 L1, w0 w1 = 3 L2, w1^2 = 3 L3.
        """
        b = _c(self.to_bezier())
        L1, L2, L3 = np.diff(b)
        scale = max(abs(L1), abs(L2), abs(L3))
        if scale == 0.0 or abs(L1 * L3 - L2 * L2) > PH_RTOL * scale**2:
            raise NotPHError("the DP cubic is not of the form P' = w^2 (not a curved PH cubic)")
        if abs(L1) >= abs(L3):
            w0 = np.sqrt(3 * L1)
            w1 = 3 * L2 / w0
        else:
            w1 = np.sqrt(3 * L3)
            w0 = 3 * L2 / w1
        return complex(w0), complex(w1)

    def sigma(self) -> np.ndarray:
        """Bernstein coefficients (3,) of the polynomial speed |P'(t)| of a PH cubic.

        |w(t)|^2 in case (b); for a straight line, the speed along the line (sign made nonnegative).
        Raises NotPHError when |P'| is not a polynomial on [0, 1].
        """
        try:
            w0, w1 = self.preimage()
        except NotPHError:
            if not (self.is_straight() and self.satisfies_ph_condition()):
                raise
            h = self.hodograph()
            e = h[np.argmax(np.linalg.norm(h, axis=1))]
            q = h @ (e / np.linalg.norm(e))
            return q if q.sum() >= 0 else -q
        return np.array([abs(w0) ** 2, (w0 * np.conj(w1)).real, abs(w1) ** 2])

    def arc_length(self, t=1.0) -> np.ndarray:
        """Exact arc length from 0 to t of a PH cubic (a cubic polynomial in t), shape like t."""
        S = bernstein.antiderivative(self.sigma())
        t = np.asarray(t, dtype=float)
        return bernstein.evaluate(S, np.atleast_1d(t)).reshape(t.shape)

    @property
    def length(self) -> float:
        """Exact total arc length of a PH cubic (metres)."""
        return float(np.sum(self.sigma()) / 3.0)
