"""A feed profile s(t) along a path: a sequence of constant-jerk phases, evaluated in closed form."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.motion.limits import MotionInputError, MotionLimits


@dataclass(frozen=True, eq=False)
class FeedProfile:
    """Arc length s(t) along a path as a piecewise cubic in time (constant jerk per phase).

    Within phase p, with tau = t - t[p]: s = s0 + v0 tau + a0 tau^2 / 2 + j tau^3 / 6 (exact
    kinematics of constant jerk). Before t = 0 nothing moves; after ``duration`` the tool rests at
    s = ``length``.

    Attributes
    ----------
    t : ndarray (P + 1,)
        Phase start times, s; ``t[-1]`` is the duration.
    s0, v0, a0, j : ndarray (P,)
        Arc length (m), speed (m/s), acceleration (m/s^2) at the start of each phase, and its jerk
        (m/s^3).
    length : float
        Path length, m.
    limits : MotionLimits
        The limits the profile was planned with.
    level_bounds : ndarray (m + 1,)
        Arc lengths where the commanded feed changes (0 and ``length`` included).
    commanded : ndarray (m,)
        Commanded feed between consecutive level bounds (span feed, capped by the speed and angular
        speed limits), m/s.
    cruise : ndarray (m,)
        Speed planned on each level (lower than ``commanded`` where a level is too short to reach it).
    """

    t: np.ndarray
    s0: np.ndarray
    v0: np.ndarray
    a0: np.ndarray
    j: np.ndarray
    length: float
    limits: MotionLimits
    level_bounds: np.ndarray
    commanded: np.ndarray
    cruise: np.ndarray

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"t": self.t, "s0": self.s0, "v0": self.v0, "a0": self.a0, "j": self.j, "length": self.length,
                "limits": self.limits, "level_bounds": self.level_bounds, "commanded": self.commanded,
                "cruise": self.cruise}

    @classmethod
    def from_state(cls, state: dict) -> FeedProfile:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    @property
    def duration(self) -> float:
        """Total time of the motion, s."""
        return float(self.t[-1])

    @property
    def n_phases(self) -> int:
        return self.j.size

    def _locate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if np.isnan(t).any():
            raise MotionInputError(f"t[{int(np.argmax(np.isnan(t)))}]", "time is NaN")
        p = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, self.n_phases - 1)
        tau = np.clip(t - self.t[p], 0.0, None)
        return t, p, tau

    def s(self, t) -> np.ndarray:
        """Arc length (m) at times t (n,), exact cubic per phase; 0 before the start, ``length`` after."""
        return self._s(*self._locate(t))

    def v(self, t) -> np.ndarray:
        """Speed ds/dt (m/s) at times t (n,)."""
        return self._v(*self._locate(t))

    def a(self, t) -> np.ndarray:
        """Acceleration d^2 s/dt^2 (m/s^2) at times t (n,)."""
        return self._a(*self._locate(t))

    def state(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(:meth:`s`, :meth:`v`, :meth:`a`) at times t (n,), the phases found once."""
        located = self._locate(t)
        return self._s(*located), self._v(*located), self._a(*located)

    def _s(self, t, p, tau) -> np.ndarray:
        # constant jerk: s = s0 + v0 tau + a0 tau^2 / 2 + j tau^3 / 6 (Horner)
        out = self.s0[p] + tau * (self.v0[p] + tau * (0.5 * self.a0[p] + tau * (self.j[p] / 6.0)))
        out = np.where(t >= self.t[-1], self.length, out)
        return np.where(t <= 0.0, 0.0, np.minimum(out, self.length))

    def _v(self, t, p, tau) -> np.ndarray:
        out = self.v0[p] + tau * (self.a0[p] + tau * (0.5 * self.j[p]))
        return np.where((t <= 0.0) | (t >= self.t[-1]), 0.0, out)

    def _a(self, t, p, tau) -> np.ndarray:
        out = self.a0[p] + tau * self.j[p]
        return np.where((t <= 0.0) | (t >= self.t[-1]), 0.0, out)

    def jerk(self, t) -> np.ndarray:
        """Jerk d^3 s/dt^3 (m/s^3) at times t (n,) (right-sided at phase starts)."""
        t, p, _ = self._locate(t)
        return np.where((t < 0.0) | (t >= self.t[-1]), 0.0, self.j[p])

    def in_cruise(self, t) -> np.ndarray:
        """True at times t (n,) inside a constant-speed phase (zero jerk and zero acceleration)."""
        t, p, _ = self._locate(t)
        return (t > 0.0) & (t < self.t[-1]) & (self.j[p] == 0.0) & (self.a0[p] == 0.0)

    def commanded_at(self, s) -> np.ndarray:
        """Commanded feed (m/s) at arc lengths s (n,)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        k = np.clip(np.searchsorted(self.level_bounds, s, side="right") - 1, 0, self.commanded.size - 1)
        return self.commanded[k]

    def time_at(self, s) -> np.ndarray:
        """Time (s) at which the tool reaches arc lengths s (n,) in [0, length]: the inverse of s(t).

        Where the tool rests (only at the ends), the first time it is there.
        """
        s = np.atleast_1d(np.asarray(s, dtype=float))
        bad = ~np.isfinite(s) | (s < 0.0) | (s > self.length)
        if bad.any():
            i = int(np.argmax(bad))
            raise MotionInputError(f"s[{i}]", f"arc length {s[i]} is outside the path [0, {self.length}]")
        p = np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, self.n_phases - 1)
        dur = np.diff(self.t)[p]
        lo, hi = np.zeros_like(s), dur.copy()
        s0, v0, a0, j = self.s0[p], self.v0[p], self.a0[p], self.j[p]
        tau = 0.5 * (lo + hi)
        for _ in range(200):  # safeguarded Newton on the monotone cubic of the phase
            f = s0 + tau * (v0 + tau * (0.5 * a0 + tau * (j / 6.0))) - s
            lo = np.where(f <= 0.0, tau, lo)
            hi = np.where(f > 0.0, tau, hi)
            df = v0 + tau * (a0 + tau * (0.5 * j))
            step = np.where(df > 0.0, tau - f / np.where(df > 0.0, df, 1.0), 0.5 * (lo + hi))
            new = np.where((step < lo) | (step > hi), 0.5 * (lo + hi), step)
            if np.all(np.abs(new - tau) <= 4.0 * np.finfo(float).eps * np.maximum(self.t[p + 1], 1.0)):
                tau = new
                break
            tau = new
        return np.where(s <= 0.0, 0.0, np.where(s >= self.length, self.t[-1], self.t[p] + tau))
