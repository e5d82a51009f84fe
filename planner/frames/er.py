"""Euler-Rodrigues frames of spatial PH curves (grm seed, section 3.1).

For r'(t) = A(t) i A*(t) the ER frame is (A i A*, A j A*, A k A*) / |A|^2: the columns of the rotation
matrix of the quaternion A(t). Column 0 is the unit tangent. The frame is rational in t but not
rotation-minimizing; the RMF and GRM frames are rotations of it about the tangent.
"""

from __future__ import annotations

import numpy as np

from planner import bernstein
from planner.frames.validation import has_curve
from planner.rotations import quaternion_to_matrix
from planner.validation import finite_floats


def quaternion_values(A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """A(t) (n, 4) from Bernstein coefficients A (m, 4) (m = 3 for quintics, 2 for cubics)."""
    return bernstein.evaluate(A, np.atleast_1d(finite_floats(t, "t")))


def er_frames(curve, t) -> np.ndarray:
    """Euler-Rodrigues frames of a PH curve (``PHQuintic`` or ``PHCubic``) at parameters t (n,).

    Returns
    -------
    ndarray (n, 3, 3)
        Columns: unit tangent A i A* / |A|^2, then A j A* / |A|^2 and A k A* / |A|^2 spanning the normal
        plane; right-handed and orthonormal to round-off.
    """
    has_curve(curve)
    t = np.atleast_1d(finite_floats(t, "t", ((), (None,))))
    return quaternion_to_matrix(quaternion_values(curve.A, t))
