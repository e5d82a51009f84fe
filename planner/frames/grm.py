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
default, ours): minimize the largest angle between the GRM frame and the exact RMF from the same start
frame (at 101 parameters, with a penalty on spins between them), which is what users of the frame feel;
eq. (13) with rho = 1 can twist the tool by tens of degrees more (DESIGN.md). Every result reports the
real figure, ``max_twist_deg``.

Search. "twist" uses the closed form of the constraint set (:mod:`planner.frames.grm_orbits`): the pairs
with W(a, b) = a b' - a' b = g are the SL(2) orbits of the few real 2-planes of degree-4 polynomials whose
Wronskian is g, so every trial point is explicit and the search costs no Newton solve of (24). The other
weights, and curves where that finds nothing acceptable (torsion-free ones, g ~ 0), use the grid search
over (b(0), b(1)) with Newton continuation onto (24) (``search="grid"`` forces it).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from planner import bernstein
from planner import quaternion as qt
from planner.curves.ph_core import batch_sigma
from planner.errors import PlannerError
from planner.frames.er import er_frames
from planner.frames.grm_orbits import (
    bernstein_bend,
    compass_search,
    g_power,
    minimax_twist,
    orbit_objective,
    orbit_point,
    plane_orbits,
    spin_suspect,
)
from planner.frames.rmf import RMFAngle, check_start_frame, normal_angle, turn_normals
from planner.frames.rmf_batch import PathRMFAngles
from planner.validation import as_int, finite_floats

#: Collocation nodes for the 7 equations of (24): Chebyshev points of [0, 1].
_COLLOC = 0.5 - 0.5 * np.cos((2 * np.arange(7) + 1) * np.pi / 14)
#: Power-basis values of degree 6 at the nodes, and at the 201 parameters that fix the scale of (24).
_V7_COLLOC = np.vander(_COLLOC, 7, increasing=True)
_V7_SCALE = np.vander(np.linspace(0.0, 1.0, 201), 7, increasing=True)
#: Quadrature for the objectives: 24-point Gauss-Legendre on [0, 1] (exact for eq. 13 with rho = 1, sigma).
_QX, _QW = np.polynomial.legendre.leggauss(24)
_QX, _QW = 0.5 * (_QX + 1.0), 0.5 * _QW
#: Search results with an objective at or above this (the spin penalty, for "twist") get the fallback.
_ACCEPT = np.pi
#: The "twist" objective rejects solutions with a^2 + b^2 below this fraction of 2 sigma^2 at a sample (half of
#: it between samples): there the frame spins fast.
_MIN_RATIO = 0.2
#: Parameters where the "twist" objective compares the GRM angle with the exact RMF angle.
_TS = np.linspace(0.0, 1.0, 101)
#: Parameters of the reported figures (residual of (24), max twist); _TS and the fit's are every 10th and 25th.
_TF = np.linspace(0.0, 1.0, 1001)
#: Curves with max |g| below this times max |A_k|^4 are torsion-free for the closed-form search.
_G_FLOOR = 1e-12
#: The global screen of each plane's orbit (every 5th sample): log(lam / lam0) and asinh(mu / mu_scale),
#: lam0 from the least-squares fit and mu_scale = rms b_V / rms a_V; its best 4 are judged on all samples.
_SCREEN_LOG_LAM = np.linspace(-4.0, 4.0, 9)
_SCREEN_ASINH_MU = np.linspace(-3.0, 3.0, 9)
_SCREEN_KEEP = 4
#: Curves whose closed-form search twists more than this (rad; 1 degree) get the dense screen: a 25 x 25
#: grid of every plane's orbit on all samples, the best 6 points of each as starts.
_HARD = np.radians(1.0)
_DENSE_LOG_LAM = np.linspace(-6.0, 4.0, 25)
_DENSE_ASINH_MU = np.linspace(-4.0, 4.0, 25)
_DENSE_KEEP = 6

WEIGHTS = ("twist", "1", "sigma", "tau_kappa")


