"""Closed-form families of spatial rational PH curves of class 3, 4, 5, 6 (seed ``dual-rational-ph-curves.txt``,
section 6, quadratic quaternion polynomials A(t) = A0 + A1 t + A2 t^2 with A2 = 1 unless said otherwise).

Each constructor builds A from the family's free parameters and returns ``RationalPH.from_dual(A, f, R=R)``;
the class is that of the theorem for a generic f of degree <= m. Quaternions are (scalar, i, j, k);
A_j = (a_{0,j}, a_{1,j}, a_{2,j}, a_{3,j}) in the seed's notation a_{i,j}.

* class 3, Theorem 7 (ten parameters: a10, a11, a20, a30, the branch, f cubic, R):
  A0 = (a00, a10, a20, a30), A1 = (2 a10 / a11, a11, 0, 0), A2 = 1,
  a00 = a10^2/a11^2 - a11^2/8 +- sqrt(a11^4 - 16 (a20^2 + a30^2)) / 8, a11^4 >= 16 (a20^2 + a30^2) > 0.
  ``class3_v_R`` and ``class3_point_form`` are the theorem's closed forms (the seed prints the prefactor of
  v_R,2 and v_R,3 garbled as "2a1,13"; it is 2 / a11^3, as the tests confirm against the generic GCD).
* class 4, Theorem 6: A0, A1, A2 = 1 linearly dependent, a11 != 0, a21^2 + a31^2 != 0; parametrized here
  as A0 = c0 + c1 A1 (then v = nu_1 v_R with nu_1 of eq. 43).
* class 5, Theorem 5: a21 = a31 = 0 (eq. 38), A0 free; v itself has degree 5 (eq. 39).
* class 6: a general quadratic A (v has relatively prime components, degree 6).
"""

from __future__ import annotations

import numpy as np

from planner.curves.rational_ph import DualFormError, RationalPH
from planner.validation import ArgumentError, as_float, as_floats

_ONE = np.array([1.0, 0.0, 0.0, 0.0])


#: Largest magnitude of a family parameter: their fourth powers must stay within the float range.
MAX_PARAMETER = 1e60


def _finite(name: str, *vals: float) -> None:
    for k, v in enumerate(vals):
        try:
            x = as_float(v, f"{name} parameter {k + 1}")
        except ArgumentError as exc:
            raise DualFormError(str(exc)) from None
        if abs(x) > MAX_PARAMETER:
            raise DualFormError(f"{name}: parameter {k + 1} = {x!r} is beyond {MAX_PARAMETER:g} (its powers overflow)")


def _quat(q, name: str) -> np.ndarray:
    try:
        a = as_floats(q, name)
    except ArgumentError as exc:
        raise DualFormError(str(exc)) from None
    if a.shape != (4,) or not np.isfinite(a).all() or np.abs(a).max() > MAX_PARAMETER:
        raise DualFormError(f"{name} must be a finite quaternion (scalar, i, j, k) of entries within "
                            f"{MAX_PARAMETER:g}, got {a.tolist() if a.size <= 8 else a.shape}")
    return a


# -- class 3 ---------------------------------------------------------------------------------------
def class3_a00(a10: float, a11: float, a20: float, a30: float, branch: int = 1) -> float:
    """a00 of Theorem 7: a10^2/a11^2 - a11^2/8 + branch sqrt(a11^4 - 16 (a20^2 + a30^2)) / 8."""
    _finite("class 3", a10, a11, a20, a30)
    if branch not in (1, -1):
        raise DualFormError(f"class 3: branch must be +1 or -1, got {branch!r}")
    s = a20**2 + a30**2
    if a11 == 0 or s == 0:
        raise DualFormError("class 3 needs a11 != 0 and a20^2 + a30^2 > 0 (Theorem 7)")
    disc = a11**4 - 16 * s
    if disc < 0:
        raise DualFormError(
            f"class 3 needs a11^4 >= 16 (a20^2 + a30^2) (Theorem 7): {a11**4:g} < {16 * s:g}"
        )
    return a10**2 / a11**2 - a11**2 / 8 + branch * np.sqrt(disc) / 8


def class3_quaternion(a10: float, a11: float, a20: float, a30: float, branch: int = 1) -> np.ndarray:
    """Power-basis coefficients (3, 4) of A for Theorem 7."""
    a00 = class3_a00(a10, a11, a20, a30, branch)
    return np.array([[a00, a10, a20, a30], [2 * a10 / a11, a11, 0.0, 0.0], _ONE])


