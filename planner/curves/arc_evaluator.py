"""Fast exact evaluation of a PH spline at dense arc lengths: inversion s -> (segment, t) and points.

The arc length of a PH segment is the polynomial s_k(t) = integral of sigma_k (grm seed, section 2.2:
sigma = |A|^2 is a polynomial, so s is one of degree deg + 1). Inverting it is root finding on a
monotone polynomial, built here for 10^5..10^7 samples: coefficients stored coefficient-major so that
every Horner step is a contiguous gather, and a quintic Hermite initial guess of the inverse t(s) (end
slopes 1 / sigma and their derivatives) so that one Newton step usually reaches round-off.
``PHSpline.parameter_at_length`` uses it.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np

from planner.curves.ph_core import arc_length_coeffs
from planner.errors import PlannerError
from planner.validation import check_arc_lengths

#: Newton step (in t) after which one more step would change t only at round-off.
_NEWTON_DONE = 1e-8


def _bernstein_to_power(n: int) -> np.ndarray:
    """Matrix M (n+1, n+1): power coefficient k of B_{n,j} is M[k, j] = C(n,k) C(k,j) (-1)^(k-j)."""
    return np.array([[comb(n, k) * comb(k, j) * (-1) ** (k - j) if j <= k else 0.0 for j in range(n + 1)]
                     for k in range(n + 1)])


def _inverse_guess(dS: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Power coefficients (5, N) (r^1..r^5) of the quintic Hermite guess of t(r) on every segment."""
    sig0, sig1 = dS[0], dS.sum(axis=0)  # sigma at t = 0 and t = 1
    dsig0, dsig1 = dS[1], (np.arange(dS.shape[0])[:, None] * dS).sum(axis=0)  # sigma' there
    a, c = h / sig0, h / sig1  # dt/dr at r = 0, 1
    b, d = -h * h * dsig0 / sig0**3, -h * h * dsig1 / sig1**3  # d2t/dr2 at r = 0, 1
    # t(0) = 0, t(1) = 1 with the quintic Hermite basis, collected by powers of r
    return np.ascontiguousarray(np.stack((
        a,
        0.5 * b,
        10.0 - 6.0 * a - 1.5 * b - 4.0 * c + 0.5 * d,
        -15.0 + 8.0 * a + 1.5 * b + 7.0 * c - d,
        6.0 - 3.0 * a - 0.5 * b - 3.0 * c + 0.5 * d,
    )))


