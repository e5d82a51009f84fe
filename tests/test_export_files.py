"""The one trajectory's exports (CSV, JSON, URScript), atomic writes, and saved jobs that load back to the
identical trajectory."""

from __future__ import annotations

import io
import json
import os

import numpy as np
import pytest

from planner import PlannerError, PlanSettings, load_job, plan
from planner.export import JSON_FORMAT, job_program, write_csv, write_json, write_script
from planner.io import read_toolpath
from tests.cam_excerpts import NX_HEAD

NX_PART = (0.4, 0.9965, -0.1, 0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def job():
    tp = read_toolpath(io.StringIO(NX_HEAD), format="apt")
    return plan(tp, PlanSettings(path="cam", robot="ur5e", part_frame=NX_PART, cut_output=("standard", 2), rate=125.0))


def _read_csv(path):
    header, rows = {}, []
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.startswith("# "):
                k, _, v = line[2:].partition(": ")
                header[k] = json.loads(v)
            else:
                names = line.strip().split(",")
                break
        rows = np.loadtxt(f, delimiter=",", ndmin=2)
    return header, names, rows


def test_csv_and_json_hold_the_trajectory_to_their_precision(job, tmp_path):
    tr = job.trajectory()
    whole = tr.collect()
    n_csv = write_csv(tr, tmp_path / "a.csv", parameters={"input": "head.cls"})
    n_json = write_json(tr, tmp_path / "a.json", parameters={"input": "head.cls"})
    assert n_csv == n_json == tr.n_samples == whole.times.size
    header, names, rows = _read_csv(tmp_path / "a.csv")
    assert names == ["t", "x", "y", "z", "rx", "ry", "rz", "move", "pass", "line", *[f"q{i}" for i in range(6)], "io"]
    assert header["settings"]["robot"] == "ur5e" and header["settings"]["path"] == "cam"
    assert header["samples"] == tr.n_samples and header["rate_hz"] == 125.0 and header["input"] == "head.cls"
    assert header["duration_s"] == rows[-1, 0] == tr.duration  # the header and the stream agree exactly
    assert 0.0 <= header["duration_s"] - header["motion_time_s"] < len(job.moves) / 125.0
    assert np.abs(rows[:, 0] - whole.times).max() <= 5e-7
    assert np.abs(rows[:, 1:7] - whole.poses).max() <= 5e-9 * max(1.0, np.abs(whole.poses).max())
    assert np.abs(rows[:, 10:16] - whole.joints).max() <= 5e-8
    assert np.array_equal(rows[:, 9].astype(int), whole.lines) and np.array_equal(rows[:, 16].astype(int), whole.io)
    doc = json.loads((tmp_path / "a.json").read_text())
    assert doc["format"] == JSON_FORMAT and list(doc)[:3] == ["format", "parameters", "moves"]
    assert doc["columns"][:8] == ["t", "x", "y", "z", "rx", "ry", "rz", "kind"]
    assert len(doc["samples"]) == tr.n_samples and len(doc["moves"]) == len(job.moves)
    assert sum(m["samples"] for m in doc["moves"]) == tr.n_samples
    s = np.array([r[:7] for r in doc["samples"]])
    assert np.abs(s[:, 1:] - whole.poses).max() <= 5e-9 * max(1.0, np.abs(whole.poses).max())
    # the cut output: on while cutting, off on the rapids
    kinds = np.array([r[7] for r in doc["samples"]])
    io_bits = np.array([r[-1] for r in doc["samples"]])
    assert set(io_bits[kinds == "rapid"]) == {0} and (io_bits[kinds == "cut"] == 4).mean() > 0.99


def test_a_failed_export_leaves_no_file(job, tmp_path):
    target = tmp_path / "out.json"
    target.write_text("previous contents\n")

    def fail(stage, done, total):
        if done > 100:
            raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        write_json(job.trajectory(), target, progress=fail)
    assert target.read_text() == "previous contents\n"  # untouched
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]  # no temporary file left behind
    write_json(job.trajectory(), target)
    mask = os.umask(0)
    os.umask(mask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~mask  # an ordinary file, not the temporary's 0600


def test_saved_job_loads_back_to_identical_exports(job, tmp_path):
    size = job.save(tmp_path / "head.job")
    assert size == (tmp_path / "head.job").stat().st_size and size < 2_000_000
    back = load_job(tmp_path / "head.job")
    for writer, name in ((write_csv, "x.csv"), (write_json, "x.json")):
        writer(job.trajectory(), tmp_path / f"a_{name}")
        writer(back.trajectory(), tmp_path / f"b_{name}")
        assert (tmp_path / f"a_{name}").read_bytes() == (tmp_path / f"b_{name}").read_bytes()
    write_script(job_program(job), tmp_path / "a.script")
    write_script(job_program(back), tmp_path / "b.script")
    assert (tmp_path / "a.script").read_bytes() == (tmp_path / "b.script").read_bytes()
    assert back.describe() == job.describe()


def test_damaged_or_foreign_job_files_are_refused(job, tmp_path):
    """(The saved-job file's refusals in full: tests/test_jobfile.py.)"""
    f = tmp_path / "head.job"
    job.save(f)
    blob = f.read_bytes()
    (tmp_path / "cut.job").write_bytes(blob[: len(blob) // 2])
    with pytest.raises(PlannerError, match="cut.job: the saved job is damaged"):
        load_job(tmp_path / "cut.job")
    (tmp_path / "v1.job").write_bytes(b"planner-job\n" + (1).to_bytes(2, "big") + bytes(20))
    with pytest.raises(PlannerError, match="v1.job: a saved job in the former pickle format"):
        load_job(tmp_path / "v1.job")
    (tmp_path / "other.job").write_text("GOTO/1,2,3\n")
    with pytest.raises(PlannerError, match="other.job: not a saved planner job"):
        load_job(tmp_path / "other.job")


def test_long_moves_come_in_bounded_chunks_with_the_same_samples(job):
    from planner.trajectory import _pose_chunks

    whole = list(_pose_chunks(job, 125.0, piece=10**9))
    small = list(_pose_chunks(job, 125.0, piece=100))
    assert len(small) > len(whole) and max(len(c) for c in small) == 100
    for name in ("times", "poses", "lines"):
        a = np.concatenate([getattr(c, name) for c in whole])
        b = np.concatenate([getattr(c, name) for c in small])
        assert np.array_equal(a, b), name  # bit for bit: the windows continue the rotation vectors exactly
    assert [c.move for c in small if c.final] == [c.move for c in whole]
