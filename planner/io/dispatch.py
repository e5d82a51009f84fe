"""``read_toolpath``: pick the reader from the file name, else from the first lines of the file."""

from __future__ import annotations

import itertools
import os
import re
from collections.abc import Callable
from pathlib import Path

from planner.io._collect import open_lines, source_name
from planner.io.apt import read_apt
from planner.io.csv_reader import read_csv
from planner.io.errors import InputFileError
from planner.io.gcode import read_gcode
from planner.io.json_reader import read_json
from planner.io.options import ReaderArgumentError, ReaderArgumentTypeError, check_src, choice
from planner.io.toolpath import Toolpath

READERS: dict[str, Callable[..., Toolpath]] = {"apt": read_apt, "gcode": read_gcode, "csv": read_csv, "json": read_json}

#: File suffixes and the format they name (".txt" and unknown suffixes are sniffed).
SUFFIXES = {
    ".apt": "apt", ".cls": "apt", ".clsf": "apt", ".cl": "apt", ".ncl": "apt", ".aptsource": "apt",
    ".nc": "gcode", ".ngc": "gcode", ".tap": "gcode", ".gcode": "gcode", ".mpf": "gcode", ".spf": "gcode",
    ".eia": "gcode",
    ".csv": "csv", ".tsv": "csv", ".xyz": "csv", ".json": "json",
}  # fmt: skip

_APT = re.compile(
    r"\s*(GOTO|FROM|TOOL PATH|MSYS|CSYS|FEDRAT|TLDATA|LOADTL|LOAD\s*/|UNITS?\s*/|PARTNO|RAPID|MULTAX|"
    r"CUTTER|SPINDL|COOLNT|PAINT|MACHIN|CIRCLE|\$\$)",
    re.IGNORECASE,
)
_GCODE = re.compile(r"\s*(%|N\d+|[GMT]\d|O\d|\(|;|[XYZ]\s*[-+.\d]|DEF\s|MSG\s*\(|_\w+\s*=)", re.IGNORECASE)
_NUMERIC = re.compile(r"\s*[-+.\d]")


def detect_format(path) -> str:
    """The reader a file needs: "apt", "gcode", "csv" or "json" (by suffix, else by content).

    Raises
    ------
    InputFileError
        When neither the name nor the first 200 lines tell.
    """
    for suffix in reversed(Path(os.fspath(path)).suffixes):
        fmt = SUFFIXES.get(suffix.lower())
        if fmt is not None:
            return fmt
    with open_lines(path) as lines:
        head = list(itertools.islice(lines, 200))
    k = 0
    if head and head[0].startswith("Information listing created by"):
        while k < len(head) and head[k].strip():
            k += 1
    for text in head[k:]:
        t = text.strip()
        if not t:
            continue
        if t[0] in "{[":
            return "json"
        if _APT.match(t):
            return "apt"
        if _GCODE.match(t):
            return "gcode"
        if _NUMERIC.match(t) or re.match(r"\s*[\"']?x\b", t, re.IGNORECASE):
            return "csv"
    raise InputFileError(
        source_name(path, None), None, "", "cannot tell the format from the name or the first lines; pass "
        "format='apt', 'gcode', 'csv' or 'json'"
    )  # fmt: skip


def read_toolpath(path, *, format: str | None = None, **options) -> Toolpath:
    """Read a toolpath file of any supported format.

    Parameters
    ----------
    path : str, os.PathLike or text stream
        The file (a stream needs ``format``).
    format : {"apt", "gcode", "csv", "json"}, optional
        Skip detection. By default the suffix decides (``.apt .cls .cl .ncl`` APT; ``.nc .ngc .tap
        .gcode .mpf .spf`` G-code, the last two in the Sinumerik dialect; ``.csv .tsv .xyz`` CSV;
        ``.json``), else the first lines of the file. Any format may be written in UTF-8, UTF-16 or UTF-32
        (with or without a byte-order mark; :func:`planner.io._collect.file_encoding`).
    **options
        Passed to the reader: :func:`~planner.io.apt.read_apt`, :func:`~planner.io.gcode.read_gcode`
        (e.g. ``machine="haas-umc-750"``), :func:`~planner.io.csv_reader.read_csv` or
        :func:`~planner.io.json_reader.read_json`.

    Returns
    -------
    Toolpath

    Raises
    ------
    ReaderArgumentError
        A bad argument (named, with the known values of a named choice), or an option the reader of this
        format does not take (naming the formats that take it), before the file is read.
    InputFileError
        A bad file (naming the file, the line and the field).
    """
    check_src(path, "path")
    if format is not None:
        choice(format, "format", READERS)
    elif not isinstance(path, str | os.PathLike):
        raise ReaderArgumentTypeError("format", "reading a stream needs format='apt', 'gcode', 'csv' or 'json'")
    else:
        format = detect_format(path)
    check_options(format, options)
    return READERS[format](path, **options)


def reader_options(fmt: str) -> tuple[str, ...]:
    """The keyword options the reader of format ``fmt`` takes (after the file)."""
    import inspect

    return tuple(list(inspect.signature(READERS[fmt]).parameters)[1:])


def check_options(fmt: str, options) -> None:
    """:class:`ReaderArgumentError` naming the first option in ``options`` that the reader of format ``fmt`` does
    not take (and the formats whose readers take it)."""
    for key in options:
        if key not in reader_options(fmt):
            where = [f for f in READERS if key in reader_options(f)]
            also = f" (it is for {', '.join(where)} files)" if where else ""
            raise ReaderArgumentError(str(key), f"option {key!r} does not apply to {fmt} files{also}")
