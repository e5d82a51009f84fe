"""Reader of waypoints in JSON.

Schema (any of three shapes)
----------------------------
1. A list of point objects::

       [{"x": 0, "y": 0, "z": 0, "i": 0, "j": 0, "k": 1, "feed": 600}, {"x": 10, "y": 0, "z": 0}, ...]

2. An object of arrays (columns)::

       {"units": "mm", "feed_units": "mm/min",
        "x": [...], "y": [...], "z": [...], "i": [...], "j": [...], "k": [...], "feed": [...]}

3. An object with rows::

       {"units": "mm", "points": [[x, y, z], ...], "axes": [[i, j, k] or null, ...],
        "feeds": [f or null, ...], "rapid": [false, true, ...]}

   (``"points"`` may also hold point objects as in shape 1).

Keys: ``x y z`` numbers, required; ``i j k`` (or ``nx ny nz``) the tool axis from the tip towards the
holder, a unit vector, all three or none (null or absent: the previous vector carries over); ``feed``
positive, null or absent: the previous feed carries over; ``rapid`` a boolean. Top-level ``units``
("mm", "m", "inch") and ``feed_units`` ("mm/min", "mm/s", "m/min", "m/s", "in/min", "in/s") override
the defaults but must agree with the options when both are given. Unknown keys are ignored with one
warning. JSON is read whole (it cannot be streamed line by line); errors name the line of the value
and its JSON path, e.g. ``points[12].z``.
"""

from __future__ import annotations

import bisect
import json
import math
import os
import re
from json.scanner import make_scanner

from planner.io import options as opts
from planner.io._collect import (
    AXIS_TOLERANCE,
    SNIFF_CHARS,
    PathCollector,
    check_text_start,
    open_text,
    source_name,
    unit_scale,
)
from planner.io.csv_reader import feed_scale
from planner.io.errors import InputFileError, WarningLimiter
from planner.io.toolpath import Toolpath

_AXIS_KEYS = (("i", "j", "k"), ("nx", "ny", "nz"))
_KNOWN = {"x", "y", "z", "i", "j", "k", "nx", "ny", "nz", "feed", "rapid"}
_TOP = {"units", "feed_units", "points", "axes", "feeds", "rapid", "x", "y", "z", "i", "j", "k", "nx", "ny",
        "nz", "feed", "source", "name", "comment", "description"}  # fmt: skip


def _locate(text: str, path: list) -> int:
    """Character offset in ``text`` of the JSON value at ``path`` (keys and indices), best effort."""
    scan = make_scanner(json.JSONDecoder(parse_int=_integer))  # type: ignore[arg-type]  # typeshed: a class
    ws = " \t\n\r"
    pos = 0
    while pos < len(text) and text[pos] in ws:
        pos += 1
    for step in path:
        if pos >= len(text):
            return pos
        if isinstance(step, str) and text[pos] == "{":
            pos += 1
            while True:
                while text[pos] in ws:
                    pos += 1
                if text[pos] == "}":
                    return pos
                key, pos = scan(text, pos)
                while text[pos] in ws + ":":
                    pos += 1
                if key == step:
                    break
                _, pos = scan(text, pos)
                while text[pos] in ws + ",":
                    pos += 1
        elif isinstance(step, int) and text[pos] == "[":
            pos += 1
            for _ in range(step):
                while text[pos] in ws:
                    pos += 1
                _, pos = scan(text, pos)
                while text[pos] in ws + ",":
                    pos += 1
            while text[pos] in ws:
                pos += 1
        else:
            return pos
    return pos


def _path_str(path: list) -> str:
    out = ""
    for step in path:
        out += f"[{step}]" if isinstance(step, int) else (f".{step}" if out else step)
    return out or "document"


class _Json:
    def __init__(self, name: str, text: str):
        self.name = name
        self.text = text

    def fail(self, path: list, problem: str):
        try:
            pos = _locate(self.text, path)
        except (IndexError, StopIteration, ValueError):
            pos = 0
        line = self.text.count("\n", 0, pos) + 1
        raise InputFileError(self.name, line, _path_str(path), problem)

    def number(self, value, path: list) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.fail(path, f"{value!r} is not a number")
        v = float(value)
        if math.isinf(v):  # Infinity, or digits beyond a double's range (1e400, an integer of 5000 digits)
            self.fail(path, "an infinite number (or one too large to be a coordinate or feed)")
        if not math.isfinite(v):
            self.fail(path, f"{value!r} is not a finite number")
        return v


def _integer(text: str) -> int | float:
    """A JSON integer: an int, or beyond a double's range the float it reads as (inf, refused by its place), never
    Python's ``ValueError`` for integers of more than 4300 digits."""
    return int(text) if len(text) < 300 else float(text)


class _DuplicateKey(Exception):
    def __init__(self, key: str):
        self.key = key


