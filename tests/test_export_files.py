"""CSV and JSON pose streams: exact round trip, joints, tool I/O state, header, bad input."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from planner.curves import fit_ph_spline
from planner.export import ExportError, read_csv, read_json, write_csv, write_json
from planner.motion import ConstantOrientation, IOEvent, MotionLimits, io_window, plan_feed, sample_poses

LIM = MotionLimits(speed=1.0, acceleration=2.0, jerk=30.0)


@pytest.fixture(scope="module")
def stream():
    x = np.linspace(0, 0.3, 8)
    path = fit_ph_spline(np.column_stack((x, 0.05 * np.sin(8 * x), 0.01 * x)))
    prof = plan_feed(path, 0.2, LIM, span_feeds=[0.2, 0.1, np.nan, 0.3, 0.3, 0.15, 0.2])
    R = np.diag([1.0, -1.0, -1.0])
    events = [*io_window(0.05, 0.2, 4, lead_time=0.03, name="glue"), IOEvent(0.25, 0, True, output="tool")]
    return sample_poses(path, prof, ConstantOrientation(R), rate=500.0, tcp=[0, 0, 0.1, 0, 0, 0],
                        base=[0.4, 0.0, 0.1, 0, 0, 0.5], events=events)


def joints_for(st):
    return np.outer(np.sin(st.times), np.arange(1, 7)) * 0.1 + np.array([0, -1.5, 1.5, -1.5, -1.5, 0.0])


@pytest.mark.parametrize("fmt", ["csv", "json"])
@pytest.mark.parametrize("with_joints", [True, False])
def test_round_trip_is_exact(tmp_path, stream, fmt, with_joints):
    q = joints_for(stream) if with_joints else None
    f = tmp_path / f"job.{fmt}"
    extra = {"input": "part.apt", "frame": "rmf", "robot": "ur5e"}
    (write_csv if fmt == "csv" else write_json)(stream, f, joints=q, parameters=extra)
    rec = (read_csv if fmt == "csv" else read_json)(f)
    np.testing.assert_array_equal(rec.times, stream.times)
    np.testing.assert_array_equal(rec.s, stream.s)
    np.testing.assert_array_equal(rec.poses, stream.poses)
    if with_joints:
        np.testing.assert_array_equal(rec.joints, q)
    else:
        assert rec.joints is None
    states = stream.io_states()
    assert set(rec.io) == {"standard_do4", "tool_do0"}
    np.testing.assert_array_equal(rec.io["standard_do4"], states[("standard", 4)])
    np.testing.assert_array_equal(rec.io["tool_do0"], states[("tool", 0)])
    assert [e["index"] for e in rec.events] == [e.index for e in stream.events]
    assert [e["time"] for e in rec.events] == [e.time for e in stream.events]
    assert [e["name"] for e in rec.events] == ["glue on", "glue off", ""]
    p = rec.parameters
    assert p["generator"].startswith("ph-toolpath-planner") and p["rate_hz"] == 500.0
    assert p["samples"] == len(stream) and p["input"] == "part.apt" and p["robot"] == "ur5e"
    assert p["duration_s"] == stream.profile.duration and p["feed_min_m_s"] == 0.1
    np.testing.assert_allclose(p["tcp_pose"], [0, 0, 0.1, 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(p["base_transform"], stream.base, atol=0)


def test_io_state_columns_switch_at_the_event_samples(stream):
    buf = io.StringIO()
    write_csv(stream, buf)
    rec = read_csv(io.StringIO(buf.getvalue()))
    on, off, tool = stream.events
    d4 = rec.io["standard_do4"]
    assert not d4[on.index - 1] and d4[on.index] and d4[off.index - 1] and not d4[off.index]
    assert rec.times[on.index] >= on.time > rec.times[on.index - 1]
    assert rec.io["tool_do0"][tool.index:].all() and not rec.io["tool_do0"][: tool.index].any()


def test_csv_layout(stream):
    buf = io.StringIO()
    write_csv(stream, buf, joints=joints_for(stream))
    lines = buf.getvalue().splitlines()
    assert lines[0].startswith("# generator: ")
    header = next(line for line in lines if not line.startswith("#"))
    assert header == "t,s,x,y,z,rx,ry,rz,q0,q1,q2,q3,q4,q5,standard_do4,tool_do0"
    events = [json.loads(line[len("# event: "):]) for line in lines if line.startswith("# event: ")]
    assert len(events) == 3 and events[0]["lead_time"] == 0.03


def test_bad_joints_are_named(stream):
    q = joints_for(stream)
    q[5] = np.inf
    for writer in (write_csv, write_json):
        with pytest.raises(ExportError, match=r"^joints\[5\]: sample 5 \(t = 0\.01 s\)"):
            writer(stream, io.StringIO(), joints=q)
        with pytest.raises(ExportError, match=r"^joints: expected shape"):
            writer(stream, io.StringIO(), joints=q[:, :5])
        with pytest.raises(ExportError, match=r"^parameters: key 'samples' is reserved"):
            writer(stream, io.StringIO(), parameters={"samples": 3})


def test_broken_files_name_the_place(tmp_path):
    f = tmp_path / "bad.csv"
    f.write_text("# rate_hz: 500\nt,s,x,y,z,rx,ry\n0,0,0,0,0,0,0\n")
    with pytest.raises(ExportError, match="missing column 'rz'"):
        read_csv(f)
    f.write_text("# rate_hz: {oops\n")
    with pytest.raises(ExportError, match="line 1"):
        read_csv(f)
    g = tmp_path / "bad.json"
    g.write_text('{"t": [0.0],\n "s": [0.0]}')
    with pytest.raises(ExportError, match="missing key 'pose'"):
        read_json(g)
    g.write_text('{"t": [0.0],\n "s": ')
    with pytest.raises(ExportError, match="line 2"):
        read_json(g)
