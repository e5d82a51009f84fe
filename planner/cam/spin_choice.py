"""Choosing the spin about an axisymmetric tool for the arm (``spin="reach"``).

The tool axis and the TCP path are the CAM system's; the rotation about the axis is free. Along each run of passes
(the passes between two rapids, :func:`planner.cam.configure.groups`: the arm keeps one configuration there) the spin
psi is chosen in two stages, the first global and coarse, the second continuous:

1. **Rating at the RMM spin.** The run is sampled about every ``reach_step`` of arc length (at most
   :data:`MAX_RUN_SAMPLES` samples; a cut shorter than that by its ends) at its planned times, and the inverse
   kinematics of every sample is solved on the eight branches. Where some branch reaches every sample with singularity
   margin at least :data:`SING_SAFE`, no joint faster than :data:`SPEED_SAFE` of its limit and the non-multiturn
   joints :data:`JOINT_SAFE` from their limits, and the arm comes from the RMM spin, the run keeps the RMM spin
   (psi = 0): a tool spun for nothing is a tool spun.
2. **Global search on a spin grid** (otherwise): psi on a grid of 15 degrees over [-180, 180] degrees from the RMM
   spin (no more than half a turn: the spin adds no wind-up of its own) at every sample, each branch on its own; a
   shortest path through the (sample, spin) graph (dynamic programming, Viterbi) minimizes the sum of node costs
   (singularity margin below :data:`SING_SAFE`: min of |sin q3|, |sin q5| and the shoulder factor as in
   :mod:`planner.cam.placement`; joint-limit margin; distance from the RMM spin) and step costs (a joint beyond
   :data:`SPEED_SAFE` of its speed limit over the step, at the planned times; wrist travel |dq4| + |dq6|, against
   wind-up; a spin step faster than ``spin_rate``), steps moving at most :data:`MAX_STEP` grid values. Samples out of
   reach cost :data:`OUT_OF_REACH`. The rapids before the run are in the same graph, the path starting at the spin the
   previous run ended with (no rate or joint-speed cost there: the rapids are timed for their spin afterwards). This
   is the ladder graph of ROS-Industrial Descartes and the sampled spin of RoboDK, over the whole run at once. The
   graph holds every :data:`COARSE`-th sample of the run where the margins are flat and every sample where a node's
   cost changes by more than :data:`FLAT` over a step (and every sample of the rapids, the ends of every move). The
   step costs and the dynamic programming run compiled (``_spin_search.c``, one pass per sample) where a C compiler
   built it at install, else in numpy (step costs for blocks of samples at once, one min-plus step per sample): the
   same arithmetic, the same bits.
3. **Continuous refinement.** psi becomes a clamped cubic B-spline (C2) of arc length along the run, at most
   :data:`MAX_COEFFS` coefficients: the least-squares fit to the grid path, smoothed, under the spin bounds as linear
   constraints on the coefficients at every sample and inside every phase of the cuts' time laws, |psi'(s) v| <=
   ``spin_rate`` and |psi''(s) v^2 + psi'(s) a| <= ``spin_acceleration`` with the planned feed v and its acceleration
   a (asked with the margin :data:`BOUND_SHARE`): a convex quadratic program in at most :data:`MAX_COEFFS` unknowns
   and thousands of bounds, solved exactly by the primal active-set method (Nocedal and Wright, Numerical
   Optimization, algorithm 16.3) from the least-squares fit scaled into the bounds, which is feasible. The result is
   rated like the RMM spin and kept only where it is better (fewer samples out of reach, fewer steps too fast, then a
   larger least singularity margin).

Where the tool is on the flange axis (the TCP turned about its z and offset along it only), a spin is wrist 3 alone
(q6 + psi): reach, the singularity margins and the other joints do not depend on it, so only wrist 3's speed decides
whether a run is searched, the inverse kinematics is solved once per sample and the grid is a shift of q6. Otherwise
(an angled nozzle) every grid value is solved.

Between runs, in the rapids, psi goes from the end of one run to the start of the next (a C2 curve per rapid near the
grid path, pinned at its ends), the rapid slowed where the spin bounds need it. Where the rapids cannot carry half a
turn within :data:`GAP_SLOWDOWN` times their time (or 2 s), psi is held through them and the next run starts where
the arm is. A turn in place or a dwell keeps psi. The result is the moves with their frames wrapped in
:class:`~planner.cam.spin.SpunFrames` (and the start and end frames turned), the first cut of every run carrying its
:class:`~planner.cam.spin.SpinFigures`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.interpolate import BSpline

from planner.cam.configure import groups
from planner.cam.spin import SPIN_DEGREE, SpinCurve, SpinFigures, SpunFrames, spun
from planner.kinematics import get_model, inverse_frames
from planner.kinematics.poses import as_transform
from planner.motion import MotionLimits, plan_feed

try:  # the grid search compiled (built at install where a C compiler is; see pyproject.toml), else its numpy version
    from planner.cam import _spin_search
except ImportError:  # pragma: no cover - an install without a C compiler
    _spin_search = None  # type: ignore[assignment]

#: Steps of the spin grid over [-pi, pi] from the RMM spin (15 deg apart, both ends included).
GRID = 24
#: Grid values a step between two samples may move at most.
MAX_STEP = 2
#: Samples rated per run at most (the spacing grows beyond).
MAX_RUN_SAMPLES = 4000
#: B-spline coefficients of a run's spin at most.
MAX_COEFFS = 48
#: Singularity margin below which a sample costs (min of |sin q3|, |sin q5|, shoulder factor).
SING_SAFE = 0.2
#: Joint-limit margin (rad) below which a sample costs (non-multiturn joints).
JOINT_SAFE = math.radians(20.0)
#: Fraction of a joint's speed limit above which a step costs.
SPEED_SAFE = 0.8
#: Cost weights: singularity, joint limit, a step too fast (beyond SPEED_SAFE, and beyond the limit), wrist travel
#: (per rad), spin rate beyond its bound, distance from the RMM spin (per sample, at half a turn).
W_SING, W_JOINT, W_SPEED, W_FAST, W_TRAVEL, W_RATE, W_RMM = 1.0, 1.0, 10.0, 20.0, 0.01, 5.0, 0.01
#: Cost of a sample out of reach on a branch.
OUT_OF_REACH = 1e6
#: Steps of the grid search whose step costs are computed at once (all shifts: about 250 kB per array).
BLOCK = 32
#: The grid search starts from every COARSE-th sample of a run (reach_step apart), ...
COARSE = 4
#: ... and takes every sample of a step over which a node's cost (capped at 2) changes by more than FLAT (a
#: singularity margin crossing about 0.78 SING_SAFE, a sample leaving reach).
FLAT = 0.05


def spin_is_wrist3(tcp) -> bool:
    """Whether a spin about the tool axis is wrist 3 alone: the TCP turned about the flange z only and offset
    along it only (then T_tcp commutes with Rz and the tool axis is the flange axis)."""
    if tcp is None:
        return True
    T = as_transform(tcp, "tcp")
    return bool(abs(T[0, 3]) < 1e-12 and abs(T[1, 3]) < 1e-12 and abs(T[2, 2] - 1.0) < 1e-12)


@dataclass(frozen=True)
class SpinChoice:
    """The job's moves with the chosen spin and what it took.

    Attributes
    ----------
    moves : list of PlannedMove
        Every move, frames wrapped in SpunFrames (rapids re-timed where the spin needs it).
    runs, spun_runs : int
        Runs of passes rated, and those given a spin other than the RMM's.
    seconds : float
        Wall time of the choice, s.
    """

    moves: list
    runs: int
    spun_runs: int
    seconds: float


@dataclass(frozen=True, eq=False)
class _Samples:
    """A run's rated samples: run coordinate X (n,) (arc length along the cuts, constant over a turn), times (n,),
    base-frame positions (n, 3) and tool frames (n, 3, 3) at the RMM spin, the time in its move (n,), and the move
    each belongs to (n,) with its coordinate (n,); ``cuts``: (move index, X at its start) of the run's
    cuts."""

    X: np.ndarray
    t: np.ndarray
    p: np.ndarray
    R: np.ndarray
    tl: np.ndarray
    move: np.ndarray
    x: np.ndarray
    cuts: tuple = ()


def _samples(moves, ks, Tb: np.ndarray, step: float) -> tuple[_Samples, dict]:
    """The run's samples and each move's offset in the run coordinate {k: X at its start}."""
    total = sum(float(moves[k].path.length) for k in ks if moves[k].kind == "cut")
    h = max(step, total / MAX_RUN_SAMPLES, 1e-6)
    parts: list[tuple] = []
    X0 = t0 = 0.0
    offsets = {}
    cuts: list[tuple] = []
    for k in ks:
        m = moves[k]
        offsets[k] = X0
        if m.profile is None:
            continue
        T = float(m.profile.duration)
        L = float(m.path.length) if m.kind == "cut" else 0.0
        if m.kind == "cut" and L <= h:  # a short cut: its ends, known without evaluating anything
            tl, x = np.array([0.0, T]), np.array([0.0, L])
            p = np.vstack((m.point, m.item.points[-1])) @ Tb[:3, :3].T + Tb[:3, 3]
            R = np.matmul(Tb[:3, :3], np.stack((m.start_frame, m.end_frame)))
            X = X0 + x
        elif m.kind == "cut":  # evenly in the path parameter, about every h of arc length
            k0, k1 = float(m.path.knots[0]), float(m.path.knots[-1])
            u = np.linspace(k0, k1, max(2, math.ceil(L / h) + 1))
            # arc length between the knots by linear interpolation: the rating's coordinate, not the spin's
            x = np.interp(u, m.path.knots, m.path.cumulative_lengths)
            # the time law inverted on a table of s(t) (closed form): the rating needs times, not to round-off
            tg = np.linspace(0.0, T, 4 * u.size + 16)
            tl = np.interp(x, np.maximum.accumulate(m.profile.s(tg)), tg)
            # positions on the CAM polyline (within the fit's tolerance of the path): what the rating needs
            wk, cp = m.path.waypoint_knots, m.item.points
            p = np.stack([np.interp(u, wk, cp[:, i]) for i in range(3)], axis=1) @ Tb[:3, :3].T + Tb[:3, 3]
            R = np.matmul(Tb[:3, :3], m.frames.frames(u))
            X = X0 + x
        else:  # a turn in place: its start and end, the coordinate stands
            tl = np.array([0.0, T])
            x = np.array([0.0, m.frames.angle])
            R = np.matmul(Tb[:3, :3], m.frames.frames(x))
            p = np.broadcast_to(Tb[:3, :3] @ m.point + Tb[:3, 3], (2, 3))
            X = np.full(2, X0)
        parts.append((X, t0 + tl, p, R, tl, np.full(x.size, k), x))
        if m.kind == "cut":
            cuts.append((k, X0))
        X0 = float(X[-1])
        t0 += float(m.profile.duration)
    cols = [np.concatenate([c[i] for c in parts]) for i in range(7)]
    keep = np.ones(cols[0].size, bool)  # a pose repeated at a move boundary (same coordinate, same time) once
    keep[1:] = (np.diff(cols[0]) > 0.0) | (np.diff(cols[1]) > 0.0)  # (and a time law's rest at its ends)
    X, t, p, R, tl, move, x = (c[keep] for c in cols)
    return _Samples(X, t, p, R, tl, move, x, tuple(cuts)), offsets


def _gap_samples(moves, ks, Tb: np.ndarray, step: float, advance: bool) -> tuple[_Samples, list]:
    """Samples of the rapids and turns in place of a gap (before a run), in a coordinate that ends at 0 (the run's
    start): X advances along the rapids when ``advance`` (the spin may change there), else stands (the spin is held).
    Also each rapid's (move index, X at its start, sample rows)."""
    parts: list[tuple] = []
    rapids = []
    total = sum(float(moves[k].path.length) for k in ks if moves[k].kind == "rapid")
    X0 = -total if advance else 0.0
    n = 0
    for k in ks:
        m = moves[k]
        if m.kind == "rapid":
            L = float(m.path.length)
            x = np.linspace(0.0, L, max(2, math.ceil(L / step) + 1))
            p = (m.point + (x / max(L, 1e-300))[:, None] * (m.item.end - m.point)) @ Tb[:3, :3].T + Tb[:3, 3]
            R = np.matmul(Tb[:3, :3], m.frames.frames(x))
            X = X0 + (x if advance else 0.0 * x)
            rapids.append((k, X0, np.arange(n, n + x.size)))
        else:  # a turn in place: its start and end
            x = np.array([0.0, m.frames.angle])
            R = np.matmul(Tb[:3, :3], m.frames.frames(x))
            p = np.broadcast_to(Tb[:3, :3] @ m.point + Tb[:3, 3], (2, 3))
            X = np.full(2, X0)
        parts.append((X, p, R, np.full(x.size, k), x))
        n += x.size
        X0 = float(X[-1])
    X, p, R, move, x = (np.concatenate([c[i] for c in parts]) for i in range(5))
    return _Samples(X, np.zeros(X.size), p, R, np.zeros(X.size), move, x, ()), rapids


