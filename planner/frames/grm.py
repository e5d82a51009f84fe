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

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from planner import bernstein
from planner import quaternion as qt
from planner.errors import PlannerError
from planner.frames.er import er_frames
from planner.frames.rmf import RMFAngle, check_start_frame, normal_angle, turn_normals
from planner.frames.rmf_batch import PathRMFAngles

#: Collocation nodes for the 7 equations of (24): Chebyshev points of [0, 1].
_COLLOC = 0.5 - 0.5 * np.cos((2 * np.arange(7) + 1) * np.pi / 14)
#: Quadrature for the objectives: 24-point Gauss-Legendre on [0, 1] (exact for eq. 13 with rho = 1, sigma).
_QX, _QW = np.polynomial.legendre.leggauss(24)
_QX, _QW = 0.5 * (_QX + 1.0), 0.5 * _QW
#: Search results with an objective at or above this (the spin penalty, for "twist") get the fallback.
_ACCEPT = np.pi
#: The "twist" objective rejects solutions with a^2 + b^2 below this fraction of 2 sigma^2 anywhere.
_MIN_RATIO = 0.2
#: Parameters where the "twist" objective compares the GRM angle with the exact RMF angle.
_TS = np.linspace(0.0, 1.0, 101)

WEIGHTS = ("twist", "1", "sigma", "tau_kappa")


