"""The constraint set of eq. (24) in closed form, and the twist search on it (batched over segments).

a b' - a' b is the Wronskian W(a, b): bilinear, antisymmetric, and W(M (a, b)) = det M W(a, b) for a 2 x 2
matrix M. So the pairs with W(a, b) = g (eq. 24) are, plane by plane, the SL(2) orbits of one basis of
each 2-plane V = span(a, b) of degree-4 polynomials whose Wronskian is a multiple of g. Those planes are
the decomposable 2-vectors w = a ^ b in the 3-dimensional affine space W(w) = g (the 7 linear equations
of (24) on the 10 Pluecker coordinates): 5 Pluecker quadrics in 3 unknowns, with 5 complex solutions
(the degree of the Wronski map of G(2, 5)), of which an odd number, so at least one, is real.

On the plane with basis a_V (a_V(0) = 0) and b_V (b_V(0) = 1), W(a_V, b_V) = g, every point with a(0) = 0
and b(0) > 0 (the normalization of :mod:`planner.frames.grm`) is

    a = lam a_V,   b = (b_V + mu a_V) / lam,   lam > 0,

so the "twist" objective (the largest angle against the exact RMF, replacing eq. 13) is an unconstrained
2-parameter problem per plane, every trial point explicit: Gauss-Newton on the mean square twist, then
Lawson's iteratively reweighted least squares towards the minimax twist, then a pattern search. With
z = b + i a the GRM angle of eq. (11) is 2 arg z, and its rate is -2 g / |z|^2, so the twist rate is
g (1 / sigma^2 - 2 / |z|^2) (eq. 12): a^2 + b^2 ~ 2 sigma^2 is what makes the frame rotation-minimizing.
"""

from __future__ import annotations

from itertools import combinations_with_replacement

import numpy as np

from planner import bernstein

#: Bernstein (degree 2) -> power basis, for the quaternion polynomial A(t).
_M2 = np.array([[1.0, 0.0, 0.0], [-2.0, 2.0, 0.0], [1.0, -2.0, 1.0]])
#: Power -> Bernstein basis (degree 4): bernstein = _P2B @ power.
_T5 = np.linspace(0.0, 1.0, 5)
_P2B = np.linalg.solve(bernstein.basis(4, _T5), np.vander(_T5, 5, increasing=True))

# monomials of degree <= 3 in the unknowns (x, y, w), graded; (i, j) = product of unknowns i and j
_MONO = [()] + [m for d in (1, 2, 3) for m in combinations_with_replacement(range(3), d)]
_IDX = {m: i for i, m in enumerate(_MONO)}
#: Position of unknown v times each monomial of degree <= 2.
_SHIFT = [np.array([_IDX[tuple(sorted(m + (v,)))] for m in _MONO[:10]]) for v in range(3)]
#: A fixed generic combination of the unknowns whose multiplication matrix gives the solutions.
_MIX = (0.7, 0.5, 0.3)


