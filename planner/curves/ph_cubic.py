"""Spatial Pythagorean-hodograph cubics and their G1 Hermite interpolation.

A(t) = (1-t) A0 + t A1 (quaternions), hodograph r'(t) = A(t) i A*(t) with Bezier control vectors
h0 = A0 i A0*, h1 = (A0 i A1* + A1 i A0*)/2, h2 = A1 i A1*. The unit tangent of a PH cubic traces a
circular arc on the unit sphere, which makes PH cubic splines the carrier of Jüttler's rational
rotation-minimizing motions (juttler seed, section 7.1).

G1 Hermite data (two points, two tangent directions) fixes a PH cubic up to finitely many solutions,
or none. Writing A0 = x n0, A1 = y n1 e^{i phi} with n0 i n0* = t0, n1 i n1* = t1 (x, y > 0), the end
condition reads 3 (p1 - p0) = x^2 t0 + y^2 t1 + x y m(phi), m(phi) the vector part of n0 i e^{-i phi} n1*:
three equations in (x, y, phi), solved here by Newton's method from a grid of starts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner import quaternion as qt
from planner.curves.ph_core import batch_hodograph
from planner.curves.ph_curve import PHSegment
from planner.errors import NoSolutionError, PlannerError
from planner.validation import check_vector


@dataclass(frozen=True, eq=False)
class PHCubic(PHSegment):
    """A spatial PH cubic r(t), t in [0, 1], with hodograph A(t) i A*(t), A linear.

    Parameters
    ----------
    A : ndarray (2, 4)
        Bernstein coefficients A0, A1 of the linear quaternion polynomial (scalar, i, j, k).
    p0 : ndarray (3,)
        Start point (metres).
    """

    M = 2
    NAME = "PHCubic"

    @classmethod
    def from_quaternions(cls, A0, A1, p0=(0.0, 0.0, 0.0)) -> PHCubic:
        """The PH cubic with A(t) = (1-t) A0 + t A1 and r(0) = p0."""
        return cls(np.array([A0, A1], dtype=float), np.asarray(p0, dtype=float))

    @classmethod
    def hermite_all(cls, p0, p1, t0, t1) -> list[PHCubic]:
        """Every PH cubic from p0 to p1 with tangent directions t0 at p0 and t1 at p1 (G1 data).

        Returns the solutions sorted by arc length (shortest first); an empty list when the data admits
        none. Tangent lengths are ignored.
        """
        p0 = check_vector(p0, "p0")
        p1 = check_vector(p1, "p1")
        t0 = check_vector(t0, "t0", nonzero=True)
        t1 = check_vector(t1, "t1", nonzero=True)
        if np.linalg.norm(p1 - p0) == 0:
            raise PlannerError("p0 and p1 coincide: a PH cubic needs distinct end points")
        sols = _g1_solutions(p1 - p0, t0 / np.linalg.norm(t0), t1 / np.linalg.norm(t1))
        curves = [cls(A, p0) for A in sols]
        return sorted(curves, key=lambda c: c.length)

    @classmethod
    def hermite(cls, p0, p1, t0, t1) -> PHCubic:
        """The shortest PH cubic matching G1 data (see :meth:`hermite_all`).

        Raises
        ------
        NoSolutionError
            When no PH cubic matches the data (e.g. the tangents point away from each other
            relative to the chord); split the span (``fit_ph_cubic_spline`` does so automatically).
        """
        sols = cls.hermite_all(p0, p1, t0, t1)
        if not sols:
            raise NoSolutionError(
                f"no PH cubic joins {np.asarray(p0, float).tolist()} to {np.asarray(p1, float).tolist()} "
                "with the given tangent directions; subdivide the span"
            )
        return sols[0]


_STARTS = {  # (ratios x / y, magnitudes x y / |dp|, phase offsets) of the Newton starts
    False: (np.array([1.0, 0.5, 2.0]), np.array([1.0]), np.arange(4) * (0.5 * np.pi)),
    True: (np.array([1.0, 0.5, 2.0, 0.25, 4.0]), np.array([1.0, 4.0, 16.0]), np.arange(16) * (0.125 * np.pi)),
}


def batch_g1(dp: np.ndarray, t0: np.ndarray, t1: np.ndarray, dense: bool = False):
    """PH cubic G1 Hermite solutions for N spans at once, by Newton's method from several starts.

    The starts surround the ordinary cubic Hermite guess (end hodograph lengths |dp|, so
    h1 = 3 dp - |dp| (t0 + t1)), with end-length ratios, magnitudes and phase turns from a small set
    (12 starts, enough for the shortest solution) or, with ``dense``, a large one (240 starts, which
    finds every solution in our tests, long loops included).

    Each span is solved for its chord scaled to length 1 and scaled back (the PH cubic of data scaled by c is
    c times the curve, A times sqrt(c)): the Newton iteration, its clipped steps and its tolerances are the
    same at every scale. (They were not: the phase step was clipped to sqrt(3 |dp|) rad, 8e-5 rad on chords
    of 2 nm, where no start converged and every span was halved to the limit.)

    Parameters
    ----------
    dp, t0, t1 : (N, 3)
        Chords p1 - p0 (nonzero) and unit end tangents.

    Returns
    -------
    A : (N, S, 2, 4)
        Candidate quaternion coefficients (S starts per span).
    ok : (N, S) bool
        Which candidates solve the end conditions to round-off. Candidates may repeat.
    """
    length = np.hypot(np.hypot(dp[:, 0], dp[:, 1]), dp[:, 2])  # (no overflow or underflow of the squares)
    A, ok = _batch_g1_unit(dp / length[:, None], t0, t1, dense)
    return A * np.sqrt(length)[:, None, None, None], ok


def _batch_g1_unit(dp: np.ndarray, t0: np.ndarray, t1: np.ndarray, dense: bool):
    """:func:`batch_g1` for chords dp (N, 3) of length 1."""
    n0, n1 = qt.rotate_i_to(t0), qt.rotate_i_to(t1)
    mc = qt.i_product(n0, n1)[:, None]  # m(phi) = cos(phi) mc + sin(phi) ms, phi the phase of A1
    ms = qt.i_product(n0, qt.mul(n1, qt.I))[:, None]
    target = 3.0 * dp[:, None]
    chord = np.linalg.norm(dp, axis=1)
    scale = np.sqrt(3.0 * chord)[:, None]
    u0, u1 = t0[:, None], t1[:, None]
    h1 = 3.0 * dp - chord[:, None] * (t0 + t1)
    phi0 = np.arctan2(np.einsum("nd,nd->n", ms[:, 0], h1), np.einsum("nd,nd->n", mc[:, 0], h1))
    r, mag, off = (g.ravel() for g in np.meshgrid(*_STARTS[dense], indexing="ij"))
    x = np.sqrt(chord)[:, None] * r * np.sqrt(mag)
    y = np.sqrt(chord)[:, None] / r * np.sqrt(mag)
    ph = phi0[:, None] + off

    def residual(x, y, ph):
        m = np.cos(ph)[..., None] * mc + np.sin(ph)[..., None] * ms
        return (x * x)[..., None] * u0 + (y * y)[..., None] * u1 + (x * y)[..., None] * m - target, m

    for _ in range(40):
        F, m = residual(x, y, ph)
        dm = -np.sin(ph)[..., None] * mc + np.cos(ph)[..., None] * ms
        J = np.stack((2 * x[..., None] * u0 + y[..., None] * m, 2 * y[..., None] * u1 + x[..., None] * m,
                      (x * y)[..., None] * dm), axis=-1)
        det = np.linalg.det(J)
        okJ = np.abs(det) > 1e-14 * scale**4
        Jsafe = np.where(okJ[..., None, None], J, np.eye(3))
        step = np.linalg.solve(Jsafe, F[..., None])[..., 0] * okJ[..., None]
        step = np.clip(step, -scale[..., None], scale[..., None])
        x, y, ph = x - step[..., 0], y - step[..., 1], ph - step[..., 2]
        if np.abs(step).max() < 1e-15 * scale.min():
            break
    F, _ = residual(x, y, ph)
    nonzero = (np.abs(x) > 1e-9 * scale) & (np.abs(y) > 1e-9 * scale)
    ok = (np.linalg.norm(F, axis=-1) < 1e-12 * scale**2) & nonzero
    A = np.stack((x[..., None] * n0[:, None], y[..., None] * qt.mul(n1[:, None], qt.exp_i(ph))), axis=-2)
    return A, ok


def _g1_solutions(dp: np.ndarray, t0: np.ndarray, t1: np.ndarray) -> list[np.ndarray]:
    """The distinct quaternion pairs (2, 4) of PH cubics with chord dp and unit end tangents t0, t1."""
    A, ok = batch_g1(dp[None], t0[None], t1[None], dense=True)
    scale = 3.0 * np.linalg.norm(dp)
    sols: list[np.ndarray] = []
    seen: list[np.ndarray] = []
    for cand in A[0][ok[0]]:
        hod = batch_hodograph(cand)  # the curve is determined by its hodograph
        if any(np.abs(hod - h).max() < 1e-8 * scale for h in seen):
            continue
        seen.append(hod)
        sols.append(cand)
    return sols
