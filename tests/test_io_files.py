"""The three real CAM files of shared/data read whole, with the counts shared/data/SOURCES.md states.

The files live outside the repository, in ``../shared/data`` relative to the repository root; the
tests are skipped (with that reason) when the folder is absent.
"""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from planner.io import InputFileWarning, detect_format, read_toolpath

DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data"
NX = DATA / "nx_clsf_variable_contour_ust_a2.cls"
SW = DATA / "solidworks_cam_apt_boss_3plus2.apt"
HAAS = DATA / "nx2022_haas_umc750_5axis_gcode.txt"

pytestmark = pytest.mark.skipif(
    not all(p.is_file() for p in (NX, SW, HAAS)),
    reason=f"the shared CAM files are not at {DATA} (expected ../shared/data next to the repository)",
)
MMPM = 1e-3 / 60.0
IN = 0.0254


def _read(path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputFileWarning)  # the real files read without any warning
        return read_toolpath(path, **kw)


def _lines(path):
    with open(path, encoding="utf-8-sig") as fh:
        return fh.read().splitlines()


@pytest.fixture(scope="module")
def nx():
    return _read(NX)


@pytest.fixture(scope="module")
def sw():
    return _read(SW)


@pytest.fixture(scope="module")
def haas():
    return _read(HAAS, machine="haas-umc-750")


# ---------------------------------------------------------------------------- NX CLSF
def test_nx_counts(nx):
    assert detect_format(NX) == "apt"
    assert len(nx) == 20_057  # GOTO records
    assert int(nx.rapid.sum()) == 459  # RAPID records
    assert int(nx.axis_given.sum()) == 4_660 and int((~nx.axis_given).sum()) == 15_397
    assert nx.units == "mm" and nx.source == NX.name


def test_nx_points_come_from_goto_lines_and_rapids_from_the_line_before(nx):
    lines = _lines(NX)
    goto = [k + 1 for k, t in enumerate(lines) if t.startswith("GOTO/")]
    assert nx.lines.tolist() == goto
    for k in np.flatnonzero(nx.rapid):
        prev = nx.lines[k] - 2
        while lines[prev].startswith("PAINT/"):
            prev -= 1
        assert lines[prev] == "RAPID"


def test_nx_modal_axes_unit_and_tilt_range(nx):
    np.testing.assert_allclose(np.linalg.norm(nx.axes, axis=1), 1.0, atol=1e-15)
    # MCS -Z is absolute +Z here; the tilt from it ranges from 0 to 89 degrees.
    tilt = np.degrees(np.arccos(np.clip(nx.axes[:, 2], -1.0, 1.0)))
    assert tilt.min() < 1e-6 and 88.5 < tilt.max() < 90.0
    # Inherited axes equal the last given one.
    last = np.maximum.accumulate(np.where(nx.axis_given, np.arange(len(nx)), 0))
    np.testing.assert_array_equal(nx.axes, nx.axes[last])


def test_nx_single_fedrat_holds_after_every_rapid(nx):
    assert np.isnan(nx.feeds[:2]).all()  # before the only FEDRAT (line 16)
    np.testing.assert_allclose(nx.feeds[2:][~nx.rapid[2:]], 250 * MMPM, rtol=1e-15)
    assert np.isnan(nx.feeds[nx.rapid]).all()


def test_nx_spacing_and_frame(nx):
    step = np.linalg.norm(np.diff(nx.points, axis=0), axis=1) / 1e-3
    assert step.min() == pytest.approx(0.0235, abs=1e-3) and step.max() == pytest.approx(121.5, abs=0.1)
    assert [e.kind for e in nx.events] == [
        "operation", "tool_data", "frame", "tool_change", "tool_select", "operation_end"
    ]  # fmt: skip
    assert nx.events_of("tool_change")[0].value == 2.0


# ---------------------------------------------------------------------------- SOLIDWORKS CAM APT
def test_sw_counts(sw):
    assert len(sw) == 9_814
    assert len(sw.arcs) == 1_026
    assert int(sw.rapid.sum()) == 775
    assert len(sw.events_of("cutcom")) == 162
    assert int(sw.axis_given.sum()) == 5_751 and int((~sw.axis_given).sum()) == 4_063
    frames = sw.events_of("frame")
    assert sum(e.name == "CSYS" for e in frames) == 8 and sum(e.name == "TRNTYP/WORLD" for e in frames) == 8
    assert len(sw.events_of("tool_change")) == 4 and sw.events_of("end")[0].name == "FINI"


def test_sw_given_axes_equal_the_world_csys_z_column(sw):
    np.testing.assert_array_equal(sw.axes[sw.axis_given], np.broadcast_to([1.0, 0.0, 0.0], (5_751, 3)))
    csys = [e for e in sw.events_of("frame") if e.name == "CSYS"]
    for e in csys:
        m = np.array([float(v) for v in e.text.split("/")[1].split(",")]).reshape(3, 4)
        stop = next((f.index for f in csys if f.index > e.index), len(sw))
        np.testing.assert_array_equal(sw.axes[e.index : stop], np.broadcast_to(m[:, 2], (stop - e.index, 3)))


