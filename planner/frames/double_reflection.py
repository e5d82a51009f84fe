"""Double reflection method for rotation-minimizing frames of sampled curves.

Wang, Jüttler, Zheng, Liu (2008), "Computation of rotation minimizing frames", ACM TOG 27(1), Alg. 1:
with v1 = x_i+1 - x_i, the reflection H1 in the bisecting plane of x_i, x_i+1 maps (t_i, r_i) to
(t_i^L, r_i^L); with v2 = t_i+1 - t_i^L, the reflection H2 maps t_i^L to t_i+1 and r_i^L to r_i+1.
The global error is O(h^4) for a step h.

Vectorization: H2 H1 is a rotation with quaternion q_i = v2^ v1^ (unit pure quaternions: a reflection is
x -> a x a), and it maps the whole frame (t_i, r_i, s_i) to (t_i+1, r_i+1, s_i+1). The recurrence
r_i+1 = H2 H1 r_i is therefore the cumulative product Q_i = q_i-1 ... q_0 of per-step quaternions that
do not depend on r, computed by a parallel prefix scan (log2(n) vectorized passes, no Python loop over
samples). Finally r_i = Q_i r_0 Q_i* is orthogonalized against the given t_i (round-off only).
"""

from __future__ import annotations

import numpy as np

from planner.frames import validation as val
from planner.frames.quaternion_scan import inclusive_scan_rows
from planner.frames.validation import FrameDataError

#: |v2| (difference of unit vectors) below which the second reflection is ill-defined (tangent reversal).
MIN_REFLECTION = 1e-10


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of component rows (3, m)."""
    return np.stack((a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]))


def _rotations(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Unit quaternions q_i (4, n - 1) of H2 H1 for each step (Wang et al. 2008, Alg. 1), on component rows:
    points x and unit tangents t (3, n).

    Where x_i+1 = x_i the first reflection uses v1 = t_i (the limit of the chord direction along a smooth
    curve), which makes q_i the shortest-arc rotation t_i -> t_i+1. Raises FrameDataError naming the step
    when t_i+1 equals the reflected tangent t_i^L up to ``MIN_REFLECTION`` (the tangents reverse against
    the chord).
    """
    v1 = x[:, 1:] - x[:, :-1]
    n1 = np.sqrt(v1[0] ** 2 + v1[1] ** 2 + v1[2] ** 2)
    scale = max(float(n1.max(initial=0.0)), np.finfo(float).tiny)
    moved = n1 > 1e-15 * scale
    v1 = np.where(moved, v1 / np.where(moved, n1, 1.0), t[:, :-1])
    t0 = t[:, :-1]
    t_l = t0 - 2.0 * (v1[0] * t0[0] + v1[1] * t0[1] + v1[2] * t0[2]) * v1  # Wang et al. Alg. 1
    v2 = t[:, 1:] - t_l  # Wang et al. Alg. 1
    n2 = np.sqrt(v2[0] ** 2 + v2[1] ** 2 + v2[2] ** 2)
    bad = n2 < MIN_REFLECTION
    if bad.any():
        i = int(np.argmax(bad))
        raise FrameDataError(f"tangents {i} and {i + 1} are inconsistent with the chord between points "
                             f"{i} and {i + 1} (the tangent reverses); the double reflection is undefined",
                             "tangents", i + 1)
    v2 = v2 / n2
    # reflections x -> a x a compose to x -> (b a) x (b a)*: q = b a = (-b.a, b x a) for unit pure a, b
    return np.concatenate((-(v2[0] * v1[0] + v2[1] * v1[1] + v2[2] * v1[2])[None], _cross(v2, v1)))


def double_reflection_frames(points, tangents, start=None) -> np.ndarray:
    """Rotation-minimizing frames of a sampled curve by the double reflection method.

    Parameters
    ----------
    points : array (n, 3)
        Curve points x_i (m), n >= 2.
    tangents : array (n, 3)
        Tangent vectors at the points (any nonzero length; normalized here).
    start : array (3, 3), optional
        Frame at x_0: right-handed orthonormal, column 0 = the unit tangent t_0. Default: the
        shortest-arc rotation taking e1 to t_0.

    Returns
    -------
    ndarray (n, 3, 3)
        Frames: column 0 the unit tangent t_i, columns 1, 2 the rotation-minimizing normal-plane
        vectors r_i, s_i = t_i x r_i; right-handed and orthonormal to round-off.

    Raises
    ------
    FrameDataError
        Fewer than 2 points, shapes that differ, non-finite data or zero tangents (naming the index),
        a start frame that is not orthonormal or not on t_0, tangents that reverse against the chord.
    """
    x = val.vectors(points, "points")
    n = x.shape[0]
    if n < 2:
        raise FrameDataError(f"needs at least 2 points, got {n}", "points")
    t = val.nonzero_directions(tangents, "tangents", n)
    f0 = val.default_frame(t[0], 0) if start is None else val.frame(start, "start", t[0], 0)
    tr = np.ascontiguousarray(t.T)
    q = inclusive_scan_rows(np.concatenate((np.array([[1.0], [0.0], [0.0], [0.0]]),
                                        _rotations(np.ascontiguousarray(x.T), tr)), axis=1))
    q /= np.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
    r0 = f0[:, 1][:, None]
    c = _cross(q[1:], r0)
    r = r0 + 2.0 * (q[0] * c + _cross(q[1:], c))  # q r0 q* for unit q
    r -= (r[0] * tr[0] + r[1] * tr[1] + r[2] * tr[2]) * tr  # orthogonalize against t (round-off)
    r /= np.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
    s = _cross(tr, r)
    return np.ascontiguousarray(np.stack((tr, r, s), axis=1).transpose(2, 0, 1))
