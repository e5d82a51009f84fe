"""The Toolpath container, arc linearisation, and read_toolpath's format detection."""

from __future__ import annotations

import dataclasses
import io
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import planner
from planner.io import (
    Arc,
    Event,
    InputFileError,
    Toolpath,
    arc_samples,
    detect_format,
    linearize_arcs,
    read_apt,
    read_toolpath,
)


def _tp(n=3, **kw):
    base = dict(
        points=np.arange(3 * n, dtype=float).reshape(n, 3),
        axes=None,
        axis_given=None,
        feeds=np.full(n, 0.01),
        rapid=np.zeros(n, bool),
        lines=np.arange(1, n + 1),
    )
    base.update(kw)
    return Toolpath(**base)


def test_toolpath_arrays_are_read_only_and_shapes_checked():
    tp = _tp()
    assert len(tp) == 3 and tp.points.dtype == float and tp.lines.dtype == np.int64
    with pytest.raises(ValueError):
        tp.points[0, 0] = 1.0
    with pytest.raises(ValueError, match=r"points must have shape \(n, 3\)"):
        _tp(points=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="feeds must have shape"):
        _tp(feeds=np.zeros(2))
    with pytest.raises(ValueError, match="both be given or both be None"):
        _tp(axes=np.zeros((3, 3)))
    assert "3 points" in repr(tp)


@pytest.mark.parametrize(
    "axis, why",
    [((0.0, 0.0, 0.0), "is zero"), ((0.0, 1e-13, 0.0), "is zero"), ((0.0, math.nan, 1.0), "is not finite"),
     ((math.inf, 0.0, 0.0), "is not finite"), ((1e200, 1e200, 0.0), "too long to normalise")],
)
def test_a_tool_axis_without_direction_is_refused_naming_the_point_and_line(axis, why):
    n = 5
    axes = np.tile([0.0, 0.0, 1.0], (n, 1))
    axes[2] = axis
    kw = dict(axes=axes, axis_given=np.ones(n, bool), lines=np.arange(10, 10 + n), source="job.cls")
    with pytest.raises(InputFileError) as exc:
        _tp(n, **kw)
    assert str(exc.value).startswith("job.cls line 12, tool axis of point 2: ") and why in str(exc.value)
    assert isinstance(exc.value, planner.PlannerError) and exc.value.line == 12
    # a toolpath changed with dataclasses.replace is checked again; one with good axes plans (any length)
    good = _tp(n, axes=np.tile([0.0, 0.0, 2.0], (n, 1)), axis_given=np.ones(n, bool), lines=np.arange(n))
    with pytest.raises(InputFileError, match="tool axis of point 2"):
        dataclasses.replace(good, axes=axes)
    assert len(planner.plan(good).moves) >= 1


def test_plan_of_a_toolpath_with_a_zero_axis_names_the_point():
    """The form of issue 24: a Toolpath built by hand with a zero axis, passed to planner.plan."""
    n = 5
    pts = np.c_[np.linspace(0.0, 0.1, n), np.zeros(n), np.zeros(n)]
    axes = np.tile([0.0, 0.0, 1.0], (n, 1))
    axes[2] = 0.0
    with pytest.raises(planner.PlannerError, match=r"<toolpath> line 3, tool axis of point 2: \(0.0, 0.0, 0.0\) is zero"):
        planner.plan(Toolpath(points=pts, axes=axes, axis_given=np.ones(n, bool), feeds=np.full(n, 0.01),
                              rapid=np.zeros(n, bool), lines=np.arange(1, n + 1)))


def test_events_of_and_arcs():
    ev = (Event("tool_change", 2, 0, "T1", 1.0), Arc(5, 2, 1, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)))
    tp = _tp(events=ev)
    assert tp.events_of("tool_change") == ev[:1]
    assert tp.arcs == ev[1:] and tp.events_of("arc") == ev[1:]


