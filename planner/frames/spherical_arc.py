"""Circular arcs on the unit sphere, vectorized over many arcs: construction, evaluation, distance.

An arc is the path of its start point ``a`` under the rotation about the unit ``axis`` u by the angle
alpha in [0, angle]; ``psi`` = angle(u, a) in [0, pi] is its angular radius. In the coordinates of
Jüttler's standard form (seed eq. 9) u = e3 and a = (sin psi, 0, cos psi).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.rotations import rotate_vectors

_TWO_PI = 2.0 * np.pi
_FIELDS = ("start", "axis", "angle", "psi")


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def geodesic_distance(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Great-circle distance (rad) between unit vectors x, y (..., 3), accurate for small angles."""
    return np.arctan2(np.linalg.norm(np.cross(x, y), axis=-1), np.einsum("...i,...i->...", x, y))


def rotate(axis: np.ndarray, angle: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v (..., 3) rotated about the unit axis (..., 3) by angle (...) (rad), by :mod:`planner.rotations`."""
    return rotate_vectors(np.asarray(angle, dtype=float)[..., None] * np.asarray(axis, dtype=float), v)


@dataclass(frozen=True, eq=False)
class SphericalArcs:
    """m circular arcs on the unit sphere (arrays over the arcs).

    Attributes
    ----------
    start : ndarray (m, 3)
        Unit start points a.
    axis : ndarray (m, 3)
        Unit rotation axes u; the arc turns counter-clockwise about u.
    angle : ndarray (m,)
        Total turning angle phi in [0, 2 pi) (rad), seed eq. (9).
    psi : ndarray (m,)
        Angular radius angle(u, a) in [0, pi] (rad), seed eq. (9).
    """

    start: np.ndarray
    axis: np.ndarray
    angle: np.ndarray
    psi: np.ndarray

    def __len__(self) -> int:
        return self.angle.shape[0]

    @property
    def end(self) -> np.ndarray:
        """Unit end points (m, 3)."""
        return rotate(self.axis, self.angle, self.start)

    @property
    def length(self) -> np.ndarray:
        """Arc lengths on the unit sphere (m,) = phi sin(psi) (rad)."""
        return self.angle * np.sin(self.psi)

    def point(self, idx: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """Points (n, 3) of arcs ``idx`` (n,) after turning by alpha (n,) (rad) from their start."""
        return rotate(self.axis[idx], alpha, self.start[idx])

    def tangent(self, idx: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """Unit tangents (n, 3) of arcs ``idx`` at turning angle alpha (zero where the arc is a point)."""
        p = self.point(idx, alpha)
        v = np.cross(self.axis[idx], p)
        n = np.linalg.norm(v, axis=1, keepdims=True)
        return np.divide(v, n, out=np.zeros_like(v), where=n > 0)

    def take(self, idx: np.ndarray) -> SphericalArcs:
        """The arcs ``idx`` as a new SphericalArcs."""
        return SphericalArcs(self.start[idx], self.axis[idx], self.angle[idx], self.psi[idx])

    @staticmethod
    def concatenate(parts) -> SphericalArcs:
        """All arcs of a sequence of SphericalArcs, in order."""
        return SphericalArcs(*(np.concatenate([getattr(p, f) for p in parts]) for f in _FIELDS))

    @staticmethod
    def interleave(first: SphericalArcs, second: SphericalArcs) -> SphericalArcs:
        """first[0], second[0], first[1], second[1], ... (the arcs of biarcs in order)."""
        def pair(f):
            a, b = getattr(first, f), getattr(second, f)
            return np.stack((a, b), axis=1).reshape((-1,) + a.shape[1:])

        return SphericalArcs(*(pair(f) for f in _FIELDS))

    def distance(self, idx: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Great-circle distance (n,) from unit points x (n, 3) to arcs ``idx`` (n,) (exact).

        The nearest point of a small circle to x lies on the meridian through x, so inside the arc's
        angular range the distance is |angle(u, x) - psi|; outside it is the distance to an end point.
        """
        u, a, phi, psi = self.axis[idx], self.start[idx], self.angle[idx], self.psi[idx]
        polar = geodesic_distance(u, x)
        ap = a - np.einsum("ij,ij->i", a, u)[:, None] * u
        xp = x - np.einsum("ij,ij->i", x, u)[:, None] * u
        beta = np.mod(np.arctan2(np.einsum("ij,ij->i", u, np.cross(ap, xp)), np.einsum("ij,ij->i", ap, xp)),
                      _TWO_PI)
        inside = beta <= phi
        d_circle = np.abs(polar - psi)
        d_ends = np.minimum(geodesic_distance(a, x), geodesic_distance(rotate(u, phi, a), x))
        return np.where(inside, d_circle, d_ends)


def arcs_from_tangent(p: np.ndarray, tangent: np.ndarray, q: np.ndarray) -> SphericalArcs:
    """The arcs (m,) that leave unit points p (m, 3) in the unit direction ``tangent`` and end at q.

    The circle lies in the plane through p spanned by the tangent and the chord d = q - p, so its
    axis is u = T x d / |T x d| (this orientation turns p towards T); the tangent-chord angle is half
    the central angle, phi = 2 angle(T, d). Where q = p the arc is the point p (phi = 0) on the
    great circle through p along T.
    """
    p = np.asarray(p, dtype=float)
    t = np.asarray(tangent, dtype=float)
    q = np.asarray(q, dtype=float)
    d = q - p
    n = np.cross(t, d)
    nn = np.linalg.norm(n, axis=1)
    point = nn <= 1e-300
    great = np.cross(p, t)  # axis of the great circle through p along t
    u = np.where(point[:, None], great, n / np.where(point, 1.0, nn)[:, None])
    u = _unit(u)
    phi = np.where(point, 0.0, 2.0 * np.arctan2(nn, np.einsum("ij,ij->i", t, d)))
    psi = np.arctan2(np.linalg.norm(np.cross(u, p), axis=1), np.einsum("ij,ij->i", u, p))
    return SphericalArcs(p, u, phi, psi)
