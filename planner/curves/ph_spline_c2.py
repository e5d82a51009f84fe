"""The C2 PH quintic spline: a Newton solve for a C1 quadratic quaternion spline A(u).

If A(u) is a C1 quadratic spline in the global parameter u, the hodograph r'(u) = A i A* is C1, so the
PH quintic spline r(u) is C2 (Farouki's C2 PH quintic spline construction, here in quaternion form).
On segment k (knot spacing h_k) the Bernstein coefficients of A are (W_k, c_k, W_{k+1}), where the joint
values W_j = (h_j c_{j-1} + h_{j-1} c_j) / (h_{j-1} + h_j) make A C1, and W_0, W_N are free end values.

Unknowns x = (W_0, c_0, ..., c_{N-1}, W_N): 4 (N + 2) reals. Equations: each segment ends at the next
waypoint, (1/5) sum(hodograph coefficients) = (p_{k+1} - p_k) / h_k (3 N), and the end derivatives
W_0 i W_0* = m_0, W_N i W_N* = m_N (6). The system is quadratic and under-determined by N + 2 (the
phases of the quaternions); Newton steps of least norm (Gauss-Newton with J^T (J J^T)^-1) started from
the C1 spline converge to the C2 spline nearest to it.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from planner import quaternion as qt
from planner.curves.ph_core import batch_hodograph
from planner.errors import ConvergenceError


def _segments(x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Per-segment quaternion coefficients (N, 3, 4) in the u-parametrization from unknowns x."""
    c = x[1:-1]
    W = np.empty((h.shape[0] + 1, 4))
    W[0], W[-1] = x[0], x[-1]
    W[1:-1] = (h[1:, None] * c[:-1] + h[:-1, None] * c[1:]) / (h[:-1] + h[1:])[:, None]
    return np.stack((W[:-1], c, W[1:]), axis=1)


def _residual(x, h, rhs_seg, m0, mN) -> np.ndarray:
    A = _segments(x, h)
    seg = batch_hodograph(A).sum(axis=1) / 5.0 - rhs_seg
    e0 = qt.sandwich(x[0], qt.I, x[0]) - m0
    eN = qt.sandwich(x[-1], qt.I, x[-1]) - mN
    return np.concatenate((seg.ravel(), e0, eN))


def _jacobian(x, h, rhs_seg, m0, mN) -> sp.csr_matrix:
    """Exact sparse Jacobian of the quadratic residual by 12 colored probes.

    For a quadratic F, J(x) e = F(x + e) - F(x) - F(e) + F(0) exactly. Segment k's equations involve
    unknown blocks k, k+1, k+2 only, so blocks of equal index mod 3 are probed together.
    """
    nb = x.shape[0]
    N = nb - 2
    f0 = _residual(np.zeros_like(x), h, rhs_seg, m0, mN)
    fx = _residual(x, h, rhs_seg, m0, mN)
    blocks = np.arange(nb)
    rows, cols, vals = [], [], []
    seg_rows = np.arange(3 * N).reshape(N, 3)
    for r in range(3):
        members = blocks % 3 == r
        # for each segment k, the block in {k, k+1, k+2} with color r
        k = np.arange(N)
        b_of_seg = k + (r - k) % 3
        for comp in range(4):
            e = np.zeros_like(x)
            e[members, comp] = 1.0
            je = _residual(x + e, h, rhs_seg, m0, mN) - fx - _residual(e, h, rhs_seg, m0, mN) + f0
            rows.append(seg_rows.ravel())
            cols.append(np.repeat(4 * b_of_seg + comp, 3))
            vals.append(je[: 3 * N])
            if r == 0:
                rows.append(3 * N + np.arange(3))
                cols.append(np.full(3, comp))
                vals.append(je[3 * N : 3 * N + 3])
            if (nb - 1) % 3 == r:
                rows.append(3 * N + 3 + np.arange(3))
                cols.append(np.full(3, 4 * (nb - 1) + comp))
                vals.append(je[3 * N + 3 :])
    J = sp.coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * N + 6, 4 * nb)
    )
    return J.tocsr()


def solve_c2(
    A_start: np.ndarray,
    points: np.ndarray,
    h: np.ndarray,
    m0: np.ndarray,
    mN: np.ndarray,
    *,
    tol: float = 1e-14,
    max_iter: int = 40,
) -> tuple[np.ndarray, int]:
    """Quaternion coefficients (N, 3, 4) of the C2 PH quintic spline, u-parametrization.

    Parameters
    ----------
    A_start : (N, 3, 4)
        Start values: a C1 PH quintic spline in the u-parametrization, phase-aligned so that
        A_k(1) = A_{k+1}(0).
    points : (N + 1, 3)
        Waypoints.
    h : (N,)
        Knot spacings.
    m0, mN : (3,)
        End derivatives dr/du.

    Returns
    -------
    (A, iterations)
    """
    rhs_seg = np.diff(points, axis=0) / h[:, None]
    x = np.concatenate((A_start[:1, 0], A_start[:, 1], A_start[-1:, 2]))
    F = _residual(x, h, rhs_seg, m0, mN)
    norm = np.abs(F).max()
    for it in range(1, max_iter + 1):
        if norm <= tol:
            return _segments(x, h), it - 1
        J = _jacobian(x, h, rhs_seg, m0, mN)
        M = (J @ J.T).tocsc()
        try:
            y = splu(M).solve(F)
        except RuntimeError as exc:  # singular J J^T: degenerate data
            msg = f"C2 PH spline: singular Newton system at iteration {it} ({exc})"
            raise ConvergenceError(msg) from None
        dx = (J.T @ y).reshape(x.shape)
        lam = 1.0
        while True:
            xn = x - lam * dx
            Fn = _residual(xn, h, rhs_seg, m0, mN)
            nn = np.abs(Fn).max()
            if nn < norm or lam < 1e-3:
                break
            lam *= 0.5
        if nn >= norm and norm > 1e3 * tol:
            break
        x, F, norm = xn, Fn, nn
    if norm <= 1e3 * tol:
        return _segments(x, h), max_iter
    worst = int(np.argmax(np.abs(F[: 3 * (points.shape[0] - 1)]).reshape(-1, 3).max(axis=1)))
    raise ConvergenceError(
        f"C2 PH spline did not converge (residual {norm:.3g} at the span from waypoint {worst} to "
        f"{worst + 1}; continuity='C1' or more waypoints there avoid it)"
    )
