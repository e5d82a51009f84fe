"""The exact rotation-minimizing frame (RMF) of a PH curve: the ER frame turned by an exact angle.

With the ER frame (e1, e2, e3), the frame (e1, cos(psi) e2 + sin(psi) e3, -sin(psi) e2 + cos(psi) e3) is
rotation-minimizing iff psi' = -e2' . e3 (the seed's eq. (6), with its angle 2 theta = -psi). Writing
U = A/|A|, the body angular velocity of the ER frame is 2 U* U', so e2' . e3 = 2 (A* A')_i / |A|^2: the
angle rate is the rational function psi'(t) = -2 q(t) / sigma(t), q = (A* A')_i of degree 2m - 2 (its
top coefficient cancels) and sigma = |A|^2. It is integrated here by composite Gauss-Legendre
quadrature with panels sized from the distance of sigma's complex roots to [0, 1], which makes the
angle exact to round-off (about 1e-15 rad), unlike the trapezoid rule of the seed's eq. (9).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np

from planner import bernstein
from planner import quaternion as qt
from planner.errors import PlannerError
from planner.frames.er import er_frames, quaternion_values
from planner.frames.validation import has_curve
from planner.validation import finite_floats

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(16)
_GL6_NODES, _GL6_WEIGHTS = np.polynomial.legendre.leggauss(6)


def angle_rate(A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """psi'(t) = -e2' . e3 = -2 (A* A')_i / |A|^2 (rad per unit t) at parameters t, any shape."""
    t = np.asarray(t, dtype=float)
    Av = bernstein.evaluate(A, t.ravel())
    dA = bernstein.evaluate(bernstein.derivative(A), t.ravel())
    # i-component of A* A' for A = (a0, a1, a2, a3): a0 d1 - a1 d0 - a2 d3 + a3 d2
    q = Av[:, 0] * dA[:, 1] - Av[:, 1] * dA[:, 0] - Av[:, 2] * dA[:, 3] + Av[:, 3] * dA[:, 2]
    return (-2.0 * q / qt.norm2(Av)).reshape(t.shape)


def _panels(A: np.ndarray) -> int:
    """Panels for 16-point Gauss-Legendre to reach round-off: about 1 / (distance of roots of sigma)."""
    sigma = np.zeros(2 * A.shape[0] - 1)
    m = A.shape[0]
    for i in range(m):
        for j in range(m):
            w = comb(m - 1, i) * comb(m - 1, j) / comb(2 * m - 2, i + j)
            sigma[i + j] += w * float(A[i] @ A[j])
    roots = np.roots(bernstein.to_power(sigma)[::-1])
    if roots.size == 0:
        return 1
    dist = np.where(roots.real < 0, np.abs(roots), np.where(roots.real > 1, np.abs(roots - 1), np.abs(roots.imag)))
    return int(np.clip(np.ceil(1.5 / max(dist.min(), 1e-6)), 2, 4096))


@dataclass(frozen=True)
class RMFAngle:
    """The exact RMF angle psi(t) - psi(0) of one PH segment, evaluable at any parameters.

    Attributes
    ----------
    A : ndarray (m, 4)
        Quaternion Bernstein coefficients of the curve.
    edges : ndarray (M + 1,)
        Quadrature panel edges on [0, 1].
    cumulative : ndarray (M + 1,)
        The angle at the panel edges.
    """

    A: np.ndarray
    edges: np.ndarray
    cumulative: np.ndarray

    @classmethod
    def of(cls, A: np.ndarray) -> RMFAngle:
        A = np.asarray(A, dtype=float)
        M = _panels(A)
        edges = np.linspace(0.0, 1.0, M + 1)
        half = 0.5 / M
        nodes = edges[:-1, None] + half * (1.0 + _GL_NODES)
        panel = angle_rate(A, nodes) @ _GL_WEIGHTS * half
        return cls(A, edges, np.concatenate(([0.0], np.cumsum(panel))))

    @property
    def total(self) -> float:
        """psi(1) - psi(0): the angle the RMF turns against the ER frame over the segment (rad)."""
        return float(self.cumulative[-1])

    def __call__(self, t) -> np.ndarray:
        """psi(t) - psi(0) at parameters t (n,) in [0, 1]."""
        t = np.atleast_1d(finite_floats(t, "t"))
        M = self.edges.size - 1
        k = np.clip((t * M).astype(int), 0, M - 1)
        a = self.edges[k]
        half = 0.5 * (t - a)
        nodes = a[:, None] + half[:, None] * (1.0 + _GL_NODES)
        return self.cumulative[k] + (angle_rate(self.A, nodes) @ _GL_WEIGHTS) * half

    def on_grid(self, t) -> np.ndarray:
        """psi(t) - psi(0) at increasing parameters t (n,): 6-point Gauss-Legendre between neighbours.

        Cheaper than the call for dense sorted samples (6 instead of 16 rate evaluations per sample);
        the intervals are shorter than the panels, so the sum stays exact to round-off.
        """
        t = np.atleast_1d(finite_floats(t, "t"))
        if t.size < 2 or np.any(np.diff(t) < 0) or np.diff(t).max() > 1.0 / (self.edges.size - 1):
            return self(t)
        half = 0.5 * np.diff(t)
        nodes = t[:-1, None] + half[:, None] * (1.0 + _GL6_NODES)
        steps = (angle_rate(self.A, nodes) @ _GL6_WEIGHTS) * half
        return self(t[:1])[0] + np.concatenate(([0.0], np.cumsum(steps)))


def turn_normals(frames: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Frames (n, 3, 3) with columns 1, 2 turned by ``angle`` (n,) about column 0 (right-handed)."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    out = frames.copy()
    out[:, :, 1] = c * frames[:, :, 1] + s * frames[:, :, 2]
    out[:, :, 2] = -s * frames[:, :, 1] + c * frames[:, :, 2]
    return out


def normal_angle(frame: np.ndarray, er0: np.ndarray) -> float:
    """Angle of a frame's column 1 in the normal plane of the ER frame er0 (3, 3), from er0's column 1."""
    return float(np.arctan2(frame[:, 1] @ er0[:, 2], frame[:, 1] @ er0[:, 1]))


def check_start_frame(start, tangent: np.ndarray) -> np.ndarray:
    """A start frame (3, 3): orthonormal, right-handed, column 0 equal to the curve's unit tangent."""
    F = np.asarray(start, dtype=float)
    if F.shape != (3, 3) or not np.isfinite(F).all():
        raise PlannerError(f"start frame must be a finite 3x3 matrix, got shape {F.shape}")
    if np.abs(F.T @ F - np.eye(3)).max() > 1e-9 or np.linalg.det(F) < 0:
        raise PlannerError("start frame must be orthonormal and right-handed (columns are the frame vectors)")
    if np.abs(F[:, 0] - tangent).max() > 1e-9:
        raise PlannerError(
            f"start frame column 0 {F[:, 0].round(9).tolist()} must be the unit tangent {tangent.round(9).tolist()}"
        )
    return F


def rmf_frames(curve, t, start=None) -> np.ndarray:
    """Exact rotation-minimizing frames of a PH curve at parameters t (n,) in [0, 1].

    Parameters
    ----------
    curve : PHQuintic or PHCubic
    t : array_like (n,)
    start : array_like (3, 3), optional
        Frame at t = 0 (column 0 the unit tangent there). Default: the ER frame at t = 0.

    Returns
    -------
    ndarray (n, 3, 3)
        Columns: unit tangent, then the two rotation-minimizing normal-plane vectors; orthonormal and
        right-handed to round-off. The angle about the tangent is exact to about 1e-15 rad.
    """
    has_curve(curve)
    t = np.atleast_1d(finite_floats(t, "t", ((), (None,))))
    psi0 = 0.0
    if start is not None:
        er0 = er_frames(curve, [0.0])[0]
        F = check_start_frame(start, er0[:, 0])
        psi0 = normal_angle(F, er0)
    return turn_normals(er_frames(curve, t), psi0 + RMFAngle.of(curve.A)(t))


__all__ = ["RMFAngle", "angle_rate", "check_start_frame", "normal_angle", "quaternion_values", "rmf_frames",
           "turn_normals"]
