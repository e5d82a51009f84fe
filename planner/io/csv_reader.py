"""Reader of waypoint tables: CSV (or semicolon, tab or whitespace separated) ``x,y,z[,i,j,k][,feed]``.

Format
------
* One point per line. Lines starting with ``#`` and blank lines are skipped.
* Header optional. With a header, columns are found by name (case-insensitive; a unit suffix such as
  ``x [mm]`` or ``x(mm)`` is ignored): ``x y z`` required; ``i j k`` (also ``nx ny nz`` or
  ``ax ay az``) the tool axis or surface normal; ``feed`` (also ``f``, ``feedrate``, ``speed``) and
  ``rapid`` (0/1, true/false) optional; other columns are ignored with one warning. Without a header
  the column count decides: 3 ``x,y,z``; 4 ``x,y,z,feed``; 6 ``x,y,z,i,j,k``; 7 ``x,y,z,i,j,k,feed``.
* The vector is taken as the tool axis pointing from the tool tip towards the holder (the CAM
  convention; an outward surface normal is the same direction). It must be a unit vector (to
  ``axis_tolerance``) unless ``normalize_axes`` is set. Empty ``i,j,k`` cells inherit the previous
  vector (``axis_given`` False); empty feed cells inherit the previous feed.
* Lengths in ``units`` (mm by default, or m, inch); feeds in ``feed_units`` (default mm/min for mm,
  in/min for inch, m/s for m).

Each bad cell raises :class:`~planner.io.errors.InputFileError` naming file, line and column.
"""

from __future__ import annotations

import csv
import math
import re

from planner.io import options as opts
from planner.io._collect import (
    AXIS_TOLERANCE,
    PathCollector,
    open_lines,
    parse_number,
    source_name,
    unit_scale,
)
from planner.io.errors import InputFileError, WarningLimiter
from planner.io.toolpath import Toolpath
from planner.validation import _described

_ALIASES = {
    "x": "x", "y": "y", "z": "z",
    "i": "i", "j": "j", "k": "k", "nx": "i", "ny": "j", "nz": "k", "ax": "i", "ay": "j", "az": "k",
    "feed": "feed", "f": "feed", "feedrate": "feed", "feed_rate": "feed", "speed": "feed",
    "rapid": "rapid",
}  # fmt: skip
_DEFAULT_COLUMNS = {
    3: ("x", "y", "z"),
    4: ("x", "y", "z", "feed"),
    6: ("x", "y", "z", "i", "j", "k"),
    7: ("x", "y", "z", "i", "j", "k", "feed"),
}
#: Feed units accepted by the table readers: metres per second per unit.
FEED_UNITS = {
    "mm/min": 1e-3 / 60.0,
    "mm/s": 1e-3,
    "m/min": 1.0 / 60.0,
    "m/s": 1.0,
    "in/min": 0.0254 / 60.0,
    "inch/min": 0.0254 / 60.0,
    "in/s": 0.0254,
    "inch/s": 0.0254,
}
_DEFAULT_FEED = {"mm": "mm/min", "inch": "in/min", "m": "m/s", "cm": "mm/min"}
_SUFFIX = re.compile(r"\s*[\[(].*[\])]\s*$")
_TRUE = {"1", "true", "yes", "y", "t"}
_FALSE = {"0", "false", "no", "n", "f", ""}


def feed_scale(feed_units: str | None, units: str) -> tuple[str, float]:
    """Canonical feed unit name and its value in m/s (default from the length unit); :class:`ReaderArgumentError`
    naming ``feed_units`` for an unknown one, listing the known ones."""
    if feed_units is None:
        name = _DEFAULT_FEED[units]
    else:
        known = ", ".join(repr(k) for k in FEED_UNITS)
        if not isinstance(feed_units, str):
            raise opts.ReaderArgumentTypeError("feed_units", f"feed_units must be one of {known}, got "
                                                             f"{_described(feed_units)}")
        name = feed_units.strip().lower()
        if name not in FEED_UNITS:
            raise opts.ReaderArgumentError("feed_units", f"feed_units must be one of {known}, got {feed_units!r}")
    return name, FEED_UNITS[name]


def _column_name(cell: str) -> str:
    return _SUFFIX.sub("", cell.strip().strip('"').strip("'")).strip().lower()


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


class _Table:
    """Which column holds what."""

    def __init__(self, source: str, columns: list[str | None], line: int):
        self.source = source
        self.columns = columns
        self.pos = {name: k for k, name in enumerate(columns) if name is not None}
        for need in ("x", "y", "z"):
            if need not in self.pos:
                raise InputFileError(source, line, "header", f"has no column {need!r} (columns: {columns})")
        axis = [c in self.pos for c in "ijk"]
        if any(axis) and not all(axis):
            raise InputFileError(source, line, "header", "tool axis needs all three columns i, j, k")
        self.has_axis = all(axis)
        self.has_feed = "feed" in self.pos
        self.has_rapid = "rapid" in self.pos


