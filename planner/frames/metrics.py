"""Quality figures of frames along a path: twist against a reference, angular velocity, baselines.

The twist of a frame field against the exact RMF is the figure every method reports (DESIGN.md,
"Quality figures"): the largest angle between the method's normal-plane vectors and the RMF's.
"""

from __future__ import annotations

import numpy as np

from planner.rotations import slerp_matrices


def twist_angles(frames: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Signed angle (rad, in (-pi, pi]) about the reference tangent from the reference's column 1 to
    the frames' column 1 projected into the reference normal plane; frames and reference (n, 3, 3)."""
    t = reference[:, :, 0]
    u = frames[:, :, 1] - np.einsum("ni,ni->n", frames[:, :, 1], t)[:, None] * t
    return np.arctan2(np.einsum("ni,ni->n", u, reference[:, :, 2]), np.einsum("ni,ni->n", u, reference[:, :, 1]))


def max_twist_deg(frames: np.ndarray, reference: np.ndarray) -> float:
    """Largest |twist angle| in degrees (see :func:`twist_angles`)."""
    return float(np.degrees(np.abs(twist_angles(frames, reference)).max()))


def angular_velocity(frame_fn, t: np.ndarray, h: float = 1e-3) -> np.ndarray:
    """Angular velocity (n, 3) of a frame field F(t) (n, 3, 3) with respect to t.

    Eighth-order central differences of F, then omega from the skew part of F' F^T; the truncation
    error is about h^8 |F^(9)|, far below round-off for h = 1e-3 on polynomial and rational frames.
    """
    t = np.asarray(t, dtype=float)
    c = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0.0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])
    dF = sum(ck * frame_fn(t + (k - 4) * h) for k, ck in enumerate(c) if ck != 0.0) / h
    W = np.einsum("nij,nkj->nik", dF, frame_fn(t))  # F' F^T = [omega]_x
    return 0.5 * np.stack((W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]), axis=1)


def frenet_frames(d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """Frenet frames (n, 3, 3) (tangent, principal normal, binormal) from derivatives r', r'' (n, 3).

    Undefined where the curvature vanishes (NaN there): one reason toolboxes that use it flip tools.
    """
    t = d1 / np.linalg.norm(d1, axis=1, keepdims=True)
    b = np.cross(d1, d2)
    with np.errstate(invalid="ignore", divide="ignore"):
        b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return np.stack((t, np.cross(b, t), b), axis=2)


def slerp_frames(f0: np.ndarray, f1: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Frames (n, 3, 3) slerped from f0 to f1 (3, 3) at fractions s (n,) in [0, 1]: what common
    toolboxes do between taught orientations (ignores the path's tangent)."""
    return slerp_matrices(f0, f1, np.asarray(s, dtype=float))