def _conv(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Products of polynomials row by row (power coefficients, lowest first): (S, m), (S, n) -> (S, m + n - 1)."""
    m, n = p.shape[1], q.shape[1]
    out = np.zeros((p.shape[0], m + n - 1))
    for i in range(m):
        out[:, i : i + n] += p[:, i : i + 1] * q
    return out


def g_power(A: np.ndarray) -> np.ndarray:
    """Power coefficients (S, 7) of g = (d/dt A j A*) . (A k A*) = 2 |A|^2 (A* A')_i (eq. 24's right-hand
    side, degree 6) for quaternion Bernstein coefficients A (S, 3, 4)."""
    P = np.einsum("kj,sjc->skc", _M2, A)  # A(t) = sum_k P_k t^k
    dP = P[:, 1:] * np.array([1.0, 2.0])[None, :, None]
    sig = (_conv(P[:, :, 0], P[:, :, 0]) + _conv(P[:, :, 1], P[:, :, 1])
           + _conv(P[:, :, 2], P[:, :, 2]) + _conv(P[:, :, 3], P[:, :, 3]))
    q = (_conv(P[:, :, 0], dP[:, :, 1]) - _conv(P[:, :, 1], dP[:, :, 0])
         - _conv(P[:, :, 2], dP[:, :, 3]) + _conv(P[:, :, 3], dP[:, :, 2]))
    return 2.0 * _conv(sig, q[:, :3])  # (A* A')_i has degree 2: its t^3 terms cancel


def pluecker_quadrics(g: np.ndarray) -> np.ndarray:
    """The 5 Pluecker relations of G(2, 5) on the solutions w of W(w) = g (eq. 24), as coefficient rows
    (S, 5, 10) over the monomials 1, x, y, w, x^2, xy, xw, y^2, yw, w^2.

    In the power basis W(a, b) = sum_{i<j} (j - i) w_ij t^(i+j-1) with w_ij = a_i b_j - a_j b_i, so
    w01 = g0, w02 = g1/2, w24 = g5/2, w34 = g6 and, with the unknowns x = w03, y = w04, w = w14,
    w12 = g2 - 3x, w13 = (g3 - 4y)/2, w23 = g4 - 3w.
    """
    S = g.shape[0]
    Q = np.zeros((S, 5, 10))
    g0, g1, g2, g3, g4, g5, g6 = g.T
    x, y, w = 1, 2, 3
    xx, xy, xw, yy, yw, ww = (_IDX[m] for m in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))
    # w01 w23 - w02 w13 + w03 w12 = 0
    Q[:, 0, 0], Q[:, 0, w], Q[:, 0, y], Q[:, 0, x], Q[:, 0, xx] = g0 * g4 - g1 * g3 / 4, -3 * g0, g1, g2, -3
    # w01 w24 - w02 w14 + w04 w12 = 0
    Q[:, 1, 0], Q[:, 1, w], Q[:, 1, y], Q[:, 1, xy] = g0 * g5 / 2, -g1 / 2, g2, -3
    # w01 w34 - w03 w14 + w04 w13 = 0
    Q[:, 2, 0], Q[:, 2, xw], Q[:, 2, y], Q[:, 2, yy] = g0 * g6, -1, g3 / 2, -2
    # w02 w34 - w03 w24 + w04 w23 = 0
    Q[:, 3, 0], Q[:, 3, x], Q[:, 3, y], Q[:, 3, yw] = g1 * g6 / 2, -g5 / 2, g4, -3
    # w12 w34 - w13 w24 + w14 w23 = 0
    Q[:, 4, 0], Q[:, 4, x], Q[:, 4, y], Q[:, 4, w], Q[:, 4, ww] = g2 * g6 - g3 * g5 / 4, -3 * g6, g5, g4, -3
    return Q


def quadric_solutions(Q: np.ndarray) -> np.ndarray:
    """The 5 complex common zeros (S, 5, 3) of 5 quadrics in 3 unknowns (none at infinity).

    Eigenvalue method: the quadrics times 1, x, y, w span the degree-3 part of the ideal (rank 15 of 20);
    the null space of that Macaulay matrix holds the monomial vectors of the 5 zeros, and multiplication
    by a generic linear form acts on it as a 5 x 5 matrix whose eigenvectors are those zeros.
    """
    S = Q.shape[0]
    M = np.zeros((S, 20, 20))
    for k in range(5):
        M[:, 4 * k, :10] = Q[:, k]
        for v in range(3):
            M[:, 4 * k + 1 + v, _SHIFT[v]] = Q[:, k]
    try:
        return _eigen_zeros(M)
    except np.linalg.LinAlgError:  # a rare non-converging decomposition: curve by curve, NaN for it
        out = np.full((S, 5, 3), np.nan, dtype=complex)
        for i in range(S):
            try:
                out[i] = _eigen_zeros(M[i : i + 1])[0]
            except np.linalg.LinAlgError:
                pass
        return out


def _eigen_zeros(M: np.ndarray) -> np.ndarray:
    """The zeros (S, 5, 3) from stacked Macaulay matrices M (S, 20, 20) (see :func:`quadric_solutions`)."""
    N = np.linalg.svd(M)[2][:, -5:, :].transpose(0, 2, 1)  # (S, 20, 5) null space
    low = N[:, :10]
    mult = sum(c * N[:, _SHIFT[v]] for v, c in enumerate(_MIX))
    K = np.linalg.eig(np.linalg.pinv(low) @ mult)[1]
    mono = low.astype(complex) @ K  # (S, 10, 5): the monomials at each zero, up to scale
    with np.errstate(all="ignore"):
        return (mono[:, 1:4, :] / mono[:, :1, :]).transpose(0, 2, 1)


def plane_orbits(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orbit bases (a_V, b_V), Bernstein coefficients (S, 5, 5) each, of the 5 planes with W = g per
    segment (real parts of the complex ones too: the caller keeps what Newton confirms on (24)).

    a_V(0) = 0, b_V(0) = 1 and W(a_V, b_V) = g; NaN where a candidate has no such basis.
    """
    scale = np.abs(g).max(axis=1)
    gn = g / scale[:, None]
    x, y, w = np.moveaxis(quadric_solutions(pluecker_quadrics(gn)).real, -1, 0)  # (S, 5) each
    G = [c[:, None] * np.ones_like(x) for c in gn.T]
    O = np.zeros(x.shape + (5, 5))
    for (i, j), v in (((0, 1), G[0]), ((0, 2), G[1] / 2), ((0, 3), x), ((1, 2), G[2] - 3 * x), ((0, 4), y),
                      ((1, 3), (G[3] - 4 * y) / 2), ((1, 4), w), ((2, 3), G[4] - 3 * w), ((2, 4), G[5] / 2),
                      ((3, 4), G[6])):
        O[..., i, j], O[..., j, i] = v, -v
    # w = a ^ b: its columns w e_j = a b_j - b a_j lie in the plane, and (w e_j) ^ (w e_k) = w_jk w
    flat = O.reshape(x.shape + (25,))
    jk = np.abs(np.triu(np.ones((5, 5)), 1).ravel() * flat).argmax(axis=-1)
    j, k = np.divmod(jk, 5)
    p = np.take_along_axis(O, j[..., None, None], axis=-1)[..., 0]
    q = np.take_along_axis(O, k[..., None, None], axis=-1)[..., 0] / np.take_along_axis(flat, jk[..., None], -1)
    r = np.sqrt(scale)[:, None, None]
    pB, qB = p @ _P2B.T * r, q @ _P2B.T * r  # W(pB, qB) = g
    p0, q0 = pB[..., :1], qB[..., :1]
    with np.errstate(all="ignore"):
        return q0 * pB - p0 * qB, (p0 * pB + q0 * qB) / (p0 * p0 + q0 * q0)  # an SL(2) change of basis


def orbit_point(aV: np.ndarray, bV: np.ndarray, lam: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(a, b) = (lam a_V, (b_V + mu a_V) / lam): the point (lam, mu) of a plane's orbit; W(a, b) = W(a_V, b_V)."""
    return lam[..., None] * aV, (bV + mu[..., None] * aV) / lam[..., None]


def _orbit_values(aVs, bVs, rot, lam, mu):
    """z = b + i a at the samples (real and imaginary parts, (R, n) each), and u = z^2 exp(-i psi) whose
    argument is the twist: with a(0) = 0 and b(0) = 1 / lam > 0 the GRM angle from the start is 2 arg z
    (eq. 11). ``rot`` = (cos psi, -sin psi) of the exact RMF angle psi from t = 0."""
    zr = (bVs + mu[..., None] * aVs) / lam[..., None]
    zi = lam[..., None] * aVs
    sq_r, sq_i = zr * zr - zi * zi, 2.0 * zr * zi
    return zr, zi, sq_r * rot[0] - sq_i * rot[1], sq_r * rot[1] + sq_i * rot[0]


def spin_suspect(zr: np.ndarray, zi: np.ndarray, m2: np.ndarray, floor2: np.ndarray, bend: np.ndarray,
                 h: float) -> np.ndarray:
    """Rows (...) where |z|^2 falls below ``floor2`` (MIN_RATIO 2 sigma^2) at a sample, or |z|^2 may fall below
    half of it between samples: z = zr + i zi at samples spaced h (..., n), m2 = |z|^2 there, ``bend`` >=
    max |z''| (...). On [t_k, t_k+1], z is within h^2/8 max |z''| of the chord from z_k to z_k+1, so |z| >=
    (distance of that chord from 0) - h^2/8 bend. Near a root of z the frame spins by up to 2 pi between
    samples, which the sampled twist (mod 2 pi) does not see."""
    at_samples = (m2 < floor2).any(axis=-1)
    gap = np.sqrt(0.5 * np.maximum(floor2[..., :-1], floor2[..., 1:])) + 0.125 * h * h * bend[..., None]
    dr, di = zr[..., 1:] - zr[..., :-1], zi[..., 1:] - zi[..., :-1]
    dot, d2 = zr[..., :-1] * dr + zi[..., :-1] * di, dr * dr + di * di
    with np.errstate(all="ignore"):
        s = np.clip(-dot / d2, 0.0, 1.0)  # nearest point of the chord: z_k + s (z_k+1 - z_k)
        between = (m2[..., :-1] + s * (2.0 * dot + s * d2) < gap * gap).any(axis=-1)
    return at_samples | between


def bernstein_bend(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """An upper bound of |z''| on [0, 1] for z = b + i a with Bernstein coefficients a, b (..., 5):
    12 max_j |c_j+2 - 2 c_j+1 + c_j| (the second derivative's Bernstein coefficients bound it)."""
    da, db = np.diff(a, 2, axis=-1), np.diff(b, 2, axis=-1)
    return 12.0 * np.sqrt((da * da + db * db).max(axis=-1))


def orbit_bend(dV, lam, mu):
    """:func:`bernstein_bend` of the orbit points (lam, mu) (...): dV = second differences of the Bernstein
    coefficients of (a_V, b_V), (2, ..., 3)."""
    da = lam[..., None] * dV[0]
    db = (dV[1] + mu[..., None] * dV[0]) / lam[..., None]
    return 12.0 * np.sqrt((da * da + db * db).max(axis=-1))


#: Elements per block of the row-wise evaluations: temporaries that stay in cache run about twice as fast.
_BLOCK = 1 << 15


def _blocks(lead: tuple, n: int):
    """Slices of axis 0 of a row shape ``lead`` whose blocks hold about _BLOCK samples (n per row)."""
    per = max(1, _BLOCK // max(1, int(np.prod(lead[1:], dtype=int)) * n))
    return [slice(i, i + per) for i in range(0, lead[0] if lead else 1, per)] if lead else [slice(None)]


def _cut(x: np.ndarray, k: slice, lead0: int, axis: int = 0) -> np.ndarray:
    """Block k of x along ``axis`` unless x is broadcast there (size 1)."""
    if x.ndim <= axis or x.shape[axis] != lead0:
        return x
    return x[(slice(None),) * axis + (k,)]


def orbit_objective(aVs, bVs, rot, floor2, dV, lam, mu):
    """:func:`_orbit_objective` block by block over the leading axis of lam, mu."""
    lead = np.broadcast_shapes(np.shape(lam), np.shape(mu))
    if not lead or lead[0] * int(np.prod(lead[1:], dtype=int)) * aVs.shape[-1] <= _BLOCK:
        return _orbit_objective(aVs, bVs, rot, floor2, dV, lam, mu)
    L = lead[0]
    return np.concatenate([
        _orbit_objective(_cut(aVs, k, L), _cut(bVs, k, L), _cut(rot, k, L, 1), _cut(floor2, k, L), _cut(dV, k, L, 1),
                         _cut(lam, k, L), _cut(mu, k, L))
        for k in _blocks(lead, aVs.shape[-1])])


def _orbit_objective(aVs, bVs, rot, floor2, dV, lam, mu):
    """The largest twist at the samples (rad), plus pi where |z|^2 may fall below ``floor2`` = MIN_RATIO
    2 sigma^2 (:func:`spin_suspect`, with the bend from dV, see :func:`orbit_bend`), as
    :meth:`planner.frames.grm._Problem.objective_batch`. Samples equally spaced on [0, 1]; rows (..., n) ->
    (...); rot (2, ..., n) and dV (2, ..., 3) carry their pair first.

    |u| = |z|^2, so |arg u| = 2 atan(|Im u| / (|z|^2 + Re u)): one arctangent per row, not per sample."""
    with np.errstate(all="ignore"):
        zr, zi, ur, ui = _orbit_values(aVs, bVs, rot, lam, mu)
        m2 = zr * zr + zi * zi
        f = 2.0 * np.arctan((np.abs(ui) / (m2 + ur)).max(axis=-1))
        spin = spin_suspect(zr, zi, m2, floor2, orbit_bend(dV, lam, mu), 1.0 / (m2.shape[-1] - 1))
        f = np.where(spin, f + np.pi, f)
    return np.where(np.isnan(f), np.inf, f)


def minimax_twist(aVs, bVs, rot, floor2, dV, lam, mu, gauss_newton: int = 3, lawson: int = 12):
    """:func:`_minimax_twist` block by block over the rows."""
    R, n = aVs.shape
    out = [_minimax_twist(aVs[k], bVs[k], rot[:, k], floor2[k], dV[:, k], lam[k], mu[k], gauss_newton, lawson)
           for k in _blocks((R,), n)]
    return tuple(np.concatenate(v) for v in zip(*out, strict=True))


def _minimax_twist(aVs, bVs, rot, floor2, dV, lam, mu, gauss_newton: int = 3, lawson: int = 12):
    """Orbit parameters (lam, mu) (R,) minimizing the largest twist at the samples, and that twist (R,).

    Gauss-Newton on the mean square twist, then Lawson's reweighting (weights times the linearized
    residual) towards the minimax point; the best iterate by :func:`orbit_objective` is kept. dTwist/dp
    is 2 Im(z_p / z), with dz/dlog(lam) = -conj(z) and dz/dmu = a_V / lam: 4 Re z Im z / |z|^2 and
    -2 a_V Im z / (lam |z|^2).
    """
    ell = np.log(lam)
    best_f = np.full(lam.shape, np.inf)
    best_ell, best_mu = ell.copy(), mu.copy()
    v = np.full(aVs.shape, 1.0 / aVs.shape[1])
    with np.errstate(all="ignore"):
        for it in range(gauss_newton + lawson + 1):
            lam = np.exp(ell)
            zr, zi, ur, ui = _orbit_values(aVs, bVs, rot, lam, mu)
            m2 = zr * zr + zi * zi
            T = np.arctan2(ui, ur)
            f = np.abs(T).max(axis=1)
            spin = spin_suspect(zr, zi, m2, floor2, orbit_bend(dV, lam, mu), 1.0 / (m2.shape[-1] - 1))
            f = np.where(spin, f + np.pi, f)
            better = f < best_f
            best_f = np.where(better, f, best_f)
            best_ell, best_mu = np.where(better, ell, best_ell), np.where(better, mu, best_mu)
            if it == gauss_newton + lawson:
                break
            J2 = -2.0 * zi / m2
            J1 = -2.0 * zr * J2
            J2 *= aVs / lam[:, None]
            w1, w2 = (J1, J2) if it < gauss_newton else (v * J1, v * J2)
            h11, h12, h22 = (w1 * J1).sum(axis=1), (w1 * J2).sum(axis=1), (w2 * J2).sum(axis=1)
            r1, r2 = (w1 * T).sum(axis=1), (w2 * T).sum(axis=1)
            det = h11 * h22 - h12 * h12
            d1, d2 = (h12 * r2 - h22 * r1) / det, (h12 * r1 - h11 * r2) / det
            if it >= gauss_newton:  # Lawson: weights times the residual of this weighted fit
                v = v * np.abs(T + J1 * d1[:, None] + J2 * d2[:, None])
                v /= v.sum(axis=1, keepdims=True)
            fine = np.isfinite(d1) & np.isfinite(d2)
            ell, mu = np.where(fine, ell + d1, best_ell), np.where(fine, mu + d2, best_mu)
    return np.exp(best_ell), best_mu, np.where(np.isnan(best_f), np.inf, best_f)


def compass_search(aVs, bVs, rot, floor2, dV, lam, mu, f, step_ell, step_mu, rounds: int = 24, floor: float = 4e-4):
    """Pattern search on :func:`orbit_objective` from (lam, mu) with objective f (R,): the 8 neighbours at
    (step_ell, step_mu) (R,) in (log lam, mu); move to the best and double the steps if it improves, else
    halve them; rows whose log-lambda step falls below ``floor`` stop. Reaches minima that Lawson's steps
    cannot: on the boundary of the spin penalty, or along plateaus where the largest twist sits at a root
    of a (there the GRM angle is fixed on the whole orbit)."""
    ell = np.log(lam)
    mu, f, step_ell, step_mu = mu.copy(), f.copy(), step_ell.copy(), step_mu.copy()
    d = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]], dtype=float)
    act = np.arange(lam.shape[0])
    for _ in range(rounds):
        act = act[step_ell[act] >= floor]
        if act.size == 0:
            break
        te = ell[act, None] + d[:, 0] * step_ell[act, None]  # (N, 8)
        tm = mu[act, None] + d[:, 1] * step_mu[act, None]
        ft = orbit_objective(aVs[act, None], bVs[act, None], rot[:, act, None], floor2[act, None],
                             dV[:, act, None], np.exp(te), tm)
        k = ft.argmin(axis=1)
        r = np.arange(act.size)
        fk = ft[r, k]
        move = fk < f[act]
        m = act[move]
        ell[m], mu[m], f[m] = te[r, k][move], tm[r, k][move], fk[move]
        grow = np.where(move, 2.0, 0.5)
        step_ell[act], step_mu[act] = step_ell[act] * grow, step_mu[act] * grow
    return np.exp(ell), mu, f
