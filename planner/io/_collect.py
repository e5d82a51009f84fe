"""Shared machinery of the readers: opening sources, number parsing, and the streaming point collector.

The collector appends plain floats to ``array.array`` columns (8 bytes a value, no per-line objects)
and stores modal state (tool axis, feed, frame) only where it changes; :meth:`PathCollector.finish`
forward-fills it with numpy, checks the data and returns a :class:`~planner.io.toolpath.Toolpath`.
"""

from __future__ import annotations

import codecs
import contextlib
import io
import math
import os
from array import array
from collections.abc import Iterator

import numpy as np

from planner.io.errors import InputFileError
from planner.io.options import ReaderArgumentError, ReaderArgumentTypeError, binary_stream, check_src
from planner.io.toolpath import Arc, Event, Nurbs, Toolpath, vec3
from planner.validation import _described

#: Metres per unit of length for the unit names the readers accept.
LENGTH_UNITS = {"mm": 1e-3, "m": 1.0, "inch": 0.0254, "in": 0.0254, "cm": 1e-2}

#: Rows transformed at a time when applying frames.
_BLOCK_ROWS = 1 << 16

#: Largest accepted deviation of a given tool axis from unit length (printed with 4+ decimals).
AXIS_TOLERANCE = 1e-3


def unit_scale(units: str, what: str = "units") -> tuple[str, float]:
    """Canonical name and metres per unit of a length unit given by the user; :class:`ReaderArgumentError` naming
    ``what`` for an unknown one (a :class:`ReaderArgumentTypeError` for a value that is not a string)."""
    if not isinstance(units, str):
        raise ReaderArgumentTypeError(what, f"{what} must be one of 'mm', 'm', 'inch', got {_described(units)}")
    key = units.strip().lower()
    key = {"millimetre": "mm", "millimeter": "mm", "inches": "inch", "metre": "m", "meter": "m"}.get(key, key)
    if key not in LENGTH_UNITS:
        raise ReaderArgumentError(what, f"{what} must be one of 'mm', 'm', 'inch', got {units!r}")
    return ("inch" if key == "in" else key), LENGTH_UNITS[key]


def source_name(src, source: str | None) -> str:
    """The name errors use for ``src``: ``source`` if given, else the file's base name."""
    if source is not None:
        return str(source)
    if isinstance(src, str | os.PathLike):
        return os.path.basename(os.fspath(src)) or os.fspath(src)
    name = getattr(src, "name", None)
    return os.path.basename(str(name)) if isinstance(name, str) else "<stream>"


#: Byte-order marks, longest first, and the codec that reads the text after them (dropping the mark).
_BOMS = (
    (codecs.BOM_UTF32_LE, "utf-32"),
    (codecs.BOM_UTF32_BE, "utf-32"),
    (codecs.BOM_UTF8, "utf-8-sig"),
    (codecs.BOM_UTF16_LE, "utf-16"),
    (codecs.BOM_UTF16_BE, "utf-16"),
)
#: Bytes of a file's start that tell its encoding (and characters of a decoded stream's start checked for a wrong one).
_SNIFF_BYTES = SNIFF_CHARS = 4096


def file_encoding(path, source: str | None = None) -> str:
    """The codec that reads the toolpath file ``path``, told from its first 4 KiB.

    UTF-8 by default (a byte-order mark dropped); UTF-16 or UTF-32 by their byte-order marks; UTF-16 little or big
    endian without a mark when at least 90 % of the odd (even) bytes are NUL and none of the even (odd) ones, as
    ASCII text written as UTF-16 is. NUL bytes at the very end (padding) are no sign of anything.

    Raises
    ------
    InputFileError
        The start holds NUL bytes in no such pattern: binary data, or text in another encoding (the message
        names the line and the encodings read).
    """
    name = source_name(path, source)
    with open(path, "rb") as fh:
        head = fh.read(_SNIFF_BYTES)
    for bom, codec in _BOMS:
        if head.startswith(bom):
            return codec
    if b"\x00" not in head.rstrip(b"\x00"):
        return "utf-8-sig"
    n = len(head) // 2 * 2
    even, odd = head[0:n:2], head[1:n:2]
    if even and b"\x00" not in even and odd.count(0) >= 0.9 * len(odd):
        return "utf-16-le"
    if odd and b"\x00" not in odd and even.count(0) >= 0.9 * len(even):
        return "utf-16-be"
    at = head.index(b"\x00")
    raise InputFileError(name, head.count(b"\n", 0, at) + 1, "", f"holds a NUL byte (byte {at} of the file): it is "
                         "binary data or text in an encoding other than UTF-8, UTF-16 and UTF-32, not a toolpath file")


