"""DP-PH cubics through G1 Hermite data (seed ``dp-ph-cubic-construction.md``, sections 3 and 4).

Two readings of "end tangent directions" are offered, because with the seed's DP basis they differ:

* ``mode="curve"`` (default, what a G1 spline needs): the *curve* leaves p0 along d0 and arrives at p3
  along d3. With P'(t) = w(t)^2, w = a (u0 (1-t) + k u3 t), u0^2 = e0, u3^2 = e3 (unit complex directions),
  the end conditions hold for any real a != 0, k > or < 0, and the chord condition
  P(1) - P(0) = (w0^2 + w0 w1 + w1^2)/3 = D becomes

      a^2 (e0 + k u0 u3 + k^2 e3) = 3 D:   Im((e0 + k u0 u3 + k^2 e3) conj(D)) = 0  (a real quadratic in k),

  with Re(...) > 0. So there are at most two PH cubics (hence DP-PH cubics) for given G1 data. Roots with
  |k| outside [1/KMAX, KMAX] are dropped: their speed at one end is below 1e-6 of the other (a near-cusp
  whose end tangent round-off cannot resolve); at k -> 0 or infinity they degenerate to a zero end speed.
* ``mode="polygon"`` (the seed's section 3 literally, eq. 3.1): the DP control points lie on the tangent
  lines, p1 = p0 + lam e0, p2 = p3 - mu e3 with lam, mu > 0. With the seed's basis the curve is then *not*
  tangent to d0 at p0 (P'(0) = 3 D0 + D1, not parallel to D0), so these curves do not have the end tangents
  the seed claims. The PH condition 3 D0 D2 + D1 (D0 + D2) = 0 with D0 = lam e0, D2 = mu e3,
  D1 = D - lam e0 - mu e3 reduces to

      lam mu e0 e3 + lam D e0 + mu D e3 - lam^2 e0^2 - mu^2 e3^2 = 0;

  on the rays mu = s lam this is lam Q(s) = R(s) with Q = s e0 e3 - e0^2 - s^2 e3^2, R = -D (e0 + s e3),
  and lam real is the real cubic Im(R conj(Q)) = 0 in s: at most three solutions.
  In the seed's setting (eq. 3.2, tangent lines meeting at O between the end points) with its bounds
  0 <= lam, mu <= 1 there is never a solution: D0 points along O - p0, D2 along p3 - O, and D1 = p2 - p1
  joins the two rays, so the polygon turns by theta - pi, less than a half turn, while a curved PH DP
  polygon turns by more than a half turn (planner.curves.dp_cubic). Solutions need lam > |O p0| or
  mu > |O p3| (control points beyond O).

The seed's own construction (eqs. 3.3-3.6) imposes |O P1| = |O P2| (eq. 3.3) and its wrong PH condition,
and eq. 3.4 has |P3 D2| = rho + lam + 1 where the figure gives rho mu; its example (theta = pi/3, rho = 1,
lam = mu = 2/5, D2 = (1/5, sqrt(3)/5)) contradicts eq. 3.3 (which gives D2 = (3/10, 3 sqrt(3)/10)), and
neither polygon is PH. ``seed_setting`` builds that data so the true solutions can be compared.

Section 4 (error between a DP curve and the DP-PH curve on the same end data) is ``dp_ph_error``: the
distance |P(t) - D(t)| at equal parameter and its exact maximum. The seed's formula for n(t) is negative
near t = 0 (its constant term (3+sqrt3)^2/400 - 3/5 < 0) and cannot be a squared norm; only its structure
n(t) = t^2 (1-t)^2 |A + B t|^2 and the bound max_i |P_i - D_i| (the DP basis is a nonnegative partition of
unity on [0, 1]) are right.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.polynomial import polynomial as P

from planner.curves.dp_cubic import DPCubic
from planner.errors import NoSolutionError, PlannerError
from planner.validation import ArgumentError, as_floats

#: Relative tolerance for "parallel" directions and for accepting polynomial roots as real.
ROOT_RTOL = 1e-10
#: Curve mode drops solutions whose end speeds differ by more than KMAX^2 (near-cusps at an end).
KMAX = 1e3


class HermiteDataError(PlannerError):
    """G1 Hermite data (end points, tangent directions) is malformed."""


def _point(v, name: str) -> complex:
    try:
        a = as_floats(v, name)
    except ArgumentError as exc:
        raise HermiteDataError(f"{name} must be a numeric 2-vector: {str(exc).partition(': ')[2]}") from None
    if a.shape != (2,):
        raise HermiteDataError(f"{name} must have shape (2,), got {a.shape}")
    if not np.isfinite(a).all():
        raise HermiteDataError(f"{name} must be finite, got {a.tolist()}")
    return complex(a[0], a[1])


def _direction(v, name: str) -> complex:
    z = _point(v, name)
    if z == 0:
        raise HermiteDataError(f"{name} must not be the zero vector")
    return z / abs(z)


def seed_setting(theta: float, rho: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The seed's normalized data (eq. 3.2): tangent lines meeting at the origin O.

    p0 = (1, 0) with tangent d0 = (-1, 0) (towards O), p3 = rho (cos theta, sin theta) with tangent
    d3 = (cos theta, sin theta) (away from O). Returns (p0, d0, p3, d3).
    """
    if not (np.isfinite(theta) and np.isfinite(rho) and rho > 0):
        raise HermiteDataError(f"seed setting needs finite theta and rho > 0, got {theta}, {rho}")
    e = np.array([np.cos(theta), np.sin(theta)])
    return np.array([1.0, 0.0]), np.array([-1.0, 0.0]), rho * e, e