def _feed_at(moves, S: _Samples) -> tuple[np.ndarray, np.ndarray]:
    """The planned feed v (n,) and its acceleration a (n,) at the samples (0 on a turn in place)."""
    v, a = np.zeros(S.X.size), np.zeros(S.X.size)
    for k in np.unique(S.move):
        if moves[k].kind == "cut":
            rows = S.move == k
            _, v[rows], a[rows] = moves[k].profile.state(S.tl[rows])
    return v, a


def _phase_points(moves, cuts) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(X, v, a) at the phase boundaries of the cuts' time laws and 7 points inside each phase (cuts: (move index, X
    at its start)): where the feed accelerates, the spin bounds are checked besides the samples."""
    out = []
    for k, X0 in cuts:
        prof = moves[k].profile
        tp = prof.t
        te = (tp[:-1, None] + np.diff(tp)[:, None] * np.linspace(0.0, 1.0, 9)[None, :]).ravel()
        se, ve, ae = prof.state(te)
        out.append((X0 + se, ve, ae))
    return tuple(np.concatenate([e[i] for e in out]) for i in range(3))  # type: ignore[return-value]


class _Arm:
    """Joints and their costs for one robot and TCP."""

    def __init__(self, robot: str, tcp):
        self.robot, self.tcp = robot, tcp
        self.model = get_model(robot)
        self.wrist3 = spin_is_wrist3(tcp)
        self.vmax = self.model.speed_limits
        self.fixed = ~self.model.multiturn

    def joints(self, p: np.ndarray, R: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joints (6, n, 8, G) (joint-major, 0 where not valid) and validity (n, 8, G) of positions p (n, 3), frames
        R (n, 3, 3) turned by each spin of psi (G,) (a row of spins (n, G) per sample also works)."""
        psi = np.broadcast_to(psi, (p.shape[0],) + np.shape(psi)[-1:])
        n, G = psi.shape
        if self.wrist3:  # the spin is wrist 3 alone: one solution per sample, q6 shifted
            q1, v1 = inverse_frames(self.model, p, R, tcp=self.tcp)  # (6, 8, n), (8, n)
            q = np.repeat(q1.transpose(0, 2, 1)[..., None], G, axis=3)
            q[5] = _wrap(q[5] + psi[:, None, :])
            valid = np.repeat(v1.T[:, :, None], G, axis=2)
        else:
            F = spun(np.repeat(R[:, None], G, axis=1), psi)
            qa, va = inverse_frames(self.model, np.repeat(p, G, axis=0), F.reshape(-1, 3, 3), tcp=self.tcp)
            q = qa.reshape(6, 8, n, G).transpose(0, 2, 1, 3)
            valid = np.ascontiguousarray(va.reshape(8, n, G).transpose(1, 0, 2))
        return np.where(valid, q, 0.0), valid

    def margins(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(singularity margin, joint-limit margin), each (...) over joints q (6, ...) (0 where not valid)."""
        m = self.model
        q12 = q[1] + q[2]
        sing = np.minimum(np.minimum(np.abs(np.sin(q[2])), np.abs(np.sin(q[4]))),
                          np.abs(m.a2 * np.cos(q[1]) + m.a3 * np.cos(q12) + m.d5 * np.sin(q12 + q[3]))
                          / (abs(m.a2) + abs(m.a3)))
        if self.fixed.any():
            f = np.flatnonzero(self.fixed)
            at = (slice(None),) + (None,) * (q.ndim - 1)
            joint = np.minimum(q[f] - m.lower[f][at], m.upper[f][at] - q[f]).min(axis=0)
        else:
            joint = np.full(sing.shape, math.pi)
        return sing, joint

    def node_cost(self, q: np.ndarray, valid: np.ndarray, psi: np.ndarray) -> np.ndarray:
        """Cost (...) of the nodes of joints q (6, ...) (0 where not valid), valid (...) and spins psi (broadcast to
        (...)): the margins below their safe values and the distance from the RMM spin; out of reach where not
        valid."""
        sing, joint = self.margins(q)
        cost = (W_SING * np.maximum(0.0, 1.0 - sing / SING_SAFE) ** 2
                + W_JOINT * np.maximum(0.0, 1.0 - joint / JOINT_SAFE) ** 2
                + W_RMM * (_wrap(psi) / math.pi) ** 2)
        return np.where(valid, cost, OUT_OF_REACH)

    def step_ratio(self, dq: np.ndarray, dt) -> np.ndarray:
        """Largest joint speed over a step as a fraction of its limit, (...) from joint steps dq (6, ...) and dt."""
        dt = np.asarray(dt, dtype=float)
        top = (np.abs(dq) / self.vmax.reshape((6,) + (1,) * (dq.ndim - 1))).max(axis=0)
        return np.where(dt > 0.0, top / np.where(dt > 0.0, dt, 1.0), np.where(top > 1e-9, np.inf, 0.0))


def _wrap(x):
    return (np.asarray(x) + math.pi) % (2.0 * math.pi) - math.pi


def _step_costs(arm: _Arm, q: np.ndarray, valid: np.ndarray, X: np.ndarray, t: np.ndarray, free: int, rate: float,
                gstep: float, shifts: np.ndarray) -> np.ndarray:
    """Cost (n - 1, 8, 2K+1, G) of every step of the grid search from grid value g - shifts[k] (clipped to the grid)
    at sample i to g at sample i + 1 on each branch, for joints q (6, n, 8, G) (0 where not valid) and their validity
    (n, 8, G) (a node out of reach: its node cost says so) at run coordinates X (n,) and times t (n,): wrist travel,
    and after the first ``free`` steps (rapids) a joint beyond SPEED_SAFE of its limit and a spin faster than
    ``rate`` (spin change |shift| gstep over the step's time); a shift over a turn in place (the run's coordinate
    stands) is out of reach. ``shifts`` are -K..K. Computed :data:`BLOCK` steps at a time, all shifts at once on
    windows of the joints padded along the grid (no copies), joint by joint into two buffers."""
    _, n, nb, G = q.shape
    K = int(np.abs(shifts).max())
    assert np.array_equal(shifts, np.arange(-K, K + 1))
    S = shifts.size
    qp = np.concatenate((np.repeat(q[..., :1], K, axis=-1), q, np.repeat(q[..., -1:], K, axis=-1)), axis=-1)
    vp = np.concatenate((np.repeat(valid[..., :1], K, axis=-1), valid, np.repeat(valid[..., -1:], K, axis=-1)),
                        axis=-1)
    # window w of the padded grid starts at w: shift k (sh = k - K) takes the one starting at K - sh = 2K - k
    qw = sliding_window_view(qp, G, axis=-1)[..., ::-1, :]  # (6, n, 8, 2K+1, G)
    vw = sliding_window_view(vp, G, axis=-1)[..., ::-1, :]  # (n, 8, 2K+1, G)
    out = np.empty((n - 1, nb, S, G))
    dX, dt = np.diff(X), np.diff(t)
    inv_v = 1.0 / arm.vmax
    two_pi = 2.0 * math.pi
    moving = (shifts != 0)[None, None, :, None]
    spin_step = (np.abs(shifts) * gstep)[None, None, :, None]
    for i0 in range(0, n - 1, BLOCK):
        i1 = min(n - 1, i0 + BLOCK)
        B = i1 - i0
        d = np.empty((B, nb, S, G))
        e = np.empty((B, nb, S, G))
        top = np.empty((B, nb, S, G))
        for j in range(6):  # |dq_j| wrapped (the joints lie in one turn, (-pi, pi])
            np.subtract(q[j, i0 + 1:i1 + 1, :, None, :], qw[j, i0:i1], out=d)
            np.abs(d, out=d)
            if d.max() > math.pi:  # (elsewhere d is the shorter way round already)
                np.subtract(two_pi, d, out=e)
                np.minimum(d, e, out=d)
            if j == 3:
                travel = d.copy()
            elif j == 5:
                travel += d
            if j == 0:
                np.multiply(d, inv_v[j], out=top)
            else:
                np.multiply(d, inv_v[j], out=e)
                np.maximum(top, e, out=top)
        both = valid[i0 + 1:i1 + 1, :, None, :] & vw[i0:i1]  # a step from or to a node out of reach
        travel *= both  # costs nothing more than its node
        top *= both
        cost = W_TRAVEL * travel
        timed = np.arange(i0, i1) >= free
        if timed.any():
            h = dt[i0:i1, None, None, None]
            if (h > 0.0).all():
                ratio = top / h
            else:
                ratio = np.where(h > 0.0, top / np.where(h > 0.0, h, 1.0), np.where(top > 1e-9, np.inf, 0.0))
            spin = W_RATE * np.maximum(0.0, spin_step / np.maximum(h, 1e-9) / max(rate, 1e-9) - 1.0) ** 2
            spin = np.where(timed[:, None, None, None], spin, 0.0)
            fast = ratio > SPEED_SAFE  # elsewhere the speed cost is 0.0 exactly
            fast &= timed[:, None, None, None]
            if spin.any():
                cost += spin
            if fast.any():
                at = np.nonzero(fast)
                r = ratio[at]
                speed = W_SPEED * np.maximum(0.0, r - SPEED_SAFE) ** 2 + W_FAST * (r > 1.0)
                cost[at] = W_TRAVEL * travel[at] + (speed + np.broadcast_to(spin, cost.shape)[at])
        stands = (dX[i0:i1] <= 0.0)[:, None, None, None]
        if stands.any():  # psi is a function of the run's arc length: it stands over a turn in place
            cost += np.where(stands & moving, OUT_OF_REACH, 0.0)
        np.minimum(cost, OUT_OF_REACH, out=out[i0:i1])
    return out


def _figures(arm: _Arm, S: _Samples, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Figures (8, 7) of spin psi (n,) on every branch (see SpinFigures; then the largest joint speed over a step as
    a fraction of its limit, of any joint and of wrist 3) and each branch's rank key (8, 3)."""
    return _rated(arm, S, *_posed(arm, S.p, S.R, psi))


def _posed(arm: _Arm, p: np.ndarray, R: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, ...]:
    """Joints (6, n, 8), validity (n, 8), singularity and joint-limit margins (n, 8) of positions p (n, 3) and frames
    R (n, 3, 3) turned by psi (n,) (each sample on its own: the samples of many runs at once give each run's)."""
    q, valid = arm.joints(p, R, psi[:, None])
    q, valid = q[..., 0], valid[..., 0]  # (6, n, 8), (n, 8)
    return (q, valid) + arm.margins(q)


def _rmm_figures(arm: _Arm, runs: list) -> list:
    """:func:`_figures` at the RMM spin (psi = 0) of the samples of every run in ``runs`` (a list of _Samples), the
    joints and margins of all of them from one inverse-kinematics call (the same bits: each sample on its own)."""
    if not runs:
        return []
    q, valid, sing, joint = _posed(arm, np.concatenate([S.p for S in runs]), np.concatenate([S.R for S in runs]),
                                   np.zeros(sum(S.X.size for S in runs)))
    out = []
    a = 0
    for S in runs:
        b = a + S.X.size
        out.append(_rated(arm, S, q[:, a:b], valid[a:b], sing[a:b], joint[a:b]))
        a = b
    return out


def _rated(arm: _Arm, S: _Samples, q: np.ndarray, valid: np.ndarray, sing: np.ndarray,
           joint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_figures` from the samples' joints (6, n, 8), validity and margins (n, 8)."""
    dq = _wrap(np.diff(q, axis=1))
    ratio = arm.step_ratio(dq, np.diff(S.t)[:, None])
    both = valid[1:] & valid[:-1]
    fast = np.where(both, ratio > 1.0, False).sum(axis=0)
    out = (~valid).sum(axis=0)
    travel = np.where(both, np.abs(dq[3]) + np.abs(dq[5]), 0.0).sum(axis=0)
    s_min = np.where(valid, sing, np.inf).min(axis=0)
    j_min = np.where(valid, joint, np.inf).min(axis=0)
    top = np.where(both, ratio, 0.0).max(axis=0, initial=0.0)
    top6 = np.where(both, np.abs(dq[5]) / arm.vmax[5] / np.maximum(np.diff(S.t), 1e-300)[:, None], 0.0).max(
        axis=0, initial=0.0)
    fig = np.stack([s_min, j_min, fast, out, travel, top, top6], axis=1)
    key = np.stack([out, fast, -np.minimum(s_min, SING_SAFE)], axis=1)
    return fig, key


def _best(key: np.ndarray) -> int:
    return int(np.lexsort(key.T[::-1])[0])


def _fine(fig: np.ndarray, b: int, wrist3: bool) -> bool:
    """Whether branch b is fine at the RMM spin: everything in reach, margins and speeds safe. With the tool on the
    flange axis a spin is wrist 3 alone: reach, the singularity margins and the other joints do not depend on it, so
    only wrist 3's speed and (where it is limited to a turn) its limits count."""
    if wrist3:
        return bool(fig[b, 6] <= SPEED_SAFE and fig[b, 1] >= JOINT_SAFE)
    return bool(fig[b, 3] == 0 and fig[b, 2] == 0 and fig[b, 0] >= SING_SAFE and fig[b, 1] >= JOINT_SAFE
                and fig[b, 5] <= SPEED_SAFE)


def _coarse(S: _Samples, free: int) -> np.ndarray:
    """The samples the grid search starts from (bool (n,)): every :data:`COARSE`-th sample of the run, and every
    sample of the rapids before it (the first ``free``), at the ends of every move and turn in place."""
    n = S.X.size
    keep = np.zeros(n, dtype=bool)
    keep[free::COARSE] = True
    keep[:free + 1] = True
    keep[-1] = True
    edge = (np.diff(S.X) <= 0.0) | (S.move[1:] != S.move[:-1])  # a turn in place, the start of another move
    keep[:-1] |= edge
    keep[1:] |= edge
    return keep


def _inside(n: int, idx: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """The samples (bool (n,)) strictly inside the steps idx[j]..idx[j + 1] of the sorted indices idx for which
    ``steps`` (bool (len(idx) - 1,)) holds."""
    d = np.zeros(n + 1, dtype=np.int64)
    np.add.at(d, idx[:-1][steps] + 1, 1)
    np.add.at(d, idx[1:][steps], -1)
    return np.cumsum(d[:n]) > 0


def _min_plus(arm: _Arm, q: np.ndarray, valid: np.ndarray, node: np.ndarray, X: np.ndarray, t: np.ndarray, free: int,
              rate: float, gstep: float, shifts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The dynamic programming of the grid search over the chain of samples: the cheapest cost (8, G) of a path to
    each node of the last sample and the shift index (n - 1, 8, G) (into ``shifts``, -K..K) of every step of the
    cheapest path to each node, for joints q (6, n, 8, G), validity (n, 8, G) and node costs (n, 8, G) at run
    coordinates X (n,) and times t (n,) (see :func:`_step_costs`; the first ``free`` steps are in rapids).

    By the compiled search (``_spin_search.c``: step costs and min-plus steps in one pass per sample, the same
    arithmetic) where it is built, else by numpy (:func:`_step_costs` for blocks of samples, then one min-plus step
    per sample); the same bits either way."""
    n, _, G = node.shape
    K = int(np.abs(shifts).max())
    pred = np.arange(G)[None, :] - shifts[:, None]  # (2K+1, G): the predecessor of g by each shift
    src = np.clip(pred, 0, G - 1)
    D = node[0].copy()  # (8, G)
    back = np.empty((n - 1, 8, G), dtype=np.int8)
    if _spin_search is not None:
        h = np.diff(t)
        spin = W_RATE * np.maximum(0.0, (np.abs(shifts) * gstep)[None, :] / np.maximum(h, 1e-9)[:, None]
                                   / max(rate, 1e-9) - 1.0) ** 2  # as in _step_costs
        spin[:free] = 0.0
        _spin_search.grid_search(np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(valid, dtype=bool),
                                 np.ascontiguousarray(node, dtype=float), h, np.diff(X), spin,
                                 np.ascontiguousarray(1.0 / arm.vmax), free, K,
                                 (W_TRAVEL, W_SPEED, W_FAST, SPEED_SAFE, OUT_OF_REACH), D, back)
        return D, back
    trans = _step_costs(arm, q, valid, X, t, free, rate, gstep, shifts)  # (n - 1, 8, 2K+1, G)
    trans += np.where((pred < 0) | (pred >= G), OUT_OF_REACH, 0.0)  # no predecessor past the grid's ends
    rows = np.arange(8)[:, None]
    cols = np.arange(G)[None, :]
    for i in range(n - 1):  # the graph is a chain over samples: the min-plus step of the dynamic programming
        total = D[:, src]
        total += trans[i]
        j = total.argmin(axis=1)  # (8, G)
        back[i] = j
        D = total[rows, j, cols] + node[i + 1]
    return D, back


def _grid_path(arm: _Arm, S: _Samples, rate: float, free: int = 0, pin: float = math.nan) -> tuple[np.ndarray, int]:
    """The grid search: spin (n,) (radians, in [-pi, pi]) and branch of the cheapest path through (sample, spin).

    The first ``free`` steps are in rapids, which are timed for their spin afterwards: no spin-rate or joint-speed
    cost there. ``pin``: the spin where the arm is at the first sample (the previous run's end), if any.

    The search runs on the samples where the margins change (:func:`_coarse` samples, then every sample of a step
    over which some node's cost changes by more than :data:`FLAT`: the margins are flat elsewhere, and the spin's
    B-spline is no finer than its knots); the path between them is linear in the sample index."""
    grid = np.linspace(-math.pi, math.pi, GRID + 1)  # within half a turn of the RMM spin: no wind-up from the spin
    gstep = float(grid[1] - grid[0])
    n_all = S.X.size
    idx = np.flatnonzero(_coarse(S, free))
    q, valid = arm.joints(S.p[idx], S.R[idx], grid)  # (6, m, 8, G), (m, 8, G)
    node = arm.node_cost(q, valid, grid)
    jump = np.abs(np.diff(np.minimum(node, 2.0), axis=0)).max(axis=(1, 2)) > FLAT
    more = np.flatnonzero(_inside(n_all, idx, jump))
    if more.size:  # where the margins are not flat: every sample
        q2, valid2 = arm.joints(S.p[more], S.R[more], grid)
        node2 = arm.node_cost(q2, valid2, grid)
        order = np.argsort(np.concatenate((idx, more)), kind="stable")
        idx = np.concatenate((idx, more))[order]
        q = np.concatenate((q, q2), axis=1)[:, order]
        valid, node = (np.concatenate(pair)[order] for pair in ((valid, valid2), (node, node2)))
    free = int(np.searchsorted(idx, free))  # the steps in the rapids (all their samples are searched)
    if np.isfinite(pin):  # start from the grid value nearest where the arm is
        node[0] += np.where(np.arange(grid.size) == int(np.abs(grid - pin).argmin()), 0.0, OUT_OF_REACH)[None]
    n = idx.size
    shifts = np.arange(-MAX_STEP, MAX_STEP + 1)
    G = grid.size
    pred = np.arange(G)[None, :] - shifts[:, None]  # (2K+1, G): the predecessor of g by each shift
    src = np.clip(pred, 0, G - 1)
    D, back = _min_plus(arm, q, valid, node, S.X[idx], S.t[idx], free, rate, gstep, shifts)
    b = int(D.min(axis=1).argmin())
    g = np.empty(n, dtype=np.int64)
    g[-1] = int(D[b].argmin())
    for i in range(n - 2, -1, -1):  # backtrack (integers only)
        g[i] = src[back[i, b, g[i + 1]], g[i + 1]]
    return np.interp(np.arange(n_all), idx, grid[g]), b


def _joined(a: _Samples, b: _Samples) -> _Samples:
    """The samples of a gap followed by those of its run (for the grid search)."""
    def cat(f: str) -> np.ndarray:
        return np.concatenate((getattr(a, f), getattr(b, f)))

    return _Samples(cat("X"), cat("t"), cat("p"), cat("R"), cat("tl"), cat("move"), cat("x"), b.cuts)


def _gap_curves(moves, rapids: list, path: np.ndarray, start: float, end: float) -> dict:
    """The spin of each rapid of a gap {move index: SpinCurve}: a C2 cubic B-spline in the rapid's arc length from
    where the previous one ended (``start`` for the first) to the grid path's value at its end (``end``, the run's
    start, for the last), near the grid path between (least squares with both ends pinned)."""
    out = {}
    a = start
    for i, (k, _, rows) in enumerate(rapids):
        L = float(moves[k].path.length)
        b = end if i == len(rapids) - 1 else float(path[rows[-1]])
        x = moves[k].path.length * np.linspace(0.0, 1.0, rows.size)
        y = path[rows]
        inner = max(0, min(4, rows.size - 2))
        t = np.concatenate(([0.0] * SPIN_DEGREE, np.linspace(0.0, L, inner + 2), [L] * SPIN_DEGREE))
        K = t.size - SPIN_DEGREE - 1
        c = np.linspace(a, b, K)
        c[:2], c[-2:] = a, b  # at rest at both ends, at the pinned values
        if K > 4 and L > 0.0:
            B = BSpline.design_matrix(np.clip(x, 0.0, L), t, SPIN_DEGREE).toarray()
            fixed = B[:, :2] @ c[:2] + B[:, -2:] @ c[-2:]
            c[2:-2] = np.linalg.lstsq(B[:, 2:-2], y - fixed, rcond=None)[0]
        out[k] = SpinCurve(t, c) if L > 0.0 else SpinCurve.constant(b)
        a = b
    return out


def _knots(end: float) -> np.ndarray:
    """Clamped cubic knots on [0, end] with uniform interior knots (at most MAX_COEFFS coefficients)."""
    pieces = max(1, MAX_COEFFS - SPIN_DEGREE)
    return np.concatenate(([0.0] * SPIN_DEGREE, np.linspace(0.0, end, pieces + 1), [end] * SPIN_DEGREE))


def _refine(moves, S: _Samples, target: np.ndarray, rate: float, acc: float, pin: float = math.nan) -> SpinCurve:
    """The C2 spin (a clamped cubic B-spline of the run coordinate) nearest the grid path under the spin bounds;
    starting at ``pin`` exactly where that is given (the arm's spin where the rapids before cannot change it)."""
    end = float(S.X[-1])
    base = float(pin) if np.isfinite(pin) else 0.0
    rate, acc = BOUND_SHARE * rate, BOUND_SHARE ** 2 * acc  # held at the constraint points: a margin between them
    if end <= 0.0:
        return SpinCurve.constant(base if np.isfinite(pin) else float(target[0]))
    t = _knots(end)
    cols = slice(1, None) if np.isfinite(pin) else slice(None)  # pinned: the first coefficient is psi(0)
    B0 = BSpline.design_matrix(S.X, t, SPIN_DEGREE).toarray()
    K = B0.shape[1]
    eye = np.eye(K)
    basis = BSpline(t, eye, SPIN_DEGREE)
    d1, d2 = basis.derivative(1), basis.derivative(2)
    B1, B2 = d1(S.X), d2(S.X)  # (n, K): psi' and psi'' at the samples per coefficient
    # the bounds in time at the planned feed: |psi' v| <= rate, |psi'' v^2 + psi' a| <= acc
    v, a = _feed_at(moves, S)
    A1 = B1 * v[:, None]
    A2 = B2 * (v ** 2)[:, None] + B1 * a[:, None]
    if S.cuts:  # the time laws' phase boundaries and midpoints: where the feed accelerates
        Xe, ve, ae = _phase_points(moves, S.cuts)
        E1, E2 = d1(Xe), d2(Xe)
        A1 = np.vstack((A1, E1 * ve[:, None]))
        A2 = np.vstack((A2, E2 * (ve ** 2)[:, None] + E1 * ae[:, None]))
    # the unknowns: the coefficients less the base (derivatives do not see a constant), the first one fixed if pinned
    B0, A1, A2 = B0[:, cols], A1[:, cols], A2[:, cols]
    y = target - base
    D = np.diff(eye, n=2, axis=0)[:, cols]
    smooth = 1e-4
    m = B0.shape[1]
    lhs = B0.T @ B0 + smooth * D.T @ D + 1e-9 * np.eye(m)
    c0 = np.linalg.solve(lhs, B0.T @ y)

    def scale_into(c):
        r1 = np.abs(A1 @ c).max(initial=0.0) / rate if rate > 0 else math.inf
        r2 = np.abs(A2 @ c).max(initial=0.0) / acc if acc > 0 else math.inf
        return c / max(1.0, r1, r2) if np.isfinite(max(r1, r2)) else np.zeros_like(c)

    if rate > 0.0 and acc > 0.0:  # the bounds as rows of |M c| <= 1 (rate rows, then acceleration rows)
        M = np.vstack((A1 / rate, A2 / acc))
        c = c0 if np.abs(M @ c0).max(initial=0.0) <= 1.0 else scale_into(_bounded_fit(lhs, B0.T @ y, M, scale_into(c0)))
    else:  # no spin change allowed
        c = np.zeros_like(c0)
    full = np.zeros(K)
    full[cols] = c
    # checked on every cut's time law every 2 ms: what is over the bounds between the constraint points scales down
    over = _over_bounds(moves, S, SpinCurve(t, base + full), rate / BOUND_SHARE, acc / BOUND_SHARE ** 2)
    return SpinCurve(t, base + full / max(1.0, over))


#: Steps of the active-set method of the spin's bounded fit at most (each adds or drops one bound; about twice the
#: bounds active at the optimum are needed, and every step stays within all the bounds).
FIT_STEPS = 400


def _bounded_fit(H: np.ndarray, g: np.ndarray, M: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Coefficients c (m,) minimizing 1/2 c^T H c - g^T c (H (m, m) positive definite) subject to |M c| <= 1 for every
    row of M (r, m), from x (m,) within those bounds.

    The primal active-set method for convex quadratic programs (Nocedal and Wright, Numerical Optimization, 2nd ed.,
    algorithm 16.3): each step solves the equality-constrained problem on the working set (its KKT system, m + |W|
    unknowns) and moves to its solution or to the first bound in the way, which joins the set; at a solution of the
    working set a bound with a negative multiplier leaves it; the optimum is where none does. H is exact, so the steps
    are a few dozen for the bounds active at the optimum, whatever the rows (thousands); every iterate is within the
    bounds, and the last one is returned if the steps run out."""
    m = x.size
    G = np.vstack((M, -M))  # G c <= 1
    work: list[int] = []
    tol = 1e-12
    for _ in range(FIT_STEPS):
        k = len(work)
        Gw = G[work]
        K = np.zeros((m + k, m + k))
        K[:m, :m], K[:m, m:], K[m:, :m] = H, Gw.T, Gw
        rhs = np.concatenate((g - H @ x, np.zeros(k)))  # (16.39): the step p and the multipliers at x + p
        try:
            sol = np.linalg.solve(K, rhs)
        except np.linalg.LinAlgError:
            sol = np.linalg.lstsq(K, rhs, rcond=None)[0]
        p, lam = sol[:m], sol[m:]
        if np.abs(p).max() <= 1e-12 * max(1.0, np.abs(x).max()):
            if k == 0 or lam.min() >= -tol:
                break  # the KKT conditions hold: the optimum
            work.pop(int(lam.argmin()))  # the bound that holds the solution back leaves the set
            continue
        Gp = G @ p
        slack = 1.0 - G @ x
        ahead = Gp > tol * np.abs(p).max()
        ahead[work] = False
        ratios = np.where(ahead, np.maximum(slack, 0.0) / np.where(ahead, Gp, 1.0), np.inf)
        j = int(ratios.argmin())
        if ratios[j] >= 1.0:
            x = x + p
        else:
            x = x + ratios[j] * p
            work.append(j)
    return x


def _over_bounds(moves, S: _Samples, curve: SpinCurve, rate: float, acc: float) -> float:
    """The largest ratio of the spin's rate and acceleration in time to their bounds over the run's cuts at their
    planned time laws (a spin over the bounds by this factor, less the base, scales back into them).

    Exact over the phases at constant feed v, where the rate is v |psi'(s)| (psi' quadratic between knots: its largest
    size at the phase's ends, the knots and the zeros of psi'' inside) and the acceleration v^2 |psi''(s)| (linear
    between knots); every 2 ms (the controller's period) over the phases where the feed changes."""
    if not S.cuts or curve.is_constant:
        return 0.0
    kn = curve.knots
    spline = BSpline(kn, curve.coeffs, SPIN_DEGREE, extrapolate=False)
    inner = np.unique(kn)
    d2 = spline(inner, 2)
    cross = d2[:-1] * d2[1:] < 0.0  # psi'' changes sign inside a knot interval: an extreme of psi' there
    w = d2[:-1][cross] / (d2[:-1][cross] - d2[1:][cross])
    vertices = inner[:-1][cross] + w * np.diff(inner)[cross]
    special = np.sort(np.concatenate((inner, vertices)))
    xs, vs, as_ = [], [], []
    for k, X0 in S.cuts:
        prof = moves[k].profile
        dur = np.diff(prof.t)
        cruise = (prof.j == 0.0) & (prof.a0 == 0.0)
        for p in np.flatnonzero(cruise & (dur > 0.0)):  # at constant feed: the ends, knots and extremes of psi'
            xa, xb = X0 + prof.s0[p], X0 + prof.s0[p] + prof.v0[p] * dur[p]
            x = np.concatenate(([xa, xb], special[(special > xa) & (special < xb)]))
            xs.append(x)
            vs.append(np.full(x.size, prof.v0[p]))
            as_.append(np.zeros(x.size))
        changing = np.flatnonzero(~cruise & (dur > 0.0))
        if changing.size:  # where the feed changes: every 2 ms
            m = np.minimum(np.maximum(2, np.ceil(dur[changing] / 2e-3).astype(np.int64) + 1), 100_001)
            start = np.repeat(np.cumsum(m) - m, m)
            frac = (np.arange(int(m.sum())) - start) / np.repeat(m - 1, m)
            tt = np.repeat(prof.t[changing], m) + frac * np.repeat(dur[changing], m)
            st, vt, at = prof.state(tt)
            xs.append(X0 + st)
            vs.append(vt)
            as_.append(at)
    if not xs:
        return 0.0
    x, v, a = np.clip(np.concatenate(xs), kn[0], kn[-1]), np.concatenate(vs), np.concatenate(as_)
    d1, d2 = spline(x, 1), spline(x, 2)
    return max(float(np.abs(d1 * v).max()) / rate, float(np.abs(d2 * v * v + d1 * a).max()) / acc)


#: Share of the spin rate bound the refinement asks at its constraint points (its square of the acceleration
#: bound): the rest covers the spin between them.
BOUND_SHARE = 0.9
#: A gap's rapids may be slowed for a spin change to at most this many times their planned time (or 2 s); where
#: that cannot carry half a turn at ``spin_rate``, the spin is held through the gap and the run starts where the arm is.
GAP_SLOWDOWN = 4.0


def _gap_flexible(moves, gap_ks, rate: float) -> bool:
    """Whether the rapids of a gap can carry half a turn of spin within :data:`GAP_SLOWDOWN` of their time."""
    rapid = [k for k in gap_ks if moves[k].kind == "rapid"]
    if not rapid:
        return False
    budget = max(GAP_SLOWDOWN * sum(float(moves[k].profile.duration) for k in rapid), 2.0)
    return rate * budget >= 1.5 * math.pi  # (the transition's peak rate is 1.5 times its mean)


def choose_spin(moves, settings) -> SpinChoice:
    """The spin of every run of passes (see the module doc) and the moves with it.

    Parameters
    ----------
    moves : list of PlannedMove
        The job's moves with the RMM spin, planned in the part frame.
    settings : PlanSettings
        Checked, with a robot; ``part_frame`` a frame (the placement already made), ``tcp``, ``reach_step``,
        ``spin_rate``, ``spin_acceleration``.
    """
    tic = time.perf_counter()
    Tb = as_transform(settings.part_frame, "part_frame")
    arm = _Arm(settings.robot, settings.tcp)
    rate, acc = float(settings.spin_rate), float(settings.spin_acceleration)
    psi_x: dict[int, SpinCurve] = {}  # the spin of every move of a run, in the move's coordinate
    figures: dict[int, SpinFigures] = {}
    ends: list[tuple[float, float]] = []  # per group: (spin at the run's start, at its end)
    runs = spun_runs = 0
    plan_groups = groups(moves)
    gap_curves: dict[int, SpinCurve] = {}
    prev = math.nan  # the spin where the arm is (the previous run's end)
    step = float(settings.reach_step)
    todo = []  # every group's moves of its run, and their samples
    for g in plan_groups:
        ks = [k for k in g.run if moves[k].kind in ("cut", "reorientation", "dwell", "skipped")]
        todo.append((ks,) + _samples(moves, ks, Tb, step) if ks else None)
    rmm = iter(_rmm_figures(arm, [w[1] for w in todo if w is not None]))
    for g, work in zip(plan_groups, todo, strict=True):
        if work is None:
            ends.append((math.nan, math.nan))
            continue
        runs += 1
        ks, S, offsets = work
        fig0, key0 = next(rmm)
        b0 = _best(key0)
        gap_ks = [k for k in g.gap if moves[k].kind in ("rapid", "reorientation") and moves[k].profile is not None]
        moved = bool(np.isfinite(prev)) and prev != 0.0
        flexible = bool(np.isfinite(prev)) and _gap_flexible(moves, gap_ks, rate)
        held = bool(np.isfinite(prev)) and not flexible  # the rapids cannot carry a spin change: start where it is
        end = max(float(S.X[-1]), 1e-300)
        if held and moved:
            curve = SpinCurve.constant(prev, end)
            figh, keyh = _figures(arm, S, np.full(S.X.size, prev))
            bh = _best(keyh)
            fig, b, key = figh[bh], bh, keyh[bh]
        else:
            curve = SpinCurve.constant(0.0, end)
            fig, b, key = fig0[b0], b0, key0[b0]
        if S.X.size >= 2 and (moved or not _fine(fig0, b0, arm.wrist3)):
            Sg, rapids = _gap_samples(moves, gap_ks, Tb, step, advance=flexible) if gap_ks else (None, [])
            both = S if Sg is None else _joined(Sg, S)
            free = 0 if Sg is None else Sg.X.size
            path, _ = _grid_path(arm, both, rate, free, prev)
            target = path[free:]
            if np.any(target) or held:
                cand = _refine(moves, S, target, rate, acc, prev if held else math.nan)
                fig1, key1 = _figures(arm, S, cand(S.X))
                b1 = _best(key1)
                if tuple(key1[b1]) < tuple(key) or (moved and tuple(key1[b1]) <= tuple(key)):
                    curve, fig, b = cand, fig1[b1], b1
            if Sg is not None and flexible and prev != float(curve(0.0)[0]):
                gap_curves.update(_gap_curves(moves, rapids, path[:free], prev, float(curve(0.0)[0])))
        spun_runs += int(not curve.is_zero)
        first_cut = next(k for k in ks if moves[k].kind == "cut")
        figures[first_cut] = SpinFigures(int(S.X.size), int(b), fig0[b0, :5].astype(float), fig[:5].astype(float))
        for k in ks:
            off = offsets[k]
            if moves[k].kind == "reorientation":  # psi stands over a turn in place
                psi_x[k] = SpinCurve.constant(float(curve(off)[0]), float(moves[k].frames.span))
            else:
                psi_x[k] = SpinCurve(curve.knots - off, curve.coeffs)
        s0, s1 = (float(curve(0.0)[0]), float(curve(S.X[-1])[0]))
        ends.append((s0, s1))
        prev = s1
    out = _apply(moves, plan_groups, {**psi_x, **gap_curves}, figures, ends, rate, acc)
    return SpinChoice(out, runs, spun_runs, time.perf_counter() - tic)


def _apply(moves, plan_groups, psi_x: dict, figures: dict, ends: list, rate: float, acc: float) -> list:
    """Every move with its spin: runs as chosen, gaps moving from one run's end spin to the next run's start."""
    out = list(moves)
    prev = math.nan  # the spin where the arm is
    starts = [e[0] for e in ends]
    for gi, g in enumerate(plan_groups):
        nxt = starts[gi] if not math.isnan(starts[gi]) else prev
        if math.isnan(prev):
            prev = nxt if not math.isnan(nxt) else 0.0
        if math.isnan(nxt):
            nxt = prev
        rapid_len = sum(float(moves[k].path.length) for k in g.gap if moves[k].kind == "rapid")
        done = 0.0
        for k in g.gap:
            m = moves[k]
            if k in psi_x:  # the spin the grid search chose through the gap
                out[k] = _spun_rapid(m, psi_x[k], rate, acc) if m.kind == "rapid" else _spun_move(m, psi_x[k])
                done += float(m.path.length) if m.kind == "rapid" else 0.0
            elif m.kind == "rapid" and rapid_len > 0.0:
                L = float(m.path.length)
                a = prev + (nxt - prev) * done / rapid_len
                done += L
                b = prev + (nxt - prev) * done / rapid_len
                out[k] = _spun_rapid(m, SpinCurve.transition(a, b, L), rate, acc)
            else:
                here = prev + (nxt - prev) * done / rapid_len if rapid_len > 0.0 else nxt
                out[k] = _spun_move(m, SpinCurve.constant(here, _coordinate_end(m)))
        for k in g.run:
            m = moves[k]
            curve = psi_x.get(k)
            if curve is None:  # a move inside the run without motion of its own: the spin where it is
                curve = SpinCurve.constant(float(ends[gi][0]), _coordinate_end(m))
            out[k] = _spun_move(m, curve, figures.get(k))
        if not math.isnan(ends[gi][1]):
            prev = ends[gi][1]
        else:
            prev = nxt
    return out


def _coordinate_end(m) -> float:
    if m.kind in ("cut", "rapid"):
        return float(m.path.length)
    if m.kind == "reorientation":
        return float(m.frames.span)
    return 1.0


def _spun_move(m, curve: SpinCurve, figures: SpinFigures | None = None):
    """The move with its frames turned by the spin (start and end frames too); the move itself where the spin is 0
    and there are no figures to carry."""
    if figures is None and curve.is_zero:
        return m
    if m.frames is not None:
        frames = SpunFrames(m.frames, curve, figures)
        return replace(m, frames=frames, start_frame=frames.start, end_frame=frames.end)
    psi = curve(0.0)
    return replace(m, start_frame=spun(m.start_frame[None], psi)[0], end_frame=spun(m.end_frame[None], psi)[0])


def _spun_rapid(m, curve: SpinCurve, rate: float, acc: float):
    """A rapid with a spin transition, slowed so that the spin keeps its bounds (rate and acceleration in time)."""
    moved = _spun_move(m, curve)
    L = float(m.path.length)
    x = np.linspace(0.0, L, 1025)
    d1 = 1.01 * float(np.abs(curve(x, 1)).max())  # (the largest between the samples: within 1 %)
    d2 = 1.01 * float(np.abs(curve(x, 2)).max())
    if d1 == 0.0 or m.profile is None:
        return moved
    lim = m.profile.limits
    v = float(m.profile.commanded.max())
    v_new = min(v, rate / d1, math.sqrt(0.5 * acc / d2) if d2 > 0.0 else math.inf)
    a_new = min(float(lim.acceleration), 0.5 * acc / d1)
    if v_new >= v and a_new >= lim.acceleration:
        return moved
    j_new = float(lim.jerk) * a_new / float(lim.acceleration)
    profile = plan_feed(L, v_new, MotionLimits(v_new, a_new, j_new))
    return replace(moved, profile=profile)


def spin_rates(m) -> tuple[float, float]:
    """Largest spin rate (rad/s) and acceleration (rad/s^2) in time of a move with SpunFrames, at its planned
    time law (sampled every 2 ms)."""
    if not isinstance(m.frames, SpunFrames) or m.profile is None or m.frames.spin.is_zero:
        return 0.0, 0.0
    T = float(m.profile.duration)
    t = np.linspace(0.0, T, min(max(3, math.ceil(T / 2e-3) + 1), 100_001))
    x, v, a = m.profile.state(t)
    c = m.frames.spin
    d1, d2 = c(x, 1), c(x, 2)
    if m.kind == "reorientation":
        d1, d2 = np.zeros_like(x), np.zeros_like(x)
    return float(np.abs(d1 * v).max()), float(np.abs(d2 * v * v + d1 * a).max())


def spin_summary(moves) -> dict | None:
    """What the spin bought over a job's moves, against the RMM spin on the same samples (None without SpunFrames):
    runs rated and spun, least singularity and joint-limit margins, sample steps too fast for a joint, samples out
    of reach, wrist travel, largest spin rate and acceleration at the planned time laws, and whether the spin
    alone makes every run reachable."""
    figs = [m.frames.figures for m in moves if isinstance(m.frames, SpunFrames) and m.frames.figures is not None]
    if not figs:
        return None
    rmm = np.array([f.rmm for f in figs])
    reach = np.array([f.reach for f in figs])
    spun_moves = [m for m in moves if isinstance(m.frames, SpunFrames) and not m.frames.spin.is_zero
                  and np.ptp(m.frames.spin.coeffs) > 0.0]
    rates = [spin_rates(m) for m in spun_moves]

    def side(a: np.ndarray) -> dict:
        return {"singularity_margin": float(a[:, 0].min()), "joint_margin_deg": math.degrees(float(a[:, 1].min())),
                "too_fast_steps": int(a[:, 2].sum()), "out_of_reach_samples": int(a[:, 3].sum()),
                "wrist_travel_deg": math.degrees(float(a[:, 4].sum()))}

    return {"runs": len(figs), "spun_runs": int(sum(not np.array_equal(f.rmm, f.reach) for f in figs)),
            "samples": int(sum(f.samples for f in figs)), "rmm": side(rmm), "reach": side(reach),
            "max_spin_deg": math.degrees(max((float(np.abs(m.frames.spin.coeffs).max()) for m in spun_moves),
                                             default=0.0)),
            "max_spin_rate_deg_s": math.degrees(max((r[0] for r in rates), default=0.0)),
            "max_spin_acceleration_deg_s2": math.degrees(max((r[1] for r in rates), default=0.0)),
            "reachable_only_by_spin": bool(rmm[:, 3].sum() > 0 and reach[:, 3].sum() == 0)}