def _unique_keys(pairs: list) -> dict:
    """``object_pairs_hook`` of json.loads: an object, refusing a key given twice (json keeps the last silently)."""
    out: dict = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKey(k)
        out[k] = v
    return out


def _line_of_second(text: str, key: str) -> int | None:
    """1-based line of the second occurrence of ``"key"`` in the text (where the duplicate is), if any."""
    token = json.dumps(key)
    first = text.find(token)
    second = text.find(token, first + len(token)) if first >= 0 else -1
    return None if second < 0 else text.count("\n", 0, second) + 1


def read_json(
    src,
    *,
    units: str | None = None,
    feed_units: str | None = None,
    axis_tolerance: float = AXIS_TOLERANCE,
    normalize_axes: bool = False,
    source: str | None = None,
) -> Toolpath:
    """Read waypoints from JSON (see the module notes for the schema) into a :class:`Toolpath`.

    Parameters
    ----------
    src : str, os.PathLike or text stream
        The file, or an open text stream.
    units : {"mm", "m", "inch"}, optional
        Unit of x, y, z when the document has no ``"units"`` (default mm).
    feed_units : str, optional
        Unit of feeds when the document has no ``"feed_units"`` (default mm/min for mm, in/min for
        inch, m/s for m).
    axis_tolerance : float, default 1e-3
        Largest accepted deviation of ``|(i, j, k)|`` from 1.
    normalize_axes : bool, default False
        Scale any non-zero vector to unit length instead of checking it.
    source : str, optional
        Name used in messages (default: the file's base name).

    Returns
    -------
    Toolpath

    Raises
    ------
    ReaderArgumentError
        A bad argument, named (a unit lists the known ones), before the file is read.
    InputFileError
        A bad value or structure, naming the file, the line and the JSON path (``points[12].z``).
    """
    opts.check_src(src)
    if units is not None:
        unit_scale(units)
    feed_scale(feed_units, "mm")
    axis_tolerance = opts.axis_tolerance(axis_tolerance)
    normalize_axes = opts.flag(normalize_axes, "normalize_axes")
    name = source_name(src, opts.source_label(source))
    if isinstance(src, str | os.PathLike):
        with open_text(src, name) as fh:
            text = fh.read()
    else:
        text = src.read() if hasattr(src, "read") else "".join(src)
        if isinstance(text, bytes | bytearray):
            raise opts.binary_stream()
        if not isinstance(text, str):
            raise opts.ReaderArgumentTypeError("src", f"src must be a text stream: it gave a {type(text).__name__}")
        text = check_text_start(text[:SNIFF_CHARS], name) + text[SNIFF_CHARS:]
    try:
        doc = json.loads(text, object_pairs_hook=_unique_keys, parse_int=_integer)
    except json.JSONDecodeError as exc:
        raise InputFileError(name, exc.lineno, f"column {exc.colno}", f"invalid JSON: {exc.msg}") from None
    except _DuplicateKey as exc:
        raise InputFileError(name, _line_of_second(text, exc.key), f"key {exc.key!r}",
                             "appears twice in one object (which value is meant?)") from None
    except RecursionError:
        raise InputFileError(name, None, "structure", "arrays or objects nested too deeply to be a toolpath") from None
    j = _Json(name, text)
    warn = WarningLimiter(name)

    def setting(key, option, what):
        if isinstance(doc, dict) and key in doc:
            val = doc[key]
            if not isinstance(val, str):
                j.fail([key], f"{val!r} is not a unit name")
            if option is not None and option.strip().lower() != val.strip().lower():
                j.fail([key], f"the file says {val!r} but {what}={option!r} was given")
            return val
        return option

    try:  # the options are valid (checked above): a bad unit here is the file's
        unit_name, scale = unit_scale(setting("units", units, "units") or "mm")
        _, fscale = feed_scale(setting("feed_units", feed_units, "feed_units"), unit_name)
    except opts.ReaderArgumentError as exc:
        j.fail([exc.argument], str(exc))
    rows = _rows(j, doc, warn)
    if not rows:
        j.fail([], "holds no points")
    lines = _element_lines(text, rows[0][0][:-1], len(rows))
    out = PathCollector(name)
    for k, (path, obj) in enumerate(rows):
        _point(j, out, k, path, obj, scale, fscale, axis_tolerance, normalize_axes, lines[k])
    warn.flush()
    return out.finish(unit_name, axis_tolerance=axis_tolerance)


def _element_lines(text: str, array_path: list, count: int) -> list[int]:
    """1-based line of each of the first ``count`` elements of the JSON array at ``array_path``."""
    scan = make_scanner(json.JSONDecoder(parse_int=_integer))  # type: ignore[arg-type]  # typeshed: a class
    newlines = [m.start() for m in re.finditer("\n", text)]
    pos = _locate(text, array_path) + 1  # just inside "["
    starts = []
    ws = " \t\n\r"
    for _ in range(count):
        while text[pos] in ws:
            pos += 1
        starts.append(pos)
        _, pos = scan(text, pos)
        while pos < len(text) and text[pos] in ws + ",":
            pos += 1
    return [bisect.bisect_right(newlines, st - 1) + 1 for st in starts]