def check_text_start(text: str, source: str) -> str:
    """The start of an already decoded text stream without its byte-order mark; :class:`InputFileError` naming the
    line when it shows UTF-16 or UTF-32 text decoded with another codec (NUL characters, or a UTF-16 mark read as
    Latin-1)."""
    if text.startswith("\ufeff"):
        text = text[1:]
    elif text.startswith("\u00ef\u00bb\u00bf"):  # a UTF-8 mark decoded as Latin-1 / cp1252: the text after it is fine
        text = text[3:]
    nul = text.find("\x00")
    if nul >= 0 or text.startswith(("\u00ff\u00fe", "\u00fe\u00ff", "\ufffe")):
        line = text.count("\n", 0, nul) + 1 if nul >= 0 else 1
        raise InputFileError(source, line, "", "holds NUL characters or a UTF-16 byte-order mark: UTF-16 or UTF-32 "
                             "text decoded as UTF-8 or Latin-1; open the file with encoding='utf-16' (or pass its "
                             "path)")
    return text


@contextlib.contextmanager
def open_text(path, source: str | None = None) -> Iterator[io.TextIOWrapper]:
    """The toolpath file ``path`` opened for reading text in the encoding :func:`file_encoding` tells (universal
    newlines; undecodable bytes become U+FFFD)."""
    with open(path, encoding=file_encoding(path, source), errors="replace", newline=None) as fh:
        yield fh


@contextlib.contextmanager
def open_lines(src, source: str | None = None) -> Iterator[Iterator[str]]:
    """Lines of a path or text stream, streamed; a byte-order mark is dropped.

    A file is decoded as UTF-8, UTF-16 or UTF-32 as its start tells (:func:`file_encoding`); undecodable bytes
    become U+FFFD (they can only matter inside comments: a number holding one fails to parse with a message
    naming its line). A text stream whose first line shows UTF-16 decoded as something else is refused
    (:func:`check_text_start`). Anything but a path or a text stream is a :class:`ReaderArgumentTypeError`
    naming ``src``; ``source`` names the file in messages (default: its base name).
    """
    check_src(src)
    if isinstance(src, str | os.PathLike):
        with open_text(src, source) as fh:
            yield iter(fh)
        return
    if isinstance(src, io.TextIOBase) or hasattr(src, "__iter__"):
        it = iter(src)
    elif hasattr(src, "readline"):
        it = iter(src.readline, "")
    else:  # a stream with read() only
        text = src.read()
        if isinstance(text, bytes | bytearray):
            raise binary_stream()
        it = iter(io.StringIO(text))
    first = next(it, None)
    if first is None:
        yield iter(())
        return
    if isinstance(first, bytes | bytearray):
        raise binary_stream()
    if not isinstance(first, str):
        raise ReaderArgumentTypeError("src", f"src must be a text stream: it yielded {_described(first)}")
    first = check_text_start(first, source_name(src, source))

    def chain():
        yield first
        yield from it

    yield chain()