def _real_roots(coeffs: np.ndarray) -> np.ndarray:
    """Real roots of a power-basis polynomial (lowest degree first), leading zeros trimmed."""
    c = np.asarray(coeffs, dtype=float)
    scale = np.abs(c).max()
    if scale == 0:
        return np.zeros(0)
    c = np.trim_zeros(np.where(np.abs(c) <= ROOT_RTOL * scale, 0.0, c), "b")
    if c.size < 2:
        return np.zeros(0)
    r = P.polyroots(c)
    return np.sort(r[np.abs(r.imag) <= 1e-7 * np.maximum(1.0, np.abs(r))].real)


def _curve_mode(p0: complex, e0: complex, p3: complex, e3: complex) -> list[DPCubic]:
    D = p3 - p0
    u0, u3 = np.sqrt(e0), np.sqrt(e3)
    c = np.array([e0, u0 * u3, e3])  # e0 + k u0 u3 + k^2 e3
    im = (c * np.conj(D)).imag / abs(D)
    if np.abs(im).max() <= ROOT_RTOL:
        # e0 = e3 = +-D/|D| and u0 u3 parallel to D: a one-parameter family of straight lines
        if (e0 * np.conj(D)).real > 0:  # w = sqrt(D) constant: P' = D, ends exactly at p3
            return [DPCubic.from_preimage(np.sqrt(D), np.sqrt(D), _xy1(p0))]
        raise NoSolutionError(
            "both tangents point backwards along the chord: a PH cubic would need a cusp"
        )
    out = []
    for k in _real_roots(im):
        # k = 0 (or infinite): zero speed at p3 (p0), where the tangent is not d3 (d0). Solutions with an
        # end speed ratio k^2 beyond KMAX^2 are near-cusps whose end tangents are lost to round-off.
        if not 1.0 / KMAX <= abs(k) <= KMAX:
            continue
        ck = c[0] + k * c[1] + k * k * c[2]
        s = (ck * np.conj(D)).real / abs(D) ** 2  # ck = s D
        if s <= ROOT_RTOL * abs(ck) / abs(D):
            continue
        a = np.sqrt(3.0 / s)
        cp = DPCubic.from_preimage(a * u0, a * k * u3, _xy1(p0)).control_points.copy()
        cp[3] = _xy1(p3)  # the chord condition holds to round-off: make the end point exact
        out.append(DPCubic(cp))
    return out