def _rows(j: _Json, doc, warn: WarningLimiter) -> list[tuple[list, dict]]:
    """Normalise the three shapes to [(json path of the point, {key: (value, json path)})]."""
    if isinstance(doc, list):
        return [_obj_row(j, item, [k], warn) for k, item in enumerate(doc)]
    if not isinstance(doc, dict):
        j.fail([], "must be a list of points or an object")
    extra = sorted(set(doc) - _TOP)
    if extra:
        warn.warn("ignored keys", 1, f"top-level keys {extra} not understood, ignored")
    if "points" in doc:
        pts = doc["points"]
        if not isinstance(pts, list):
            j.fail(["points"], "must be a list")
        rows = []
        for k, item in enumerate(pts):
            if isinstance(item, dict):
                rows.append(_obj_row(j, item, ["points", k], warn))
                continue
            if not isinstance(item, list) or len(item) != 3:
                j.fail(["points", k], f"must be [x, y, z], got {item!r}")
            rows.append((["points", k], {c: (item[m], ["points", k, m]) for m, c in enumerate("xyz")}))
        for key, cols in (("axes", "ijk"), ("feeds", None), ("rapid", None)):
            if key not in doc:
                continue
            col = doc[key]
            if not isinstance(col, list) or len(col) != len(pts):
                j.fail([key], f"must be a list of {len(pts)} entries, like points")
            for k, val in enumerate(col):
                if val is None:
                    continue
                if cols:
                    if not isinstance(val, list) or len(val) != 3:
                        j.fail([key, k], f"must be [i, j, k] or null, got {val!r}")
                    for m, c in enumerate(cols):
                        rows[k][1][c] = (val[m], [key, k, m])
                else:
                    rows[k][1]["feed" if key == "feeds" else "rapid"] = (val, [key, k])
        return rows
    if "x" in doc:
        n = None
        for key in doc:
            if key in _KNOWN:
                if not isinstance(doc[key], list):
                    j.fail([key], "must be a list (an object of columns)")
                if n is None:
                    n = len(doc[key])
                elif len(doc[key]) != n:
                    j.fail([key], f"has {len(doc[key])} entries, column x has {len(doc['x'])}")
        return [
            (
                ["x", k],
                {key: (doc[key][k], [key, k]) for key in doc if key in _KNOWN and doc[key][k] is not None},
            )
            for k in range(n or 0)
        ]
    j.fail([], "has neither 'points' nor columns 'x', 'y', 'z'")
    return []


def _obj_row(j: _Json, item, path: list, warn: WarningLimiter) -> tuple[list, dict]:
    if not isinstance(item, dict):
        j.fail(path, f"must be an object with x, y, z, got {item!r}")
    extra = set(item) - _KNOWN
    if extra:
        warn.warn("ignored keys", None, f"keys {sorted(extra)} of the points not understood, ignored")
    return path, {k: (v, path + [k]) for k, v in item.items() if k in _KNOWN and v is not None}


def _point(j: _Json, out: PathCollector, k: int, path, obj: dict, scale, fscale, tol, normalize, line) -> None:
    for c in "xyz":
        if c not in obj:
            j.fail(path, f"point has no {c!r}")
    xyz = [j.number(*obj[c]) * scale for c in "xyz"]
    out.xyz.extend(xyz)
    out.lines.append(line)
    keys = next((ks for ks in _AXIS_KEYS if any(c in obj for c in ks)), None)
    if keys is not None:
        missing = [c for c in keys if c not in obj]
        if missing:
            j.fail(path, f"tool axis needs {', '.join(keys)}; {missing[0]!r} is missing")
        v = [j.number(*obj[c]) for c in keys]
        n = math.hypot(*v)  # no overflow: a component of 1e308 has the length 1e308
        if normalize:
            if n == 0.0:
                j.fail(path, "the tool axis is zero")
            v = [c / n for c in v]
        elif abs(n - 1.0) > tol:
            where = obj[keys[0]][1]
            where = where[:-1] if where[0] == "axes" else path  # "axes[k]" or the point itself
            j.fail(where, f"tool axis ({v[0]:g}, {v[1]:g}, {v[2]:g}) is not a unit vector (length {n:.9g})")
        out.set_axis(k, v[0], v[1], v[2], True)
    if "feed" in obj:
        f = j.number(*obj["feed"])
        if not f > 0.0:
            j.fail(obj["feed"][1], f"feed rate must be positive, got {f:g}")
        out.set_feed(k, f * fscale)
    if "rapid" in obj:
        val, p = obj["rapid"]
        if not isinstance(val, bool):
            j.fail(p, f"{val!r} is not true or false")
        if val:
            out.rapid_idx.append(k)
