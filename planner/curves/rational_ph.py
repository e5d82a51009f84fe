"""Spatial rational PH curves in dual form (seed ``dual-rational-ph-curves.txt``).

From a quaternion polynomial A(t) and polynomials f, g (all in the power basis) the seed builds

* h = A i A*  (eq. 22/25), |h| = rho = |A|^2, the Euler-Rodrigues tangent direction;
* v = h x h'  (Theorem 3), v = theta v_R with theta the monic greatest common divisor of the components
  of v (Lemma 1, eqs. 28-30: theta^2 divides lambda = det(h, h', h''));
* the dual form L = (-f; g R v_R) (eq. 16 with the reduction of section 4 and a rotation R, Lemma 2);
* the point form P = L ^ L' ^ L'' (the wedge product of section 2, eq. 7), r = (P1, P2, P3) / P0;
* the hodograph r' = psi R h with psi from eq. (18), applied to the equivalent form (-theta f; g R v).

The curve's class is the degree of L with relatively prime components (Definition 1) and its degree
that of P with relatively prime components.

Numerics: polynomials are power-basis coefficient arrays, lowest degree first. Greatest common divisors
are computed by ``poly_gcd``: the largest d for which the generalized Sylvester matrix of
p_1 u_i - p_i u_1 = 0 (deg u_i = deg p_i - d) has a singular value below ``GCD_RTOL`` times its largest,
each p_i scaled to unit norm; the cofactors give the divisor by least squares, which is accepted only if
it reproduces every p_i to ``GCD_ACCEPT`` = 1e-9 (true divisors of the seed's families reproduce to about
1e-15; near-miss candidates of high-degree point forms to about 1e-5). This is an approximate GCD:
polynomials whose common root is perturbed by less than about 1e-9 (relative) are treated as sharing it.

psi of eq. (18) is a sum of terms that cancel heavily; its numerator is accurate to round-off for the
seed's examples and generic members (tests: 1e-8 and better), but loses digits near nearly real complex
roots of lambda and for members close to degenerate (A nearly sharing a factor): up to 1e-6 relative in
the property tests. ``derivative`` (quotient rule on P) does not have this cancellation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import polynomial as P

from planner import quaternion as qt
from planner.errors import PlannerError

#: Relative singular-value threshold of the numerical polynomial GCD.
GCD_RTOL = 1e-10
#: A candidate GCD g is accepted only if every p_i = g (p_i / g) to this relative residual.
GCD_ACCEPT = 1e-9
#: A polynomial coefficient below this fraction of the polynomial's largest one counts as zero.
ZERO_RTOL = 1e-13
#: |P0(t)| below this fraction of sum |c_k t^k| is a pole of the curve (round-off level).
POLE_RTOL = 64 * np.finfo(float).eps


class DualFormError(PlannerError):
    """The data (A, f, g, R) of a dual-form rational PH curve is malformed or degenerate."""


class SingularParameterError(PlannerError):
    """A rational curve was evaluated at a parameter where it is at infinity (a pole)."""


# -- power-basis polynomial helpers -----------------------------------------------------------------
def trim(c, rtol: float = ZERO_RTOL) -> np.ndarray:
    """Drop leading (highest-degree) coefficients below rtol * max|c|; the zero polynomial is [0.]."""
    c = np.atleast_1d(np.asarray(c, dtype=float))
    scale = np.abs(c).max() if c.size else 0.0
    if scale == 0.0:
        return np.zeros(1)
    keep = np.nonzero(np.abs(c) > rtol * scale)[0]
    return c[: keep[-1] + 1].copy()


def degree(c) -> int:
    """Degree of a polynomial (-1 for the zero polynomial)."""
    c = trim(c)
    return -1 if (c.size == 1 and c[0] == 0) else c.size - 1


def stack(polys) -> np.ndarray:
    """Polynomials as rows of a zero-padded array (n, max_len)."""
    polys = [np.atleast_1d(np.asarray(p, dtype=float)) for p in polys]
    n = max(p.size for p in polys)
    out = np.zeros((len(polys), n))
    for i, p in enumerate(polys):
        out[i, : p.size] = p
    return out


def vtrim(V) -> np.ndarray:
    """Rows of a polynomial vector with common trailing zero columns removed."""
    V = np.atleast_2d(np.asarray(V, dtype=float))
    scale = np.abs(V).max()
    if scale == 0:
        return V[:, :1] * 0
    keep = np.nonzero(np.abs(V).max(axis=0) > ZERO_RTOL * scale)[0]
    return V[:, : keep[-1] + 1]


def vder(V, m: int = 1) -> np.ndarray:
    """Row-wise m-th derivative of a polynomial vector (n, k)."""
    V = np.asarray(V, dtype=float)
    if V.shape[1] <= m:
        return np.zeros((V.shape[0], 1))
    return P.polyder(V, m, axis=1)


def vdot(U, V) -> np.ndarray:
    """sum_i U_i V_i for polynomial vectors U, V."""
    out = np.zeros(1)
    for a, b in zip(np.atleast_2d(U), np.atleast_2d(V), strict=True):
        out = P.polyadd(out, P.polymul(a, b))
    return out


def vcross(U, V) -> np.ndarray:
    """Cross product of polynomial 3-vectors."""
    (u1, u2, u3), (v1, v2, v3) = U, V
    m = P.polymul
    return stack(
        [P.polysub(m(u2, v3), m(u3, v2)), P.polysub(m(u3, v1), m(u1, v3)), P.polysub(m(u1, v2), m(u2, v1))]
    )


def vdet(U, V, W) -> np.ndarray:
    """det(U, V, W) of polynomial 3-vectors (as columns)."""
    return vdot(U, vcross(V, W))


def wedge(L) -> np.ndarray:
    """L ^ L' ^ L'' (seed section 2): component i is (-1)^i det of (L, L', L'') without row i (1-based)."""
    L = np.asarray(L, dtype=float)
    L1, L2 = vder(L, 1), vder(L, 2)
    L1 = np.pad(L1, ((0, 0), (0, L.shape[1] - L1.shape[1])))
    L2 = np.pad(L2, ((0, 0), (0, L.shape[1] - L2.shape[1])))
    out = []
    for i in range(4):
        rows = [j for j in range(4) if j != i]
        sign = -1.0 if i % 2 == 0 else 1.0  # (-1)^(i+1) for the 1-based row index i+1
        out.append(sign * vdet(L[rows], L1[rows], L2[rows]))
    return stack(out)


def qpoly_mul(A, B) -> np.ndarray:
    """Product of quaternion polynomials A (m+1, 4), B (n+1, 4) -> (m+n+1, 4)."""
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    prod = qt.mul(A[:, None, :], B[None, :, :])  # (m+1, n+1, 4)
    out = np.zeros((A.shape[0] + B.shape[0] - 1, 4))
    for i in range(A.shape[0]):
        out[i : i + B.shape[0]] += prod[i]
    return out


def polyval_rows(V, t) -> np.ndarray:
    """Values (n, rows) of the polynomial rows of V at t (n,)."""
    V = np.atleast_2d(np.asarray(V, dtype=float))
    return P.polyval(np.atleast_1d(np.asarray(t, dtype=float)), V.T).T


def real_roots(c, imag_rtol: float = 1e-8) -> np.ndarray:
    """Sorted real roots of a power-basis polynomial (roots with |Im| <= imag_rtol (1 + |root|))."""
    c = trim(c)
    if c.size < 2:
        return np.zeros(0)
    r = P.polyroots(c)
    return np.sort(r[np.abs(r.imag) <= imag_rtol * (1 + np.abs(r))].real)


def _conv_matrix(p: np.ndarray, n: int) -> np.ndarray:
    """Matrix (len(p) + n - 1, n) of multiplication by p acting on coefficient vectors of length n."""
    M = np.zeros((p.size + n - 1, n))
    for j in range(n):
        M[j : j + p.size, j] = p
    return M


def deconvolve(p, g) -> np.ndarray:
    """Least-squares quotient y with g y = p (exact when g divides p)."""
    p, g = trim(p), trim(g)
    n = p.size - g.size + 1
    if n <= 0:
        return np.zeros(1)
    y, *_ = np.linalg.lstsq(_conv_matrix(g, n), p, rcond=None)
    return y


def poly_gcd(polys, rtol: float = GCD_RTOL) -> tuple[np.ndarray, list[np.ndarray]]:
    """Monic greatest common divisor of polynomials and their quotients (numerical, see module doc).

    Returns ``(g, [p_i / g])``; zero polynomials are allowed (quotient zero). Raises DualFormError if
    all are zero.
    """
    polys = [trim(p) for p in polys]
    nz = [i for i, p in enumerate(polys) if degree(p) >= 0]
    if not nz:
        raise DualFormError("the greatest common divisor of zero polynomials is undefined")
    quot = [np.zeros(1) for _ in polys]
    if len(nz) == 1:
        p = polys[nz[0]]
        quot[nz[0]] = np.array([p[-1]])
        return p / p[-1], quot
    if not all(np.isfinite(polys[i]).all() for i in nz):
        raise DualFormError("polynomial gcd of non-finite coefficients")
    order = sorted(nz, key=lambda i: polys[i].size)
    q = [polys[i] / np.abs(polys[i]).max() for i in order]
    q = [x / np.linalg.norm(x) for x in q]
    n = [x.size - 1 for x in q]
    for d in range(n[0], 0, -1):
        sizes = [ni - d + 1 for ni in n]
        offs = np.concatenate(([0], np.cumsum(sizes)))
        blocks = []
        for i in range(1, len(q)):
            rows = n[0] + n[i] - d + 1
            B = np.zeros((rows, offs[-1]))
            B[:, offs[i] : offs[i + 1]] = _conv_matrix(q[0], sizes[i])
            B[:, offs[0] : offs[1]] = -_conv_matrix(q[i], sizes[0])
            blocks.append(B)
        M = np.vstack(blocks)
        _, s, Vt = np.linalg.svd(M)
        if M.shape[0] >= M.shape[1] and s[-1] > rtol * s[0]:
            continue
        u = [Vt[-1, offs[i] : offs[i + 1]] for i in range(len(q))]
        G = np.vstack([_conv_matrix(u[i], d + 1) for i in range(len(q))])
        g, *_ = np.linalg.lstsq(G, np.concatenate(q), rcond=None)
        if g[-1] == 0:
            continue
        g = g / g[-1]
        ok = True
        for i in nz:
            y = deconvolve(polys[i], g)
            sc = np.abs(polys[i]).max()  # scale first: the norm of tiny coefficients underflows
            res = np.linalg.norm(P.polysub(P.polymul(g, y), polys[i]) / sc) / np.linalg.norm(polys[i] / sc)
            ok &= bool(res <= GCD_ACCEPT)
            quot[i] = y
        if ok:
            return g, quot
    for i in nz:
        quot[i] = polys[i]
    return np.ones(1), quot


def reduce_rows(V) -> tuple[np.ndarray, np.ndarray]:
    """(theta, V / theta): a polynomial vector divided by the monic GCD of its rows."""
    g, quot = poly_gcd(list(np.atleast_2d(V)))
    return g, stack(quot)


# -- the curve -------------------------------------------------------------------------------------
def _check_poly(c, name: str) -> np.ndarray:
    try:
        a = np.atleast_1d(np.asarray(c, dtype=float))
    except (TypeError, ValueError):
        raise DualFormError(f"{name} must be a list of numbers (power-basis coefficients), got {c!r}") from None
    if a.ndim != 1 or a.size == 0:
        raise DualFormError(f"{name} must be a 1-D list of power-basis coefficients, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise DualFormError(f"{name} has a non-finite coefficient at index {int(np.argmax(~np.isfinite(a)))}")
    if not np.any(a):
        raise DualFormError(f"{name} is the zero polynomial")
    return trim(a)


def _check_rotation(R) -> np.ndarray:
    if R is None:
        return np.eye(3)
    try:
        M = np.asarray(R, dtype=float)
    except (TypeError, ValueError):
        raise DualFormError(f"R must be a 3x3 rotation matrix, got {R!r}") from None
    if M.shape != (3, 3) or not np.isfinite(M).all():
        raise DualFormError(f"R must be a finite 3x3 rotation matrix, got shape {M.shape}")
    if np.abs(M @ M.T - np.eye(3)).max() > 1e-9 or np.linalg.det(M) < 0:
        raise DualFormError("R must be a rotation matrix (orthonormal, det +1)")
    return M


def _check_quaternion_poly(A) -> np.ndarray:
    try:
        a = np.asarray(A, dtype=float)
    except (TypeError, ValueError):
        raise DualFormError("A must be a list of quaternion coefficients (scalar, i, j, k)") from None
    if a.ndim != 2 or a.shape[1] != 4:
        raise DualFormError(f"A must have shape (k+1, 4) (power-basis quaternion coefficients), got {a.shape}")
    if not np.isfinite(a).all():
        raise DualFormError(f"A has a non-finite coefficient A[{int(np.argmax(~np.isfinite(a).all(axis=1)))}]")
    a = vtrim(a.T).T
    if a.shape[0] < 2:
        raise DualFormError("A must have degree >= 1: a constant A gives a constant tangent (a line)")
    return a


def _rat_psi(f, g, h) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """psi of eq. (18) as num / den with den = g^4 lambda^3, and lambda = det(h, h', h'').

    With F = f/g, a = f'g - fg', b = a' g lam - a (2 g' lam + g lam'), c = f D1 g^2 + b,
    d = c' g lam - c (3 g' lam + 2 g lam'): psi = (d + f D2 g^3 lam) / (g^4 lam^3), where
    D1 = det(h, h'', h'''), D2 = det(h', h'', h''') (a direct expansion of eq. (18)).
    """
    m, add, sub, der = P.polymul, P.polyadd, P.polysub, P.polyder
    h1, h2, h3 = vder(h, 1), vder(h, 2), vder(h, 3)
    lam = vdet(h, h1, h2)
    D1 = vdet(h, h2, h3)
    D2 = vdet(h1, h2, h3)
    dg, dl = der(g), der(lam)
    a = sub(m(der(f), g), m(f, dg))
    b = sub(m(m(der(a), g), lam), m(a, add(2 * m(dg, lam), m(g, dl))))
    c = add(m(m(f, D1), m(g, g)), b)
    d = sub(m(m(der(c), g), lam), m(c, add(3 * m(dg, lam), 2 * m(g, dl))))
    g3 = m(m(g, g), g)
    num = add(d, m(m(m(f, D2), g3), lam))
    den = m(m(g3, g), m(m(lam, lam), lam))
    return trim(num), trim(den), trim(lam)


def _factor_table(weighted) -> list[tuple[np.ndarray, int]]:
    """Distinct monic real irreducible factors q (linear or quadratic) of prod p^w, with multiplicities.

    ``weighted`` is a list of (polynomial, weight). Roots closer than 1e-7 (relative) are merged; the
    polynomials used here (theta, lambda / theta^2, g) have simple roots in the seed's families, so the
    factors are accurate to round-off even where the product has roots of high multiplicity.
    """
    clusters: list[list] = []  # [root, multiplicity]
    for p, w in weighted:
        if degree(p) <= 0:
            continue
        r_all = P.polyroots(trim(p))
        for r in r_all[r_all.imag >= -1e-7 * (1 + np.abs(r_all))]:  # one of each conjugate pair
            for cl in clusters:
                if abs(r - cl[0]) <= 1e-7 * (1 + abs(r)):
                    cl[1] += w
                    break
            else:
                clusters.append([complex(r), w])
    out = []
    for r, m in clusters:
        if abs(r.imag) <= 1e-7 * (1 + abs(r)):
            out.append((np.array([-r.real, 1.0]), m))
        else:
            out.append((np.array([abs(r) ** 2, -2 * r.real, 1.0]), m))
    return out


def _divides(q, p, rtol: float = 1e-8) -> np.ndarray | None:
    """p / q if q divides p (least-squares remainder below rtol), else None."""
    y = deconvolve(p, q)
    sc = np.abs(p).max()
    res = np.linalg.norm(P.polysub(P.polymul(q, y), p) / sc) / np.linalg.norm(p / sc)
    return trim(y) if res <= rtol else None


def _cancel(num, table) -> tuple[np.ndarray, tuple[tuple[np.ndarray, int], ...]]:
    """Cancel the factors of the denominator table that divide num (with multiplicity)."""
    out = []
    for q, m in table:
        while m > 0 and degree(num) >= q.size - 1:
            y = _divides(q, num)
            if y is None:
                break
            num, m = y, m - 1
        if m > 0:
            out.append((q, m))
    return num, tuple(out)


@dataclass(frozen=True)
class SingularPoints:
    """Real parameters where r' = psi R h vanishes (zeros of psi) or is unbounded (poles of psi)."""

    zeros: np.ndarray
    poles: np.ndarray
    zero_at_infinity: bool


@dataclass(frozen=True, eq=False)
class RationalPH:
    """A spatial rational PH curve r(t) = (P1, P2, P3) / P0 in dual form L = (-f; g R v_R).

    All polynomial attributes are power-basis coefficient arrays, lowest degree first; vector ones have
    one row per component.

    Attributes
    ----------
    A : ndarray (k+1, 4)          quaternion polynomial (scalar, i, j, k) coefficients
    f, g : ndarray                the polynomials of the dual form
    R : ndarray (3, 3)            rotation applied to v_R (and hence to the curve)
    h : ndarray (3, 2k+1)         A i A* (not rotated)
    rho : ndarray                 |A|^2 = |h|
    v : ndarray (3, .)            h x h'
    theta : ndarray               monic gcd of the components of v
    v_R : ndarray (3, .)          v / theta
    lam : ndarray                 det(h, h', h'')  (eq. 30)
    L : ndarray (4, .)            dual form with relatively prime components (divided by their gcd)
    P : ndarray (4, .)            homogeneous point form with relatively prime components
    psi_num : ndarray             numerator of psi (eq. 18) in lowest terms
    psi_den_factors : tuple       its monic denominator as ((q_j, m_j), ...), prod q_j^m_j, the q_j
                                  real irreducible (kept factored: accurate near multiple poles)
    """

    A: np.ndarray
    f: np.ndarray
    g: np.ndarray
    R: np.ndarray
    h: np.ndarray
    rho: np.ndarray
    v: np.ndarray
    theta: np.ndarray
    v_R: np.ndarray
    lam: np.ndarray
    L: np.ndarray
    P: np.ndarray
    psi_num: np.ndarray
    psi_den_factors: tuple[tuple[np.ndarray, int], ...]

    @classmethod
    def from_dual(cls, A, f, g=(1.0,), R=None) -> RationalPH:
        """The rational PH curve of the dual form L = (-f; g R v_R) generated by A (seed eqs. 16-30).

        Parameters
        ----------
        A : array_like (k+1, 4)
            Power-basis quaternion coefficients: A(t) = A[0] + A[1] t + ..., each (scalar, i, j, k).
        f, g : array_like
            Power-basis coefficients of f and g (nonzero polynomials).
        R : array_like (3, 3), optional
            Rotation matrix (default identity).

        Raises
        ------
        DualFormError
            Malformed or degenerate data: constant A, components of A with a common factor, h, h', h''
            linearly dependent (lambda = 0), zero f or g, R not a rotation; the message says which.
        """
        A = _check_quaternion_poly(A)
        f = _check_poly(f, "f")
        g = _check_poly(g, "g")
        R = _check_rotation(R)
        cg, _ = poly_gcd(list(A.T))
        if cg.size > 1:
            raise DualFormError(
                f"the components of A share the factor {np.round(cg, 12).tolist()} (power basis): "
                "A must have relatively prime components"
            )
        k = A.shape[0] - 1
        h = vtrim(qpoly_mul(qpoly_mul(A, qt.I[None, :]), qt.conj(A))[:, 1:].T)  # A i A*, eq. (22)
        rho = trim(vdot(A.T, A.T))  # |A|^2, eq. (25)
        v = vtrim(vcross(h, vder(h))[:, : 4 * k - 1])  # Theorem 3; deg v <= 4k - 2 (eq. 27, Theorem 2)
        lam = trim(vdet(h, vder(h), vder(h, 2)))  # eq. (30)
        scale = float(np.abs(h).max()) ** 3
        if np.abs(lam).max() <= 1e-12 * scale:
            raise DualFormError("det(h, h', h'') vanishes identically: A generates a planar tangent field")
        theta, v_R = reduce_rows(v)  # Lemma 1
        L = stack([-f, *(P.polymul(g, row) for row in R @ v_R)])  # eq. (16)
        _, L = reduce_rows(L)
        L = vtrim(L)
        m = L.shape[1] - 1
        Pw = vtrim(wedge(L)[:, : 3 * (m - 2) + 1] if m >= 3 else wedge(L))  # eq. (7); deg <= 3 (m - 2)
        sv = np.linalg.svd(Pw / np.abs(Pw).max(), compute_uv=False)
        if degree(Pw[0]) < 0 or sv.size < 2 or sv[1] <= 1e-9 * sv[0]:
            raise DualFormError(
                "degenerate dual form: P = L ^ L' ^ L'' has rank 1 (f is a combination of the components "
                "of g R v_R, so every osculating plane passes through one point) or P0 = 0"
            )
        _, Pw = reduce_rows(Pw)
        big = np.abs(Pw).max(axis=1, keepdims=True)
        Pw = np.where(np.abs(Pw) <= ZERO_RTOL * big, 0.0, Pw)  # round-off where the exact value is 0
        num, den, lam = _rat_psi(P.polymul(f, theta), g, h)  # eq. (18) for (-theta f; g v)
        mu = deconvolve(lam, P.polymul(theta, theta))  # lambda = theta^2 mu, eq. (29)
        table = _factor_table([(theta, 6), (mu, 3), (g, 4)])  # den = g^4 lambda^3 = g^4 theta^6 mu^3
        const = float(g[-1] ** 4 * lam[-1] ** 3)  # leading coefficient of den
        if sum(m * (q.size - 1) for q, m in table) != degree(den):  # clustering failed: keep it whole
            table = [(den / const, 1)]
        num, factors = _cancel(num, table)
        return cls(A, f, g, R, h, rho, v, theta, v_R, lam, L, vtrim(Pw), num / const, factors)

    # -- degrees ---------------------------------------------------------------------------------
    @property
    def curve_class(self) -> int:
        """Class m: degree of the dual form with relatively prime components (Definition 1)."""
        return max(degree(row) for row in self.L)

    @property
    def degree(self) -> int:
        """Degree of the curve: that of its homogeneous form with relatively prime components."""
        return max(degree(row) for row in self.P)

    # -- evaluation ------------------------------------------------------------------------------
    def _homogeneous(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if not np.isfinite(t).all():
            i = int(np.argmax(~np.isfinite(t)))
            raise SingularParameterError(f"parameter t[{i}] = {float(t[i])} is not finite")
        Pt = polyval_rows(self.P, t)
        mag = P.polyval(np.abs(t), np.abs(self.P[0]))
        pole = np.abs(Pt[:, 0]) <= POLE_RTOL * mag
        if pole.any():
            i = int(np.argmax(pole))
            raise SingularParameterError(
                f"t[{i}] = {float(t[i])!r} is a pole of the curve (P0(t) = 0): the point is at infinity"
            )
        return Pt

    def points(self, t) -> np.ndarray:
        """Points r(t) = (P1, P2, P3) / P0, shape (n, 3). Raises SingularParameterError at poles."""
        Pt = self._homogeneous(t)
        return Pt[:, 1:] / Pt[:, :1]

    def derivative(self, t) -> np.ndarray:
        """r'(t) from the point form by the quotient rule (independent of eq. 18), shape (n, 3)."""
        Pt = self._homogeneous(t)
        dP = polyval_rows(vder(self.P), np.atleast_1d(np.asarray(t, dtype=float)))
        return (dP[:, 1:] * Pt[:, :1] - Pt[:, 1:] * dP[:, :1]) / Pt[:, :1] ** 2

    @property
    def psi_den(self) -> np.ndarray:
        """Monic denominator of psi in lowest terms, expanded (power basis)."""
        out: np.ndarray = np.ones(1)
        for q, m in self.psi_den_factors:
            out = P.polymul(out, P.polypow(q, m))
        return out

    def psi(self, t) -> np.ndarray:
        """psi(t) of eq. (18), shape (n,) (the denominator evaluated in factored form)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        den = np.ones_like(t)
        for q, m in self.psi_den_factors:
            den = den * P.polyval(t, q) ** m
        return P.polyval(t, self.psi_num) / den

    def direction(self, t) -> np.ndarray:
        """R h(t), the (polynomial) direction of the hodograph, shape (n, 3)."""
        return polyval_rows(self.h, t) @ self.R.T

    def hodograph(self, t) -> np.ndarray:
        """r'(t) = psi(t) R h(t), shape (n, 3)."""
        return self.psi(t)[:, None] * self.direction(t)

    def unit_tangent(self, t) -> np.ndarray:
        """The rational unit vector field R h / rho (the E-R frame's first axis, eq. 22), shape (n, 3).

        It is r'/|r'| where psi > 0 and -r'/|r'| where psi < 0 (see ``tangent``).
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return self.direction(t) / P.polyval(t, self.rho)[:, None]

    def tangent(self, t) -> np.ndarray:
        """Unit tangent r'/|r'| = sign(psi) R h / rho, shape (n, 3) (R h / rho where psi = 0, a cusp)."""
        return np.where(self.psi(t) < 0, -1.0, 1.0)[:, None] * self.unit_tangent(t)

    def speed(self, t) -> np.ndarray:
        """|r'(t)| = |psi(t)| rho(t), a rational function (the PH property), shape (n,)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return np.abs(self.psi(t)) * P.polyval(t, self.rho)

    def singular_points(self) -> SingularPoints:
        """Real zeros and poles of psi (the seed's singular points: r' = 0 or r' unbounded)."""
        zeros = [-q[0] for q, _ in _factor_table([(self.psi_num, 1)]) if q.size == 2]
        poles = [-q[0] for q, _ in self.psi_den_factors if q.size == 2]
        poles += [r for q, _ in self.psi_den_factors if q.size > 3 for r in real_roots(q)]
        return SingularPoints(np.sort(zeros), np.sort(poles), degree(self.psi_num) < degree(self.psi_den))


__all__ = [
    "DualFormError",
    "RationalPH",
    "SingularParameterError",
    "SingularPoints",
    "poly_gcd",
]
