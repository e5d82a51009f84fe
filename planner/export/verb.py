"""The export verb: a planned job as the bytes of a format, the one place the command line and the REST service
both take them from (``planner plan -o/--plot``, ``planner run --plot``, the service's downloads and its plot).

Formats (:data:`FORMATS`, by a file's suffix in :data:`SUFFIXES`):

- ``csv``, ``json``: the trajectory table (:mod:`planner.export.tables`), streamed one move at a time;
- ``script``: the job's URScript program (:func:`planner.export.job_script.job_program`; needs a robot), refused
  when larger than ``max_program_bytes`` (default :data:`~planner.export.job_script.MAX_PROGRAM_BYTES`, the size a
  controller's script ports are known to take; None: any size). A program a controller cannot take is not written:
  the one-line refusal names its size, the limit and the ways to run the job (``planner run --mode program`` sends
  it in pieces under the limit, one after the other; fewer passes with ``--pass``; stream mode);
- ``png``, ``svg``, ``pdf``: the picture of the job (:func:`planner.export.plot.plot_job`) titled by
  :func:`plot_title` (with ``execution=``, the run drawn over it);
- ``job``: the saved plan (:meth:`planner.PlannedJob.save`).

``parameters`` are extra header entries of the trajectory and the program (the CLI and the service give
``{"input": <the input file's name>}``); their ``"input"`` also names the job in the plot's title. A job an export
cannot be made of is refused with a one-line :class:`planner.PlannerError` ``"not writing <name>: <reason>"``.

Example (the demo pass of the repository, planned for a UR5e):

>>> from planner import PlanSettings, plan
>>> from planner.export import export, write
>>> job = plan("examples/nx_first_pass.cls", PlanSettings(robot="ur5e", part_frame=(0.4, 0.9965, -0.1, 0, 0, 0)))
>>> export(job, "csv", parameters={"input": "nx_first_pass.cls"}).startswith(b"# generator: ")
True
>>> program = export(job, "script")
>>> program.startswith(b"def ") and program.rstrip().endswith(b"end")
True
"""

from __future__ import annotations

import io
import itertools
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path

from planner.errors import PlannerError
from planner.export.files import as_path, atomic_binary, output_target, write_bytes_atomic
from planner.export.job_script import MAX_PROGRAM_BYTES, job_program
from planner.export.plot import plot_job
from planner.export.tables import csv_text, json_text
from planner.export.urscript import write_script
from planner.wording import counted

#: The formats of the export verb.
FORMATS = ("csv", "json", "script", "png", "svg", "pdf", "job")
#: A file's suffix (lower case) -> its format.
SUFFIXES = {".csv": "csv", ".json": "json", ".script": "script", ".urscript": "script", ".png": "png",
            ".svg": "svg", ".pdf": "pdf", ".job": "job"}
#: The formats that are pictures.
PLOTS = ("png", "svg", "pdf")
#: The HTTP media type of each format.
MEDIA_TYPES = {"csv": "text/csv; charset=utf-8", "json": "application/json", "script": "text/plain; charset=utf-8",
               "png": "image/png", "svg": "image/svg+xml", "pdf": "application/pdf",
               "job": "application/octet-stream"}


def format_of(target) -> str:
    """The format a file name's suffix asks for (``"out/a.CSV"`` -> ``"csv"``), or PlannerError naming the file."""
    path = as_path(target)
    fmt = SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise PlannerError(f"{path.name}: unknown output type {path.suffix or '(none)'!r} (use "
                           f"{', '.join(SUFFIXES)})")
    return fmt


def _checked_format(fmt) -> str:
    if not isinstance(fmt, str) or fmt not in FORMATS:
        raise PlannerError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    return fmt


def _checked_job(job) -> None:
    if not all(hasattr(job, name) for name in ("trajectory", "summary", "settings", "source")):
        raise PlannerError(f"job must be a PlannedJob (planner.plan(...)), got {type(job).__name__}")


def input_name(job, parameters: Mapping | None = None) -> str:
    """The name the exports give the job's input: ``parameters["input"]`` if given, else the job's source."""
    if parameters is not None and not isinstance(parameters, Mapping):
        raise PlannerError(f"parameters must be a mapping (dict) of header entries, got {type(parameters).__name__}")
    name = (parameters or {}).get("input")
    return str(name) if name is not None else str(job.source)


def file_name(input_name: str, fmt: str) -> str:
    """The file name of a job's export for download: the input's stem and the format (``"part.cls"``, ``"csv"`` ->
    ``"part.csv"``; ``"job.csv"`` for an input without a stem)."""
    return f"{Path(input_name).stem or 'job'}.{_checked_format(fmt)}"


def plot_title(job, name: str, execution=None) -> str:
    """The title of the job's picture: the input's name, passes, cut length (mm) and duration (s); with an
    execution, the robot it was executed on."""
    s = job.summary()
    if execution is not None:
        return f"{name}: {counted(s['passes'], 'pass')}, executed on a {job.settings.robot}"
    return f"{name}: {counted(s['passes'], 'pass')}, {s['cut_length_mm']:.0f} mm of cut, {s['duration_s']:.1f} s"


def stream(job, fmt: str, *, parameters: Mapping | None = None, progress=None, execution=None,
           name: str | None = None, max_program_bytes: int | None = MAX_PROGRAM_BYTES) -> Iterator[bytes]:
    """The bytes of ``job`` in format ``fmt``, in pieces (one move at a time for ``csv`` and ``json``: bounded
    memory whatever the job's length; the others whole).

    The first piece is made before this returns: a job the format cannot be made of is refused here
    (PlannerError ``"not writing <name>: <reason>"``; ``name`` default :func:`file_name`), never in the middle
    of a stream. ``progress(stage, done, total)`` is called as the trajectory is read; ``execution`` (a run's
    report) is drawn over a picture.
    """
    _checked_job(job)
    fmt = _checked_format(fmt)
    shown = input_name(job, parameters)
    name = file_name(shown, fmt) if name is None else name
    pieces = _pieces(job, fmt, parameters, progress, execution, shown, name, max_program_bytes)
    first = next(pieces, b"")
    return itertools.chain((first,), pieces)


