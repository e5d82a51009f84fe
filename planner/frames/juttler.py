"""Rotation-minimizing motion (RMM) of a spherical circular arc, exact and rational (Jüttler 1998).

Seed: ``juttler-rotation-minimizing-spherical-motions.md``. A spherical motion U(t) with U(t) e3 = c(t)
is rotation minimizing iff its angular velocity is c x c' (Prop. 1, eq. 5). For the standard arc
c(t) = (sin psi cos t phi, sin psi sin t phi, cos psi) (eq. 9) the RMM is Q = Q1 * Q2 (eq. 10): Q1 turns
about e3 by t phi after tilting by psi about e2, Q2 spins back about the moving axis by t phi cos psi + rho.
Its rational approximation is R = R1 * R2 (eqs. 13-15): R1 is linear (a rational quadratic
reparameterization of Q1, exact), R2 is quadratic and matches Q2 in position and in angular velocity
at both ends, so R is a rational motion of degree 6 that is exactly rotation minimizing at t = 0, 1.

Conventions
-----------
Quaternions are arrays (..., 4) laid out (scalar, i, j, k); ``U p = Q p Q*``. A motion's frame is
``frames(t) = U(t) P``: U(t) carries the moving axis in its third column (seed eq. 1) and the cyclic
permutation P moves it to column ``axis_column`` (2 for tool frames, 0 for path frames whose first
column is the unit tangent). Arcs in general position are handled by a constant left factor
``left`` (the rotation G taking the standard arc (9) to the given one) and P by a right factor
``right``: the quaternion of the frame is ``left * Q(t) * right``.

Parameterizations: ``exact_arc_motion`` uses the uniform angle t phi of eq. (9) unless weights are
given; with weights (w0, w1) it uses the rational parameterization of R1 (eqs. 13, 16), so that the
exact and the rational motion move the axis through the same point at every t and can be compared
frame by frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from planner import bernstein
from planner import quaternion as quat
from planner.frames import validation as val
from planner.frames.validation import FrameDataError
from planner.rotations import matrix_to_quaternion, quaternion_to_matrix
from planner.validation import finite_floats

_ONE = np.array([1.0, 0.0, 0.0, 0.0])


# --------------------------------------------------------------------------------------------------
# Closed forms in standard position
# --------------------------------------------------------------------------------------------------
def arc_q1(alpha: np.ndarray | float, psi: np.ndarray | float) -> np.ndarray:
    """Q1 of seed eq. (10) with t phi replaced by the turned angle alpha, shape (..., 4)."""
    ca, sa = np.cos(alpha / 2), np.sin(alpha / 2)
    cp, sp = np.cos(psi / 2), np.sin(psi / 2)
    return np.stack((ca * cp, -sa * sp, ca * sp, cp * sa), axis=-1)  # seed eq. (10)


def _q2(alpha: np.ndarray, psi: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Q2 of seed eq. (10): the spin back about the moving axis by alpha cos psi + rho, shape (..., 4)."""
    h = (alpha * np.cos(psi) + rho) / 2
    z = np.zeros_like(h)
    return np.stack((np.cos(h), z, z, -np.sin(h)), axis=-1)  # seed eq. (10)


def _rz(angle) -> np.ndarray:
    """Quaternions (..., 4) of the rotations about e3 by ``angle`` (...)."""
    h = np.asarray(angle, dtype=float) / 2
    z = np.zeros_like(h)
    return np.stack((np.cos(h), z, z, np.sin(h)), axis=-1)


def _turned_angle(t, phi, w0, w1, uniform):
    """Angle alpha(t) turned along the arc and its rate alpha'(t), each shape (n,).

    Uniform: alpha = t phi (eq. 9). Weighted: alpha = 2 arg S(t) with the complex-like linear
    S = (1 - t) w0 + t w1 exp(k phi / 2) of R1 (eq. 13); alpha' = 2 w0 w1 sin(phi/2) / |S|^2.
    """
    x = (1 - t) * w0 + t * w1 * np.cos(phi / 2)
    y = t * w1 * np.sin(phi / 2)
    alpha_w = 2 * np.arctan2(y, x)  # seed eq. (13): R1 is a reparameterized Q1
    rate_w = 2 * w0 * w1 * np.sin(phi / 2) / (x * x + y * y)
    alpha = np.where(uniform, t * phi, alpha_w)
    rate = np.where(uniform, phi * np.ones_like(t), rate_w)
    return alpha, rate


