"""Bernstein-basis polynomials, vectorized over the parameter and over coefficient arrays.

A polynomial of degree n is stored as its n + 1 Bernstein coefficients along axis 0 (any trailing
shape: scalars, 3-vectors, quaternions). Evaluation uses the de Casteljau-free Horner-like form
through the basis matrix, which is exact to round-off on [0, 1].
"""

from __future__ import annotations

from functools import lru_cache
from math import comb

import numpy as np

from planner import quaternion as quat


@lru_cache(maxsize=64)
def _binomials(n: int) -> np.ndarray:
    return np.array([comb(n, j) for j in range(n + 1)], dtype=float)


def basis(n: int, t: np.ndarray) -> np.ndarray:
    """Bernstein basis B_{n,k}(t), shape t.shape + (n + 1,)."""
    t = np.asarray(t, dtype=float)[..., None]
    reps = t.shape[:-1] + (n + 1,)
    tp: np.ndarray = np.ones(reps)
    sp: np.ndarray = np.ones(reps)
    if n > 0:
        tp[..., 1:] = t
        sp[..., 1:] = 1.0 - t
        tp = np.cumprod(tp, axis=-1)  # t^k
        sp = np.cumprod(sp, axis=-1)[..., ::-1]  # (1 - t)^(n - k)
    return _binomials(n) * tp * sp


def evaluate(coeffs: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Value of the polynomial with Bernstein coefficients ``coeffs`` (n+1, ...) at t (m,) -> (m, ...)."""
    coeffs = np.asarray(coeffs, dtype=float)
    b = basis(coeffs.shape[0] - 1, t)
    return np.tensordot(b, coeffs, axes=(-1, 0))


def derivative(coeffs: np.ndarray) -> np.ndarray:
    """Bernstein coefficients (n, ...) of the derivative of a degree-n polynomial."""
    coeffs = np.asarray(coeffs, dtype=float)
    n = coeffs.shape[0] - 1
    return n * np.diff(coeffs, axis=0)


def antiderivative(coeffs: np.ndarray, c0: np.ndarray | float = 0.0) -> np.ndarray:
    """Bernstein coefficients (n+2, ...) of the integral from 0, plus c0, of a degree-n polynomial."""
    coeffs = np.asarray(coeffs, dtype=float)
    n = coeffs.shape[0] - 1
    zero = np.zeros((1,) + coeffs.shape[1:])
    return np.asarray(c0, dtype=float) + np.concatenate((zero, np.cumsum(coeffs, axis=0) / (n + 1)))


def quaternion_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Bernstein coefficients of the quaternion polynomial product a(t) b(t) (Hamilton product).

    Unlike the rest of this module the degree runs along axis -2: a (..., m+1, 4) and b (..., n+1, 4)
    (leading axes broadcast) give (..., m+n+1, 4), with the Bernstein product rule
    c_k = sum_{i+j=k} C(m, i) C(n, j) / C(m+n, k) a_i b_j.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    m, n = a.shape[-2] - 1, b.shape[-2] - 1
    out = np.zeros(np.broadcast_shapes(a.shape[:-2], b.shape[:-2]) + (m + n + 1, 4))
    for i in range(m + 1):  # (m + 1) (n + 1) products of whole coefficient arrays: degrees are small
        for j in range(n + 1):
            c = comb(m, i) * comb(n, j) / comb(m + n, i + j)
            out[..., i + j, :] += c * quat.mul(a[..., i, :], b[..., j, :])
    return out


def to_power(coeffs: np.ndarray) -> np.ndarray:
    """Power-basis coefficients (lowest degree first) of a scalar Bernstein polynomial."""
    c = np.asarray(coeffs, dtype=float)
    n = c.shape[0] - 1
    out = np.zeros(n + 1)
    for k in range(n + 1):
        for j in range(k + 1):
            out[k] += comb(n, k) * comb(k, j) * (-1) ** (k - j) * c[j]
    return out