def parse_number(token: str, source: str, line: int, field: str) -> float:
    """A finite float from ``token`` (``6.``, ``.9625``, ``-1.5E-3`` accepted); InputFileError if not."""
    t = token.strip()
    if not t:
        raise InputFileError(source, line, field, "value is missing (empty field)")
    if "_" not in t:
        try:
            v = float(t)
        except ValueError:
            pass
        else:
            if math.isfinite(v):
                return v
            raise InputFileError(source, line, field, f"{t!r} is not a finite number")
        if t[-1:] in "0123456789" and ("D" in t or "d" in t):  # Fortran exponent, e.g. 1.5D+02
            return parse_number(t.replace("D", "E").replace("d", "e"), source, line, field)
    raise InputFileError(source, line, field, f"{t!r} is not a number")


def _last_per_index(idx: np.ndarray) -> np.ndarray:
    """Mask keeping, among equal consecutive entries of the sorted ``idx``, only the last one."""
    keep = np.ones(len(idx), dtype=bool)
    keep[:-1] = idx[1:] != idx[:-1]
    return keep


def forward_fill(n: int, idx: np.ndarray, values: np.ndarray, default) -> np.ndarray:
    """Modal values at ``n`` points from changes: row j of ``values`` holds from point ``idx[j]`` on.

    ``idx`` must be non-decreasing (entries up to ``n``); of several changes at one index the last
    wins; points before the first change get ``default``. Memory: the output only.
    """
    values = np.asarray(values)
    idx = np.asarray(idx, dtype=np.int64)
    tail = values.shape[1:]
    if len(idx) == 0:
        return np.broadcast_to(np.asarray(default, dtype=values.dtype), (n,) + tail).copy()
    keep = _last_per_index(idx)
    idx, values = idx[keep], values[keep]
    out = np.empty((n,) + tail, dtype=values.dtype)
    first = min(int(idx[0]), n)
    out[:first] = default
    out[first:] = np.repeat(values, np.diff(np.append(idx, n)), axis=0)
    return out