def test_sw_arcs_lie_on_circles_normal_to_the_tool(sw):
    for arc in sw.arcs:
        assert arc.start == arc.index - 1
        c, n = np.array(arc.centre), np.array(arc.axis)
        r0 = np.linalg.norm(np.cross(sw.points[arc.start] - c, n))
        r1 = np.linalg.norm(np.cross(sw.points[arc.index] - c, n))
        assert abs(r0 - r1) < 1e-9 and r0 > 0.5e-3
        assert abs(n @ sw.axes[arc.index]) == pytest.approx(1.0, abs=1e-15)


def test_sw_every_fedrat_sets_the_next_feed(sw):
    lines = _lines(SW)
    for k, t in enumerate(lines):
        if t.startswith("FEDRAT/"):
            value = float(t.split("/")[1].split(",")[0])
            i = int(np.searchsorted(sw.lines, k + 1))
            if not sw.rapid[i]:
                assert sw.feeds[i] == pytest.approx(value * MMPM, rel=1e-15)


# ---------------------------------------------------------------------------- Haas UMC-750 G-code
def _code(line: str) -> str:
    return re.sub(r"\([^)]*\)", "", line)


def test_haas_counts(haas):
    assert detect_format(HAAS) == "gcode"
    lines = _lines(HAAS)
    assert abs(len(haas) - 15_900) < 100  # "about 15,900 motion blocks"
    arcs = sum(1 for t in lines if re.search(r"\bG0?[23]\b", _code(t)))
    assert len(haas.arcs) == arcs and abs(arcs - 535) <= 5
    rot = [k + 1 for k, t in enumerate(lines) if re.search(r"[BC][-+.\d]", _code(t))]
    assert len(rot) == 13_710
    # Each given axis comes from a block with B/C; the others are rotary-only moves with no point.
    assert set(haas.lines[haas.axis_given].tolist()) <= set(rot)
    assert 13_710 - 22 <= int(haas.axis_given.sum()) <= 13_710
    b, c = np.degrees(haas.rotary).T
    assert b.min() == pytest.approx(-25.2, abs=0.05) and b.max() == pytest.approx(95.9, abs=0.05)
    assert c.min() == pytest.approx(-663, abs=0.5) and c.max() == pytest.approx(459, abs=0.5)
    assert haas.units == "inch"
    feeds = set(np.round(haas.feeds[np.isfinite(haas.feeds)] / (IN / 60), 9))
    assert feeds == {9.8, 10.0}


def test_haas_operations_tools_and_listing(haas):
    lines = _lines(HAAS)
    opers = [re.search(r"OPER:\s*(.*?)\s*\)", t).group(1) for t in lines if "( OPER:" in t]
    assert [e.name for e in haas.events_of("operation")] == opers and len(opers) == 26
    assert [e.value for e in haas.events_of("tool_change")] == [1.0, 2.0, 3.0]
    listing = haas.events_of("listing")
    assert listing[0].name == "header" and listing[-1].text == "Tool Path Listing has 16115 lines."
    np.testing.assert_allclose(np.linalg.norm(haas.axes, axis=1), 1.0, atol=1e-15)


@pytest.mark.parametrize(
    "oper, coord, lo, hi, direction",
    [
        ("POCKETING_SIDE_OVAL", 0, -0.05, 0.40, (-1, 0, 0)),  # 3+2 under G254 (DWO)
        ("POCKETING_SIDE_OPPOSITE", 0, 3.60, 4.05, (1, 0, 0)),
        ("POCKETING_CIRCLE", 1, -0.05, 0.45, (0, -1, 0)),
        ("POCKETING_CIRCLE_OPPOSITE", 1, 3.55, 4.05, (0, 1, 0)),
        ("VARIABLE_AXIS_GUIDING_CURVES_OVAL", 0, -2.05, 0.30, (-1, 0, 0)),  # 5-axis under G234 (TCPC)
        ("VARIABLE_AXIS_GUIDING_CURVES_CIRCLE_OPPOSITE", 1, 3.70, 6.05, (0, 1, 0)),
    ],
)
def test_haas_side_operations_land_on_the_faces_of_the_4in_block(haas, oper, coord, lo, hi, direction):
    """The kinematics check on real data: side features sit on the block's faces, tools point out."""
    ops = haas.events_of("operation")
    k = next(i for i, e in enumerate(ops) if e.name == oper)
    stop = ops[k + 1].index if k + 1 < len(ops) else len(haas)
    sl = slice(ops[k].index, stop)
    x = haas.points[sl, coord] / IN
    assert lo <= x.min() and x.max() <= hi
    mean_axis = haas.axes[sl].mean(axis=0)
    assert mean_axis @ np.array(direction) > math.cos(math.radians(12))