#: Choices of the free parameter of R2 (seed sec. 6, after property 3); see ``rational_coefficients``.
R2_WEIGHTS = ("paper", "reparameterized")


def rational_coefficients(phi, psi, w0=1.0, w1=1.0, rho=0.0,
                          r2_weights: str = "paper") -> tuple[np.ndarray, np.ndarray]:
    """Bernstein coefficients of R1 (..., 2, 4) and R2 (..., 3, 4) of seed eqs. (13)-(15) for any rho.

    Arguments broadcast (scalars or arrays of arcs). Eq. (15) holds for rho = 0; for rho != 0 all
    three coefficients of R2 are multiplied by (cos rho/2, 0, 0, -sin rho/2) (seed footnote 2). The
    middle coefficient is written with sinc so that it stays finite on great circles (cos psi = 0) and
    for phi -> 0: (1/2) sin(phi/2) cos psi / sin(theta/2) = (sin(phi/2)/phi) / sinc(theta/2),
    theta = phi cos psi.

    R2 has one free parameter once the end angular velocities are fixed: the ratio |R2(1)|/|R2(0)|.

    - ``"paper"``: the seed's heuristic |R2(0)| = w0, |R2(1)| = w1, i.e. eq. (15) as printed.
    - ``"reparameterized"``: |R2(0)| = w0^2, |R2(1)| = w1^2 and middle coefficient w0 w1 times that
      of eq. (15) with unit weights. R1 with weights (w0, w1) is R1 with unit weights under the Möbius
      reparameterization s = t w1 / ((1 - t) w0 + t w1); this choice applies the same
      reparameterization to R2, so R is the unit-weight motion reparameterized, and its twist against
      the exact RMM does not depend on the weights. The paper's choice twists more when w0 != w1
      (e.g. 0.036 deg instead of 0.013 deg for phi = 96.6 deg, psi = 67.8 deg, w1/w0 = 1.06; 0.33 deg
      for w1/w0 = 2). Both coincide for w0 = w1.
    """
    if r2_weights not in R2_WEIGHTS:
        raise FrameDataError(f"must be one of {R2_WEIGHTS}, got {r2_weights!r}", "r2_weights")
    args = (val._floats(v, name) for v, name in ((phi, "phi"), (psi, "psi"), (w0, "w0"), (w1, "w1"), (rho, "rho")))
    phi, psi, w0, w1, rho = np.broadcast_arrays(*args)
    theta = phi * np.cos(psi)
    zero = np.zeros_like(phi)
    r1 = np.stack((w0[..., None] * arc_q1(zero, psi), w1[..., None] * arc_q1(phi, psi)), axis=-2)  # seed eq. (13)
    ratio = 0.5 * np.sinc(phi / (2 * np.pi)) / np.sinc(theta / (2 * np.pi))
    if r2_weights == "paper":
        v0, v1, v01 = w0, w1, 1.0
    else:  # the unit-weight R2 under the Moebius reparameterization of R1
        v0, v1, v01 = w0 * w0, w1 * w1, w0 * w1
        w0, w1 = np.ones_like(w0), np.ones_like(w1)
    b20 = np.stack((v0, zero, zero, zero), axis=-1)  # seed eq. (15)
    b21 = np.asarray(v01)[..., None] * np.stack((ratio * (w0 + w1 * np.cos(theta / 2)), zero, zero,  # seed eq. (15)
                          -0.5 * np.sin(phi / 2) * np.cos(psi) * w1), axis=-1)
    b22 = v1[..., None] * np.stack((np.cos(theta / 2), zero, zero, -np.sin(theta / 2)), axis=-1)  # eq. (15)
    r2 = np.stack((b20, b21, b22), axis=-2)
    r2 = quat.mul(r2, _rz(-rho)[..., None, :])  # seed footnote 2
    return r1, r2


