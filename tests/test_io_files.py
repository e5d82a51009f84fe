"""The three real CAM files read whole, with the counts shared/data/SOURCES.md states, and their excerpts.

Every test runs on the verbatim excerpt in ``tests/data`` (default suite; figures from tests/data/SOURCES.md)
and on the whole file in ``../shared/data`` (marked ``slow``; skipped with that reason when the folder is
absent, as on a clean clone). The last tests check that the excerpts are what SOURCES.md says: byte-exact line
ranges of the whole files that a reader reads exactly as it reads those lines of the whole files.
"""

from __future__ import annotations

import hashlib
import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from planner.io import InputFileWarning, detect_format, read_toolpath
from tests.cam_excerpts import EXCERPTS, HAAS, NX, SW, Excerpt
from tests.conftest import EXCERPT_DATA, SHARED_DATA

MMPM = 1e-3 / 60.0
IN = 0.0254
WHOLE = [
    pytest.mark.slow,
    pytest.mark.skipif(
        not SHARED_DATA.is_dir(),
        reason=f"the whole CAM files are not at {SHARED_DATA} (expected ../shared/data next to the repository)",
    ),
]
VARIANTS = ["excerpt", pytest.param("whole", marks=WHOLE)]


@dataclass(frozen=True)
class Case:
    """One file to read: an excerpt (with its line ranges) or a whole file, and the figures it must give."""

    path: Path
    fig: dict
    excerpt: Excerpt | None = None

    def range_of_line(self, lines: np.ndarray) -> np.ndarray:
        """Index of the excerpt range holding each (excerpt) line number; all 0 for a whole file."""
        if self.excerpt is None:
            return np.zeros(len(lines), int)
        ends = np.cumsum([b - a + 1 for a, b in self.excerpt.ranges])
        return np.searchsorted(ends, lines)


# Whole files: the counts of shared/data/SOURCES.md (steps and tilts measured on the file, in mm and deg).
# Excerpts: the counts of tests/data/SOURCES.md (grep on the excerpt); steps only within the copied ranges.
FIGURES = {
    "nx": {
        "whole": dict(gotos=20_057, rapids=459, given=4_660, step=(0.0235, 121.5)),
        "excerpt": dict(gotos=746, rapids=26, given=150, step=(0.0235, 98.48)),
    },
    "sw": {
        "whole": dict(gotos=9_814, arcs=1_026, rapids=775, cutcom=162, given=5_751, csys=8, tools=4),
        "excerpt": dict(gotos=205, arcs=28, rapids=19, cutcom=6, given=106, csys=5, tools=3),
    },
    "haas": {
        # "about 15,900 motion blocks", "about 535 arcs"; 13,710 blocks with B/C, up to 22 of them rotary-only
        "whole": dict(points=(15_900, 100), arcs=(535, 5), rot=13_710, given=(13_710 - 22, 13_710),
                      b=(-25.2, 95.9), c=(-663.0, 459.0), opers=26, tools=[1.0, 2.0, 3.0]),
        # 565 blocks with X/Y/Z words, less 11 G53/G28 moves and 5 XY moves while Z is unknown after a G53;
        # 259 blocks with B/C, 9 of them rotary-only
        "excerpt": dict(points=(549, 0), arcs=(31, 0), rot=259, given=(250, 250),
                        b=(0.0, 95.865), c=(-550.231, 90.0), opers=11, tools=[1.0]),
    },
}


def _case(key: str, variant: str, excerpt: Excerpt) -> Case:
    if variant == "whole":
        return Case(SHARED_DATA / excerpt.source, FIGURES[key]["whole"])
    return Case(excerpt.path, FIGURES[key]["excerpt"], excerpt)


def _read(path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputFileWarning)  # the real files read without any warning
        return read_toolpath(path, **kw)


def _lines(path):
    with open(path, encoding="utf-8-sig") as fh:
        return fh.read().splitlines()


@pytest.fixture(scope="module", params=VARIANTS)
def nx(request):
    case = _case("nx", request.param, NX)
    return case, _read(case.path)


