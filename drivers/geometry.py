"""Distances of a tracked TCP path from the planned path, and joint margins: the geometry the execution report and
the recording it is reduced into share (:mod:`drivers.report`, :mod:`drivers.recording`, :mod:`drivers.plan_window`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree


class PolylineIndex:
    """A polyline ``path`` (n, 3) prepared once for many :meth:`distance` queries (a k-d tree of its vertices,
    repeated vertices dropped)."""

    def __init__(self, path: np.ndarray) -> None:
        path = np.asarray(path, dtype=float).reshape(-1, 3)
        self.n = path.shape[0]
        # drop repeated vertices (the tool rests at move boundaries): they make the k nearest all the same point
        keep = np.concatenate(([True], np.linalg.norm(np.diff(path, axis=0), axis=1) > 1e-12)) if self.n else \
            np.zeros(0, bool)
        self.idx_map = np.flatnonzero(keep)
        self.v = path[keep]
        self.tree = cKDTree(self.v) if self.v.shape[0] > 1 else None

    def distance(self, points: np.ndarray, *, k: int = 8) -> tuple[np.ndarray, np.ndarray]:
        """Distance (m) of each point (m, 3) from the polyline, and the index of the nearest segment's start
        (m,), as :func:`distance_to_polyline`."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        m = points.shape[0]
        if self.n == 0 or m == 0:
            return np.full(m, np.nan), np.zeros(m, np.int64)
        v = self.v
        if self.tree is None:
            return np.linalg.norm(points - v[0], axis=1), np.zeros(m, np.int64)
        kk = min(k, v.shape[0])
        _, near = self.tree.query(points, k=kk)
        near = near.reshape(m, kk)
        nseg = v.shape[0] - 1
        seg = np.concatenate((np.clip(near - 1, 0, nseg - 1), np.clip(near, 0, nseg - 1)), axis=1)  # (m, 2k)
        a = v[seg]
        d = v[seg + 1] - a
        w = points[:, None, :] - a
        dd = np.einsum("mkj,mkj->mk", d, d)
        u = np.clip(np.einsum("mkj,mkj->mk", w, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
        dist = np.linalg.norm(w - u[..., None] * d, axis=2)
        best = dist.argmin(axis=1)
        rows = np.arange(m)
        return dist[rows, best], self.idx_map[seg[rows, best]]


def distance_to_polyline(points: np.ndarray, path: np.ndarray, *, k: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Distance (m) of each point (m, 3) from the polyline ``path`` (n, 3), and the index of the segment
    start nearest to it (m,). The candidate segments are those next to the ``k`` nearest vertices (exact for a
    polyline sampled densely against the distances measured, as the planned path at the controller rate is).
    Many queries against one path: :class:`PolylineIndex`."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    path = np.asarray(path, dtype=float).reshape(-1, 3)
    if path.shape[0] == 0 or points.shape[0] == 0:
        return np.full(points.shape[0], np.nan), np.zeros(points.shape[0], np.int64)
    return PolylineIndex(path).distance(points, k=k)


def joint_limit_margin(model: str | None, joints: np.ndarray) -> float:
    """Smallest distance of the recorded joints (n, 6) rad from the model's position limits, rad (NaN without)."""
    q = np.asarray(joints, dtype=float).reshape(-1, 6)
    q = q[np.isfinite(q).all(axis=1)]
    if model is None or q.shape[0] == 0:
        return math.nan
    from planner.kinematics.ur_models import get_model

    m = get_model(model)
    lo, hi = np.asarray(m.q_min), np.asarray(m.q_max)
    return float(np.minimum(q - lo, hi - q).min())
