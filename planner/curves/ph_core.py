"""Batched polynomial algebra of spatial PH curves r'(t) = A(t) i A*(t) of any degree.

A quaternion polynomial of degree m - 1 in Bernstein form is stored as coefficients A (..., m, 4);
m = 2 gives PH cubics, m = 3 PH quintics (grm seed sections 2.1-2.2). The hodograph has degree
2m - 2, the curve degree 2m - 1, and the parametric speed sigma(t) = |A(t)|^2 is a polynomial, so the
arc length is one too: lengths and their inversion need no quadrature. Every function is vectorized
over the leading axes, so a spline's segments are built and evaluated together.
"""

from __future__ import annotations

from math import comb

import numpy as np

from planner import bernstein
from planner import quaternion as qt


def _product_weights(m: int):
    """(k, i, j, w): Bernstein product B_{m-1,i} B_{m-1,j} = w B_{2m-2,k} with k = i + j."""
    n = m - 1
    return [(i + j, i, j, comb(n, i) * comb(n, j) / comb(2 * n, i + j)) for i in range(m) for j in range(m)]


def batch_hodograph(A: np.ndarray) -> np.ndarray:
    """Bernstein coefficients (..., 2m-1, 3) of the hodograph A i A* (products as in grm seed eq. 3)."""
    m = A.shape[-2]
    out = np.zeros(A.shape[:-2] + (2 * m - 1, 3))
    for k, i, j, w in _product_weights(m):
        if i <= j:  # the vector part of A_i i A_j* is symmetric in i and j
            out[..., k, :] += (w if i == j else 2 * w) * qt.i_product(A[..., i, :], A[..., j, :])
    return out


def batch_sigma(A: np.ndarray) -> np.ndarray:
    """Bernstein coefficients (..., 2m-1) of the parametric speed sigma(t) = |A(t)|^2 = |r'(t)|."""
    m = A.shape[-2]
    out = np.zeros(A.shape[:-2] + (2 * m - 1,))
    for k, i, j, w in _product_weights(m):
        out[..., k] += w * qt.dot(A[..., i, :], A[..., j, :])
    return out


def batch_control_points(A: np.ndarray, p0: np.ndarray) -> np.ndarray:
    """Bezier control points (..., 2m, 3): P_{k+1} = P_k + h_k / (2m - 1) (grm seed section 2.2)."""
    h = batch_hodograph(A)
    p0 = np.asarray(p0, dtype=float)[..., None, :]
    return np.concatenate((p0, p0 + np.cumsum(h, axis=-2) / h.shape[-2]), axis=-2)


def arc_length_coeffs(sigma: np.ndarray) -> np.ndarray:
    """Bernstein coefficients (..., d+2) of s(t) = integral_0^t sigma, for sigma of degree d."""
    zero = np.zeros(sigma.shape[:-1] + (1,))
    return np.concatenate((zero, np.cumsum(sigma, axis=-1) / sigma.shape[-1]), axis=-1)


def invert_arc_length(sigma: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Parameters t (n,) with s(t) = s, for per-sample speed coefficients sigma (n, d+1), 0 <= s <= L.

    Safeguarded Newton iteration on the polynomial s(t) - s (sigma > 0 makes s strictly increasing),
    vectorized over samples; each sample stops once its residual is at round-off, so a few steps do.
    """
    S = arc_length_coeffs(sigma)
    d = sigma.shape[-1] - 1
    total = S[:, -1]
    t = np.clip(s / np.where(total > 0, total, 1.0), 0.0, 1.0)
    lo = np.zeros_like(t)
    hi = np.ones_like(t)
    tol = 4 * np.finfo(float).eps * np.maximum(total, np.abs(s))
    active = np.arange(t.size)
    for _ in range(60):
        ta = t[active]
        f = np.einsum("nk,nk->n", bernstein.basis(d + 1, ta), S[active]) - s[active]
        conv = np.abs(f) <= tol[active]
        lo[active] = np.where(f < 0, ta, lo[active])
        hi[active] = np.where(f > 0, ta, hi[active])
        dsdt = np.einsum("nk,nk->n", bernstein.basis(d, ta), sigma[active])
        tn = ta - f / np.where(dsdt > 0, dsdt, 1.0)
        la, ha = lo[active], hi[active]
        tn = np.where((tn < la) | (tn > ha) | (dsdt <= 0), 0.5 * (la + ha), tn)
        t[active] = np.where(conv, ta, tn)
        active = active[~conv & (ha - la > 2 * np.finfo(float).eps)]
        if active.size == 0:
            break
    return t


def curvature_torsion(d1: np.ndarray, d2: np.ndarray, d3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Curvature |r' x r''| / |r'|^3 and torsion (r' x r'').r''' / |r' x r''|^2 from derivatives (n, 3).

    The torsion is reported as 0 where the curvature vanishes (straight pieces).
    """
    c = np.cross(d1, d2)
    c2 = np.einsum("ni,ni->n", c, c)
    speed = np.linalg.norm(d1, axis=1)
    kappa = np.sqrt(c2) / speed**3
    nz = c2 > 0
    tau = np.where(nz, np.einsum("ni,ni->n", c, d3) / np.where(nz, c2, 1.0), 0.0)
    return kappa, tau