@dataclass(frozen=True, eq=False)
class SplineEvaluator:
    """Arc-length inversion and point evaluation of a PH spline, vectorized for long sample sets.

    Attributes
    ----------
    knots : ndarray (N + 1,)
        The spline's global parameter at its knots.
    cumulative : ndarray (N + 1,)
        Arc length at the knots, m.
    S : ndarray (d + 2, N)
        Power-basis coefficients (lowest first) of each segment's arc length s_k(t), t in [0, 1].
    dS : ndarray (d + 1, N)
        Power-basis coefficients of sigma_k(t) = s_k'(t).
    P : ndarray (d + 2, 3, N)
        Power-basis coefficients of each segment's points r_k(t).
    guess : ndarray (5, N)
        Power coefficients (r^1..r^5) of each segment's initial guess of the inverse t(r), r = s / (segment
        length) in [0, 1]: the quintic Hermite interpolant of t(r) with t' = h / sigma and
        t'' = -h^2 sigma' / sigma^3 at both ends (h the segment length), good to ~1e-9 on CAM paths, so
        that one Newton step usually reaches round-off.
    """

    knots: np.ndarray
    cumulative: np.ndarray
    S: np.ndarray
    dS: np.ndarray
    P: np.ndarray
    guess: np.ndarray

    @classmethod
    def of(cls, path) -> SplineEvaluator:
        """Build from a PH spline (``sigma_coeffs``, ``control_points``, ``knots``, ``cumulative_lengths``)."""
        for name in ("sigma_coeffs", "control_points", "knots", "cumulative_lengths"):
            if not hasattr(path, name):
                raise PlannerError(f"path has no {name}: not a PH spline (use its parameter_at_length)")
        B = arc_length_coeffs(np.asarray(path.sigma_coeffs, dtype=float))  # Bernstein coefficients of s_k(t)
        S = _bernstein_to_power(B.shape[1] - 1) @ B.T  # (d + 2, N)
        dS = S[1:] * np.arange(1, S.shape[0])[:, None]
        cp = np.asarray(path.control_points, dtype=float)  # (N, d + 2, 3)
        P = np.einsum("kj,njc->kcn", _bernstein_to_power(cp.shape[1] - 1), cp)
        cumulative = np.asarray(path.cumulative_lengths, float)
        return cls(np.asarray(path.knots, float), cumulative, np.ascontiguousarray(S), np.ascontiguousarray(dS),
                   np.ascontiguousarray(P), _inverse_guess(dS, np.diff(cumulative)))

    @property
    def length(self) -> float:
        return float(self.cumulative[-1])

    def locate(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Segment index k (n,) and local parameter t (n,) in [0, 1] with s_k(t) = s - cumulative[k]."""
        L = self.length
        s = check_arc_lengths(s, L)
        n_seg = self.S.shape[1]
        k = np.clip(np.searchsorted(self.cumulative, s, side="right") - 1, 0, n_seg - 1)
        c0, c1 = self.cumulative[k], self.cumulative[k + 1]
        x = np.maximum(s - c0, 0.0)
        S = [row[k] for row in self.S]  # contiguous gathers, one per coefficient
        dS = [row[k] for row in self.dS]
        r = x / (c1 - c0)
        G = self.guess
        t = G[4][k] * r
        for j in (3, 2, 1, 0):
            t += G[j][k]
            t *= r
        t = np.clip(t, 0.0, 1.0)
        lo = np.zeros_like(t)
        hi = np.ones_like(t)
        active = np.arange(t.size)
        for _ in range(60):  # safeguarded Newton: s_k is strictly increasing (sigma > 0)
            ta = t[active]
            Sa = [c[active] for c in S] if active.size < t.size else S
            dSa = [c[active] for c in dS] if active.size < t.size else dS
            f = Sa[-1] * ta
            for c in Sa[-2:0:-1]:
                f += c
                f *= ta
            f -= x[active]  # S[0] = 0
            g = dSa[-1] * ta
            for c in dSa[-2:0:-1]:
                g += c
                g *= ta
            g += dSa[0]
            la = np.where(f < 0, ta, lo[active])
            ha = np.where(f > 0, ta, hi[active])
            tn = ta - f / g
            outside = (tn <= la) | (tn >= ha) | ~np.isfinite(tn)  # leave the bracket: bisect instead
            tn = np.where(outside, 0.5 * (la + ha), tn)
            t[active], lo[active], hi[active] = tn, la, ha
            # a Newton step below 1e-8 leaves an error at round-off (quadratic convergence); the
            # residual itself stalls at the polynomial's round-off, so do not wait for f = 0
            done = (~outside & (np.abs(tn - ta) <= _NEWTON_DONE)) | (ha - la <= 4 * np.finfo(float).eps)
            active = active[~done]
            if active.size == 0:
                break
        return k, t

    def parameter(self, k, t) -> np.ndarray:
        """Global parameters u (n,) of segments k (n,) at local parameters t (n,)."""
        return self.knots[k] + t * (self.knots[k + 1] - self.knots[k])

    def points(self, k, t) -> np.ndarray:
        """Points r_k(t) (n, 3) by Horner's rule per coordinate."""
        out = np.empty((np.size(t), 3))
        for c in range(3):
            r = self.P[-1, c][k] * t
            for j in range(self.P.shape[0] - 2, 0, -1):
                r += self.P[j, c][k]
                r *= t
            r += self.P[0, c][k]
            out[:, c] = r
        return out

    def __call__(self, s) -> np.ndarray:
        """Global parameters u (n,) at arc lengths s (n,), exact to round-off."""
        return self.parameter(*self.locate(s))
