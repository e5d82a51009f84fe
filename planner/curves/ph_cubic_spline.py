"""The G1 PH cubic spline through waypoints (juttler seed, section 7.1).

Each span between consecutive waypoints is the shortest PH cubic matching the points and the tangent
directions there. Spans whose G1 data admit no PH cubic are split at the midpoint of the C2 cubic
spline through the waypoints (point and tangent taken from it), repeatedly, until every piece has one:
the user's waypoints are all interpolated and the extra knots are recorded in ``waypoint_index``.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from planner.curves.ph_core import batch_sigma
from planner.curves.ph_cubic import batch_g1
from planner.curves.spline import PHSpline
from planner.curves.tangents import chord_knots, cubic_spline_slopes, line_direction
from planner.errors import NoSolutionError, WaypointError
from planner.validation import as_int, check_tangents, check_waypoints

#: Maximum number of times one span between waypoints is halved looking for PH cubic data.
MAX_SPLITS = 12
#: At most this many pieces of one span between waypoints may still lack a PH cubic after a halving. Where the
#: tangent turns too fast at one place (a tight turn, a cusp of the cubic spline) one or two pieces lack one at
#: each level; where every piece keeps failing, their number would double at each level (4096 per span at 12
#: halvings: 28 s and 421 MiB for 3 spans, memory exhausted for 111), so the span is refused instead: the work
#: is at most MAX_OPEN_PIECES pieces per span and level.
MAX_OPEN_PIECES = 8


def fit_ph_cubic_spline(waypoints, tangents=None, *, max_splits: int = MAX_SPLITS) -> PHSpline:
    """G1 PH cubic spline through N >= 2 waypoints.

    Parameters
    ----------
    waypoints : array_like (N, 3)
        Points to pass through, metres.
    tangents : array_like (N, 3), optional
        Tangent directions at the waypoints (lengths ignored). Default: those of the not-a-knot C2
        cubic spline through the waypoints with chord-length knots.
    max_splits : int
        How often one span may be halved where its data admit no PH cubic.

    Returns
    -------
    PHSpline
        Degree-3 segments; ``continuity`` "G1"; ``waypoint_index`` marks the user's waypoints among the
        knots when spans were split.

    Raises
    ------
    WaypointError
        Bad waypoints or tangents (the message names the index); with the default tangents, waypoints that turn
        back where no G1 PH cubic spline passes: a zero estimated tangent, or a reversal on a line (names it).
    NoSolutionError
        A span still admits no PH cubic after ``max_splits`` halvings, or more than MAX_OPEN_PIECES of its
        pieces have none after a halving, or the cubic spline stops inside it (names the span).
    """
    p = check_waypoints(waypoints)
    u = chord_knots(p)
    if tangents is None:
        m = cubic_spline_slopes(u, p)
        _refuse_reversals(p, m)
    else:
        d = check_tangents(tangents, p.shape[0])
        m = d / np.linalg.norm(d, axis=1, keepdims=True)
    guide = CubicHermiteSpline(u, p, m)  # where spans are split

    knots, pts, tans = u, p, m
    origin = np.arange(p.shape[0] - 1)  # waypoint span of each piece
    A = np.zeros((p.shape[0] - 1, 2, 4))
    todo = np.arange(p.shape[0] - 1)  # pieces still to solve
    for level in range(as_int(max_splits, "max_splits", 0, 64) + 1):
        t_unit = tans / np.linalg.norm(tans, axis=1, keepdims=True)
        dp = pts[todo + 1] - pts[todo]
        cand, ok = batch_g1(dp, t_unit[todo], t_unit[todo + 1])
        retry = ~ok.any(axis=1)
        if retry.any():  # before splitting, look for solutions with many more starts
            c2, ok2 = batch_g1(dp[retry], t_unit[todo[retry]], t_unit[todo[retry] + 1], dense=True)
            cand = np.concatenate((cand, np.zeros((cand.shape[0], c2.shape[1] - cand.shape[1], 2, 4))), 1)
            ok = np.concatenate((ok, np.zeros((ok.shape[0], ok2.shape[1] - ok.shape[1]), bool)), 1)
            cand[retry], ok[retry] = c2, ok2
        # per piece, the shortest solution: length = (sigma_0 + sigma_1 + sigma_2) / 3
        length = np.where(ok, batch_sigma(cand).sum(axis=-1), np.inf)
        A[todo] = cand[np.arange(todo.size), np.argmin(length, axis=1)]
        bad = todo[~ok.any(axis=1)]
        if bad.size == 0:
            break
        open_pieces = np.bincount(origin[bad], minlength=p.shape[0] - 1)
        if level == max_splits or open_pieces.max() > MAX_OPEN_PIECES:
            k = int(origin[bad[0]]) if level == max_splits else int(np.argmax(open_pieces))
            what = f"after {max_splits} subdivisions" if level == max_splits else \
                f"({open_pieces[k]} of its pieces have none after {level} subdivisions)"
            raise NoSolutionError(
                f"no PH cubic spline piece found between waypoints {k} and {k + 1} {what} (the tangent there "
                "turns too fast); use fit_ph_spline (PH quintics) instead"
            )
        mid = 0.5 * (knots[bad] + knots[bad + 1])
        tan_mid = guide(mid, 1)
        stop = ~(np.linalg.norm(tan_mid, axis=1) > 0.0)
        if stop.any():  # the cubic spline stops there: no direction for a G1 curve (it turns back)
            k = int(origin[bad[np.argmax(stop)]])
            raise NoSolutionError(
                f"no PH cubic spline piece found between waypoints {k} and {k + 1}: the cubic spline through the "
                "waypoints stops and turns back there; use fit_ph_spline (PH quintics) instead"
            )
        knots = np.insert(knots, bad + 1, mid)
        pts = np.insert(pts, bad + 1, guide(mid), axis=0)
        tans = np.insert(tans, bad + 1, tan_mid, axis=0)
        origin = np.insert(origin, bad + 1, origin[bad])
        A = np.insert(A, bad + 1, 0.0, axis=0)
        # the split pieces (old index b becomes b + j, its new half b + j + 1) are solved next
        shifted = bad + np.arange(bad.size)
        todo = np.sort(np.concatenate((shifted, shifted + 1)))
    index = np.searchsorted(knots, u)
    return PHSpline(A, pts[:-1], knots, "G1", 0, None if knots.size == u.size else index)


def _refuse_reversals(p: np.ndarray, m: np.ndarray) -> None:
    """WaypointError naming the first waypoint where the estimated tangents m (n, 3) of waypoints p (n, 3) leave a
    G1 PH cubic spline no way on: a zero tangent (the waypoints turn back symmetrically there), or, for waypoints
    on one line, a turn back along it (a PH cubic on a line moves one way: none passes a reversal)."""
    zero = ~(np.linalg.norm(m, axis=1) > 0.0)
    if zero.any():
        raise WaypointError("the estimated tangent vanishes (the waypoints turn back here): a G1 PH cubic spline "
                            "needs a direction; give tangents, or fit PH quintics (fit_ph_spline)",
                            int(np.argmax(zero)))
    e = line_direction(p)
    if e is not None and p.shape[0] > 2:
        way = np.sign(np.diff(p, axis=0) @ e)
        turn = np.flatnonzero(way[1:] != way[:-1])
        if turn.size:
            raise WaypointError("the waypoints turn back along their line here: no G1 PH cubic spline passes a "
                                "reversal on a line; fit PH quintics (fit_ph_spline, which stops there)",
                                int(turn[0]) + 1)
