"""Pose streams as CSV and JSON files: time, arc length, pose, joint solution, tool I/O state.

Both carry the generator and the job's parameters, and the I/O events with their switching times and
sample indices. Numbers are written with 17 significant digits, so reading a file back gives the
written arrays exactly. Readers return a :class:`PoseRecord`.
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from planner.export.header import (
    ExportError,
    check_joints,
    event_dicts,
    header_lines,
    io_column,
    job_parameters,
    parse_header_line,
)

POSE_COLUMNS = ("x", "y", "z", "rx", "ry", "rz")
JOINT_COLUMNS = tuple(f"q{i}" for i in range(6))


@dataclass(frozen=True, eq=False)
class PoseRecord:
    """A pose stream read back from a CSV or JSON export.

    Attributes
    ----------
    times, s : ndarray (n,)
        Sample times (s) and arc lengths (m).
    poses : ndarray (n, 6)
        TCP poses p[x, y, z, rx, ry, rz] in the base frame.
    joints : ndarray (n, 6) or None
        Joint solutions (rad), if the export had them.
    io : dict
        Column name (``standard_do0`` ...) -> state (n,) of bool.
    events : list of dict
        I/O events: time, index, s, output, pin, value, lead_time, name.
    parameters : dict
        The header: generator and job parameters.
    """

    times: np.ndarray
    s: np.ndarray
    poses: np.ndarray
    joints: np.ndarray | None
    io: dict = field(default_factory=dict)
    events: list = field(default_factory=list)
    parameters: dict = field(default_factory=dict)


def _columns(stream, joints):
    io_states = stream.io_states()
    names = ["t", "s", *POSE_COLUMNS]
    cols = [stream.times[:, None], stream.s[:, None], stream.poses]
    if joints is not None:
        names += JOINT_COLUMNS
        cols.append(joints)
    for ch, state in io_states.items():
        names.append(io_column(ch))
        cols.append(state.astype(float)[:, None])
    return names, np.hstack(cols)


def _open_text(target, mode: str):
    if isinstance(target, str | os.PathLike):
        return open(Path(target), mode, newline="", encoding="utf-8"), True
    return target, False


def write_csv(stream, target, *, joints=None, parameters: Mapping | None = None) -> None:
    """Write a pose stream as CSV: ``#`` header lines, then ``t,s,x,y,z,rx,ry,rz[,q0..q5][,<io>]``.

    Parameters
    ----------
    stream : PoseStream
    target : path or text file
    joints : array_like (n, 6), optional
        Joint solution of every sample (rad), e.g. from ``planner.kinematics.inverse_path``.
    parameters : mapping, optional
        Extra job parameters for the header (JSON-serializable values).

    The header has one ``# key: <json>`` line per parameter and one ``# event: <json>`` line per I/O
    event; I/O state columns are 0/1.
    """
    q = check_joints(joints, stream.times)
    params = job_parameters(stream, parameters)
    names, data = _columns(stream, q)
    f, close = _open_text(target, "w")
    try:
        for line in header_lines(params):
            f.write(f"# {line}\n")
        for e in event_dicts(stream):
            f.write(f"# event: {json.dumps(e)}\n")
        f.write(",".join(names) + "\n")
        np.savetxt(f, data, delimiter=",", fmt="%.17g")
    finally:
        if close:
            f.close()


def read_csv(source) -> PoseRecord:
    """Read a CSV written by :func:`write_csv`; errors name the line."""
    f, close = _open_text(source, "r")
    try:
        text = f.read()
    finally:
        if close:
            f.close()
    name = str(source) if isinstance(source, str | os.PathLike) else "<csv>"
    params: dict = {}
    events: list = []
    lines = text.splitlines()
    i = 0
    while i < len(lines) and lines[i].startswith("#"):
        try:
            key, value = parse_header_line(lines[i][2:])
        except ValueError as exc:
            raise ExportError(f"{name}, line {i + 1}: bad header line ({exc})") from None
        (events.append(value) if key == "event" else params.__setitem__(key, value))
        i += 1
    if i >= len(lines):
        raise ExportError(f"{name}: no column line after the header")
    names = next(csv.reader([lines[i]]))
    for need in ("t", "s", *POSE_COLUMNS):
        if need not in names:
            raise ExportError(f"{name}, line {i + 1}: missing column {need!r}")
    body = "\n".join(lines[i + 1:])
    try:
        data = np.loadtxt(io.StringIO(body), delimiter=",", ndmin=2) if body.strip() else np.zeros((0, len(names)))
    except ValueError as exc:
        raise ExportError(f"{name}: bad number in the data after line {i + 1} ({exc})") from None
    if data.shape[1] != len(names):
        raise ExportError(f"{name}: {data.shape[1]} values per row, {len(names)} columns named on line {i + 1}")
    col = {n: data[:, j] for j, n in enumerate(names)}
    joints = np.column_stack([col[c] for c in JOINT_COLUMNS]) if "q0" in col else None
    io_cols = {n: col[n] != 0.0 for n in names if "_do" in n}
    return PoseRecord(col["t"], col["s"], np.column_stack([col[c] for c in POSE_COLUMNS]), joints, io_cols,
                      events, params)


def write_json(stream, target, *, joints=None, parameters: Mapping | None = None, indent: int | None = None) -> None:
    """Write a pose stream as one JSON object.

    Keys: ``parameters`` (generator and job), ``events``, ``t``, ``s``, ``pose`` (n x 6), ``joints``
    (n x 6 or null), ``io`` (column name -> list of 0/1).
    """
    q = check_joints(joints, stream.times)
    doc = {
        "parameters": job_parameters(stream, parameters),
        "events": event_dicts(stream),
        "t": stream.times.tolist(),
        "s": stream.s.tolist(),
        "pose": stream.poses.tolist(),
        "joints": None if q is None else q.tolist(),
        "io": {io_column(ch): state.astype(int).tolist() for ch, state in stream.io_states().items()},
    }
    f, close = _open_text(target, "w")
    try:
        json.dump(doc, f, indent=indent)  # floats as repr: exact round trip
    finally:
        if close:
            f.close()


def read_json(source) -> PoseRecord:
    """Read a JSON file written by :func:`write_json`."""
    f, close = _open_text(source, "r")
    try:
        doc = json.load(f)
    except json.JSONDecodeError as exc:
        raise ExportError(f"{source}: not JSON (line {exc.lineno}: {exc.msg})") from None
    finally:
        if close:
            f.close()
    for key in ("t", "s", "pose"):
        if key not in doc:
            raise ExportError(f"{source}: missing key {key!r}")
    poses = np.asarray(doc["pose"], dtype=float).reshape(-1, 6)
    joints = None if doc.get("joints") is None else np.asarray(doc["joints"], dtype=float).reshape(-1, 6)
    io_cols = {k: np.asarray(v, dtype=int) != 0 for k, v in doc.get("io", {}).items()}
    return PoseRecord(np.asarray(doc["t"], float), np.asarray(doc["s"], float), poses, joints, io_cols,
                      list(doc.get("events", [])), dict(doc.get("parameters", {})))