def g_poly_values(A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """g(t) = (d/dt A j A*) . (A k A*), the right-hand side of eq. (24), at parameters t (n,).

    Computed as 2 |A|^2 (A* A')_i: the ER frame's body angular velocity about e1 times sigma^2.
    """
    Av = bernstein.evaluate(A, t)
    dA = bernstein.evaluate(bernstein.derivative(A), t)
    q = Av[:, 0] * dA[:, 1] - Av[:, 1] * dA[:, 0] - Av[:, 2] * dA[:, 3] + Av[:, 3] * dA[:, 2]
    return 2.0 * qt.norm2(Av) * q


def _sigma2_batch(A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """2 sigma^2 = 2 |A|^4 for stacked curves A (S, 3, 4) at parameters t (n,): (S, n)."""
    s = (bernstein.basis(4, t) @ batch_sigma(A).T).T
    return 2.0 * s * s


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
        Value of eq. (13) with the weight (for ``"twist"``: the largest twist angle at 101 parameters, rad,
        plus pi if the frame may spin).
    constraint_residual : float
        max over [0, 1] of |a b' - a' b - g| / max |g| (eq. 24; round-off for a converged solve).
    max_twist_deg : float
        Largest angle (deg) between this frame's normal-plane vectors and the exact RMF's from the
        same start frame, over 1001 parameters.
    start_angle : float
        Angle (rad) of the frame's column 1 against the ER frame's at t = 0.
    seconds : float
        Wall time the solve took (for the per-segment speed figure).
    """

    curve: object
    a: np.ndarray
    b: np.ndarray
    weight: object
    objective: float
    constraint_residual: float
    max_twist_deg: float
    start_angle: float = 0.0
    seconds: float = 0.0

    def to_state(self) -> dict:
        """The solution's data, for the saved-job file (:mod:`planner.jobfile`); the curve is its owner's (a
        segment of a path: :meth:`planner.frames.path.PathFrames.from_state`)."""
        return {"a": self.a, "b": self.b, "weight": self.weight, "objective": self.objective,
                "constraint_residual": self.constraint_residual, "max_twist_deg": self.max_twist_deg,
                "start_angle": self.start_angle, "seconds": self.seconds}

    @classmethod
    def from_state(cls, state: dict, curve) -> GRMFrame:
        """The solution from :meth:`to_state` fields read back, on ``curve``."""
        return cls(curve, **state)

    def angle(self, t) -> np.ndarray:
        """psi_R(t) - psi_R(0) + start_angle (rad), modulo 2 pi: the frame's angle against the ER frame."""
        t = np.atleast_1d(finite_floats(t, "t"))
        ang = 2.0 * np.arctan2(bernstein.evaluate(self.a, t), bernstein.evaluate(self.b, t))
        return self.start_angle + ang - 2.0 * np.arctan2(self.a[0], self.b[0])

    def frames(self, t) -> np.ndarray:
        """GRM frames (n, 3, 3) at parameters t (n,): the rational rotation of eq. (11), normalized."""
        t = np.atleast_1d(finite_floats(t, "t"))
        return turn_normals(er_frames(self.curve, t), self.angle(t))

    def with_start(self, start) -> GRMFrame:
        """The same GRM motion started from a given frame (3, 3) at t = 0 (column 0 the tangent)."""
        er0 = er_frames(self.curve, [0.0])[0]
        F = check_start_frame(start, er0[:, 0])
        return GRMFrame(self.curve, self.a, self.b, self.weight, self.objective, self.constraint_residual,
                        self.max_twist_deg, normal_angle(F, er0), self.seconds)


class _Problem:
    """Constraint (24) and objectives for S curves at once; unknowns per curve x = (a1..a4, b0..b4), a0 = 0.

    Batched methods take rows X (R, 9) and the curve index of each row, ``seg`` (R,).
    """

    def __init__(self, curves, weight, psi=None, gp=None):
        """``psi``: the exact RMF angle at _TS (S, 101) if already known; ``gp``: g's power coefficients."""
        A = np.stack([c.A for c in curves])  # (S, 3, 4)
        S = A.shape[0]
        gp = g_power(A) if gp is None else gp
        self.B7, self.dB7 = bernstein.basis(4, _COLLOC), 4 * _diff_basis(_COLLOC)
        self.g7 = gp @ _V7_COLLOC.T
        self.target = self.g7  # right-hand side of (24) at the collocation nodes
        self.gscale = np.maximum(np.abs(gp @ _V7_SCALE.T).max(axis=1), 1e-300)
        self.weight = weight
        self.gp = gp
        if weight == "twist":  # judged directly by the largest twist against the exact RMF
            self.Bs = bernstein.basis(4, _TS)
            if psi is None:
                psi = PathRMFAngles(A)(np.repeat(np.arange(S), _TS.size), np.tile(_TS, S)).reshape(S, _TS.size)
            self.psi = psi
            self.w = np.exp(-0.5j * psi)  # conj of the exact RMF's half-angle phase
            self.s2s = _sigma2_batch(A, _TS)  # 2 sigma^2 at the samples
        else:
            self.Bq = bernstein.basis(4, _QX)
            self.s2q = _sigma2_batch(A, _QX)
            self.rho = np.stack([_weight_values(weight, c, _QX) for c in curves]) * _QW

    @staticmethod
    def split(x):
        return np.concatenate(([0.0], x[:4])), x[4:]

    @staticmethod
    def _ab(X):
        return np.concatenate((np.zeros((X.shape[0], 1)), X[:, :4]), axis=1), X[:, 4:]

    def constraint_batch(self, X, seg):
        """(a b' - a' b - g) / max |g| at the collocation nodes, rows X (R, 9) -> (R, 7)."""
        a, b = self._ab(X)
        av, bv, dav, dbv = a @ self.B7.T, b @ self.B7.T, a @ self.dB7.T, b @ self.dB7.T
        return (av * dbv - dav * bv - self.target[seg]) / self.gscale[seg, None]

    def newton_system(self, X, seg):
        """Residual (R, 7) and its Jacobian in the free unknowns a1..a4, b1..b3 (R, 7, 7), sharing the
        polynomial values (the Newton step of :func:`_on_constraint`)."""
        a, b = self._ab(X)
        av, bv, dav, dbv = a @ self.B7.T, b @ self.B7.T, a @ self.dB7.T, b @ self.dB7.T
        inv = 1.0 / self.gscale[seg]
        C = (av * dbv - dav * bv - self.target[seg]) * inv[:, None]
        B, dB = self.B7[:, 1:4], self.dB7[:, 1:4]  # the free columns (b1..b3; a1..a4 take 1..4)
        ja = self.B7[:, 1:] * dbv[:, :, None] - self.dB7[:, 1:] * bv[:, :, None]
        jb = av[:, :, None] * dB - dav[:, :, None] * B
        return C, np.concatenate((ja, jb), axis=2) * inv[:, None, None]

    def objective_batch(self, X, seg, coarse: bool = False):
        """Eq. (13) with the weight, rows X (R, 9) -> (R,); for "twist", the largest twist (rad) against
        the exact RMF on 101 parameters (every third with ``coarse``), plus pi where |z|^2 = a^2 + b^2 may
        dip so low that the frame spins (:func:`planner.frames.grm_orbits.spin_suspect`). NaN rows give NaN."""
        a, b = self._ab(X)
        if self.weight == "twist":
            # with z = b + i a, the GRM angle is 2 arg z; against the RMF (from the same start) the twist
            # is arg(u^2) for u = z e^{-i psi/2} conj(z(0)): one principal angle per sample, no unwrapping
            step = 3 if coarse else 1  # the global grid screens on every third sample
            Bs = self.Bs[::step]
            zr = b @ Bs.T + 1j * (a @ Bs.T)
            z = zr * self.w[seg][:, ::step]
            u = z * np.conj(z[:, :1])
            with np.errstate(invalid="ignore"):
                twist = np.abs(np.angle(u * u)).max(axis=1)
                # |z|^2 = a^2 + b^2 far below 2 sigma^2 somewhere, at the samples or between, means a fast
                # spin that samples can miss
                m2 = zr.real**2 + zr.imag**2
                dip = spin_suspect(zr.real, zr.imag, m2, _MIN_RATIO * self.s2s[seg][:, ::step], bernstein_bend(a, b),
                                   step / (_TS.size - 1))
            return np.where(dip, twist + np.pi, twist)
        av, bv = a @ self.Bq.T, b @ self.Bq.T
        r = av * av + bv * bv - self.s2q[seg]
        return np.einsum("rq,rq->r", r * r, self.rho[seg])

    # single-curve conveniences (curve 0)
    def constraint(self, x):
        return self.constraint_batch(x[None], np.zeros(1, int))[0]

    def objective(self, x):
        return float(self.objective_batch(x[None], np.zeros(1, int))[0])


def _diff_basis(t):
    """d/dt of the degree-4 Bernstein basis divided by 4: B_{3,k-1} - B_{3,k}, shape (n, 5)."""
    b3 = bernstein.basis(3, t)
    out = np.zeros((t.size, 5))
    out[:, 1:] += b3
    out[:, :-1] -= b3
    return out


_B_TF, _DB_TF = bernstein.basis(4, _TF), 4 * _diff_basis(_TF)
_V7_TF = np.vander(_TF, 7, increasing=True)


_FREE = np.array([0, 1, 2, 3, 5, 6, 7])  # a1..a4, b1..b3; (b0, b4) = x[4], x[8] parametrize the set


def _solve_batch(J: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Solutions of J x = C for stacked square systems; singular ones by least squares."""
    try:
        return np.linalg.solve(J, C[..., None])[..., 0]
    except np.linalg.LinAlgError:
        pass
    with np.errstate(all="ignore"):
        ok = np.abs(np.linalg.det(J)) > 1e-300
    x = np.empty(C.shape)
    if ok.any():
        x[ok] = np.linalg.solve(J[ok], C[ok][..., None])[..., 0]
    for i in np.flatnonzero(~ok):
        x[i] = np.linalg.lstsq(J[i], C[i], rcond=None)[0]
    return x


def _on_constraint(p: _Problem, X: np.ndarray, b0: np.ndarray, b4: np.ndarray, seg=None, iters: int = 12):
    """Points (G, 9) of the constraint sets (24) of curves ``seg`` (G,) (default curve 0) with b(0) = b0,
    b(1) = b4 (G,), by batched Newton from X.

    Only rows still iterating are computed; rows where Newton fails (no point of the set nearby, or
    divergence) are NaN.
    """
    X = np.array(X, dtype=float)
    X[:, 4], X[:, 8] = b0, b4
    seg = np.zeros(X.shape[0], int) if seg is None else np.asarray(seg)
    bound = 1e6 * np.maximum(np.abs(X).max(axis=1), 1e-300)
    active = np.arange(X.shape[0])
    first = None
    for it in range(iters):
        Xa = X[active]
        C, J = p.newton_system(Xa, seg[active])
        err = np.abs(C).max(axis=1)
        first = err if first is None else first
        failing = ~np.isfinite(err) | ((it >= 3) & (err > 10 * first))
        keep = (err >= 1e-14) & ~failing
        X[active[failing]] = np.nan
        active, C, J, first, Xa = active[keep], C[keep], J[keep], first[keep], Xa[keep]
        if active.size == 0:
            break
        Xa[:, _FREE] -= _solve_batch(J, C)
        bad = ~np.isfinite(Xa).all(axis=1) | (np.abs(Xa).max(axis=1) > bound[active])
        Xa[bad] = np.nan
        X[active] = Xa
        active, first = active[~bad], first[~bad]
    with np.errstate(invalid="ignore"):
        feasible = np.abs(p.constraint_batch(X, seg)).max(axis=1) < 1e-12
    X[~feasible] = np.nan
    return X


def _closest_feasible(p: _Problem, x: np.ndarray, iters: int = 20) -> np.ndarray:
    """Column-scaled least-squares Newton towards (24) from x, keeping the least violating iterate.

    Used where the grid finds no exactly feasible point: on nearly torsion-free segments g is tiny
    and the constraint set is ill-conditioned (condition numbers of 1e14), but the start itself is
    already nearly rotation-minimizing. ``constraint_residual`` reports what remains.
    """
    best = (np.abs(p.constraint(x)).max(), x)
    first = np.zeros(1, int)
    for _ in range(iters):
        c, J = (v[0] for v in p.newton_system(x[None], first))
        sc = np.maximum(np.linalg.norm(J, axis=0), 1e-300)
        x = x.copy()
        x[_FREE] -= np.linalg.lstsq(J / sc, c, rcond=None)[0] / sc
        r = np.abs(p.constraint(x)).max()
        if r < best[0]:
            best = (r, x)
    return best[1]


def _search(p: _Problem, x0: np.ndarray, size: float, grid: int) -> np.ndarray | None:
    """Global search of the 2-dimensional constraint set parametrized by (b(0), b(1)).

    A grid x grid of (b(0), b(1)) around the least-squares fit of the exact RMF, solved by Newton with
    continuation along the b(1) direction (all rows at once), widened if no point is feasible; then
    Nelder-Mead from the best point, each trial point continued from the last one found.
    """
    best = None
    for widen in (1.0, 4.0, 16.0):
        offs = np.linspace(-2.0, 2.0, grid) * size * widen
        X: np.ndarray = np.full((grid, grid, 9), np.nan)  # reshaped to (grid * grid, 9) below
        # sweep b(1) across the grid for all rows of b(0) at once, each point started from its solved
        # neighbour (continuation), then sweep back to fill the points the first sweep missed
        for order in (range(grid), range(grid - 1, -1, -1)):
            prev = np.tile(x0, (grid, 1))
            for j in order:
                todo = ~np.isfinite(X[:, j, 0])
                if todo.any():
                    start = np.where(np.isfinite(prev[:, :1]), prev, x0)[todo]
                    X[todo, j] = _on_constraint(p, start, x0[4] + offs[todo], np.full(todo.sum(), x0[8] + offs[j]))
                prev = np.where(np.isfinite(X[:, j, :1]), X[:, j], prev)
        X = X.reshape(-1, 9)
        f = p.objective_batch(X, np.zeros(X.shape[0], int))
        if np.isfinite(f).any():
            k = int(np.nanargmin(f))
            best, spacing = (f[k], X[k]), offs[1] - offs[0]
            break
    if best is None:
        return None
    anchor = [best[1]]

    def key(v):  # the objective on the constraint set, continued from the last point found
        x = _on_constraint(p, anchor[0][None], np.array([v[0]]), np.array([v[1]]))[0]
        if not np.isfinite(x).all():
            return 10.0 * best[0] + 1.0
        anchor[0] = x
        return p.objective(x)

    x = best[1]
    simplex = x[[4, 8]] + 0.5 * spacing * np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    res = minimize(key, x[[4, 8]], method="Nelder-Mead",
                   options={"xatol": 1e-7 * size, "fatol": 1e-9, "maxfev": 60, "initial_simplex": simplex})
    x = _on_constraint(p, anchor[0][None], res.x[:1], res.x[1:])[0]
    return x if np.isfinite(x).all() and p.objective(x) <= best[0] else best[1]


def _twist_deg(curve, a, b) -> float:
    t = np.linspace(0.0, 1.0, 1001)
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


def grm(curve, weight: str | Callable = "twist", *, grid: int = 11) -> GRMFrame:
    """The GRM frame of a PH quintic (``PHQuintic``), starting at its ER frame at t = 0.

    Parameters
    ----------
    curve : PHQuintic
    weight : "twist" (default), "1", "sigma", "tau_kappa" or callable rho(t) -> (n,)
        What a^2 + b^2 ~ 2 sigma^2 is optimized for: "twist" minimizes the largest angle to the exact
        RMF (the search of :func:`grm_many`, so both give the same frame); the others are the paper's
        eq. (13) with that weight rho.
    grid : int
        For the weights other than "twist" (and its torsion-free fallback): the constraint set (24) with
        a(0) = 0 is 2-dimensional, parametrized here by (b(0), b(1)); it is searched globally on a grid x
        grid around the least-squares fit of the exact RMF (its branches and infeasible holes included),
        then refined by Nelder-Mead.

    Returns
    -------
    GRMFrame
        Use ``.with_start(F0)`` to start from another frame.
    """
    grid = as_int(grid, "grid", 2, 1000)
    if getattr(curve, "A", None) is None or np.shape(curve.A) != (3, 4):
        raise PlannerError("grm needs a PH quintic (quaternion coefficients A of shape (3, 4))")
    if not callable(weight) and weight not in WEIGHTS:
        raise PlannerError(f"weight must be one of {WEIGHTS} or a callable rho(t), got {weight!r}")
    if weight == "twist":
        return grm_many([curve], weight, grid=grid)[0]
    tic = time.perf_counter()
    p = _Problem([curve], weight)
    x0 = _ideal_starts([curve])[0]
    size = np.sqrt(2.0) * float(np.mean(sigma_values(curve.A, _TS)))  # typical |b + i a|
    x = _search(p, x0, size, grid)
    if x is None or not p.objective(x) < _ACCEPT:
        # nearly torsion-free segment: (24) is ill-conditioned there (a ~ 0), and the grid finds no
        # point or only spinning ones; best effort from the start, which is already nearly RM
        alt = _closest_feasible(p, x0)
        if x is None or p.objective(alt) < p.objective(x):
            x = alt
    f = p.objective(x)
    a, b = p.split(x)
    if b[0] < 0:  # same frame, nicer coefficients
        a, b = -a, -b
    resid, twist = constraint_residual(curve, a, b), _twist_deg(curve, a, b)
    return GRMFrame(curve, a, b, weight, f, resid, twist, 0.0, time.perf_counter() - tic)


def _ideal_starts(curves, psi=None) -> np.ndarray:
    """Least-squares degree-4 fits (S, 9) of a = sqrt2 sigma sin(psi/2), b = sqrt2 sigma cos(psi/2), a(0) = 0,
    to the exact RMF angle psi of each curve (at 41 parameters: ``psi`` (S, 41) if already known): the
    starting point of the search."""
    A = np.stack([c.A for c in curves])
    S = A.shape[0]
    t = _TF[::25]
    if psi is None:
        psi = PathRMFAngles(A)(np.repeat(np.arange(S), t.size), np.tile(t, S)).reshape(S, t.size)
    s = np.sqrt(_sigma2_batch(A, t))
    B = bernstein.basis(4, t)
    a = np.linalg.lstsq(B[:, 1:], (s * np.sin(0.5 * psi)).T, rcond=None)[0].T
    b = np.linalg.lstsq(B, (s * np.cos(0.5 * psi)).T, rcond=None)[0].T
    return np.concatenate((a, b), axis=1)


def _search_many(p: _Problem, x0: np.ndarray, size: np.ndarray, grid: int, rounds: int = 8):
    """:func:`_search` for S curves at once, the refinement by shrinking 5 x 5 local grids (batched)
    instead of Nelder-Mead. Returns X (S, 9), NaN rows where no feasible point was found."""
    S = x0.shape[0]
    best_f = np.full(S, np.inf)
    best_x = np.full((S, 9), np.nan)
    spacing = np.zeros(S)
    todo = np.arange(S)
    unit = np.linspace(-2.0, 2.0, grid)
    for widen in (1.0, 4.0, 16.0):
        if todo.size == 0:
            break
        offs = unit[None, :] * (size[todo] * widen)[:, None]  # (T, grid)
        T = todo.size
        X = np.full((T, grid, grid, 9), np.nan)  # [curve, b0 offset, b4 offset]
        rows_seg = np.repeat(todo, grid)
        for order in (range(grid), range(grid - 1, -1, -1)):
            prev = np.repeat(x0[todo], grid, axis=0)  # (T * grid, 9) per (curve, b0 offset)
            for j in order:
                cur = X[:, :, j].reshape(T * grid, 9)
                need = ~np.isfinite(cur[:, 0])
                if need.any():
                    start = np.where(np.isfinite(prev[:, :1]), prev, np.repeat(x0[todo], grid, axis=0))[need]
                    b0 = (x0[todo, 4][:, None] + offs).ravel()[need]
                    b4 = np.repeat(x0[todo, 8] + offs[:, j], grid)[need]
                    cur[need] = _on_constraint(p, start, b0, b4, rows_seg[need])
                    X[:, :, j] = cur.reshape(T, grid, 9)
                prev = np.where(np.isfinite(cur[:, :1]), cur, prev)
        flat = X.reshape(T, grid * grid, 9)
        f = p.objective_batch(flat.reshape(-1, 9), np.repeat(todo, grid * grid), coarse=True).reshape(T, grid * grid)
        f = np.where(np.isfinite(f), f, np.inf)
        k = np.argmin(f, axis=1)
        found = np.isfinite(f[np.arange(T), k])
        fine = p.objective_batch(flat[np.arange(T), k], todo)  # the chosen points on all samples
        best_f[todo[found]] = fine[found]
        best_x[todo[found]] = flat[found, k[found]]
        spacing[todo[found]] = (offs[:, 1] - offs[:, 0])[found]
        todo = todo[~found]
    ok = np.flatnonzero(np.isfinite(best_f))
    local = np.linspace(-1.0, 1.0, 5)
    d0, d4 = (g.ravel() for g in np.meshgrid(local, local, indexing="ij"))
    for _ in range(rounds):
        spacing[ok] /= 2.0
        G = d0.size
        start = np.repeat(best_x[ok], G, axis=0)
        b0 = (best_x[ok, 4][:, None] + spacing[ok, None] * d0).ravel()
        b4 = (best_x[ok, 8][:, None] + spacing[ok, None] * d4).ravel()
        seg = np.repeat(ok, G)
        X = _on_constraint(p, start, b0, b4, seg)
        f = p.objective_batch(X, seg).reshape(ok.size, G)
        f = np.where(np.isfinite(f), f, np.inf)
        k = np.argmin(f, axis=1)
        better = f[np.arange(ok.size), k] < best_f[ok]
        best_f[ok[better]] = f[better, k[better]]
        best_x[ok[better]] = X.reshape(ok.size, G, 9)[better, k[better]]
    return best_x


def _orbit_planes(p: _Problem, A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The real planes of (24) of every curve as rows: curve index (R,), orbit basis a_V, b_V (R, 5) each
    (a_V(0) = 0, b_V(0) = 1, W(a_V, b_V) = g to round-off: Newton confirms each candidate of
    :func:`planner.frames.grm_orbits.plane_orbits`; those from complex solutions fail). Torsion-free curves
    (max |g| below _G_FLOOR max |A_k|^4) get none."""
    g = p.gp  # eq. (24)'s right-hand side, power basis
    live = np.flatnonzero(np.abs(g).max(axis=1) > _G_FLOOR * np.abs(A).max(axis=(1, 2)) ** 4)
    aV, bV = plane_orbits(g[live])  # (L, 5, 5) each: 5 candidate planes per curve
    seg = np.repeat(live, 5)
    Xc = np.concatenate((aV[..., 1:], bV), axis=-1).reshape(-1, 9)
    keep = np.isfinite(Xc).all(axis=1)
    seg, Xc = seg[keep], Xc[keep]
    Xc = _on_constraint(p, Xc, Xc[:, 4], Xc[:, 8], seg, iters=6)
    keep = np.isfinite(Xc[:, 0])
    seg, Xc = seg[keep], Xc[keep]
    return seg, np.concatenate((np.zeros((seg.size, 1)), Xc[:, :4]), axis=1), Xc[:, 4:]


def _best_per_curve(seg: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Indices of the row with the least f for each curve in seg (ties: the first)."""
    order = np.lexsort((f, seg))
    first = np.ones(order.size, bool)
    first[1:] = seg[order][1:] != seg[order][:-1]
    return order[first]


def _orbit_search(p: _Problem, A: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The "twist" search on the closed-form constraint set (:mod:`planner.frames.grm_orbits`), all curves
    at once. On every real plane of (24): the minimax iteration from the orbit point nearest the
    least-squares fit x0 (S, 9), and from the best point of a coarse global screen of the orbit where that
    is better still; a pattern search from the best row per curve. Curves still twisting more than _HARD
    get a dense screen of every plane and more starts. Then Newton onto (24) to round-off. Returns X (S, 9),
    NaN rows where no plane was found (e.g. a torsion-free curve, g = 0), and the objective (S,)."""
    S = A.shape[0]
    X = np.full((S, 9), np.nan)
    fo = np.full(S, np.inf)
    seg, aV, bV = _orbit_planes(p, A)
    if seg.size == 0:
        return X, fo
    aVs, bVs = aV @ p.Bs.T, bV @ p.Bs.T
    dV = np.stack((np.diff(aV, 2, axis=1), np.diff(bV, 2, axis=1)))
    psi = p.psi[seg]
    rot = np.stack((np.cos(psi), -np.sin(psi)))  # exp(-i psi): the exact RMF angle (eq. 6) to compare with
    floor2 = _MIN_RATIO * p.s2s[seg]  # the least |z|^2 = a^2 + b^2 at the samples (2 sigma^2 is ideal, eq. 13)
    # lam from b(0) of the fit, mu by least squares of the fit's b on the plane; the screen's mu scale
    lam0 = 1.0 / np.maximum(np.abs(x0[seg, 4]), 1e-300)
    with np.errstate(all="ignore"):
        mu0 = ((lam0[:, None] * (x0[seg, 4:] @ p.Bs.T) - bVs) * aVs).sum(axis=1) / (aVs * aVs).sum(axis=1)
        mscale = np.sqrt((bVs * bVs).sum(axis=1) / (aVs * aVs).sum(axis=1))
    mu0 = np.where(np.isfinite(mu0), mu0, 0.0)
    mscale = np.where(np.isfinite(mscale), mscale, 1.0)

    def screen(rows, log_lam, asinh_mu, step, keep):
        """The best ``keep`` points (rows, keep) of a grid of each row's orbit, on every step-th sample."""
        E, U = (v.ravel() for v in np.meshgrid(log_lam, asinh_mu, indexing="ij"))
        lg, mg = lam0[rows, None] * np.exp(E), mscale[rows, None] * np.sinh(U)
        c = slice(None, None, step)
        fg = orbit_objective(aVs[rows, None, c], bVs[rows, None, c], rot[:, rows, None, c], floor2[rows, None, c],
                             dV[:, rows, None], lg, mg)
        k = np.argsort(fg, axis=1, kind="stable")[:, :keep]
        r = np.arange(rows.size)[:, None]
        return lg[r, k], mg[r, k]

    def minimax(rows, lam, mu):
        return minimax_twist(aVs[rows], bVs[rows], rot[:, rows], floor2[rows], dV[:, rows], lam, mu)

    def polish(rows, lam, mu, f):
        """The pattern search from the best row per curve: its rows, lam, mu, f (one per curve, by curve)."""
        pick = _best_per_curve(seg[rows], f)
        pr = rows[pick]
        lam, mu, f = compass_search(aVs[pr], bVs[pr], rot[:, pr], floor2[pr], dV[:, pr], lam[pick], mu[pick], f[pick],
                                    np.full(pick.size, 0.02), 0.02 * mscale[pr])
        return pr, lam, mu, f

    R = np.arange(seg.size)
    lam, mu, f = minimax(R, lam0, mu0)
    lg, mg = screen(R, _SCREEN_LOG_LAM, _SCREEN_ASINH_MU, 5, _SCREEN_KEEP)
    fg = orbit_objective(aVs[:, None], bVs[:, None], rot[:, :, None], floor2[:, None], dV[:, :, None], lg, mg)
    k = fg.argmin(axis=1)
    redo = np.flatnonzero(fg[R, k] < f)  # the screen found better than the descent from the fit: go there
    if redo.size:
        l2, m2, f2 = minimax(redo, lg[redo, k[redo]], mg[redo, k[redo]])
        better = f2 < f[redo]
        lam[redo[better]], mu[redo[better]], f[redo[better]] = l2[better], m2[better], f2[better]
    pr, lam, mu, f = polish(R, lam, mu, f)
    hard = np.isin(seg, seg[pr[f >= _HARD]])
    if hard.any():  # dense screen of every plane of these curves, several starts each
        H = np.flatnonzero(hard)
        lg, mg = screen(H, _DENSE_LOG_LAM, _DENSE_ASINH_MU, 1, _DENSE_KEEP)
        rows = np.repeat(H, lg.shape[1])
        hl, hm, hf = minimax(rows, lg.ravel(), mg.ravel())
        hr, hl, hm, hf = polish(rows, hl, hm, hf)
        pos = np.searchsorted(seg[pr], seg[hr])  # pr is sorted by curve
        won = hf < f[pos]
        pr[pos[won]], lam[pos[won]], mu[pos[won]], f[pos[won]] = hr[won], hl[won], hm[won], hf[won]
    a, b = orbit_point(aV[pr], bV[pr], lam, mu)  # W(a, b) = W(a_V, b_V) = g (eq. 24)
    Xb = np.concatenate((a[:, 1:], b), axis=1)
    sb = seg[pr]
    Xp = _on_constraint(p, Xb, Xb[:, 4], Xb[:, 8], sb, iters=4)  # round-off on (24)
    Xb = np.where(np.isfinite(Xp[:, :1]), Xp, Xb)
    X[sb] = Xb
    fo[sb] = p.objective_batch(Xb, sb)
    return X, np.where(np.isfinite(fo), fo, np.inf)


def grm_many(curves, weight: str | Callable = "twist", *, grid: int = 11, search: str = "auto") -> list[GRMFrame]:
    """:func:`grm` for many PH quintics at once (e.g. every segment of a path), vectorized over them.

    ``search``: "auto" is, for weight "twist", the closed-form search on the planes of (24)
    (:func:`_orbit_search`), with the grid search for the curves where it finds nothing acceptable
    (torsion-free ones); for the other weights the grid search. "grid" forces the grid search (the slower
    exhaustive reference): a grid x grid grid over (b(0), b(1)) with Newton continuation onto (24), refined
    by shrinking local grids for all curves together. ``seconds`` of each result is the wall time divided
    by the number of curves.
    """
    curves = list(curves)
    if not curves:
        return []
    for c in curves:
        if getattr(c, "A", None) is None or np.shape(c.A) != (3, 4):
            raise PlannerError("grm needs PH quintics (quaternion coefficients A of shape (3, 4))")
    if not callable(weight) and weight not in WEIGHTS:
        raise PlannerError(f"weight must be one of {WEIGHTS} or a callable rho(t), got {weight!r}")
    if search not in ("auto", "grid"):
        raise PlannerError(f"search must be 'auto' or 'grid', got {search!r}")
    tic = time.perf_counter()
    A = np.stack([c.A for c in curves])
    S = A.shape[0]
    gp = g_power(A)
    # the exact RMF angle once, at the figures' parameters; the search and the fit use every 10th, 25th
    exact = PathRMFAngles(A)(np.repeat(np.arange(S), _TF.size), np.tile(_TF, S)).reshape(S, _TF.size)
    p = _Problem(curves, weight, exact[:, ::10], gp)
    x0 = _ideal_starts(curves, exact[:, ::25])
    if weight == "twist" and search == "auto":
        X, f = _orbit_search(p, A, x0)
        rest = np.flatnonzero(~(f < _ACCEPT))  # nothing acceptable (e.g. torsion-free): the grid search
    else:
        X, f, rest = np.full((S, 9), np.nan), np.full(S, np.inf), np.arange(S)
    if rest.size:
        q = _Problem([curves[i] for i in rest], weight, exact[rest, ::10], gp[rest]) if rest.size < S else p
        size = np.sqrt(_sigma2_batch(A[rest], _TS)).mean(axis=1)
        Xr = _search_many(q, x0[rest], size, grid)
        fr = q.objective_batch(Xr, np.arange(rest.size))
        take = (fr < f[rest]) | ~np.isfinite(X[rest, 0])  # else keep the closed-form point
        Xr, fr = np.where(take[:, None], Xr, X[rest]), np.where(take, fr, f[rest])
        for j in np.flatnonzero(~(fr < _ACCEPT)):  # nothing found, or only spinning points: best effort
            i = rest[j]
            qi = _Problem([curves[i]], weight, exact[i : i + 1, ::10], gp[i : i + 1])
            alt = _closest_feasible(qi, x0[i])
            if not np.isfinite(Xr[j]).all() or qi.objective(alt) < fr[j]:
                Xr[j] = alt
        X[rest] = Xr
    a, b = _ab_normalized(X)
    resid, twist = _figures_batch(A, a, b, exact, gp)
    f = p.objective_batch(X, np.arange(S))
    per = (time.perf_counter() - tic) / len(curves)
    return [GRMFrame(c, a[i], b[i], weight, float(f[i]), float(resid[i]), float(twist[i]), 0.0, per)
            for i, c in enumerate(curves)]


def _ab_normalized(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients a, b (R, 5) of rows X (R, 9), signs flipped so that b(0) >= 0 (the same frame)."""
    a = np.concatenate((np.zeros((X.shape[0], 1)), X[:, :4]), axis=1)
    b = X[:, 4:]
    flip = b[:, :1] < 0
    return np.where(flip, -a, a), np.where(flip, -b, b)


def _figures_batch(A: np.ndarray, a: np.ndarray, b: np.ndarray, exact=None, gp=None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`constraint_residual` and :func:`_twist_deg` for stacked curves and coefficients (``exact``:
    the exact RMF angle at the 1001 parameters, ``gp``: g's power coefficients, if already known)."""
    t = _TF
    B, dB = _B_TF, _DB_TF
    av, bv, dav, dbv = a @ B.T, b @ B.T, a @ dB.T, b @ dB.T
    g = (g_power(A) if gp is None else gp) @ _V7_TF.T
    resid = np.abs(av * dbv - dav * bv - g).max(axis=1) / np.maximum(np.abs(g).max(axis=1), 1e-300)
    S = A.shape[0]
    if exact is None:
        exact = PathRMFAngles(A)(np.repeat(np.arange(S), t.size), np.tile(t, S)).reshape(S, t.size)
    z = (bv + 1j * av) * np.exp(-0.5j * exact)
    u = z * np.conj(z[:, :1])
    return resid, np.degrees(np.abs(np.angle(u * u)).max(axis=1))


def grm_from_coefficients(curve, a, b, weight=None) -> GRMFrame:
    """A GRMFrame from given Bernstein coefficients a, b (5,) (e.g. the paper's printed solution)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape != (5,) or b.shape != (5,):
        raise PlannerError("a and b must each have 5 Bernstein coefficients")
    obj = float("nan")
    if weight is not None:
        p = _Problem([curve], weight)
        x = np.concatenate((a[1:], b))
        obj = p.objective(x) if a[0] == 0 else float("nan")
    return GRMFrame(curve, a, b, weight, obj, constraint_residual(curve, a, b), _twist_deg(curve, a, b))