@pytest.fixture(scope="module", params=VARIANTS)
def sw(request):
    case = _case("sw", request.param, SW)
    return case, _read(case.path)


@pytest.fixture(scope="module", params=VARIANTS)
def haas(request):
    case = _case("haas", request.param, HAAS)
    return case, _read(case.path, machine="haas-umc-750")


# ---------------------------------------------------------------------------- NX CLSF
def test_nx_counts(nx):
    case, tp = nx
    f = case.fig
    assert detect_format(case.path) == "apt"
    assert len(tp) == f["gotos"]  # GOTO records
    assert int(tp.rapid.sum()) == f["rapids"]  # RAPID records
    assert int(tp.axis_given.sum()) == f["given"] and int((~tp.axis_given).sum()) == f["gotos"] - f["given"]
    assert tp.units == "mm" and tp.source == case.path.name


def test_nx_points_come_from_goto_lines_and_rapids_from_the_line_before(nx):
    case, tp = nx
    lines = _lines(case.path)
    goto = [k + 1 for k, t in enumerate(lines) if t.startswith("GOTO/")]
    assert tp.lines.tolist() == goto
    for k in np.flatnonzero(tp.rapid):
        prev = tp.lines[k] - 2
        while lines[prev].startswith("PAINT/"):
            prev -= 1
        assert lines[prev] == "RAPID"


def test_nx_modal_axes_unit_and_tilt_range(nx):
    _, tp = nx
    np.testing.assert_allclose(np.linalg.norm(tp.axes, axis=1), 1.0, atol=1e-15)
    # MCS -Z is absolute +Z here; the tilt from it ranges from 0 to 89 degrees (89.04 at line 7269 of the file,
    # which the excerpt keeps).
    tilt = np.degrees(np.arccos(np.clip(tp.axes[:, 2], -1.0, 1.0)))
    assert tilt.min() < 1e-6 and 88.5 < tilt.max() < 90.0
    # Inherited axes equal the last given one.
    last = np.maximum.accumulate(np.where(tp.axis_given, np.arange(len(tp)), 0))
    np.testing.assert_array_equal(tp.axes, tp.axes[last])


def test_nx_single_fedrat_holds_after_every_rapid(nx):
    _, tp = nx
    assert np.isnan(tp.feeds[:2]).all()  # before the only FEDRAT (line 16)
    np.testing.assert_allclose(tp.feeds[2:][~tp.rapid[2:]], 250 * MMPM, rtol=1e-15)
    assert np.isnan(tp.feeds[tp.rapid]).all()


def test_nx_spacing_and_frame(nx):
    case, tp = nx
    step = np.linalg.norm(np.diff(tp.points, axis=0), axis=1) / 1e-3
    rng = case.range_of_line(tp.lines)
    within = rng[1:] == rng[:-1]  # an excerpt's joins are rapids the whole file does not have
    assert tp.rapid[1:][~within].all()
    lo, hi = case.fig["step"]
    assert step[within].min() == pytest.approx(lo, abs=1e-3) and step[within].max() == pytest.approx(hi, abs=0.1)
    assert [e.kind for e in tp.events] == [
        "operation", "tool_data", "frame", "tool_change", "tool_select", "operation_end"
    ]  # fmt: skip
    assert tp.events_of("tool_change")[0].value == 2.0


# ---------------------------------------------------------------------------- SOLIDWORKS CAM APT
def test_sw_counts(sw):
    case, tp = sw
    f = case.fig
    assert len(tp) == f["gotos"]
    assert len(tp.arcs) == f["arcs"]
    assert int(tp.rapid.sum()) == f["rapids"]
    assert len(tp.events_of("cutcom")) == f["cutcom"]
    assert int(tp.axis_given.sum()) == f["given"] and int((~tp.axis_given).sum()) == f["gotos"] - f["given"]
    frames = tp.events_of("frame")
    assert sum(e.name == "CSYS" for e in frames) == f["csys"]
    assert sum(e.name == "TRNTYP/WORLD" for e in frames) == f["csys"]
    assert len(tp.events_of("tool_change")) == f["tools"] and tp.events_of("end")[0].name == "FINI"