class PathCollector:
    """Streaming accumulator of points (metres, CL frame) and of the modal state around them.

    Attributes written by the readers' hot loops (bind them to locals): ``xyz`` (3 floats a point),
    ``lines`` (source line a point), ``rapid_idx`` (indices of rapid points).
    """

    def __init__(self, source: str):
        self.source = source
        self.xyz = array("d")
        self.lines = array("q")
        self.rapid_idx = array("q")
        self.axis_idx = array("q")
        self.axis_val = array("d")
        self.axis_given = bytearray()
        self.feed_idx = array("q")
        self.feed_val = array("d")
        self.frames: list[tuple[int, np.ndarray, np.ndarray]] = []  # (from index, R, t in metres)
        self.events: list[Event] = []
        self.arcs: list[tuple] = []  # (line, end index, centre(3), axis(3), radius) in metres, CL frame
        self.nurbs: list[tuple] = []  # (line, end index, degree, knots, control (m,3) m, weights, axes) CL frame
        self.axis_info = False  # the file said something about the tool axis
        self.units_seen: list[str] = []

    @property
    def count(self) -> int:
        return len(self.lines)

    def set_axis(self, index: int, i: float, j: float, k: float, given: bool) -> None:
        """Modal tool axis (CL frame) from point ``index`` on; ``given`` when the file gave it there."""
        self.axis_idx.append(index)
        self.axis_val.extend((i, j, k))
        self.axis_given.append(1 if given else 0)
        self.axis_info = True

    def set_feed(self, index: int, feed: float) -> None:
        """Modal feed rate (m/s, NaN unknown) from point ``index`` on."""
        self.feed_idx.append(index)
        self.feed_val.append(feed)

    def set_frame(self, index: int, rotation: np.ndarray, origin: np.ndarray) -> None:
        """Points from ``index`` on are mapped to the part frame by ``rotation @ p + origin``."""
        self.frames.append((index, np.asarray(rotation, float), np.asarray(origin, float)))

    def event(self, kind: str, line: int, name: str = "", value: float = math.nan, text: str = "") -> None:
        self.events.append(Event(kind, line, self.count, name, value, text))

    def add_arc(self, line: int, index: int, centre, axis, radius: float) -> None:
        self.arcs.append((line, index, *centre, *axis, radius))

    def add_nurbs(self, line: int, index: int, degree: int, knots, control, weights, axes) -> None:
        """A NURBS ending at point ``index`` (control points in metres, CL frame; axes None or (m, 3))."""
        self.nurbs.append((line, index, degree, knots, control, weights, axes))

    def add_point(self, line: int, x: float, y: float, z: float, rapid: bool = False) -> int:
        """Append one point (metres, CL frame); returns its index."""
        k = len(self.lines)
        self.xyz.extend((x, y, z))
        self.lines.append(line)
        if rapid:
            self.rapid_idx.append(k)
        return k

    def cutting(self) -> bool:
        """True inside a pass: a feed move has been added since the last rapid (a unit switch here is refused)."""
        n = len(self.lines)
        return n >= 2 and not (len(self.rapid_idx) and self.rapid_idx[-1] == n - 1)

    # ------------------------------------------------------------------ finishing
    def finish(
        self,
        units: str,
        point_field: str = "field {col} of GOTO",
        axis_field: str = "fields 4-6 of GOTO",
        axis_tolerance: float = AXIS_TOLERANCE,
        rotary: np.ndarray | None = None,
    ) -> Toolpath:
        """Forward-fill the modal state, apply the frames, check the values and build the Toolpath.

        ``point_field`` names coordinate ``col`` (1-based) of a point's record in error messages.
        """
        n = self.count
        # Views on the collector's buffers (no copy); the collector is not appended to any more.
        pts = np.frombuffer(self.xyz, dtype=float).reshape(n, 3) if n else np.empty((0, 3))
        lines = np.frombuffer(self.lines, dtype=np.int64) if n else np.empty(0, np.int64)
        bad = ~np.isfinite(pts)
        if bad.any():
            r, c = np.argwhere(bad)[0]
            field = point_field.format(col=c + 1)
            raise InputFileError(self.source, int(lines[r]), field, f"{float(pts[r, c])!r} is not a finite number")
        del bad
        rapid = np.zeros(n, dtype=bool)
        if len(self.rapid_idx):
            rapid[np.frombuffer(self.rapid_idx, dtype=np.int64)] = True
        feed_idx = np.frombuffer(self.feed_idx, dtype=np.int64) if len(self.feed_idx) else np.empty(0, np.int64)
        feeds = forward_fill(n, feed_idx, np.frombuffer(self.feed_val, dtype=float), np.nan)
        feeds[rapid] = np.nan

        axes = given = None
        if self.axis_info or len(self.axis_idx):
            aidx = np.frombuffer(self.axis_idx, dtype=np.int64)
            aval = np.frombuffer(self.axis_val, dtype=float).reshape(-1, 3).copy()
            agiven = np.frombuffer(bytes(self.axis_given), dtype=np.uint8).astype(bool)
            if agiven.any():
                rows = aval[agiven]
                bad = ~np.isfinite(rows).all(axis=1)
                finite = np.where(np.isfinite(rows), rows, 0.0)
                norm = np.hypot(np.hypot(finite[:, 0], finite[:, 1]), finite[:, 2])  # 1e308 does not overflow
                bad |= np.abs(norm - 1.0) > axis_tolerance
                if bad.any():
                    j = int(np.argmax(bad))
                    at = int(aidx[agiven][j])
                    vec = ", ".join(f"{v:.9g}" for v in rows[j])
                    raise InputFileError(
                        self.source,
                        int(lines[at]) if at < n else None,
                        axis_field,
                        f"tool axis ({vec}) is not a unit vector (length {norm[j]:.9g}, tolerance {axis_tolerance:g})",
                    )
                aval[agiven] = rows / norm[:, None]
            axes = forward_fill(n, aidx, aval, (0.0, 0.0, 1.0))
            # A point's axis is "given" when the last change at its index was given there.
            keep = _last_per_index(aidx)
            at = aidx[keep][agiven[keep]]
            given = np.zeros(n, dtype=bool)
            given[at[at < n]] = True

        arcs = np.array(self.arcs, dtype=float).reshape(-1, 9) if self.arcs else np.empty((0, 9))
        arc_idx = arcs[:, 1].astype(np.int64)
        centre, arc_axis = arcs[:, 2:5].copy(), arcs[:, 5:8].copy()
        # Frames: apply each to its slice of points (and to arcs ending there), in blocks of rows so
        # that temporaries stay small.
        bounds = [f[0] for f in self.frames] + [n]
        copied = False
        for (start, rot, org), stop in zip(self.frames, bounds[1:], strict=True):
            if stop <= start or (np.array_equal(rot, np.eye(3)) and not org.any()):
                continue
            if not copied:
                pts, copied = pts.copy(), True
            for lo in range(start, stop, _BLOCK_ROWS):
                sl = slice(lo, min(stop, lo + _BLOCK_ROWS))
                pts[sl] = pts[sl] @ rot.T + org
                if axes is not None:
                    axes[sl] = axes[sl] @ rot.T
            sel = (arc_idx >= start) & (arc_idx < stop)
            if sel.any():
                centre[sel] = centre[sel] @ rot.T + org
                arc_axis[sel] = arc_axis[sel] @ rot.T
        events: list = list(self.events)
        for line, k, degree, knots, ctrl, weights, nax in self.nurbs:
            ctrl = np.asarray(ctrl, dtype=float)
            for start, rot, org in reversed(self.frames):
                if start <= k:
                    ctrl = ctrl @ rot.T + org
                    nax = None if nax is None else np.asarray(nax) @ rot.T
                    break
            events.append(Nurbs(line, k, k - 1, degree, knots, ctrl, weights, nax))
        for row, c, a in zip(arcs, centre, arc_axis, strict=True):
            k = int(row[1])
            events.append(Arc(int(row[0]), k, k - 1, vec3(c), vec3(a), float(row[8])))
        # Events are appended in file order except arcs (their line precedes their end point); a
        # stable sort on the line restores file order.
        events.sort(key=lambda e: e.line)
        units_label = ",".join(dict.fromkeys(self.units_seen)) or units
        return Toolpath(
            points=pts,
            axes=axes,
            axis_given=given,
            feeds=feeds,
            rapid=rapid,
            lines=lines,
            events=tuple(events),
            units=units_label,
            source=self.source,
            rotary=rotary,
        )


