"""Vectorized quaternion algebra on arrays of shape (..., 4), laid out as (scalar, i, j, k).

These are the few operations the PH curve and frame formulas are written in. For rotations as such
(conversion to matrices, rotation vectors, slerp) the planner uses :mod:`planner.rotations` (on
``scipy.spatial.transform``, same layout); these helpers exist because PH hodographs need the
*unnormalized* products ``A u A*``.
"""

from __future__ import annotations

import numpy as np

I = np.array([0.0, 1.0, 0.0, 0.0])
J = np.array([0.0, 0.0, 1.0, 0.0])
K = np.array([0.0, 0.0, 0.0, 1.0])


def mul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p q of quaternion arrays broadcast against each other."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    p0, p1, p2, p3 = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty(np.broadcast_shapes(p.shape, q.shape))
    out[..., 0] = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
    out[..., 1] = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
    out[..., 2] = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
    out[..., 3] = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
    return out


def i_product(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Vector part of p i q* (..., 3), in closed form; symmetric in p and q, so it equals sym(p, I, q).

    For p = q it is the PH hodograph A i A* = (u^2 + v^2 - p^2 - q^2, 2(uq + vp), 2(vq - up)) of the
    grm seed, eq. (1), with A = u + v i + p j + q k.
    """
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    p0, p1, p2, p3 = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    q0, q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty(np.broadcast_shapes(p.shape, q.shape)[:-1] + (3,))
    out[..., 0] = p0 * q0 + p1 * q1 - p2 * q2 - p3 * q3
    out[..., 1] = p1 * q2 + p2 * q1 + p0 * q3 + p3 * q0
    out[..., 2] = p1 * q3 + p3 * q1 - p0 * q2 - p2 * q0
    return out


def conj(q: np.ndarray) -> np.ndarray:
    """Conjugate q* = (q0, -q1, -q2, -q3)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def norm2(q: np.ndarray) -> np.ndarray:
    """Squared norm |q|^2 = q q*, shape (...)."""
    q = np.asarray(q, dtype=float)
    return np.einsum("...i,...i->...", q, q)


def dot(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Euclidean inner product <p, q> = scalar part of p q*, shape (...)."""
    return np.einsum("...i,...i->...", np.asarray(p, float), np.asarray(q, float))


def sandwich(p: np.ndarray, u: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Vector part of p u q* (shape (..., 3)) for a pure unit quaternion u in {I, J, K}.

    For p = q this is the PH hodograph form A u A*; symmetrised, (p u q* + q u p*)/2 is the
    "star" product of the seeds (grm seed eq. 3).
    """
    return mul(mul(p, u), conj(q))[..., 1:]


def sym(p: np.ndarray, u: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Symmetric product (p u q* + q u p*)/2 as a vector, shape (..., 3) (grm seed eq. 3)."""
    return 0.5 * (sandwich(p, u, q) + sandwich(q, u, p))


def rotate_i_to(v: np.ndarray) -> np.ndarray:
    """A unit quaternion n with n i n* = v / |v|, for nonzero vectors v of shape (..., 3), shape (..., 4).

    With v/|v| = (l, m, n): for l >= 0 the shortest-arc rotation about i x v,
    (1 + l, 0, -n, m) / sqrt(2 (1 + l)); for l < 0 the same times j, (-n, m, 1 - l, 0) / sqrt(2 (1 - l)),
    which keeps full precision for v near -i (check either with the hodograph formula of grm eq. 1).
    """
    v = np.asarray(v, dtype=float)
    u = v / np.sqrt(np.einsum("...i,...i->...", v, v))[..., None]
    lam, mu, nu = u[..., 0], u[..., 1], u[..., 2]
    pos = lam >= 0
    c = 1.0 + np.abs(lam)
    s = 1.0 / np.sqrt(2.0 * c)
    out = np.empty(v.shape[:-1] + (4,))
    out[..., 0] = np.where(pos, c, -nu) * s
    out[..., 1] = np.where(pos, 0.0, mu) * s
    out[..., 2] = np.where(pos, -nu, c) * s
    out[..., 3] = np.where(pos, mu, 0.0) * s
    return out


def exp_i(phi: np.ndarray) -> np.ndarray:
    """The unit quaternion exp(i phi) = cos(phi) + i sin(phi), shape (..., 4)."""
    phi = np.asarray(phi, dtype=float)
    z = np.zeros_like(phi)
    return np.stack((np.cos(phi), np.sin(phi), z, z), axis=-1)