def test_sw_given_axes_equal_the_world_csys_z_column(sw):
    case, tp = sw
    given = case.fig["given"]
    np.testing.assert_array_equal(tp.axes[tp.axis_given], np.broadcast_to([1.0, 0.0, 0.0], (given, 3)))
    csys = [e for e in tp.events_of("frame") if e.name == "CSYS"]
    for e in csys:
        m = np.array([float(v) for v in e.text.split("/")[1].split(",")]).reshape(3, 4)
        stop = next((f.index for f in csys if f.index > e.index), len(tp))
        np.testing.assert_array_equal(tp.axes[e.index : stop], np.broadcast_to(m[:, 2], (stop - e.index, 3)))


def test_sw_arcs_lie_on_circles_normal_to_the_tool(sw):
    _, tp = sw
    for arc in tp.arcs:
        assert arc.start == arc.index - 1
        c, n = np.array(arc.centre), np.array(arc.axis)
        r0 = np.linalg.norm(np.cross(tp.points[arc.start] - c, n))
        r1 = np.linalg.norm(np.cross(tp.points[arc.index] - c, n))
        assert abs(r0 - r1) < 1e-9 and r0 > 0.5e-3
        assert abs(n @ tp.axes[arc.index]) == pytest.approx(1.0, abs=1e-15)


def test_sw_every_fedrat_sets_the_next_feed(sw):
    case, tp = sw
    lines = _lines(case.path)
    for k, t in enumerate(lines):
        if t.startswith("FEDRAT/"):
            value = float(t.split("/")[1].split(",")[0])
            i = int(np.searchsorted(tp.lines, k + 1))
            if not tp.rapid[i]:
                assert tp.feeds[i] == pytest.approx(value * MMPM, rel=1e-15)


# ---------------------------------------------------------------------------- Haas UMC-750 G-code
def _code(line: str) -> str:
    return re.sub(r"\([^)]*\)", "", line)


def test_haas_counts(haas):
    case, tp = haas
    f = case.fig
    assert detect_format(case.path) == "gcode"
    lines = _lines(case.path)
    n, tol = f["points"]
    assert abs(len(tp) - n) <= tol
    arcs = sum(1 for t in lines if re.search(r"\bG0?[23]\b", _code(t)))
    n, tol = f["arcs"]
    assert len(tp.arcs) == arcs and abs(arcs - n) <= tol
    rot = [k + 1 for k, t in enumerate(lines) if re.search(r"[BC][-+.\d]", _code(t))]
    assert len(rot) == f["rot"]
    # Each given axis comes from a block with B/C; the others are rotary-only moves with no point.
    assert set(tp.lines[tp.axis_given].tolist()) <= set(rot)
    lo, hi = f["given"]
    assert lo <= int(tp.axis_given.sum()) <= hi
    b, c = np.degrees(tp.rotary).T
    assert b.min() == pytest.approx(f["b"][0], abs=0.05) and b.max() == pytest.approx(f["b"][1], abs=0.05)
    assert c.min() == pytest.approx(f["c"][0], abs=0.5) and c.max() == pytest.approx(f["c"][1], abs=0.5)
    assert tp.units == "inch"
    feeds = set(np.round(tp.feeds[np.isfinite(tp.feeds)] / (IN / 60), 9))
    assert feeds == {9.8, 10.0}