@settings(max_examples=60, deadline=None)
@given(
    r=st.floats(1e-4, 0.5),
    a0=st.floats(-math.pi, math.pi),
    sweep=st.floats(0.01, 2 * math.pi - 0.01),
    tol=st.floats(1e-7, 1e-3),
    h=st.floats(-0.01, 0.01),
)
def test_arc_samples_stay_within_the_chord_tolerance(r, a0, sweep, tol, h):
    n = np.array([0.0, 0.0, 1.0])
    c = np.array([0.1, -0.2, 0.3])
    start = c + r * np.array([math.cos(a0), math.sin(a0), 0.0])
    end = c + r * np.array([math.cos(a0 + sweep), math.sin(a0 + sweep), 0.0]) + h * n
    pts = np.vstack([start, arc_samples(start, end, c, n, tol), end])
    rad = np.linalg.norm((pts - c)[:, :2], axis=1)
    np.testing.assert_allclose(rad, r, rtol=1e-12)
    ang = np.unwrap(np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0]))
    assert np.all(np.diff(ang) > 0)  # counter-clockwise about +Z
    assert ang[-1] - ang[0] == pytest.approx(sweep, abs=1e-9)
    np.testing.assert_allclose(pts[:, 2] - c[2], h * (ang - ang[0]) / sweep, atol=1e-12)
    steps = np.diff(ang)
    assert np.all(r * (1 - np.cos(steps / 2)) <= tol * (1 + 1e-9))  # sagitta of every chord


def test_linearize_arcs_keeps_events_in_place():
    text = (
        "GOTO/10,0,0,0,0,1\n"
        "FEDRAT/100\n"
        "CUTCOM/LEFT\n"
        "CIRCLE/0,0,0,0,0,1,10\n"
        "GOTO/0,10,0,0,1,0\n"
        "COOLNT/OFF\n"
        "GOTO/0,20,0\n"
    )
    tp = read_apt(io.StringIO(text), source="t.apt")
    lin = linearize_arcs(tp, 1e-6)
    (arc,) = lin.arcs
    assert arc.start == 0 and arc.index == len(lin) - 2
    inner = slice(1, arc.index)
    np.testing.assert_allclose(np.linalg.norm(lin.points[inner], axis=1), 0.01, rtol=1e-12)
    assert (lin.lines[inner] == 5).all() and not lin.axis_given[inner].any()
    np.testing.assert_allclose(lin.feeds[inner], 100e-3 / 60, rtol=1e-15)
    # Axes are slerped from (0,0,1) to (0,1,0): unit, monotone in angle.
    np.testing.assert_allclose(np.linalg.norm(lin.axes, axis=1), 1.0, atol=1e-15)
    assert np.all(np.diff(np.arctan2(lin.axes[: arc.index + 1, 1], lin.axes[: arc.index + 1, 2])) > 0)
    cut = lin.events_of("cutcom")[0]
    cool = lin.events_of("coolant")[0]
    assert cut.index == 1  # before the arc's first chord point, as it was before its end point
    assert cool.index == arc.index + 1
    np.testing.assert_array_equal(lin.points[[0, -2, -1]], tp.points)
    assert linearize_arcs(lin, 1e-6) is not None and len(linearize_arcs(lin, 1e-6)) == len(lin)
    with pytest.raises(ValueError, match="tolerance must be positive"):
        linearize_arcs(tp, 0.0)


def test_read_toolpath_dispatch(tmp_path):
    files = {
        "a.apt": "GOTO/1,2,3\n",
        "b.cls": "GOTO/1,2,3\n",
        "c.ncl.2": "GOTO / 1, 2, 3\n",
        "d.nc": "G21 G01 X1 Y2 Z3 F100\n",
        "e.csv": "1,2,3\n",
        "f.json": '[{"x": 1, "y": 2, "z": 3}]',
        "g.txt": "\ufeffInformation listing created by\tx\n\n%\nN5 G21 G01 X1 Y2 Z3 F100\n%\n",
        "h.txt": "$$ cl\nGOTO/1,2,3\n",
        "i.txt": "x y z\n1 2 3\n",
        "j.dat": '  {"points": [[1, 2, 3]]}',
    }
    want = dict(zip(files, ["apt", "apt", "apt", "gcode", "csv", "json", "gcode", "apt", "csv", "json"], strict=True))
    for name, text in files.items():
        p = tmp_path / name
        p.write_text(text, encoding="utf-8")
        assert detect_format(p) == want[name], name
        tp = read_toolpath(p)
        np.testing.assert_allclose(tp.points, [[1e-3, 2e-3, 3e-3]], atol=1e-18)
        assert tp.source == name
    bad = tmp_path / "k.txt"
    bad.write_text("hello world\n")
    with pytest.raises(InputFileError, match=r"k\.txt: cannot tell the format"):
        read_toolpath(bad)
    with pytest.raises(TypeError, match="needs format"):
        read_toolpath(io.StringIO("GOTO/1,2,3\n"))
    assert len(read_toolpath(io.StringIO("GOTO/1,2,3\n"), format="apt")) == 1
    with pytest.raises(ValueError, match="format must be one of"):
        read_toolpath(bad, format="step")