def export(job, fmt: str, *, parameters: Mapping | None = None, progress=None, execution=None,
           max_program_bytes: int | None = MAX_PROGRAM_BYTES) -> bytes:
    """The bytes of ``job`` in format ``fmt`` (one of :data:`FORMATS`) at once: what :func:`write` writes to a file
    of that type, and the service sends. See :func:`stream` for a large trajectory.

    Examples
    --------
    >>> import numpy as np
    >>> from planner import PlanSettings, plan
    >>> from planner.export import export
    >>> t = np.linspace(0.0, 1.0, 9)
    >>> bead = np.c_[0.2 * t, 0.03 * np.sin(2 * np.pi * t), np.zeros_like(t)]
    >>> job = plan(bead, PlanSettings(feed=0.02, robot="ur5e", part_frame=(0.4, -0.1, 0.2, 0, 0, 0)))
    >>> rows = [r for r in export(job, "csv").decode().splitlines() if not r.startswith("#")]
    >>> rows[0], len(rows) - 1          # the columns, then one row per 500 Hz sample (m, rad)
    ('t,x,y,z,rx,ry,rz,move,pass,line,q0,q1,q2,q3,q4,q5', 6036)
    >>> export(job, "script").decode().count("movep(")   # the URScript program: movep along the pass
    176
    """
    return b"".join(stream(job, fmt, parameters=parameters, progress=progress, execution=execution,
                           max_program_bytes=max_program_bytes))


def _pieces(job, fmt: str, parameters, progress, execution, shown: str, name: str,
            max_program_bytes: int | None) -> Iterator[bytes]:
    if fmt in ("csv", "json"):
        writer = csv_text if fmt == "csv" else json_text
        for piece in writer(job.trajectory(), parameters=parameters, progress=progress):
            yield piece.encode("utf-8")
    elif fmt == "script":
        yield _program(job, parameters, progress, name, max_program_bytes).encode("utf-8")
    elif fmt in PLOTS:
        buf = io.BytesIO()
        plot_job(job, buf, title=plot_title(job, shown, execution), execution=execution, image_format=fmt)
        yield buf.getvalue()
    else:  # "job"
        with tempfile.TemporaryDirectory(prefix="planner-export-") as folder:
            target = Path(folder) / "plan.job"
            job.save(target)
            yield target.read_bytes()


def _program(job, parameters, progress, name: str, max_program_bytes: int | None, moves=None) -> str:
    if max_program_bytes is not None and not (isinstance(max_program_bytes, int) and max_program_bytes > 0):
        raise PlannerError(f"max_program_bytes must be a number of bytes > 0 or None, got {max_program_bytes!r}")
    try:
        text = job_program(job, moves, parameters=parameters, progress=progress)
    except PlannerError as exc:
        raise PlannerError(f"not writing {name}: {exc}") from None
    size = len(text.encode("utf-8"))
    if max_program_bytes is not None and size > max_program_bytes:
        raise PlannerError(
            f"not writing {name}: the program is {size} bytes ({text.count(chr(10))} lines), over the "
            f"{max_program_bytes} bytes a UR controller is known to take in one program (the limit): run the job "
            "with `planner run --mode program` (sent in pieces under the limit), export fewer passes (--pass), stream "
            "it, or raise the limit for a controller known to take more (--max-program-bytes)")
    return text


def write(job, target, *, parameters: Mapping | None = None, progress=None, execution=None,
          max_program_bytes: int | None = MAX_PROGRAM_BYTES, program=None) -> str:
    """Write ``job`` to the file ``target`` in the format of its suffix (:data:`SUFFIXES`), atomically (the bytes
    :func:`export` gives); what was written, for a person (``"31250 poses, with joints"``, ``"212 movep"``,
    ``"speeds from all 31250 poses, joints from 1 in 2"``, ``"1204 bytes"``). ``program``: for a URScript target,
    the job's program moves already made (:func:`planner.export.plan_job_program`; default: made here)."""
    _checked_job(job)
    fmt = format_of(target)
    path = as_path(target)
    if fmt == "job":
        return f"{job.save(path)} bytes"
    if fmt == "script":
        text = _program(job, parameters, progress, path.name, max_program_bytes, program)
        write_script(text, path)
        counts = {cmd: text.count(f"\n  {cmd}(") for cmd in ("movep", "movel", "movej")}
        return ", ".join(f"{n} {cmd}" for cmd, n in counts.items() if n)
    if fmt in PLOTS:
        output_target(path)  # a target it may not replace is refused before the drawing
        buf = io.BytesIO()
        dg = plot_job(job, buf, title=plot_title(job, input_name(job, parameters), execution), execution=execution,
                      image_format=fmt)
        write_bytes_atomic(path, buf.getvalue())
        return f"speeds from all {dg.samples} poses, joints from 1 in {dg.step}"
    pieces = stream(job, fmt, parameters=parameters, progress=progress, name=path.name)
    with atomic_binary(path) as f:
        for piece in pieces:
            f.write(piece)
    return f"{job.trajectory().n_samples} poses" + (", with joints" if job.settings.robot is not None else "")


__all__ = ["FORMATS", "MEDIA_TYPES", "PLOTS", "SUFFIXES", "export", "file_name", "format_of", "input_name",
           "plot_title", "stream", "write"]
