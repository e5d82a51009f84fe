"""A fixed-period loop on an absolute schedule, and its timing figures.

:class:`Schedule` paces a control loop on the deadlines ``t0 + k * period`` (wall clock,
``time.perf_counter``): it sleeps until ``spin`` seconds before the next deadline, then spins to it. Unlike a
relative wait (ur_rtde's ``initPeriod``/``waitPeriod``, which waits one period from the start of each
iteration), the small delays between iterations do not add up: the loop's mean rate is the controller's.

An iteration that starts a whole period or more late has missed periods: they are counted (never hidden) and
the schedule moves on from the late start (``t0`` shifts by the missed periods), so that the targets never come
faster than one per period afterwards (catching up would skip targets on the controller's side, a jump of the
arm). :class:`LoopStats` holds the figures: the period between iteration starts (p50, p99, max, from a
fixed-size histogram: bounded memory for a run of any length), the mean rate and the missed periods.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

#: Histogram of the periods: 10 us bins up to 50 ms (anything longer counts in the last bin; ``max`` is exact).
_BIN = 1e-5
_NBINS = 5000


@dataclass(frozen=True)
class LoopStats:
    """Timing of a fixed-period loop: ``period`` s nominal; ``n`` periods measured (between iteration starts);
    ``rate`` their mean rate, Hz; ``p50``, ``p99``, ``max`` the period, s (p50/p99 to 10 us); ``missed`` the
    periods lost (iterations that started one period or more late, counted in whole periods)."""

    period: float
    n: int
    rate: float
    p50: float
    p99: float
    max: float
    missed: int

    def describe(self) -> str:
        held = (f" (the arm held its last target through each: the job ran {1e3 * self.missed * self.period:.0f} ms "
                "late)" if self.missed else "")
        return (f"control loop {self.rate:.2f} Hz over {self.n} periods: period p50 {1e3 * self.p50:.3f} ms, "
                f"p99 {1e3 * self.p99:.3f} ms, max {1e3 * self.max:.3f} ms; {self.missed} missed periods{held}")


class Schedule:
    """Deadlines ``t0 + k * period`` (see the module doc).

    Parameters
    ----------
    period : float
        The loop's period, s (> 0).
    spin : float
        How long before a deadline the loop stops sleeping and spins, s (0.3 ms: a sleep on a loaded Linux
        machine wakes up to a few hundred microseconds late).
    """

    def __init__(self, period: float, spin: float = 3e-4) -> None:
        if not (isinstance(period, (int, float)) and math.isfinite(period) and period > 0):
            raise ValueError(f"period must be a positive number of seconds, got {period!r}")
        if not (isinstance(spin, (int, float)) and 0 <= spin < period):
            raise ValueError(f"spin must be within [0, period) s, got {spin!r}")
        self.period = float(period)
        self.spin = float(spin)
        self.t0 = 0.0
        self.k = 0
        self.missed = 0
        self._last = math.nan
        self._first = math.nan
        self._hist = [0] * _NBINS
        self._max = 0.0
        self._n = 0

    def start(self) -> float:
        """Begin: the first iteration starts now; returns its start time (perf_counter, s)."""
        now = time.perf_counter()
        self.t0 = now
        self.k = 0
        self._first = self._last = now
        return now

    def wait(self) -> float:
        """Wait for the next deadline (sleep, then spin); returns the time the iteration starts (perf_counter s).

        A start one period or more past its deadline counts its whole missed periods and moves the schedule on
        from there."""
        self.k += 1
        period = self.period
        due = self.t0 + self.k * period
        now = time.perf_counter()
        if now - due >= period:  # late by whole periods: count them, keep the phase, never catch up
            lost = int((now - due) // period)
            self.missed += lost
            self.t0 += lost * period
            due += lost * period
        rest = due - now - self.spin
        if rest > 0:
            time.sleep(rest)
        now = time.perf_counter()
        while now < due:
            now = time.perf_counter()
        self._count(now)
        return now

    def time_left(self) -> float:
        """Seconds until the next deadline (negative: it has passed)."""
        return self.t0 + (self.k + 1) * self.period - time.perf_counter()

    def _count(self, now: float) -> None:
        d = now - self._last
        self._last = now
        self._n += 1
        if d > self._max:
            self._max = d
        b = int(d / _BIN)
        self._hist[b if b < _NBINS else _NBINS - 1] += 1

    def stats(self) -> LoopStats:
        """The figures so far (see :class:`LoopStats`)."""
        n = self._n
        if n == 0:
            return LoopStats(self.period, 0, math.nan, math.nan, math.nan, math.nan, self.missed)

        def pct(p: float) -> float:
            want = p * n
            acc = 0
            for b, c in enumerate(self._hist):
                acc += c
                if acc >= want:
                    return min((b + 0.5) * _BIN, self._max)
            return self._max

        rate = n / (self._last - self._first) if self._last > self._first else math.nan
        return LoopStats(self.period, n, rate, pct(0.5), pct(0.99), self._max, self.missed)