def g_poly_values(A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """g(t) = (d/dt A j A*) . (A k A*), the right-hand side of eq. (24), at parameters t (n,).

    Computed as 2 |A|^2 (A* A')_i: the ER frame's body angular velocity about e1 times sigma^2.
    """
    Av = bernstein.evaluate(A, t)
    dA = bernstein.evaluate(bernstein.derivative(A), t)
    q = Av[:, 0] * dA[:, 1] - Av[:, 1] * dA[:, 0] - Av[:, 2] * dA[:, 3] + Av[:, 3] * dA[:, 2]
    return 2.0 * qt.norm2(Av) * q


def _values_batch(A: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A(t) and A'(t) for stacked curves A (S, 3, 4) at parameters t (n,): (S, n, 4) each."""
    B = bernstein.basis(2, t)
    dB = bernstein.basis(1, t)
    return np.einsum("nj,sjc->snc", B, A), np.einsum("nj,sjc->snc", dB, 2.0 * np.diff(A, axis=1))


def g_values_batch(A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """:func:`g_poly_values` for stacked curves A (S, 3, 4): (S, n)."""
    Av, dA = _values_batch(A, t)
    q = Av[..., 0] * dA[..., 1] - Av[..., 1] * dA[..., 0] - Av[..., 2] * dA[..., 3] + Av[..., 3] * dA[..., 2]
    return 2.0 * (Av * Av).sum(axis=-1) * q


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
                        self.max_twist_deg, normal_angle(F, er0), self.seconds)


class _Problem:
    """Constraint (24) and objectives for S curves at once; unknowns per curve x = (a1..a4, b0..b4), a0 = 0.

    Batched methods take rows X (R, 9) and the curve index of each row, ``seg`` (R,).
    """

    def __init__(self, curves, weight):
        A = np.stack([c.A for c in curves])  # (S, 3, 4)
        S = A.shape[0]
        self.B7, self.dB7 = bernstein.basis(4, _COLLOC), 4 * _diff_basis(_COLLOC)
        self.g7 = g_values_batch(A, _COLLOC)
        self.target = self.g7  # right-hand side of (24) at the collocation nodes
        self.gscale = np.maximum(np.abs(g_values_batch(A, np.linspace(0, 1, 201))).max(axis=1), 1e-300)
        self.weight = weight
        if weight == "twist":  # judged directly by the largest twist against the exact RMF
            self.Bs = bernstein.basis(4, _TS)
            psi = PathRMFAngles(A)(np.repeat(np.arange(S), _TS.size), np.tile(_TS, S)).reshape(S, _TS.size)
            self.w = np.exp(-0.5j * psi)  # conj of the exact RMF's half-angle phase
            self.s2s = 2.0 * (_values_batch(A, _TS)[0] ** 2).sum(axis=-1) ** 2  # 2 sigma^2 at the samples
        else:
            self.Bq = bernstein.basis(4, _QX)
            self.s2q = 2.0 * (_values_batch(A, _QX)[0] ** 2).sum(axis=-1) ** 2
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
        the exact RMF on 201 parameters (the GRM angle unwrapped along t, so a spin of 2 pi is seen).
        NaN rows give NaN."""
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
                # |z|^2 = a^2 + b^2 far below 2 sigma^2 somewhere means a fast spin that samples can miss
                dip = ((zr.real**2 + zr.imag**2) / self.s2s[seg][:, ::step]).min(axis=1) < _MIN_RATIO
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
        X = np.full((grid, grid, 9), np.nan)
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
        What a^2 + b^2 ~ 2 sigma^2 is optimized for: "twist" minimizes the mean square angle to the
        exact RMF; the others are the paper's eq. (13) with that weight rho.
    grid : int
        The constraint set (24) with a(0) = 0 is 2-dimensional, parametrized here by (b(0), b(1)); it is
        searched globally on a grid x grid around the least-squares fit of the exact RMF (its branches
        and infeasible holes included), then refined on finer local grids.

    Returns
    -------
    GRMFrame
        Use ``.with_start(F0)`` to start from another frame.
    """
    if getattr(curve, "A", None) is None or np.shape(curve.A) != (3, 4):
        raise PlannerError("grm needs a PH quintic (quaternion coefficients A of shape (3, 4))")
    if not callable(weight) and weight not in WEIGHTS:
        raise PlannerError(f"weight must be one of {WEIGHTS} or a callable rho(t), got {weight!r}")
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


def _ideal_starts(curves) -> np.ndarray:
    """Least-squares degree-4 fits (S, 9) of a = sqrt2 sigma sin(psi/2), b = sqrt2 sigma cos(psi/2), a(0) = 0,
    to the exact RMF angle psi of each curve: the starting point of the search."""
    A = np.stack([c.A for c in curves])
    S = A.shape[0]
    t = np.linspace(0.0, 1.0, 41)
    psi = PathRMFAngles(A)(np.repeat(np.arange(S), t.size), np.tile(t, S)).reshape(S, t.size)
    s = np.sqrt(2.0) * (_values_batch(A, t)[0] ** 2).sum(axis=-1)
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


def grm_many(curves, weight: str | Callable = "twist", *, grid: int = 11) -> list[GRMFrame]:
    """:func:`grm` for many PH quintics at once (e.g. every segment of a path), vectorized over them.

    The search is the same grid with continuation; its refinement uses shrinking local grids for all
    curves together instead of a Nelder-Mead run per curve, which makes paths of hundreds of segments
    fast. ``seconds`` of each result is the wall time divided by the number of curves.
    """
    curves = list(curves)
    if not curves:
        return []
    for c in curves:
        if getattr(c, "A", None) is None or np.shape(c.A) != (3, 4):
            raise PlannerError("grm needs PH quintics (quaternion coefficients A of shape (3, 4))")
    if not callable(weight) and weight not in WEIGHTS:
        raise PlannerError(f"weight must be one of {WEIGHTS} or a callable rho(t), got {weight!r}")
    tic = time.perf_counter()
    p = _Problem(curves, weight)
    x0 = _ideal_starts(curves)
    A = np.stack([c.A for c in curves])
    size = np.sqrt(2.0) * (_values_batch(A, _TS)[0] ** 2).sum(axis=-1).mean(axis=1)
    X = _search_many(p, x0, size, grid)
    f = p.objective_batch(X, np.arange(len(curves)))
    for i in np.flatnonzero(~(f < _ACCEPT)):  # nothing found, or only spinning points: best effort
        q = _Problem([curves[i]], weight)
        alt = _closest_feasible(q, x0[i])
        if not np.isfinite(X[i]).all() or q.objective(alt) < f[i]:
            X[i] = alt
    a = np.concatenate((np.zeros((X.shape[0], 1)), X[:, :4]), axis=1)
    b = X[:, 4:]
    flip = b[:, :1] < 0  # same frame, nicer coefficients
    a, b = np.where(flip, -a, a), np.where(flip, -b, b)
    f = p.objective_batch(X, np.arange(len(curves)))
    resid, twist = _figures_batch(A, a, b)
    per = (time.perf_counter() - tic) / len(curves)
    return [GRMFrame(c, a[i], b[i], weight, float(f[i]), float(resid[i]), float(twist[i]), 0.0, per)
            for i, c in enumerate(curves)]


def _figures_batch(A: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`constraint_residual` and :func:`_twist_deg` for stacked curves and coefficients."""
    t = np.linspace(0.0, 1.0, 1001)
    B, dB = bernstein.basis(4, t), 4 * _diff_basis(t)
    av, bv, dav, dbv = a @ B.T, b @ B.T, a @ dB.T, b @ dB.T
    g = g_values_batch(A, t)
    resid = np.abs(av * dbv - dav * bv - g).max(axis=1) / np.maximum(np.abs(g).max(axis=1), 1e-300)
    S = A.shape[0]
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