def _polygon_mode(p0: complex, e0: complex, p3: complex, e3: complex) -> list[DPCubic]:
    D = p3 - p0
    if abs((e0 * np.conj(D)).imag) <= ROOT_RTOL * abs(D) and abs((e3 * np.conj(D)).imag) <= ROOT_RTOL * abs(
        D
    ):
        # straight: a two-parameter family of lines, PH where the speed does not reverse; return the
        # member with lam = mu = |D| / 3 / 2^j for the smallest j that gives one (j exists: as lam, mu
        # -> 0 the Bezier points tend to p0 + D/3, p0 + 2D/3 whatever the leg directions)
        for j in range(60):
            lam = abs(D) / 3 / 2**j
            c = DPCubic(_xy(np.array([p0, p0 + lam * e0, p3 - lam * e3, p3])))
            if c.satisfies_ph_condition():
                return [c]
        raise NoSolutionError("straight data: no DP cubic without reversal")  # pragma: no cover
    q = np.array([-(e0**2), e0 * e3, -(e3**2)])  # Q(s) = q0 + q1 s + q2 s^2
    r = np.array([-D * e0, -D * e3])  # R(s) = r0 + r1 s
    prod = P.polymul(r, np.conj(q))  # R conj(Q), complex cubic in s
    out = []
    for s in _real_roots(prod.imag / np.abs(prod).max()):
        if s <= ROOT_RTOL:
            continue
        Q = q[0] + s * q[1] + s * s * q[2]
        R = r[0] + s * r[1]
        if abs(Q) <= ROOT_RTOL * abs(R):
            continue
        lam = (R * np.conj(Q)).real / abs(Q) ** 2
        if lam <= ROOT_RTOL * abs(D):
            continue
        mu = s * lam
        out.append(DPCubic(_xy(np.array([p0, p0 + lam * e0, p3 - mu * e3, p3]))))
    return out


def _xy1(z: complex) -> np.ndarray:
    return np.array([z.real, z.imag])


def _xy(z: np.ndarray) -> np.ndarray:
    return np.stack((z.real, z.imag), axis=-1)


def dp_ph_hermite(p0, d0, p3, d3, mode: Literal["curve", "polygon"] = "curve") -> list[DPCubic]:
    """All DP-PH cubics from p0 to p3 with end tangent directions d0, d3.

    Parameters
    ----------
    p0, p3 : array_like (2,)
        End points (metres), distinct.
    d0, d3 : array_like (2,)
        Tangent directions at p0 and p3 (nonzero; lengths ignored).
    mode : "curve" or "polygon"
        "curve": the curve's own tangents are d0 and d3 (P'(0) = c0 d0, P'(1) = c3 d3 with c0, c3 > 0);
        at most two solutions. "polygon": the seed's eq. (3.1), p1 = p0 + lam d0, p2 = p3 - mu d3 with
        lam, mu > 0; at most three. See the module docstring for the derivation of both.

    Returns
    -------
    list of DPCubic
        Every solution, ordered by arc length (shortest first). For straight data (d0 = d3 along the
        chord) the family is infinite and the single uniformly parametrized line is returned.

    Raises
    ------
    HermiteDataError
        Malformed data (the message names the argument), or p0 = p3.
    NoSolutionError
        No DP-PH cubic fits the data (e.g. an inflection is needed: PH cubics have none).
    """
    if mode not in ("curve", "polygon"):
        raise HermiteDataError(f"mode must be 'curve' or 'polygon', got {mode!r}")
    a, b = _point(p0, "p0"), _point(p3, "p3")
    e0, e3 = _direction(d0, "d0"), _direction(d3, "d3")
    if abs(b - a) <= 1e-14 * max(abs(a), abs(b), 1e-300):
        raise HermiteDataError("p0 and p3 coincide: a DP-PH Hermite cubic needs distinct end points")
    sols = (_curve_mode if mode == "curve" else _polygon_mode)(a, e0, b, e3)
    if not sols:
        raise NoSolutionError(
            f"no DP-PH cubic ({mode} mode) from {_xy1(a).tolist()} along {_xy1(e0).tolist()} "
            f"to {_xy1(b).tolist()} along {_xy1(e3).tolist()}"
            + (" (the data needs an inflection or too much turning)" if mode == "curve" else "")
        )
    return sorted(sols, key=lambda c: c.length)