#: An arc whose start and end radii differ by more than this (metres) plus ARC_RTOL times the
#: radius draws a warning (CAM files round to 4-6 decimals; 0.0002 in is seen in real G-code).
ARC_ATOL = 1e-5
ARC_RTOL = 1e-3


def check_arcs(tp: Toolpath, warn) -> None:
    """Warn (through a WarningLimiter) about arcs whose end points are not on one circle."""
    arcs = tp.arcs
    if not arcs:
        return
    start = np.array([a.start for a in arcs])
    end = np.array([a.index for a in arcs])
    c = np.array([a.centre for a in arcs])
    n = np.array([a.axis for a in arcs])
    u = tp.points[start] - c
    v = tp.points[end] - c
    ru = np.linalg.norm(u - np.sum(u * n, axis=1)[:, None] * n, axis=1)
    rv = np.linalg.norm(v - np.sum(v * n, axis=1)[:, None] * n, axis=1)
    bad = np.abs(ru - rv) > ARC_ATOL + ARC_RTOL * np.maximum(ru, rv)
    bad |= (ru == 0.0) | (rv == 0.0)
    for j in np.flatnonzero(bad):
        warn.warn(
            "inconsistent arcs",
            arcs[j].line,
            f"arc end points are {ru[j] * 1e3:.6g} mm and {rv[j] * 1e3:.6g} mm from its axis: "
            "not on one circle (the radius is blended linearly along the arc)",
        )
