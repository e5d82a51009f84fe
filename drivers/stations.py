"""Where a job's digital outputs switch: at their stations on the path, reached by the ACTUAL tool.

One rule for every driver (:class:`drivers.ur.URDriver`, :class:`drivers.sim.SimDriver`): a planned change of
the trajectory's output bits at sample ``k`` is made when the actual TCP reaches the planned position of that
sample (passes the plane through it normal to the direction of travel, or comes within ``near`` m of it), not
when the servo target does: the arm lags its targets by the servo's following error, which would otherwise be
the switch's distance from its station. Where the tool comes to rest at the station and the next move leaves it in
another direction (the end of a cut before a rapid or a joint move), it is made where the actual TCP comes closest.
``late`` seconds of job time after its target was commanded it is made in any case (an arm that stopped short of
the station still switches, and the report shows how far off).
"""

from __future__ import annotations

import numpy as np

#: Planned samples looked back for the direction of travel at a station.
BACK = 50
#: A switch undone this many samples later or sooner is no switch (the output is kept as it is).
BLIP = 1


class Station:
    """A planned switch of outputs ``mask`` to ``value`` at job-wide sample ``k``, at position ``p`` (3,) m,
    travelled in the unit direction ``u`` (3,) (zeros: no direction, switched by distance only).

    ``near``: distance that counts as reached, m; ``late``: seconds after which it is made anyway; ``rate``:
    samples per second (the deadline in samples is ``k + late * rate``)."""

    __slots__ = ("k", "mask", "value", "p", "u", "deadline", "near", "close", "best")

    def __init__(self, k: int, mask: int, value: int, p, u, *, near: float = 5e-5, close: float = 2e-3,
                 late: float = 0.5, rate: float = 500.0) -> None:
        self.k, self.mask, self.value = int(k), int(mask), int(value)
        self.p = np.asarray(p, dtype=float).reshape(3)
        self.u = np.asarray(u, dtype=float).reshape(3)
        self.deadline = self.k + int(late * rate)
        self.near = float(near)
        self.close = float(close)
        self.best = np.inf  # the actual TCP's smallest squared distance from the station so far

    @classmethod
    def on_path(cls, k: int, mask: int, value: int, positions: np.ndarray, i: int, **kw) -> Station:
        """The station of sample ``k``, which is row ``i`` of the planned positions ``positions`` (n, 3) m (the
        rows before it give the direction of travel)."""
        i = min(int(i), positions.shape[0] - 1)
        back = positions[max(i - BACK, 0):i + 1]
        step = np.diff(back, axis=0)
        nz = np.flatnonzero(np.linalg.norm(step, axis=1) > 1e-9)
        u = step[nz[-1]] if nz.size else np.zeros(3)
        nu = float(np.linalg.norm(u))
        return cls(k, mask, value, positions[i], u / nu if nu > 0 else u, **kw)

    def reached(self, x, k: int) -> bool:
        """Whether the actual TCP at ``x`` (its first three values: position, m), with target sample ``k``
        commanded, has reached the station: passed its plane, come within ``near``, or, having come within
        ``close``, begun to move away from it (a station where the tool comes to rest and the next move leaves
        in another direction, e.g. the end of a cut before a rapid: the lagging TCP never passes the plane)."""
        d = np.asarray(x[:3], dtype=float) - self.p
        d2 = float(d @ d)
        if bool((self.u @ d) >= 0.0 and np.any(self.u)) or d2 <= self.near**2 or k >= self.deadline:
            return True
        if d2 < self.best:
            self.best = d2
            return False
        return d2 > self.best and self.best <= self.close**2


class Stations:
    """The switches not yet made, in order; ``switch(mask, value)`` makes one (the driver's output call)."""

    def __init__(self, switch) -> None:
        self._switch = switch
        self.pending: list[Station] = []

    def add(self, station: Station) -> None:
        """A new switch; one that undoes the pending switch of the sample just before it (the trajectory's output
        off for the one sample between two cuts joined at a corner) cancels it instead: the output stays as it
        is (the planned switches drop it too: :func:`drivers.plan_window.drop_blips`)."""
        last = self.pending[-1] if self.pending else None
        if (last is not None and last.mask == station.mask and station.k - last.k <= BLIP
                and last.value & last.mask != station.value & station.mask):
            self.pending.pop()
            return
        self.pending.append(station)

    def reached(self, x, k: int) -> None:
        """Make every pending switch the actual TCP at ``x`` has reached (in order)."""
        pending = self.pending
        while pending and pending[0].reached(x, k):
            ev = pending.pop(0)
            self._switch(ev.mask, ev.value)

    def flush(self) -> None:
        """Make every pending switch now (the end of a run)."""
        while self.pending:
            ev = self.pending.pop(0)
            self._switch(ev.mask, ev.value)

    def __bool__(self) -> bool:
        return bool(self.pending)