def class3_v_R(a10: float, a11: float, a20: float, a30: float, branch: int = 1) -> np.ndarray:
    """v_R (3, 4) of Theorem 7 in closed form (v divided by the monic theta), power basis."""
    a00 = class3_a00(a10, a11, a20, a30, branch)
    s = a20**2 + a30**2
    k = 2 / a11**3
    c = (a11**4 + 5 * a00 * a11**2 - 2 * a10**2) * a11**2
    v1 = [-4 * a11 * s, 0.0, 0.0, 0.0]
    v2 = k * np.array(
        [
            c * a30 + 2 * a10 * (2 * a10**2 - 3 * a00 * a11**2) * a20,
            6 * a11**3 * (a10 * a30 - a00 * a20),
            3 * a11**4 * a30 - 6 * a10 * a11**2 * a20,
            -2 * a20 * a11**3,
        ]
    )
    v3 = -k * np.array(
        [
            c * a20 + 2 * a10 * (3 * a00 * a11**2 - 2 * a10**2) * a30,
            6 * a11**3 * (a10 * a20 + a00 * a30),
            3 * a20 * a11**4 + 6 * a10 * a30 * a11**2,
            2 * a30 * a11**3,
        ]
    )
    return np.array([v1, v2, v3])


def class3_point_form(a10: float, a11: float, a20: float, a30: float, branch: int = 1) -> np.ndarray:
    """Homogeneous form P (4, 4) of the seed after Theorem 7, for f = t^3 and R = I (up to scale)."""
    a00 = class3_a00(a10, a11, a20, a30, branch)
    s = a20**2 + a30**2
    P0 = -16 * a11**3 * s * np.array([2 * a10**2 - a00 * a11**2, 2 * a11 * a10, a11**2, 0.0])
    P1 = np.array(
        [
            0.0,
            -4 * a10**4 + (5 * a11**4 + 8 * a00 * a11**2) * a10**2 - a11**4 * (a00 * a11**2 + 5 * s),
            4 * a10 * a11**3 * (a11**2 + 2 * a00),
            8 * a10**2 * a11**2 - 4 * a00 * a11**4,
        ]
    )
    P2 = 4 * a11**3 * np.array([0.0, 2 * a11 * (a10 * a20 + a00 * a30), a20 * a11**2 + 2 * a10 * a30, 0.0])
    P3 = 4 * a11**3 * np.array([0.0, 2 * a11 * (a10 * a30 - a00 * a20), a30 * a11**2 - 2 * a10 * a20, 0.0])
    return np.array([P0, P1, P2, P3])


def class3(
    a10: float, a11: float, a20: float, a30: float, branch: int = 1, f=(0.0, 0.0, 0.0, 1.0), R=None
) -> RationalPH:
    """Class 3 rational PH curve of Theorem 7 (f of degree <= 3, default t^3)."""
    return RationalPH.from_dual(class3_quaternion(a10, a11, a20, a30, branch), f, R=R)


# -- class 4 ---------------------------------------------------------------------------------------
def class4_quaternion(A1, c0: float, c1: float) -> np.ndarray:
    """A (3, 4) of Theorem 6 with A0 = c0 + c1 A1 (A0, A1, A2 = 1 linearly dependent)."""
    A1 = _quat(A1, "A1")
    _finite("class 4", c0, c1)
    if A1[1] == 0 or A1[2] ** 2 + A1[3] ** 2 == 0:
        raise DualFormError("class 4 needs a11 != 0 and a21^2 + a31^2 != 0 (Theorem 6)")
    return np.array([c0 * _ONE + c1 * A1, A1, _ONE])


def class4(A1, c0: float, c1: float, f=(0.0, 0.0, 0.0, 1.0), R=None) -> RationalPH:
    """Class 4 rational PH curve of Theorem 6 (f of degree <= 4)."""
    return RationalPH.from_dual(class4_quaternion(A1, c0, c1), f, R=R)


# -- class 5 ---------------------------------------------------------------------------------------
def class5_quaternion(A0, a01: float, a11: float) -> np.ndarray:
    """A (3, 4) of Theorem 5: A1 = (a01, a11, 0, 0) (a21 = a31 = 0, eq. 38), A2 = 1."""
    A0 = _quat(A0, "A0")
    _finite("class 5", a01, a11)
    if A0[2] ** 2 + A0[3] ** 2 == 0:
        raise DualFormError("class 5 needs a20^2 + a30^2 > 0 (else v_R degenerates, eq. 39)")
    return np.array([A0, [a01, a11, 0.0, 0.0], _ONE])


def class5(A0, a01: float, a11: float, f=(0.0, 0.0, 0.0, 1.0), R=None) -> RationalPH:
    """Class 5 rational PH curve of Theorem 5 (f of degree <= 5)."""
    return RationalPH.from_dual(class5_quaternion(A0, a01, a11), f, R=R)


# -- class 6 ---------------------------------------------------------------------------------------
def class6(A0, A1, A2=(1.0, 0.0, 0.0, 0.0), f=(1.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0), R=None) -> RationalPH:
    """Class 6 rational PH curve from a general quadratic A (v_R = v; f of degree <= 6)."""
    A = np.array([_quat(A0, "A0"), _quat(A1, "A1"), _quat(A2, "A2")])
    return RationalPH.from_dual(A, f, R=R)


__all__ = [
    "class3",
    "class3_a00",
    "class3_point_form",
    "class3_quaternion",
    "class3_v_R",
    "class4",
    "class4_quaternion",
    "class5",
    "class5_quaternion",
    "class6",
]
