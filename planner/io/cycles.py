"""Canned drilling cycles expanded into the moves they mean (shared by the APT and G-code readers).

A cycle is given by levels along the hole's tool axis ``a`` (unit, from the tip towards the spindle),
measured from a point ``P`` of the hole axis: the hole position of an APT ``GOTO`` (levels relative to
it), or the G-code hole ``X Y`` with the drilling coordinate 0 (levels are then the programmed Z, R).
For each hole, :func:`hole_moves` returns the tool-tip points, in order:

1. a rapid traverse to the hole axis at the tool's current level (omitted when the tool is already on
   it or its position is unknown);
2. a rapid along the axis to the clearance level (``R``, APT ``RAPTO``);
3. feed moves down to the bottom (``Z``, ``FEDTO``); a peck cycle feeds ``peck`` deep first, from the
   clearance level, then ``peck_next`` at a time (SOLIDWORKS CAM's ``1STPECK`` and ``SUBPECK``; the same
   depth by default), and between pecks either rapids out to the clearance level and back down to
   ``peck_clearance`` above the last depth (``"full"``: G83, APT ``DEEP``) or backs off by
   ``peck_clearance`` (``"chip"``: G73, APT ``BRKCHP``);
4. the dwell at the bottom (the caller records a ``dwell`` event after the bottom point);
5. the retract: a rapid (drilling) or a feed (tapping, boring) to the clearance level, then a rapid to
   the retract level if it is above (G98 initial level, APT ``RTRCTO``).

Every plunge is a feed move between two rapids, so the pass splitter makes each one a pass of its
own and never joins two holes into a cut.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Default back-off / re-approach distance between pecks, metres (Fanuc parameters 5114/5115 set it
#: per machine; 0.5 mm is a common value). Readers take ``peck_clearance`` to change it.
DEFAULT_PECK_CLEARANCE = 0.5e-3


@dataclass(frozen=True)
class DrillCycle:
    """One canned cycle's values, SI units, levels as offsets along the tool axis (metres).

    Attributes
    ----------
    name : str
        How the file names it ("G83", "CYCLE/DRILL,DEEP"), for messages.
    line : int
        Line of the record that set the cycle.
    clearance : float
        Level the tool rapids to before feeding (R, RAPTO).
    bottom : float
        Level of the hole bottom; must be below ``clearance``.
    retract : float or None
        Level the tool leaves the hole to; None: the level it came from (G98 initial level, RTRCTO AUTO).
        A retract level below the clearance level is the clearance level.
    feed : float
        Feed of the plunge (and of a fed retract), m/s; NaN: the reader's modal feed.
    peck : float
        Depth of the first peck (of each peck unless ``peck_next`` is given), metres (0: one feed to the bottom).
    peck_next : float
        Depth of each peck after the first, metres (0: ``peck``).
    peck_mode : {"", "full", "chip"}
        Between pecks: rapid out to the clearance level and back ("full") or back off ("chip").
    peck_clearance : float
        Back-off / re-approach distance between pecks, metres.
    dwell : float
        Seconds at the bottom (0: none).
    feed_out : bool
        The tool leaves the hole at the feed (tapping, boring) instead of a rapid.
    """

    name: str
    line: int
    clearance: float
    bottom: float
    retract: float | None = None
    feed: float = math.nan
    peck: float = 0.0
    peck_next: float = 0.0
    peck_mode: str = ""
    peck_clearance: float = DEFAULT_PECK_CLEARANCE
    dwell: float = 0.0
    feed_out: bool = False

    def problem(self) -> str:
        """Why these values make no hole ("" when they do)."""
        if not (math.isfinite(self.clearance) and math.isfinite(self.bottom)):
            return "the clearance level and the depth must be finite numbers"
        if self.bottom >= self.clearance:
            return (f"the hole bottom ({self.bottom * 1e3:.6g} mm along the tool axis) is not below the clearance "
                    f"level ({self.clearance * 1e3:.6g} mm)")
        for what, depth in (("peck depth", self.peck), ("depth of the later pecks", self.peck_next)):
            if depth < 0.0 or not math.isfinite(depth):
                return f"the {what} must be positive, got {depth * 1e3:g} mm"
        if self.peck_mode and self.peck > 0.0 and self.pecks() > 100_000:
            return "more than 100000 pecks: the peck depth is too small for the hole"
        if self.dwell < 0.0:
            return f"the dwell must not be negative, got {self.dwell:g} s"
        return ""

    def pecks(self) -> int:
        """Number of feeds to the bottom: 1, or the pecks of a peck cycle (``peck`` then ``peck_next`` each)."""
        if not (self.peck_mode and self.peck > 0.0):
            return 1
        rest = self.clearance - self.bottom - self.peck
        step = self.peck_next or self.peck
        return 1 + max(0, math.ceil(rest / step - 1e-9))

    def peck_levels(self) -> list[float]:
        """Levels along the tool axis, metres, the tool feeds to in turn: the pecks, the last at the bottom."""
        n = self.pecks()
        if n == 1:
            return [self.bottom]
        r, step = self.clearance, self.peck_next or self.peck
        return [max(r - self.peck - k * step, self.bottom) for k in range(n)]


def hole_moves(current, hole, axis, cycle: DrillCycle) -> tuple[list[tuple[tuple[float, float, float], bool]], int]:
    """The tool-tip points of one hole of ``cycle`` (see the module notes).

    Parameters
    ----------
    current : 3 floats or None
        Where the tool is before the hole (None: unknown, e.g. the first record of a file).
    hole : 3 floats
        The point of the hole axis the levels are measured from.
    axis : 3 floats
        Unit tool axis (tip towards spindle).
    cycle : DrillCycle

    Returns
    -------
    moves : list of ((x, y, z), rapid)
        The points in order; ``rapid`` False for feed moves. Consecutive repeats are left out.
    bottom : int
        Index in ``moves`` of the (last) point at the hole bottom, where the dwell happens.

    Plain Python floats throughout: a hole is a handful of points, and per-point numpy calls would cost
    more than the arithmetic.
    """
    px, py, pz = (float(v) for v in hole)
    ax, ay, az = (float(v) for v in axis)
    norm = math.hypot(ax, ay, az)
    ax, ay, az = ax / norm, ay / norm, az / norm
    moves: list[tuple[tuple[float, float, float], bool]] = []
    last = None if current is None else tuple(float(v) for v in current)

    def go(level: float, rapid: bool) -> None:
        nonlocal last
        p = (px + level * ax, py + level * ay, pz + level * az)
        if last is not None and abs(p[0] - last[0]) + abs(p[1] - last[1]) + abs(p[2] - last[2]) <= 1e-12:
            return
        moves.append((p, rapid))
        last = p

    came_from = cycle.clearance
    if last is not None:
        came_from = (last[0] - px) * ax + (last[1] - py) * ay + (last[2] - pz) * az
        go(came_from, True)  # traverse at the current level
    r = cycle.clearance
    go(r, True)
    prev = r
    for k, level in enumerate(cycle.peck_levels()):
        if k > 0:
            back = min(prev + cycle.peck_clearance, r)
            if cycle.peck_mode == "full":
                go(r, True)
            go(back, True)
        go(level, False)
        prev = level
    bottom = len(moves) - 1
    retract = came_from if cycle.retract is None else cycle.retract
    go(r, not cycle.feed_out)
    if retract > r:
        go(retract, True)
    return moves, bottom
