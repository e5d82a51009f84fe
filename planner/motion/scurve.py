"""Jerk-limited speed transitions between two constant speeds (the S-curve), in closed form.

A change of speed from va to vb with |jerk| <= J and |acceleration| <= A, starting and ending at zero
acceleration, takes three constant-jerk phases: jerk +-J for Tj, zero jerk at the peak acceleration
for Ta, jerk -+J for Tj. With d = |vb - va| (standard S-curve kinematics, e.g. Biagiotti & Melchiorri,
"Trajectory Planning for Automatic Machines and Robots", 2008, section 3.4):

- d >= A^2 / J:  Tj = A / J,         Ta = d / A - A / J,  peak acceleration A;
- d <  A^2 / J:  Tj = sqrt(d / J),   Ta = 0,              peak acceleration sqrt(d J).

The speed profile is point-symmetric about the midpoint of the transition, so the distance covered is
exactly the mean speed times the duration: D = (va + vb) / 2 * (2 Tj + Ta).
"""

from __future__ import annotations

import math

import numpy as np


def phase_times(d, A: float, J: float) -> tuple[np.ndarray, np.ndarray]:
    """(Tj, Ta) of a speed change |vb - va| = d (any shape), s."""
    d = np.asarray(d, dtype=float)
    long = d >= A * A / J
    Tj = np.where(long, A / J, np.sqrt(np.maximum(d, 0.0) / J))  # double S profile, Biagiotti-Melchiorri 2008 s. 3.4
    Ta = np.where(long, d / A - A / J, 0.0)
    return Tj, Ta


def duration(d, A: float, J: float) -> np.ndarray:
    """Duration 2 Tj + Ta (s) of a speed change d (m/s)."""
    Tj, Ta = phase_times(d, A, J)
    return 2.0 * Tj + Ta


def distance(va, vb, A: float, J: float) -> np.ndarray:
    """Distance (m) covered while the speed changes from va to vb: (va + vb) / 2 * duration."""
    va = np.asarray(va, dtype=float)
    vb = np.asarray(vb, dtype=float)
    return 0.5 * (va + vb) * duration(np.abs(vb - va), A, J)


def reach(v0: float, ell: float, A: float, J: float) -> float:
    """Largest speed v >= v0 with distance(v0, v) <= ell: the speed reachable from v0 within ell metres.

    By symmetry it is also the largest speed from which v0 can be reached within ell. Closed form:
    with d = v - v0, the long case solves (2 v0 + d)(d / A + A / J) = 2 ell (a quadratic in d), the
    short case (2 v0 + x^2) x = ell sqrt(J) with x = sqrt(d) (a depressed cubic, one real root).
    """
    if ell <= 0.0:
        return v0
    dstar = A * A / J
    if ell >= (2.0 * v0 + dstar) * A / J:  # distance of the change d* = A^2 / J
        b = 2.0 * v0 + dstar
        c = 2.0 * A * (v0 * A / J - ell)  # < 0 here
        return v0 + -2.0 * c / (b + math.sqrt(b * b - 4.0 * c))  # root of d^2 + b d + c, no cancellation
    p, q = 2.0 * v0, ell * math.sqrt(J)
    # x^3 + p x - q = 0 with p >= 0 has one real root (Cardano). Where p dominates, the hyperbolic form
    # x = 2 sqrt(p/3) sinh(asinh(z) / 3), z = 3 q / (2 p) sqrt(3 / p), avoids cancellation; where q
    # dominates (z > 1, also p -> 0), the radical form x = u - p / (3 u), u = cbrt(q/2 + sqrt(q^2/4 + p^3/27)).
    if p > 0.0 and 1.5 * q * math.sqrt(3.0 / p) <= p:
        x = 2.0 * math.sqrt(p / 3.0) * math.sinh(math.asinh(1.5 * q / p * math.sqrt(3.0 / p)) / 3.0)
    else:
        w = (0.5 * q + math.sqrt(0.25 * q * q + p**3 / 27.0)) ** (1.0 / 3.0)
        x = w - p / (3.0 * w)
    x -= (x**3 + p * x - q) / (3.0 * x * x + p)  # one Newton step polishes the last bits
    return v0 + x * x


def transition_phases(va, vb, s_start, A: float, J: float) -> tuple[np.ndarray, ...]:
    """The three constant-jerk phases of speed changes va -> vb starting at arc lengths s_start.

    All arguments broadcast to shape (m,). Returns arrays of shape (m, 3): phase durations, start arc
    length, start speed, start acceleration and jerk of each phase (a phase may have zero duration).
    """
    va, vb, s_start = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (va, vb, s_start)))
    sg = np.sign(vb - va)
    Tj, Ta = phase_times(np.abs(vb - va), A, J)
    total = 0.5 * (va + vb) * (2.0 * Tj + Ta)
    jv = sg * J * Tj * Tj / 2.0  # speed gained in a jerk phase
    ap = sg * J * Tj  # peak acceleration
    d1 = va * Tj + sg * J * Tj**3 / 6.0  # distance of phase 1 (jerk +-J from zero acceleration)
    d3 = vb * Tj - sg * J * Tj**3 / 6.0  # distance of phase 3 (jerk -+J down to zero acceleration)
    dur = np.stack((Tj, Ta, Tj), axis=-1)
    s0 = np.stack((s_start, s_start + d1, s_start + total - d3), axis=-1)
    v0 = np.stack((va, va + jv, vb - jv), axis=-1)
    a0 = np.stack((np.zeros_like(ap), ap, ap), axis=-1)
    jerk = np.stack((sg * J, np.zeros_like(sg), -sg * J), axis=-1)
    return dur, s0, v0, a0, jerk
