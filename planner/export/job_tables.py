"""The pose stream of a whole CAM job as CSV or JSON, written move by move in bounded memory.

A whole NX job is millions of poses: both writers take the chunks of ``CamJob.iter_stream(rate)``
(one move each, optionally with the robot's joints from :func:`planner.cam.stream.track_joints`) and
write them as they come. Numbers: times with 6 decimals (s), poses and joints with 9 significant
digits (nm and 1e-8 rad at the scale of a robot cell); joints without an inverse-kinematics solution
are empty (CSV) or ``null`` (JSON).

JSON layout (one object; the keys come in this order, so a streaming parser meets the header first)::

    {"format": "planner-cam-job-stream/1",
     "parameters": {...},                  # generator, job parameters and figures (header.cam_job_parameters)
     "moves": [{"move", "kind", "pass", "operation", "first_line", "last_line", "t_start", "duration_s",
                "samples"(, "for_pass", "q_from", "q_to")}, ...],  # every move, skipped records included;
                                           # a change of the arm configuration with its joints (rad)
     "columns": ["t", "x", "y", "z", "rx", "ry", "rz", "kind", "move", "pass", "line"(, "q0".."q5")],
     "samples": [[t, x, y, z, rx, ry, rz, kind, move, pass, line(, q0..q5)], ...]}

Poses are p[x, y, z, rx, ry, rz] of the TCP in the robot base frame (m, rotation vector, continuous
over the job, so |r| may exceed pi); ``pass`` is -1 on rapids, turns and changes of the arm
configuration ("reconfiguration": a joint move in a rapid, its poses the forward kinematics of its
joints); ``line`` is the source line of the record the sample carries out.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping

import numpy as np

from planner.export.header import ExportError, cam_job_parameters, header_lines

#: The ``format`` value of a whole-job JSON stream.
JOB_JSON_FORMAT = "planner-cam-job-stream/1"
POSE_COLUMNS = ("x", "y", "z", "rx", "ry", "rz")
JOINT_COLUMNS = tuple(f"q{i}" for i in range(6))


def _chunks_with_joints(chunks: Iterable) -> Iterable:
    """(chunk, joints or None) pairs from chunks or (chunk, joints) pairs."""
    for item in chunks:
        yield item if isinstance(item, tuple) else (item, None)


def move_table(job, rate: float) -> list[dict]:
    """One dict per move of the job: move, kind, pass, operation, first_line, last_line, t_start (s),
    duration_s, samples (poses the move starts in the stream at ``rate``; 0 for skipped records); a change
    of the arm configuration adds for_pass (the first pass made on it) and q_from, q_to (rad)."""
    from planner.cam.stream import sample_counts

    counts = sample_counts(job.moves, rate)
    starts = np.concatenate(([0], np.cumsum(counts)))[:-1] / rate
    out = []
    for k, m in enumerate(job.moves):
        item = m.item
        last = getattr(item, "last_line", None)
        out.append({
            "move": k, "kind": m.kind, "pass": int(m.pass_index), "operation": getattr(item, "operation", ""),
            "first_line": int(m.line), "last_line": int(m.line if last is None else last),
            "t_start": float(starts[k]), "duration_s": m.duration, "samples": int(counts[k]),
        })
        if m.kind == "reconfiguration":
            out[-1].update({"for_pass": int(item.pass_index), "q_from": [float(x) for x in item.q_from],
                            "q_to": [float(x) for x in item.q_to]})
    if out and counts.any():
        out[int(np.flatnonzero(counts)[-1])]["samples"] += 1  # the job's final pose
    return out


def _parameters(job, rate: float, parameters: Mapping | None) -> dict:
    """The header of a job's stream: its parameters and figures, and its changes of the arm configuration."""
    extra = {"reconfigurations": job.reconfiguration_lines()} if getattr(job, "reconfigurations", ()) else {}
    return cam_job_parameters(job, rate, {**extra, **dict(parameters or {})})


