"""Deprecated: the float path of the rotation-vector conversions moved to :mod:`planner.rotations`.

The names of this module clashed with planner.rotations' own (``rotvec_to_matrix``, ``matrix_to_rotvec``: scipy,
any leading axes, checked shapes) for different functions. They stay importable for the next release; each call
warns (``DeprecationWarning``) naming its replacement and returns what the replacement returns:

=====================  ===========================================
here                   planner.rotations
=====================  ===========================================
rotvec_to_matrix       rotvec_to_matrix_n (n, 3) -> (n, 3, 3)
matrix_to_rotvec       matrix_to_rotvec_n (n, 3, 3) -> (n, 3)
rotvec_to_matrix_1     rotvec_to_matrix_1 (one, on Python floats)
matrix_to_rotvec_1     matrix_to_rotvec_1 (one, on Python floats)
=====================  ===========================================
"""

from __future__ import annotations

import warnings

import numpy as np

from planner import rotations

__all__ = ["rotvec_to_matrix", "matrix_to_rotvec", "rotvec_to_matrix_1", "matrix_to_rotvec_1"]


def _warn(name: str, replacement: str) -> None:
    warnings.warn(f"planner.kinematics.rotvec.{name} is deprecated and will be removed in the release after the "
                  f"next one: use planner.rotations.{replacement}", DeprecationWarning, stacklevel=3)


def rotvec_to_matrix(r: np.ndarray) -> np.ndarray:
    """Deprecated: :func:`planner.rotations.rotvec_to_matrix_n`."""
    _warn("rotvec_to_matrix", "rotvec_to_matrix_n")
    return rotations.rotvec_to_matrix_n(r)


def matrix_to_rotvec(R: np.ndarray) -> np.ndarray:
    """Deprecated: :func:`planner.rotations.matrix_to_rotvec_n`."""
    _warn("matrix_to_rotvec", "matrix_to_rotvec_n")
    return rotations.matrix_to_rotvec_n(R)


def rotvec_to_matrix_1(rx: float, ry: float, rz: float) -> tuple[float, ...]:
    """Deprecated: :func:`planner.rotations.rotvec_to_matrix_1`."""
    _warn("rotvec_to_matrix_1", "rotvec_to_matrix_1")
    return rotations.rotvec_to_matrix_1(rx, ry, rz)


def matrix_to_rotvec_1(r00, r01, r02, r10, r11, r12, r20, r21, r22) -> tuple[float, float, float]:
    """Deprecated: :func:`planner.rotations.matrix_to_rotvec_1`."""
    _warn("matrix_to_rotvec_1", "matrix_to_rotvec_1")
    return rotations.matrix_to_rotvec_1(r00, r01, r02, r10, r11, r12, r20, r21, r22)
