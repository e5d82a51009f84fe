"""GRM frames: rational approximately rotation-minimizing frames of PH quintics (Peng, Pang, Pan 2023).

The ER frame (e1, e2, e3) turned by psi_R(t) = 2 atan2(a(t), b(t)) with polynomials a, b of degree 4,

    u = ((b^2 - a^2) e2 + 2 a b e3) / (a^2 + b^2),   v = (-2 a b e2 + (b^2 - a^2) e3) / (a^2 + b^2)   (eq. 11)

is rational. It is rotation-minimizing iff psi_R' = -e2'.e3, i.e. 2 (a' b - a b') / (a^2 + b^2) = -g / sigma^2
with g = (d/dt A j A*) . (A k A*) (eqs. 6, 12). GRM keeps the numerator exact,

    a b' - a' b = g                                                                          (eq. 24)

(g has degree 6, so 7 independent equations: DESIGN.md), and makes a^2 + b^2 close to 2 sigma^2 (the
objective of eq. 13, with a weight rho). Of the 10 coefficients, 7 go to eq. (24) and 1 to the rotation
(a, b) -> (a cos c - b sin c, a sin c + b cos c) that leaves (24) unchanged and only shifts the start
angle: fixing a(0) = 0 leaves a 2-dimensional constraint set to search.

Weights: "1", "sigma", "tau_kappa" (|tau kappa|, the paper's three), a callable rho(t), and "twist" (the
default, ours): minimize the mean square angle between the GRM frame and the exact RMF from the same
start frame, which is what users of the frame feel; eq. (13) with rho = 1 can twist the tool by tens of
degrees more (DESIGN.md). Every result reports the real figure, ``max_twist_deg``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from planner import bernstein
from planner import quaternion as qt
from planner.errors import PlannerError
from planner.frames.er import er_frames
from planner.frames.rmf import RMFAngle, check_start_frame, normal_angle, turn_normals

#: Collocation nodes for the 7 equations of (24): Chebyshev points of [0, 1].
_COLLOC = 0.5 - 0.5 * np.cos((2 * np.arange(7) + 1) * np.pi / 14)
#: Quadrature for the objectives: 24-point Gauss-Legendre on [0, 1] (exact for eq. 13 with rho = 1, sigma).
_QX, _QW = np.polynomial.legendre.leggauss(24)
_QX, _QW = 0.5 * (_QX + 1.0), 0.5 * _QW
#: Twist objective: angle error at the ends of 48 panels, each integrated with 4-point Gauss-Legendre.
_TP = 48
_TX, _TW = np.polynomial.legendre.leggauss(4)
_TNODES = (np.arange(_TP)[:, None] + 0.5 * (_TX + 1.0)) / _TP
_TW = 0.5 * _TW / _TP

WEIGHTS = ("twist", "1", "sigma", "tau_kappa")


def g_poly_values(A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """g(t) = (d/dt A j A*) . (A k A*), the right-hand side of eq. (24), at parameters t (n,).

    Computed as 2 |A|^2 (A* A')_i: the ER frame's body angular velocity about e1 times sigma^2.
    """
    Av = bernstein.evaluate(A, t)
    dA = bernstein.evaluate(bernstein.derivative(A), t)
    q = Av[:, 0] * dA[:, 1] - Av[:, 1] * dA[:, 0] - Av[:, 2] * dA[:, 3] + Av[:, 3] * dA[:, 2]
    return 2.0 * qt.norm2(Av) * q


def sigma_values(A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """sigma(t) = |A(t)|^2 at parameters t (n,)."""
    return qt.norm2(bernstein.evaluate(A, t))


def _weight_values(weight, curve, t: np.ndarray) -> np.ndarray:
    if callable(weight):
        w = np.asarray(weight(t), dtype=float)
        if w.shape != t.shape or not np.isfinite(w).all() or (w < 0).any():
            raise PlannerError("weight callable must return finite non-negative values of the shape of t")
        return w
    if weight == "1":
        return np.ones_like(t)
    if weight == "sigma":
        return sigma_values(curve.A, t)
    if weight == "tau_kappa":
        return np.abs(curve.torsion(t) * curve.curvature(t))
    raise PlannerError(f"weight must be one of {WEIGHTS} or a callable rho(t), got {weight!r}")


@dataclass(frozen=True, eq=False)
class GRMFrame:
    """A GRM frame of one PH quintic.

    Attributes
    ----------
    curve : PHQuintic
    a, b : ndarray (5,)
        Bernstein coefficients of the degree-4 polynomials of eqs. (10)-(11).
    weight : str or callable
        The objective the pair minimizes.
    objective : float
        Value of eq. (13) with the weight (for ``"twist"``: the mean square twist angle, rad^2).
    constraint_residual : float
        max over [0, 1] of |a b' - a' b - g| / max |g| (eq. 24; round-off for a converged solve).
    max_twist_deg : float
        Largest angle (deg) between this frame's normal-plane vectors and the exact RMF's from the
        same start frame, over 2001 parameters.
    start_angle : float
        Angle (rad) of the frame's column 1 against the ER frame's at t = 0.
    """

    curve: object
    a: np.ndarray
    b: np.ndarray
    weight: object
    objective: float
    constraint_residual: float
    max_twist_deg: float
    start_angle: float = 0.0

    def angle(self, t) -> np.ndarray:
        """psi_R(t) - psi_R(0) + start_angle (rad), modulo 2 pi: the frame's angle against the ER frame."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        ang = 2.0 * np.arctan2(bernstein.evaluate(self.a, t), bernstein.evaluate(self.b, t))
        return self.start_angle + ang - 2.0 * np.arctan2(self.a[0], self.b[0])

    def frames(self, t) -> np.ndarray:
        """GRM frames (n, 3, 3) at parameters t (n,): the rational rotation of eq. (11), normalized."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return turn_normals(er_frames(self.curve, t), self.angle(t))

    def with_start(self, start) -> GRMFrame:
        """The same GRM motion started from a given frame (3, 3) at t = 0 (column 0 the tangent)."""
        er0 = er_frames(self.curve, [0.0])[0]
        F = check_start_frame(start, er0[:, 0])
        return GRMFrame(self.curve, self.a, self.b, self.weight, self.objective, self.constraint_residual,
                        self.max_twist_deg, normal_angle(F, er0))


class _Problem:
    """Constraint (24) and objectives for one curve; unknowns x = (a1..a4, b0..b4) with a0 = 0."""

    def __init__(self, curve, weight):
        A = curve.A
        self.curve = curve
        self.B7, self.dB7 = bernstein.basis(4, _COLLOC), 4 * _diff_basis(_COLLOC)
        self.g7 = g_poly_values(A, _COLLOC)
        self.gscale = max(np.abs(g_poly_values(A, np.linspace(0, 1, 201))).max(), 1e-300)
        self.weight = weight
        if weight == "twist":
            t = _TNODES.ravel()
            self.Bt, self.g_t, self.s2_t = bernstein.basis(4, t), g_poly_values(A, t), sigma_values(A, t) ** 2
        else:
            self.Bq = bernstein.basis(4, _QX)
            self.s2q = 2.0 * sigma_values(A, _QX) ** 2
            self.rho = _weight_values(weight, curve, _QX) * _QW

    @staticmethod
    def split(x):
        return np.concatenate(([0.0], x[:4])), x[4:]

    def constraint(self, x):
        a, b = self.split(x)
        return (self.B7 @ a * (self.dB7 @ b) - (self.dB7 @ a) * (self.B7 @ b) - self.g7) / self.gscale

    def constraint_jac(self, x):
        a, b = self.split(x)
        av, bv, dav, dbv = self.B7 @ a, self.B7 @ b, self.dB7 @ a, self.dB7 @ b
        ja = self.B7 * dbv[:, None] - self.dB7 * bv[:, None]
        jb = av[:, None] * self.dB7 - dav[:, None] * self.B7
        return np.hstack((ja[:, 1:], jb)) / self.gscale

    def residuals(self, x):
        """The objective as a sum of squares: residual vector R (m,) and its Jacobian (m, 9)."""
        a, b = self.split(x)
        if self.weight == "twist":
            B = self.Bt
            av, bv = B @ a, B @ b
            r2 = av * av + bv * bv
            rate = self.g_t * (1.0 / self.s2_t - 2.0 / r2)  # d/dt (psi - psi_R) at the nodes
            drate = self.g_t * 4.0 / (r2 * r2)  # d rate / d(a^2 + b^2), times 2 for d/da = 2 a
            R = np.cumsum(rate.reshape(_TP, 4) @ _TW) / np.sqrt(_TP)
            Ja = np.cumsum(np.einsum("pk,k,pkj->pj", (drate * av).reshape(_TP, 4), _TW,
                                     B.reshape(_TP, 4, 5)), axis=0)
            Jb = np.cumsum(np.einsum("pk,k,pkj->pj", (drate * bv).reshape(_TP, 4), _TW,
                                     B.reshape(_TP, 4, 5)), axis=0)
            return R, np.hstack((Ja[:, 1:], Jb)) / np.sqrt(_TP)
        B = self.Bq
        av, bv = B @ a, B @ b
        sw = np.sqrt(self.rho)
        R = sw * (av * av + bv * bv - self.s2q)
        return R, np.hstack(((2 * sw * av)[:, None] * B[:, 1:], (2 * sw * bv)[:, None] * B))

    def objective(self, x):
        R, _ = self.residuals(x)
        return float(R @ R)


def _diff_basis(t):
    """d/dt of the degree-4 Bernstein basis divided by 4: B_{3,k-1} - B_{3,k}, shape (n, 5)."""
    b3 = bernstein.basis(3, t)
    out = np.zeros((t.size, 5))
    out[:, 1:] += b3
    out[:, :-1] -= b3
    return out


def _ideal_start(curve) -> np.ndarray:
    """Least-squares degree-4 fit of a = sqrt2 sigma sin(psi/2), b = sqrt2 sigma cos(psi/2) (exact RMF)."""
    t = np.linspace(0.0, 1.0, 41)
    psi = RMFAngle.of(curve.A)(t)
    s = np.sqrt(2.0) * sigma_values(curve.A, t)
    B = bernstein.basis(4, t)
    B0 = B[:, 1:]  # a0 = 0
    a = np.linalg.lstsq(B0, s * np.sin(0.5 * psi), rcond=None)[0]
    b = np.linalg.lstsq(B, s * np.cos(0.5 * psi), rcond=None)[0]
    return np.concatenate((a, b))


def _project(p: _Problem, x: np.ndarray, iters: int = 30) -> np.ndarray:
    """Minimum-norm Newton projection onto the constraint set (24), to round-off."""
    for _ in range(iters):
        c = p.constraint(x)
        if np.abs(c).max() < 1e-15:
            break
        x = x - np.linalg.lstsq(p.constraint_jac(x), c, rcond=None)[0]
    return x


def _solve(p: _Problem, x: np.ndarray, iters: int = 60) -> np.ndarray:
    """Constrained Gauss-Newton: min |R(x)|^2 subject to (24), from a feasible x.

    Each step solves the linearized KKT system [[J'J + mu I, C'], [C, 0]] of the residual Jacobian J
    and the constraint Jacobian C; steps that do not lower the objective are damped.
    """
    n = x.size
    f = p.objective(x)
    mu = 1e-12
    for _ in range(iters):
        R, J = p.residuals(x)
        c, C = p.constraint(x), p.constraint_jac(x)
        H = J.T @ J
        K = np.block([[H + mu * np.trace(H) / n * np.eye(n), C.T], [C, np.zeros((C.shape[0], C.shape[0]))]])
        step = np.linalg.lstsq(K, -np.concatenate((J.T @ R, c)), rcond=None)[0][:n]
        xn = _project(p, x + step, 8)
        fn = p.objective(xn)
        stalled = np.abs(step).max() <= 1e-9 * np.abs(x).max()
        if fn <= f:
            stalled |= f - fn <= 1e-10 * f
            x, f = xn, fn
            mu = max(mu / 10, 1e-12)
        else:
            mu *= 100
        if stalled or mu > 1e6:
            break
    return x


def _twist_deg(curve, a, b) -> float:
    t = np.linspace(0.0, 1.0, 2001)
    exact = RMFAngle.of(curve.A).on_grid(t)
    ang = np.unwrap(2.0 * np.arctan2(bernstein.evaluate(a, t), bernstein.evaluate(b, t)))
    d = (ang - ang[0]) - exact
    return float(np.degrees(np.abs(np.angle(np.exp(1j * d))).max()))


def constraint_residual(curve, a, b) -> float:
    """max over [0, 1] of |a b' - a' b - g| / max |g| for Bernstein coefficients a, b (5,) (eq. 24)."""
    t = np.linspace(0.0, 1.0, 1001)
    av, bv = bernstein.evaluate(a, t), bernstein.evaluate(b, t)
    dav, dbv = bernstein.evaluate(bernstein.derivative(a), t), bernstein.evaluate(bernstein.derivative(b), t)
    g = g_poly_values(curve.A, t)
    return float(np.abs(av * dbv - dav * bv - g).max() / np.abs(g).max())


#: Deterministic perturbations of the start (relative amplitude) for the global search.
_PERTURB = np.random.default_rng(20231105).uniform(-1.0, 1.0, size=(6, 9))


def grm(curve, weight: str | Callable = "twist", *, starts: int = 4) -> GRMFrame:
    """The GRM frame of a PH quintic (``PHQuintic``), starting at its ER frame at t = 0.

    Parameters
    ----------
    curve : PHQuintic
    weight : "twist" (default), "1", "sigma", "tau_kappa" or callable rho(t) -> (n,)
        What a^2 + b^2 ~ 2 sigma^2 is optimized for: "twist" minimizes the mean square angle to the
        exact RMF; the others are the paper's eq. (13) with that weight rho.
    starts : int
        Local solves from the exact-RMF least-squares start and ``starts - 1`` deterministic
        perturbations of it (the constraint set has several branches); the best feasible one wins.

    Returns
    -------
    GRMFrame
        Use ``.with_start(F0)`` to start from another frame.
    """
    if getattr(curve, "A", None) is None or np.shape(curve.A) != (3, 4):
        raise PlannerError("grm needs a PH quintic (quaternion coefficients A of shape (3, 4))")
    if not callable(weight) and weight not in WEIGHTS:
        raise PlannerError(f"weight must be one of {WEIGHTS} or a callable rho(t), got {weight!r}")
    p = _Problem(curve, weight)
    x0 = _project(p, _ideal_start(curve))
    scale = np.abs(x0).max()
    best = None
    for k in range(max(1, starts)):
        xs = x0 if k == 0 else _project(p, x0 + 0.25 * scale * _PERTURB[(k - 1) % len(_PERTURB)])
        x = _project(p, _solve(p, xs))
        if np.abs(p.constraint(x)).max() > 1e-10:
            continue
        f = p.objective(x)
        if best is None or f < best[0]:
            best = (f, x)
    if best is None:  # the projected start is always feasible
        best = (p.objective(x0), x0)
    f, x = best
    a, b = p.split(x)
    if b[0] < 0:  # same frame, nicer coefficients
        a, b = -a, -b
    return GRMFrame(curve, a, b, weight, f, constraint_residual(curve, a, b), _twist_deg(curve, a, b))


def grm_from_coefficients(curve, a, b, weight=None) -> GRMFrame:
    """A GRMFrame from given Bernstein coefficients a, b (5,) (e.g. the paper's printed solution)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape != (5,) or b.shape != (5,):
        raise PlannerError("a and b must each have 5 Bernstein coefficients")
    obj = float("nan")
    if weight is not None:
        p = _Problem(curve, weight)
        x = np.concatenate((a[1:], b))
        obj = p.objective(x) if a[0] == 0 else float("nan")
    return GRMFrame(curve, a, b, weight, obj, constraint_residual(curve, a, b), _twist_deg(curve, a, b))