def read_csv(
    src,
    *,
    units: str = "mm",
    feed_units: str | None = None,
    delimiter: str | None = None,
    axis_tolerance: float = AXIS_TOLERANCE,
    normalize_axes: bool = False,
    source: str | None = None,
) -> Toolpath:
    """Read a waypoint table (see the module notes for the columns) into a :class:`Toolpath`.

    Parameters
    ----------
    src : str, os.PathLike or text stream
        The file, or an open text stream.
    units : {"mm", "m", "inch"}, default "mm"
        Unit of x, y, z.
    feed_units : str, optional
        Unit of the feed column: "mm/min", "mm/s", "m/min", "m/s", "in/min", "in/s" (default mm/min
        for mm, in/min for inch, m/s for m).
    delimiter : str, optional
        Column separator; by default the first data line decides (",", ";", tab, else whitespace).
    axis_tolerance : float, default 1e-3
        Largest accepted deviation of ``|(i, j, k)|`` from 1.
    normalize_axes : bool, default False
        Scale any non-zero vector to unit length instead of checking it.
    source : str, optional
        Name used in messages (default: the file's base name).

    Returns
    -------
    Toolpath
        Points in metres, axes (None without i,j,k columns), feeds in m/s (NaN without a feed column),
        rapid flags (all False without a rapid column).

    Raises
    ------
    ReaderArgumentError
        A bad argument, named (a unit lists the known ones), before the file is opened.
    InputFileError
        A bad cell or row, naming the file, the line and the column.
    """
    opts.check_src(src)
    unit_name, scale = unit_scale(units)
    _, fscale = feed_scale(feed_units, unit_name)
    delimiter = opts.delimiter(delimiter)
    axis_tolerance = opts.axis_tolerance(axis_tolerance)
    normalize_axes = opts.flag(normalize_axes, "normalize_axes")
    name = source_name(src, opts.source_label(source))
    out = PathCollector(name)
    warn = WarningLimiter(name)
    table: _Table | None = None
    split = None
    with open_lines(src, name) as lines:
        for lineno, raw in enumerate(lines, 1):
            text = raw.strip()
            if not text or text.startswith("#"):
                continue
            if split is None:
                d = delimiter
                if d is None:
                    d = next((c for c in (",", ";", "\t") if c in text), None)
                if d is None or d == " ":
                    split = str.split
                else:
                    split = _make_splitter(d)
            cells = [c.strip() for c in split(text)]
            if table is None:
                if all(_is_number(c) for c in cells if c):
                    columns = _DEFAULT_COLUMNS.get(len(cells))
                    if columns is None:
                        problem = (
                            f"has {len(cells)} values and there is no header: expected 3 (x,y,z), "
                            "4 (x,y,z,feed), 6 (x,y,z,i,j,k) or 7 (x,y,z,i,j,k,feed)"
                        )
                        raise InputFileError(name, lineno, "row", problem)
                    table = _Table(name, list(columns), lineno)
                else:
                    names = [_column_name(c) for c in cells]
                    cols = [_ALIASES.get(nm) for nm in names]
                    dup = {c for c in cols if c is not None and cols.count(c) > 1}
                    if dup:
                        raise InputFileError(name, lineno, "header", f"column {sorted(dup)[0]!r} appears twice")
                    ignored = [cells[k] for k, c in enumerate(cols) if c is None]
                    if ignored:
                        warn.warn("ignored columns", lineno, f"columns {ignored} not understood, ignored")
                    table = _Table(name, cols, lineno)
                    continue
            _row(out, table, cells, lineno, scale, fscale, axis_tolerance, normalize_axes)
    warn.flush()
    if table is None:
        raise InputFileError(name, None, "", "no data rows")
    tp = out.finish(unit_name, point_field="column {col}", axis_field="columns i,j,k", axis_tolerance=axis_tolerance)
    return tp


def _make_splitter(d: str):
    def split(text: str) -> list[str]:
        if '"' in text:
            return next(csv.reader([text], delimiter=d))
        return text.split(d)

    return split


def _row(out: PathCollector, t: _Table, cells, line, scale, fscale, tol, normalize) -> None:
    src = t.source
    if len(cells) != len(t.columns):
        raise InputFileError(src, line, "row", f"has {len(cells)} values, expected {len(t.columns)} "
                             f"({', '.join(c or '?' for c in t.columns)})")  # fmt: skip
    p = t.pos
    xyz = [parse_number(cells[p[c]], src, line, f"column {c}") * scale for c in "xyz"]
    k = out.count
    out.xyz.extend(xyz)
    out.lines.append(line)
    if t.has_axis:
        raw = [cells[p[c]] for c in "ijk"]
        if any(raw):
            v = [parse_number(r, src, line, f"column {c}") for r, c in zip(raw, "ijk", strict=True)]
            n = math.hypot(*v)  # no overflow: a component of 1e308 has the length 1e308
            if normalize:
                if n == 0.0:
                    raise InputFileError(src, line, "columns i,j,k", "the vector is zero")
                v = [c / n for c in v]
            elif abs(n - 1.0) > tol:
                problem = (
                    f"tool axis ({v[0]:g}, {v[1]:g}, {v[2]:g}) is not a unit vector (length {n:.9g}, tolerance {tol:g})"
                )
                raise InputFileError(src, line, "columns i,j,k", problem)
            out.set_axis(k, v[0], v[1], v[2], True)
        elif k == 0:
            raise InputFileError(src, line, "columns i,j,k", "the first row must give the tool axis")
    if t.has_feed:
        cell = cells[p["feed"]]
        if cell:
            f = parse_number(cell, src, line, "column feed")
            if not f > 0.0:
                raise InputFileError(src, line, "column feed", f"feed rate must be positive, got {f:g}")
            out.set_feed(k, f * fscale)
    if t.has_rapid:
        cell = cells[p["rapid"]].lower()
        if cell in _TRUE:
            out.rapid_idx.append(k)
        elif cell not in _FALSE:
            raise InputFileError(src, line, "column rapid", f"{cell!r} is not 0/1 or true/false")
