"""A job's trajectory as CSV or JSON, written chunk by chunk in bounded memory (one layout each, every mode).

A whole NX job is millions of poses: both writers read the chunks of a :class:`planner.trajectory.Trajectory`
(one move each) and write them as they come, to a temporary file that replaces the target only when
complete. Numbers: times with 6 decimals (s), poses and joints with 9 significant digits (nm and 1e-8 rad at
the scale of a robot cell); joints without an inverse-kinematics solution are empty (CSV) or ``null`` (JSON).

CSV layout: ``# key: <json>`` header lines (:func:`~planner.export.header.trajectory_parameters`), then the
column line and one row per sample::

    t,x,y,z,rx,ry,rz,move,pass,line[,q0..q5][,io]

JSON layout (one object; the keys come in this order, so a streaming parser meets the header first)::

    {"format": "planner-trajectory/1",
     "parameters": {...},                  # generator, settings and figures of the job
     "moves": [{"move", "kind", "pass", "operation", "first_line", "last_line", "t_start", "duration_s",
                "samples"(, "for_pass", "q_from", "q_to")}, ...],  # every move, skipped records included
     "columns": ["t", "x", "y", "z", "rx", "ry", "rz", "kind", "move", "pass", "line"(, "q0".."q5")(, "io")],
     "samples": [[t, x, y, z, rx, ry, rz, kind, move, pass, line(, q0..q5)(, io)], ...]}

Poses are p[x, y, z, rx, ry, rz] of the TCP in the robot base frame (m, rotation vector, continuous over the
job, so |r| may exceed pi); the joint columns come with a robot; ``io`` (the digital output bits, the 18-bit word
of :mod:`planner.kinematics.ur_outputs`) when the job switches an output; ``pass`` is -1 on rapids, turns, dwells
and changes of the arm configuration; a dwell's rows (kind "dwell" in JSON and in ``moves``) repeat one pose while
the time advances; ``line`` is the source line of the record the sample carries out (for
waypoint arrays: the waypoint index).
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping

import numpy as np

from planner.export.files import text_target
from planner.export.header import ExportError, header_lines, trajectory_parameters
from planner.protocols import TrajectoryLike

#: The ``format`` value of a JSON trajectory.
JSON_FORMAT = "planner-trajectory/1"
POSE_COLUMNS = ("x", "y", "z", "rx", "ry", "rz")
JOINT_COLUMNS = tuple(f"q{i}" for i in range(6))


def columns(trajectory: TrajectoryLike, kind_column: bool = False) -> list[str]:
    """The column names of a trajectory's table (``kind`` after the pose in JSON)."""
    job = trajectory.job
    return (["t", *POSE_COLUMNS] + (["kind"] if kind_column else []) + ["move", "pass", "line"]
            + (list(JOINT_COLUMNS) if trajectory.robot is not None else [])
            + (["io"] if job.settings.cut_output is not None else []))


def _rows(chunk, fixed: str, with_io: bool) -> tuple[str, list]:
    q = chunk.joints
    fmt = "%.6f" + ",%.9g" * 6 + fixed + ",%d" + (",%.9g" * 6 if q is not None else "") + (",%d" if with_io else "")
    cols = [chunk.times[:, None], chunk.poses, chunk.lines[:, None]] + ([q] if q is not None else [])
    if with_io:
        cols.append(chunk.io[:, None])
    return fmt, np.hstack(cols).tolist()


def csv_text(trajectory: TrajectoryLike, *, parameters: Mapping | None = None, progress=None) -> Iterator[str]:
    """The CSV text of a trajectory (layout in the module doc) in pieces, one move at a time: for streaming
    (e.g. an HTTP response) in bounded memory. ``parameters`` and ``progress`` as in :func:`write_csv`."""
    params = trajectory_parameters(trajectory, parameters)
    with_io = trajectory.job.settings.cut_output is not None
    yield "".join(f"# {line}\n" for line in header_lines(params)) + ",".join(columns(trajectory)) + "\n"
    for chunk in trajectory.chunks(progress=progress):
        fmt, rows = _rows(chunk, f",{chunk.move},{chunk.pass_index}", with_io)
        text = "\n".join(fmt % tuple(r) for r in rows)
        if chunk.joints is not None and not np.isfinite(chunk.joints).all():
            text = text.replace("nan", "")
        yield text + "\n"


def json_text(trajectory: TrajectoryLike, *, parameters: Mapping | None = None, progress=None) -> Iterator[str]:
    """The JSON text of a trajectory (layout in the module doc) in pieces, one move at a time (see
    :func:`csv_text`). The header is checked before the first piece: a bad parameter raises ExportError."""
    params = trajectory_parameters(trajectory, parameters)
    try:
        head = json.dumps(params, allow_nan=False)
        moves = json.dumps(trajectory.moves(), allow_nan=False)
    except ValueError as exc:
        raise ExportError(f"parameters: values must be finite numbers for JSON ({exc})") from None
    return _json_pieces(trajectory, head, moves, progress)


def _json_pieces(trajectory: TrajectoryLike, head: str, moves: str, progress) -> Iterator[str]:
    with_io = trajectory.job.settings.cut_output is not None
    yield (f'{{"format": "{JSON_FORMAT}",\n "parameters": {head},\n "moves": {moves},\n'
           f' "columns": {json.dumps(columns(trajectory, kind_column=True))},\n "samples": [\n')
    first = True
    for chunk in trajectory.chunks(progress=progress):
        fmt, rows = _rows(chunk, f',"{chunk.kind}",{chunk.move},{chunk.pass_index}', with_io)
        text = ",\n".join(f"[{fmt % tuple(r)}]" for r in rows)
        if chunk.joints is not None and not np.isfinite(chunk.joints).all():
            text = text.replace("nan", "null")
        yield ("" if first else ",\n") + text
        first = False
    yield "\n]}\n"


def _write(pieces: Iterator[str], target, trajectory: TrajectoryLike) -> int:
    with text_target(target) as f:
        for piece in pieces:
            f.write(piece)
    return trajectory.n_samples


def write_csv(trajectory: TrajectoryLike, target, *, parameters: Mapping | None = None, progress=None) -> int:
    """Write a trajectory as CSV (layout in the module doc); returns the number of samples written.

    Parameters
    ----------
    trajectory : Trajectory
        ``job.trajectory(rate)``; with a robot the joint columns come too.
    target : path or text file
        A path is written atomically.
    parameters : mapping, optional
        Extra header entries (e.g. the input file name).
    progress : callable (stage, done, total), optional
        Called with the samples written.
    """
    return _write(csv_text(trajectory, parameters=parameters, progress=progress), target, trajectory)


def write_json(trajectory: TrajectoryLike, target, *, parameters: Mapping | None = None, progress=None) -> int:
    """Write a trajectory as one JSON object (layout in the module doc); returns the samples written.

    Parameters are those of :func:`write_csv`. Memory stays bounded by one move's samples.
    """
    return _write(json_text(trajectory, parameters=parameters, progress=progress), target, trajectory)