def test_haas_operations_tools_and_listing(haas):
    case, tp = haas
    lines = _lines(case.path)
    opers = [re.search(r"OPER:\s*(.*?)\s*\)", t).group(1) for t in lines if "( OPER:" in t]
    assert [e.name for e in tp.events_of("operation")] == opers and len(opers) == case.fig["opers"]
    assert [e.value for e in tp.events_of("tool_change")] == case.fig["tools"]
    listing = tp.events_of("listing")
    assert listing[0].name == "header" and listing[-1].text == "Tool Path Listing has 16115 lines."
    np.testing.assert_allclose(np.linalg.norm(tp.axes, axis=1), 1.0, atol=1e-15)


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
    _, tp = haas
    ops = tp.events_of("operation")
    k = next(i for i, e in enumerate(ops) if e.name == oper)
    stop = ops[k + 1].index if k + 1 < len(ops) else len(tp)
    sl = slice(ops[k].index, stop)
    x = tp.points[sl, coord] / IN
    assert lo <= x.min() and x.max() <= hi
    mean_axis = tp.axes[sl].mean(axis=0)
    assert mean_axis @ np.array(direction) > math.cos(math.radians(12))


# ---------------------------------------------------------------------------- the excerpts themselves
def _sources_table() -> dict[str, tuple[int, int, str]]:
    """tests/data/SOURCES.md's table: excerpt name -> (bytes, lines, sha256)."""
    text = (EXCERPT_DATA / "SOURCES.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| (\S+) \| ([\d,]+) \| (\d+) \| ([0-9a-f]{64}) \|$", text, flags=re.M)
    return {name: (int(size.replace(",", "")), int(n), digest) for name, size, n, digest in rows}


@pytest.mark.parametrize("name", list(EXCERPTS))
def test_excerpt_is_the_file_sources_md_describes(name):
    """Size, line count and sha256 as SOURCES.md lists them (an editor that strips the BOM or a trailing space,
    or changes line ends, fails here), and SOURCES.md lists the ranges that tests.cam_excerpts maps."""
    ex = EXCERPTS[name]
    data = ex.path.read_bytes()
    size, n, digest = _sources_table()[name]
    assert (len(data), data.count(b"\n"), hashlib.sha256(data).hexdigest()) == (size, n, digest)
    assert len(ex.original_lines) == n
    section = (EXCERPT_DATA / "SOURCES.md").read_text(encoding="utf-8").split(f"## {name}: from {ex.source}")[1]
    listed = re.findall(r"^\| (\d+)-(\d+) \|", section.split("\n## ")[0], flags=re.M)
    assert [(int(a), int(b)) for a, b in listed] == list(ex.ranges)


@pytest.mark.parametrize("name", list(EXCERPTS))
@pytest.mark.slow
@pytest.mark.skipif(not SHARED_DATA.is_dir(), reason=f"the whole CAM files are not at {SHARED_DATA}")
def test_excerpt_copies_the_whole_file_and_reads_like_it(name):
    """Byte-exact ranges of the whole file; and every kept motion record gets the same point, axis, feed, rapid
    flag and rotary angles as in the whole file (the joins carry the modal state over unchanged), and the same
    events."""
    ex = EXCERPTS[name]
    whole_bytes = (SHARED_DATA / ex.source).read_bytes()
    pieces = whole_bytes.split(b"\n")
    lines = [p + b"\n" for p in pieces[:-1]] + ([pieces[-1]] if pieces[-1] else [])
    assert ex.path.read_bytes() == b"".join(b"".join(lines[a - 1 : b]) for a, b in ex.ranges)

    kw = {"machine": "haas-umc-750"} if ex is HAAS else {}
    whole, part = _read(SHARED_DATA / ex.source, **kw), _read(ex.path, **kw)
    orig = ex.original_line(part.lines)
    idx = np.searchsorted(whole.lines, orig)
    np.testing.assert_array_equal(whole.lines[idx], orig)
    for field in ("points", "axes", "axis_given", "feeds", "rapid", "rotary"):
        a, b = getattr(part, field), getattr(whole, field)
        assert (a is None) == (b is None), field
        if a is not None:
            np.testing.assert_array_equal(a, b[idx], err_msg=field)

    def key(e, line):
        return (line, e.kind, getattr(e, "name", ""), getattr(e, "text", ""), getattr(e, "centre", None))

    kept = {key(e, e.line) for e in whole.events}
    assert all(key(e, int(ex.original_line(e.line))) in kept for e in part.events)
    assert len(part.events) == sum(1 for e in whole.events if e.line in set(ex.original_lines.tolist()))