def _open(target):
    if hasattr(target, "write"):
        return target, False
    return open(target, "w", encoding="utf-8", newline="\n"), True


def write_job_csv(job, chunks: Iterable, target, *, rate: float, parameters: Mapping | None = None) -> int:
    """Write a whole job's pose stream as CSV; returns the number of poses written.

    ``# key: <json>`` header lines (:func:`~planner.export.header.cam_job_parameters`), then the column
    line ``t,x,y,z,rx,ry,rz,move,pass,line[,q0..q5]`` and one row per pose.

    Parameters
    ----------
    job : CamJob
    chunks : iterable of StreamChunk, or of (StreamChunk, joints (k, 6)) pairs
        ``job.iter_stream(rate)``, or ``track_joints(job, job.iter_stream(rate))`` for the joint columns.
    target : path or text file
    rate : float
        The rate the chunks were sampled at, Hz (for the header).
    parameters : mapping, optional
        Extra header entries (e.g. the input file name).
    """
    params = _parameters(job, rate, parameters)
    f, close = _open(target)
    n, names = 0, None
    try:
        for line in header_lines(params):
            f.write(f"# {line}\n")
        for chunk, q in _chunks_with_joints(chunks):
            if names is None:
                names = ["t", *POSE_COLUMNS, "move", "pass", "line"] + (list(JOINT_COLUMNS) if q is not None else [])
                f.write(",".join(names) + "\n")
            k = chunk.times.size
            fmt = "%.6f" + ",%.9g" * 6 + f",{chunk.move},{chunk.pass_index},%d" + (",%.9g" * 6 if q is not None else "")
            cols = [chunk.times[:, None], chunk.poses, chunk.lines[:, None]] + ([q] if q is not None else [])
            text = "\n".join(fmt % tuple(r) for r in np.hstack(cols).tolist())
            if q is not None and not np.isfinite(q).all():
                text = text.replace("nan", "")
            f.write(text + "\n")
            n += k
    finally:
        if close:
            f.close()
    return n


def write_job_json(job, chunks: Iterable, target, *, rate: float, parameters: Mapping | None = None) -> int:
    """Write a whole job's pose stream as one JSON object (layout in the module doc); returns the poses written.

    Parameters are those of :func:`write_job_csv`; with joints the columns ``q0..q5`` (rad) follow.
    Memory stays bounded by one move's poses; the file is valid JSON only once complete.
    """
    params = _parameters(job, rate, parameters)
    try:
        head = json.dumps(params, allow_nan=False)
        moves = json.dumps(move_table(job, rate), allow_nan=False)
    except ValueError as exc:
        raise ExportError(f"parameters: values must be finite numbers for JSON ({exc})") from None
    f, close = _open(target)
    n = 0
    try:
        f.write(f'{{"format": "{JOB_JSON_FORMAT}",\n "parameters": {head},\n "moves": {moves},\n')
        first = True
        for chunk, q in _chunks_with_joints(chunks):
            if first:
                cols = ["t", *POSE_COLUMNS, "kind", "move", "pass", "line"] + (list(JOINT_COLUMNS) if q is not None
                                                                               else [])
                f.write(f' "columns": {json.dumps(cols)},\n "samples": [\n')
            fixed = f',"{chunk.kind}",{chunk.move},{chunk.pass_index},%d'
            fmt = "[%.6f" + ",%.9g" * 6 + fixed + (",%.9g" * 6 if q is not None else "") + "]"
            cols = [chunk.times[:, None], chunk.poses, chunk.lines[:, None]] + ([q] if q is not None else [])
            text = ",\n".join(fmt % tuple(r) for r in np.hstack(cols).tolist())
            if q is not None and not np.isfinite(q).all():
                text = text.replace("nan", "null")
            f.write(("" if first else ",\n") + text)
            first = False
            n += chunk.times.size
        if first:  # no motion at all
            f.write(' "columns": [], "samples": [\n')
        f.write("\n]}\n")
    finally:
        if close:
            f.close()
    return n
