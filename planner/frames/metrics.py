"""Quality figures of frames along a path: twist against a reference, angular velocity, baselines.

The twist of a frame field against the exact RMF is the figure every method reports (DESIGN.md,
"Quality figures"): the largest angle between the method's normal-plane vectors and the RMF's.
"""

from __future__ import annotations

import numpy as np

from planner.rotations import slerp_matrices
from planner.validation import ArgumentError, as_float, finite_floats


def twist_angles(frames: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Signed angle (rad, in (-pi, pi]) about the reference tangent from the reference's column 1 to
    the frames' column 1 projected into the reference normal plane; frames and reference (n, 3, 3).

    Raises ArgumentError (a PlannerError) naming the argument when either is not a finite array (n, 3, 3) or
    their lengths differ."""
    frames = finite_floats(frames, "frames", (None, 3, 3))
    reference = finite_floats(reference, "reference", (len(frames), 3, 3))
    t = reference[:, :, 0]
    u = frames[:, :, 1] - np.einsum("ni,ni->n", frames[:, :, 1], t)[:, None] * t
    return np.arctan2(np.einsum("ni,ni->n", u, reference[:, :, 2]), np.einsum("ni,ni->n", u, reference[:, :, 1]))


def max_twist_deg(frames: np.ndarray, reference: np.ndarray) -> float:
    """Largest |twist angle| in degrees (see :func:`twist_angles`; 0 for no frames)."""
    return float(np.degrees(np.abs(twist_angles(frames, reference)).max(initial=0.0)))


def angular_velocity(frame_fn, t: np.ndarray, h: float = 1e-3) -> np.ndarray:
    """Angular velocity (n, 3) of a frame field F(t) (n, 3, 3) with respect to t.

    Eighth-order central differences of F, then omega from the skew part of F' F^T; the truncation
    error is about h^8 |F^(9)|, far below round-off for h = 1e-3 on polynomial and rational frames.
    """
    t = finite_floats(t, "t", ((None,),))
    h = as_float(h, "h")
    if h <= 0.0:
        raise ArgumentError("h", f"must be > 0, got {h!r}")
    if not callable(frame_fn):
        raise ArgumentError("frame_fn", "must be a function of t giving frames (n, 3, 3)")
    c = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0.0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])
    dF = sum(ck * frame_fn(t + (k - 4) * h) for k, ck in enumerate(c) if ck != 0.0) / h
    W = np.einsum("nij,nkj->nik", dF, frame_fn(t))  # F' F^T = [omega]_x
    return 0.5 * np.stack((W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]), axis=1)


def frenet_frames(d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """Frenet frames (n, 3, 3) (tangent, principal normal, binormal) from derivatives r', r'' (n, 3).

    Undefined where the curvature vanishes (NaN there): one reason toolboxes that use it flip tools.
    ``d1`` must be finite and nonzero, ``d2`` finite, of the same length (ArgumentError otherwise).
    """
    d1 = finite_floats(d1, "d1", (None, 3))
    d2 = finite_floats(d2, "d2", (len(d1), 3))
    n1 = np.linalg.norm(d1, axis=1)
    if (n1 == 0.0).any():
        i = int(np.argmax(n1 == 0.0))
        raise ArgumentError(f"d1[{i}]", "is the zero vector: no tangent there")
    t = d1 / n1[:, None]
    b = np.cross(d1, d2)
    with np.errstate(invalid="ignore", divide="ignore"):
        b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return np.stack((t, np.cross(b, t), b), axis=2)


def slerp_frames(f0: np.ndarray, f1: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Frames (n, 3, 3) slerped from f0 to f1 (3, 3) at fractions s (n,) in [0, 1]: what common
    toolboxes do between taught orientations (ignores the path's tangent)."""
    f0, f1 = (_rotation(f, name) for f, name in ((f0, "f0"), (f1, "f1")))
    return slerp_matrices(f0, f1, finite_floats(s, "s", ((None,),)))


def _rotation(f, name: str) -> np.ndarray:
    """A finite rotation matrix (3, 3) (orthonormal to 1e-6, det +1), or ArgumentError naming ``name``."""
    f = finite_floats(f, name, (3, 3))
    if np.abs(f.T @ f - np.eye(3)).max() > 1e-6 or np.linalg.det(f) < 0.0:
        raise ArgumentError(name, "must be a rotation matrix (orthonormal, det +1)")
    return f