def place_arcs(start: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Angular radii psi (m,) and left factors (m, 4) taking the standard arc (eq. 9) to given arcs.

    The left factor is the rotation G = [ex, u x ex, u] with G e3 = u and
    G (sin psi, 0, cos psi) = start, where ex is the unit component of start normal to u (any unit
    normal of u when the arc is the point u itself).
    """
    a = np.asarray(start, dtype=float)
    u = np.asarray(axis, dtype=float)
    cos_psi = np.einsum("ij,ij->i", u, a)
    psi = np.arctan2(np.linalg.norm(np.cross(u, a), axis=1), cos_psi)
    ex = a - cos_psi[:, None] * u
    nx = np.linalg.norm(ex, axis=1)
    other = np.where((np.abs(u[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    ex = np.where((nx < 1e-12)[:, None], np.cross(u, other), ex)
    ex /= np.linalg.norm(ex, axis=1, keepdims=True)
    g = np.stack((ex, np.cross(u, ex), u), axis=-1)
    return psi, matrix_to_quaternion(g)


def arc_transport(phi: np.ndarray, psi: np.ndarray, left: np.ndarray) -> np.ndarray:
    """Quaternions T (m, 4) of the exact RMM from the start to the end of each arc: f_end = T f_start.

    T = Q(phi) Q(0)* for Q = left Q1 Q2 (eq. 10); it does not depend on rho nor on the right factor,
    and its sign follows the continuous quaternion path of the motion.
    """
    zero = np.zeros_like(phi)
    q_end = quat.mul(left, quat.mul(arc_q1(phi, psi), _q2(phi, psi, zero)))
    q_start = quat.mul(left, arc_q1(zero, psi))
    return quat.mul(q_end, quat.conj(q_start))


def spin_for_start(f0: np.ndarray, psi: np.ndarray | float, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Initial spins rho (m,) with left Q1(0) Q2(0; rho) right = f0 (m, 4), sign included (eq. 10).

    f0 must be the quaternion of a frame whose axis column is the arc's start point; then
    Q1(0)* left* f0 right* = (cos rho/2, 0, 0, -sin rho/2).
    """
    zero = np.zeros_like(psi)
    m = quat.mul(quat.mul(quat.conj(arc_q1(zero, psi)), quat.mul(quat.conj(left), f0)), quat.conj(right))
    return -2.0 * np.arctan2(m[..., 3], m[..., 0])


# --------------------------------------------------------------------------------------------------
# Motions
# --------------------------------------------------------------------------------------------------
class ArcMotion:
    """What the exact and the rational RMM of an arc share: the frames, the angular velocity, the axis and the
    arc angle, all from the kind's evaluation rule ``_eval`` (vectorized over arcs: :class:`PiecewiseArcMotion`
    uses the same rule) applied to a stack of one arc.

    Subclasses hold ``phi, psi, rho, w0, w1, left, right, axis_column`` and ``uniform`` (the axis turns by
    t phi, eq. 9, rather than by the angle of R1, eq. 13), and give ``_stack(segments)`` (the arrays of
    their arcs) and ``_eval(stack, idx, t)`` (quaternions (n, 4) and angular velocities (n, 3) of arcs
    ``idx`` at t).
    """

    phi: float
    psi: float
    rho: float
    w0: float
    w1: float
    uniform: bool = False
    axis_column: int

    @staticmethod
    def _stack(segments) -> dict:
        raise NotImplementedError

    @staticmethod
    def _eval(st: dict, idx: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _at(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Quaternions (n, 4) and angular velocities (n, 3) at t (n,)."""
        t = np.atleast_1d(finite_floats(t, "t"))
        return self._eval(self._stack((self,)), np.zeros(t.shape, int), t)

    def quaternion(self, t) -> np.ndarray:
        """Quaternions (n, 4) of the frames at t (n,), signs continuous in t."""
        return self._at(t)[0]

    def frames(self, t) -> np.ndarray:
        """Frames (n, 3, 3) at t (n,); column ``axis_column`` is the moving axis."""
        return quaternion_to_matrix(self.quaternion(t))

    def angular_velocity(self, t) -> np.ndarray:
        """Angular velocity (n, 3) (rad per unit t) at t (n,): c x c' of the axis c (seed eqs. 5, 7, 11)."""
        return self._at(t)[1]

    def axis(self, t) -> np.ndarray:
        """The moving axis c(t) (n, 3), a point of the arc."""
        return self.frames(t)[:, :, self.axis_column]

    def arc_angle(self, t) -> np.ndarray:
        """Angle alpha(t) (n,) turned along the arc at t (rad): t phi (eq. 9) or the argument of R1 (eq. 13)."""
        t = np.atleast_1d(finite_floats(t, "t"))
        return _turned_angle(t, self.phi, self.w0, self.w1, self.uniform)[0]


@dataclass(frozen=True, eq=False)
class ExactArcMotion(ArcMotion):
    """The exact RMM of a circular arc on the unit sphere (seed eqs. 10, 11), in general position.

    Attributes
    ----------
    phi, psi, rho : float
        Arc angle, angular radius and initial spin (rad), seed eqs. (9), (10).
    w0, w1 : float
        Weights of the rational parameterization (used when ``uniform`` is False).
    uniform : bool
        True: the axis turns by t phi (eq. 9); False: by the angle of R1 (eq. 13, same as
        :class:`RationalArcMotion` with these weights).
    left, right : ndarray (4,)
        Constant unit quaternions: frame quaternion = left * Q1 * Q2 * right.
    axis_column : int
        Column of ``frames(t)`` that holds the moving axis.
    """

    phi: float
    psi: float
    rho: float = 0.0
    w0: float = 1.0
    w1: float = 1.0
    uniform: bool = True
    left: np.ndarray = field(default_factory=lambda: _ONE.copy())
    right: np.ndarray = field(default_factory=lambda: _ONE.copy())
    axis_column: int = 2

    @staticmethod
    def _stack(segments) -> dict:
        def arr(name):
            return np.array([getattr(s, name) for s in segments], dtype=float)

        return {name: arr(name) for name in ("phi", "psi", "rho", "w0", "w1", "uniform", "left", "right")}

    @staticmethod
    def _eval(st: dict, idx: np.ndarray, t: np.ndarray):
        """Quaternions (n, 4) and angular velocities (n, 3) (rad per unit t) of segments idx at t."""
        phi, psi, rho = st["phi"][idx], st["psi"][idx], st["rho"][idx]
        alpha, rate = _turned_angle(t, phi, st["w0"][idx], st["w1"][idx], st["uniform"][idx] > 0)
        left = st["left"][idx]
        q = quat.mul(quat.mul(left, quat.mul(arc_q1(alpha, psi), _q2(alpha, psi, rho))), st["right"][idx])
        sp, cp = np.sin(psi), np.cos(psi)
        # seed eq. (11) with phi -> alpha': omega = alpha' (e3 - cos psi c), c = Q1 e3 Q1*
        w_std = rate[:, None] * np.stack((-np.cos(alpha) * sp * cp, -np.sin(alpha) * sp * cp, sp * sp), -1)
        omega = np.einsum("nij,nj->ni", quaternion_to_matrix(left), w_std)
        return q, omega


@dataclass(frozen=True, eq=False)
class RationalArcMotion(ArcMotion):
    """Jüttler's rational RMM of a circular arc: R(t) = left * R1(t) * R2(t) * right (eqs. 13-15).

    R is a cubic quaternion polynomial (a rational motion of degree 6). Its axis moves exactly on the
    arc (with the rational parameterization of eq. 16) and R(0) = w0^2 Q(0), R(1) = w1^2 Q(1) (eq. 18).

    Attributes
    ----------
    phi, psi, w0, w1, rho : float
        Arc angle, angular radius (rad), weights and initial spin (rad), seed eqs. (9)-(15).
    left, right : ndarray (4,)
        Constant unit quaternions placing the standard arc (see module docstring).
    axis_column : int
        Column of ``frames(t)`` that holds the moving axis.
    r1 : ndarray (2, 4)
        Bernstein coefficients of R1 (eq. 13), standard position.
    r2 : ndarray (3, 4)
        Bernstein coefficients of R2 (eqs. 14, 15, footnote 2), standard position.
    coeffs : ndarray (4, 4)
        Bernstein coefficients of R(t) = left * R1 * R2 * right (degree 3).
    r2_weights : str
        Choice of the free parameter of R2, see :func:`rational_coefficients`.
    """

    phi: float
    psi: float
    w0: float
    w1: float
    rho: float
    left: np.ndarray
    right: np.ndarray
    axis_column: int
    r1: np.ndarray
    r2: np.ndarray
    coeffs: np.ndarray
    r2_weights: str = "paper"

    @staticmethod
    def _stack(segments) -> dict:
        c = np.array([s.coeffs for s in segments])
        return {"c": c, "dc": 3.0 * np.diff(c, axis=1)}

    @staticmethod
    def _eval(st: dict, idx: np.ndarray, t: np.ndarray):
        """Polynomial quaternions R (n, 4) and angular velocities (n, 3) of segments idx at t."""
        r = np.einsum("nk,nkc->nc", bernstein.basis(3, t), st["c"][idx])
        dr = np.einsum("nk,nkc->nc", bernstein.basis(2, t), st["dc"][idx])
        omega = 2.0 * quat.mul(dr, quat.conj(r))[:, 1:] / quat.norm2(r)[:, None]  # seed eq. (7), R not unit
        return r, omega

    def quaternion(self, t) -> np.ndarray:
        """The polynomial quaternion R(t) (n, 4) (not normalized; |R(0)| = w0^2, |R(1)| = w1^2)."""
        return bernstein.evaluate(self.coeffs, np.atleast_1d(finite_floats(t, "t")))

    def exact(self) -> ExactArcMotion:
        """The exact RMM of the same arc, same start frame and same parameterization of the axis."""
        return ExactArcMotion(self.phi, self.psi, self.rho, self.w0, self.w1, False,
                              self.left, self.right, self.axis_column)


def _check_arc(phi, psi, w0, w1, rho) -> tuple[float, float, float, float, float]:
    phi = val.finite_scalar(phi, "phi")
    if abs(phi) >= 2 * np.pi:
        raise FrameDataError(f"arc angle must satisfy |phi| < 2 pi, got {phi!r}", "phi")
    psi = val.finite_scalar(psi, "psi")
    if not 0.0 <= psi <= np.pi:
        raise FrameDataError(f"angular radius must lie in [0, pi], got {psi!r}", "psi")
    w0, w1 = val.positive_scalar(w0, "w0"), val.positive_scalar(w1, "w1")
    return phi, psi, w0, w1, val.finite_scalar(rho, "rho")


def _rational(phi, psi, w0, w1, rho, left=_ONE, right=_ONE, axis_column=2,
              r2_weights="paper") -> RationalArcMotion:
    r1, r2 = rational_coefficients(phi, psi, w0, w1, rho, r2_weights)
    coeffs = quat.mul(quat.mul(left, bernstein.quaternion_product(r1, r2)), right)  # R = R1 * R2 (seed sec. 6)
    return RationalArcMotion(phi, psi, w0, w1, rho, np.array(left, float), np.array(right, float),
                             axis_column, r1, r2, coeffs, r2_weights)


def rmm_arc(phi: float, psi: float, w0: float = 1.0, w1: float = 1.0, rho: float = 0.0,
            r2_weights: str = "paper") -> RationalArcMotion:
    """Jüttler's rational RMM R(t) = R1(t) * R2(t) of the standard arc (seed eqs. 9, 13-15).

    Parameters
    ----------
    phi : float
        Arc angle (rad), |phi| < 2 pi.
    psi : float
        Angular radius of the arc (rad) in [0, pi] (the arc runs on the parallel of latitude pi/2 - psi).
    w0, w1 : float
        Positive weights of R1 (eq. 13); they fix the parameterization of the axis (eqs. 16, 17) and
        the free parameter of R2 (|R2(0)| = w0, |R2(1)| = w1, the seed's heuristic).
    rho : float
        Initial spin about the axis (rad), eq. (10) and footnote 2.
    r2_weights : str
        ``"paper"`` (eq. 15 as printed) or ``"reparameterized"`` (same motion as unit weights, less
        twist when w0 != w1); see :func:`rational_coefficients`.

    Returns
    -------
    RationalArcMotion
        With frames(t) = U(t) (column 2 is the moving axis c(t)); ``.exact()`` gives the exact RMM
        with the same parameterization of the axis.
    """
    return _rational(*_check_arc(phi, psi, w0, w1, rho), r2_weights=r2_weights)


def exact_arc_motion(phi: float, psi: float, rho: float = 0.0, w0: float | None = None,
                     w1: float | None = None) -> ExactArcMotion:
    """The exact RMM Q(t) = Q1(t) * Q2(t) of the standard arc (seed eq. 10).

    Without weights the axis turns uniformly (angle t phi, eq. 9); with weights (w0, w1) it follows the
    parameterization of ``rmm_arc(phi, psi, w0, w1, rho)``, for frame-by-frame comparison.
    Frames: column 2 is the moving axis.
    """
    uniform = w0 is None and w1 is None
    phi, psi, w0, w1, rho = _check_arc(phi, psi, 1.0 if w0 is None else w0, 1.0 if w1 is None else w1, rho)
    return ExactArcMotion(phi, psi, rho, w0, w1, uniform)


def arc_motion(start, axis, angle, *, start_frame=None, axis_column: int = 2, w0: float = 1.0,
               w1: float = 1.0, sign_reference=None, r2_weights: str = "paper") -> RationalArcMotion:
    """Jüttler's rational RMM of an arc in general position on the unit sphere.

    Parameters
    ----------
    start : array (3,)
        Unit start point a of the arc.
    axis : array (3,)
        Unit axis u; the arc is a turned counter-clockwise about u by alpha in [0, angle].
    angle : float
        Arc angle phi (rad), |phi| < 2 pi.
    start_frame : array (3, 3), optional
        Frame at t = 0, right-handed orthonormal with column ``axis_column`` equal to ``start``.
        Default: rho = 0 in the standard coordinates of the arc.
    axis_column : int
        Column of the frames holding the moving axis (0 for path frames, 2 for tool frames).
    w0, w1 : float
        Weights of R1 (eq. 13).
    sign_reference : array (4,), optional
        The quaternion R(0) is given the sign of positive inner product with this one (continuity of
        quaternion signs along a chain of arcs).
    r2_weights : str
        Free parameter of R2, see :func:`rational_coefficients`.

    Returns
    -------
    RationalArcMotion
    """
    start, axis = (val.vector3(v, name) for v, name in ((start, "start"), (axis, "axis")))
    a = val.unit_vectors(np.reshape(start, (1, 3)), "start")[0]
    u = val.unit_vectors(np.reshape(axis, (1, 3)), "axis")[0]
    phi = val.finite_scalar(angle, "angle")
    right = matrix_to_quaternion(val.cyclic_permutation(axis_column))
    psis, lefts = place_arcs(a[None], u[None])
    psi, left = float(psis[0]), lefts[0]
    if start_frame is None:
        f0 = quat.mul(quat.mul(left, arc_q1(np.float64(0.0), np.float64(psi))), right)
    else:
        f0 = matrix_to_quaternion(val.frame(start_frame, "start_frame", a, axis_column))
    if sign_reference is not None and quat.dot(f0, sign_reference) < 0:
        f0 = -f0
    rho = float(spin_for_start(f0, np.float64(psi), left, right))
    phi, psi, w0, w1, rho = _check_arc(phi, psi, w0, w1, rho)
    return _rational(phi, psi, w0, w1, rho, left, right, axis_column, r2_weights)