def polygon_parameters(curve: DPCubic, d0, d3) -> tuple[float, float]:
    """(lam, mu) with p1 = p0 + lam d0/|d0| and p2 = p3 - mu d3/|d3| (the seed's eq. 3.1).

    Meaningful for curves from ``mode="polygon"``; the seed's normalized mu is this mu divided by rho.
    """
    p = curve.control_points
    e0 = np.asarray(d0, float) / np.linalg.norm(d0)
    e3 = np.asarray(d3, float) / np.linalg.norm(d3)
    return float((p[1] - p[0]) @ e0), float((p[3] - p[2]) @ e3)


@dataclass(frozen=True, eq=False)
class DPError:
    """Seed section 4: the distance between a DP curve and a DP-PH curve at equal parameter t.

    Attributes
    ----------
    curve, ph : DPCubic
        The DP curve P and the DP-PH curve D (same end points).
    max_error : float
        eps = max_{t in [0, 1]} |P(t) - D(t)| (seed eq. 4.1), exact to round-off (metres).
    t_max : float
        A parameter value where the maximum is reached.
    bound : float
        max_i |P_i - D_i| >= eps (the DP basis is a nonnegative partition of unity on [0, 1]).
    """

    curve: DPCubic
    ph: DPCubic
    max_error: float
    t_max: float
    bound: float

    def distance(self, t) -> np.ndarray:
        """|P(t) - D(t)|, shape (n,)."""
        return np.linalg.norm(self.curve.points(t) - self.ph.points(t), axis=-1)

    def squared_distance_poly(self) -> np.ndarray:
        """Power coefficients (7,) of n(t) = |P(t) - D(t)|^2 = t^2 (1-t)^2 |A + B t|^2 (lowest first)."""
        return _squared_distance_poly(self.curve.control_points - self.ph.control_points)


def _squared_distance_poly(E: np.ndarray) -> np.ndarray:
    # P - D = sum_i E_i D_i(t) with DP basis power coefficients (lowest first)
    basis = np.array([[1, -3, 3, -1], [0, 2, -3, 1], [0, 1, 0, -1], [0, 0, 0, 1]], dtype=float)
    x = basis.T @ E[:, 0]
    y = basis.T @ E[:, 1]
    n = P.polyadd(P.polymul(x, x), P.polymul(y, y))
    return np.pad(n, (0, 7 - n.size))


def dp_ph_error(curve: DPCubic, ph: DPCubic) -> DPError:
    """Distance function and its exact maximum between a DP curve and a DP-PH curve (seed section 4).

    The curves must share their end points. The maximum of the degree-6 polynomial |P - D|^2 is found at
    the real roots of its derivative in [0, 1].
    """
    E = curve.control_points - ph.control_points
    scale = max(float(np.abs(curve.control_points).max()), float(np.abs(ph.control_points).max()), 1.0)
    if np.abs(E[[0, 3]]).max() > 1e-12 * scale:
        raise PlannerError("dp_ph_error needs two curves with the same end points")
    n = _squared_distance_poly(E)
    cand = np.concatenate(([0.0, 1.0], [r for r in _real_roots(P.polyder(n)) if 0.0 < r < 1.0]))
    vals = P.polyval(cand, n)
    i = int(np.argmax(vals))
    bound = float(np.linalg.norm(E, axis=1).max())
    return DPError(curve, ph, float(np.sqrt(max(vals[i], 0.0))), float(cand[i]), bound)


def dp_ph_errors(curve: DPCubic, mode: Literal["curve", "polygon"] = "curve") -> list[DPError]:
    """Errors between a DP curve and every DP-PH curve built on its end data (seed section 4).

    End data: the end points and, for ``mode="curve"``, the curve's end tangents P'(0), P'(1); for
    ``mode="polygon"``, the end legs p1 - p0 and p3 - p2 (the seed's setting). Raises NoSolutionError
    when no DP-PH cubic has that end data.
    """
    p = curve.control_points
    if mode == "curve":
        d = curve.derivative(np.array([0.0, 1.0]))
        d0, d3 = d[0], d[1]
    else:
        d0, d3 = p[1] - p[0], p[3] - p[2]
    return [dp_ph_error(curve, ph) for ph in dp_ph_hermite(p[0], d0, p[3], d3, mode=mode)]


__all__ = [
    "DPError",
    "HermiteDataError",
    "dp_ph_error",
    "dp_ph_errors",
    "dp_ph_hermite",
    "polygon_parameters",
    "seed_setting",
]
