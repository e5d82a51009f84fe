"""APT / CL data reader: every quirk of the real CAM files on short excerpts, and broken records."""

from __future__ import annotations

import io
import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from planner.errors import PlannerError
from planner.io import InputFileError, InputFileWarning, read_apt

MM = 1e-3
MMPM = 1e-3 / 60.0


def read(text: str, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputFileWarning)  # a test that expects a warning says so
        return read_apt(io.StringIO(text), source="t.apt", **kw)


# Lines 1-21 of the NX CLSF file (shared/data/nx_clsf_variable_contour_ust_a2.cls), verbatim.
NX_HEAD = """\
TOOL PATH/VARIABLE_CONTOUR,TOOL,BPR-SNR-323S32
TLDATA/MILL,32.0000,5.0000,75.0000,0.0000,0.0000
MSYS/-120.2591,-1196.5000,142.5000,0.0000000,1.0000000,0.0000000,1.0000000,0.0000000,0.0000000
$$ centerline data
PAINT/PATH
PAINT/SPEED,10
LOAD/TOOL,2,ADJUST,2 
SELECT/TOOL,2
PAINT/COLOR,186
RAPID
GOTO/0.0000,222.6719,-177.5000,0.0000000,0.0000000,-1.0000000
PAINT/COLOR,211
RAPID
GOTO/0.0000,222.6719,-113.5000
PAINT/COLOR,42
FEDRAT/MMPM,250.0000
GOTO/0.0000,222.5552,-111.5714
GOTO/0.0000,222.2069,-109.6709
GOTO/207.7600,10.9219,-82.3063,0.0679850,-0.9833858,-0.1683164
GOTO/207.7600,10.6875,-80.9370
END-OF-PATH
"""  # noqa: W291 (line 7 has a trailing space in the real file)

NX_ORIGIN = np.array([-120.2591, -1196.5, 142.5])
NX_R = np.column_stack([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # X, Y, X x Y of the MSYS


def test_nx_excerpt_points_in_absolute_frame_after_msys():
    tp = read(NX_HEAD)
    mcs = np.array(
        [
            [0.0, 222.6719, -177.5],
            [0.0, 222.6719, -113.5],
            [0.0, 222.5552, -111.5714],
            [0.0, 222.2069, -109.6709],
            [207.76, 10.9219, -82.3063],
            [207.76, 10.6875, -80.937],
        ]
    )
    np.testing.assert_allclose(tp.points, (NX_ORIGIN + mcs @ NX_R.T) * MM, rtol=0, atol=1e-15)
    # Hand check of the first point: MCS (0, 222.6719, -177.5) is absolute (102.4128, -1196.5, 320).
    np.testing.assert_allclose(tp.points[0], [0.1024128, -1.1965, 0.32], rtol=0, atol=1e-15)
    assert tp.lines.tolist() == [11, 14, 17, 18, 19, 20]
    assert tp.units == "mm" and tp.source == "t.apt"


def test_nx_excerpt_modal_axis_carried_and_flagged():
    tp = read(NX_HEAD)
    up = [0.0, 0.0, 1.0]  # MCS (0,0,-1) is absolute +Z: the MCS Z axis is absolute -Z
    v = np.array([0.0679850, -0.9833858, -0.1683164])
    v_abs = NX_R @ (v / np.linalg.norm(v))
    np.testing.assert_allclose(tp.axes[:4], [up] * 4, atol=1e-15)
    np.testing.assert_allclose(tp.axes[4:], [v_abs, v_abs], atol=1e-15)
    assert tp.axis_given.tolist() == [True, False, False, False, True, False]
    np.testing.assert_allclose(np.linalg.norm(tp.axes, axis=1), 1.0, atol=1e-15)


def test_nx_excerpt_rapid_applies_to_next_goto_only_and_feed_resumes():
    tp = read(NX_HEAD)
    assert tp.rapid.tolist() == [True, True, False, False, False, False]
    assert np.isnan(tp.feeds[:2]).all()
    np.testing.assert_allclose(tp.feeds[2:], 250.0 * MMPM, rtol=1e-15)


def test_nx_excerpt_events_with_lines_and_indices():
    tp = read(NX_HEAD)
    got = [(e.kind, e.line, e.index, e.name) for e in tp.events]
    assert got == [
        ("operation", 1, 0, "VARIABLE_CONTOUR"),
        ("tool_data", 2, 0, "MILL"),
        ("frame", 3, 0, "MSYS"),
        ("tool_change", 7, 0, "TOOL,2,ADJUST,2"),
        ("tool_select", 8, 0, "TOOL,2"),
        ("operation_end", 21, 6, "END-OF-PATH"),
    ]
    assert tp.events[3].value == 2.0 and tp.events[4].value == 2.0


def test_rapid_with_slash_and_bare_rapid_are_one_shot():
    text = "FEDRAT/100\nGOTO/0,0,0\nRAPID\nGOTO/1,0,0\nGOTO/2,0,0\nRAPID/\nGOTO/3,0,0\nGOTO/4,0,0\n"
    tp = read(text)
    assert tp.rapid.tolist() == [False, True, False, True, False]
    f = 100 * MMPM
    np.testing.assert_array_equal(np.isnan(tp.feeds), [False, True, False, True, False])
    np.testing.assert_allclose(tp.feeds[[0, 2, 4]], f, rtol=1e-15)


@pytest.mark.parametrize(
    "record, mps",
    [
        ("FEDRAT/MMPM,250.0000", 250 * MMPM),  # NX: unit first
        ("FEDRAT/411.48,MMPM", 411.48 * MMPM),  # SOLIDWORKS: value first
        ("FEDRAT / 400.000000,  MMPM", 400 * MMPM),  # Pro/CLfile: spaces
        ("FEDRAT/IPM,10", 10 * 0.0254 / 60),
        ("FEDRAT/10.,IPM", 10 * 0.0254 / 60),
        ("FEDRAT/300", 300 * MMPM),  # no unit word: file units per minute
        ("FEDRAT/2,MMPS", 2e-3),
    ],
)
def test_fedrat_forms(record, mps):
    tp = read(f"GOTO/0,0,0\n{record}\nGOTO/1,0,0\n")
    assert math.isnan(tp.feeds[0])
    assert tp.feeds[1] == pytest.approx(mps, rel=1e-14)


def test_fedrat_per_revolution_uses_spindle_speed_and_inch_default():
    tp = read("SPINDL/1200,RPM,CLW\nFEDRAT/0.1,MMPR\nGOTO/0,0,0\nUNITS/INCH\nFEDRAT/20\nGOTO/1,0,0\n")
    assert tp.feeds[0] == pytest.approx(0.1e-3 * 1200 / 60, rel=1e-14)
    assert tp.feeds[1] == pytest.approx(20 * 0.0254 / 60, rel=1e-14)
    spindle = tp.events_of("spindle")[0]
    assert spindle.value == pytest.approx(1200 * 2 * math.pi / 60, rel=1e-14)


def test_units_inch_and_unit_mm_and_compact_numbers():
    tp = read("UNITS/INCH\nGOTO/1.,-.5,2.25\nUNIT/MM\nGOTO/94.0375,.9625,-3.\nGOTO/6.,0,-1.5E-1\n")
    np.testing.assert_allclose(tp.points[0], np.array([1.0, -0.5, 2.25]) * 0.0254, rtol=0, atol=1e-17)
    np.testing.assert_allclose(tp.points[1], np.array([94.0375, 0.9625, -3.0]) * MM, rtol=0, atol=1e-17)
    np.testing.assert_allclose(tp.points[2], np.array([6.0, 0.0, -0.15]) * MM, rtol=0, atol=1e-17)
    assert tp.units == "inch,mm"
    assert read("GOTO/1,2,3\n", units="inch").points[0, 0] == pytest.approx(0.0254, rel=1e-15)


# A Pro/CLfile excerpt (MichaHofft/CreoPost profilfraesen_2.ncl.2 style): spaces around "/", "$"
# continuation lines, a commented-out CSYS whose continuation lines are part of the comment.
CREO = """\
$$*          Pro/CLfile  Version 8.0 - 8.0.3.0
PARTNO / MFG0004
UNITS / MM
LOADTL / 1
$$-> CSYS / 1.0000000000, 0.0000000000, 0.0000000000, 0.0000000000,  $
            0.0000000000, 1.0000000000, 0.0000000000, 0.0000000000,  $
            0.0000000000, 0.0000000000, 1.0000000000, 0.0000000000
SPINDL / RPM, 15915.507752,  CLW
RAPID 
GOTO / 0.0000000000, 1.5000000000, 2.0000000000
FEDRAT / 400.000000,  MMPM
GOTO / 0.0000000000, 1.5000000000, -1.5000000000
CIRCLE / 0.0000000000, 0.0000000000, -1.5000000000,  $
0.0000000000, 0.0000000000, -1.0000000000,  1.5000000000
GOTO / 1.5000000000, 0.0000000000, -1.5000000000
SPINDL / OFF
FINI 
"""  # noqa: W291


def test_creo_spaces_continuation_and_commented_records():
    tp = read(CREO)
    np.testing.assert_allclose(tp.points / MM, [[0, 1.5, 2], [0, 1.5, -1.5], [1.5, 0, -1.5]], atol=1e-12)
    assert tp.rapid.tolist() == [True, False, False]
    assert tp.lines.tolist() == [10, 12, 15]
    (arc,) = tp.arcs
    assert (arc.line, arc.start, arc.index) == (13, 1, 2)
    assert arc.centre == pytest.approx((0.0, 0.0, -1.5e-3), abs=1e-15)
    assert arc.axis == (0.0, 0.0, -1.0) and arc.radius == pytest.approx(1.5e-3, rel=1e-15)
    assert [e.kind for e in tp.events_of("spindle")] == ["spindle", "spindle"]
    assert tp.events_of("spindle")[1].value == 0.0
    assert tp.events_of("tool_change")[0].value == 1.0
    assert tp.events_of("partno")[0].name == "MFG0004"
    assert tp.axes is None  # the file says nothing about the tool axis (its CSYS is commented out)


def test_inline_comment_after_record():
    tp = read("GOTO/1,2,3 $$ first point\nGOTO/4,5,6$$x\n")
    np.testing.assert_allclose(tp.points / MM, [[1, 2, 3], [4, 5, 6]], atol=1e-12)


# SOLIDWORKS CAM excerpt (shared/data/solidworks_cam_apt_boss_3plus2.apt lines 1-20 and 5550-5555).
SW = """\
PARTNO/1
UNIT/MM
INSERT/[HOLDER=C40-M06EM2] 6MM CRB 2FL 19 LOC
CUTTER/6.,0,3.,0,0,0,51.
LOAD/TOOL,1
CSI_SET_FLUTE_LENGTH/19.
CSI_SET_EXTENSION_LENGTH/25.
SELECT/TOOL,5
COOLNT/FLOOD
SPINDL/12000,RPM,CLW
INSERT/Stock Size X95. Y150. Z120.
TRNTYP/WORLD,0,0,0
CSYS/1.,0,0,0,0,1.,0,0,0,0,1.,0
RAPID/
GOTO/89.2375,5.7625,25.
RAPID/
GOTO/89.2375,5.7625,2.5
FEDRAT/411.48,MMPM
GOTO/89.2375,5.7625,-3.
CUTCOM/LEFT
GOTO/96.4375,41.334899,-3.
CIRCLE/95.,44.249705,-3.,0,0,-1.
GOTO/95.,40.999705,-3.
CUTCOM/OFF
TRNTYP/WORLD,0,0,0
CSYS/0,0,1.,0,1.,0,0,0,0,1.,0,0
RAPID/
GOTO/120.,24.9625,-30.35,1.,0,0
RAPID/
GOTO/97.5,24.9625,-30.35
FINI
"""


def test_solidworks_excerpt_world_csys_not_applied_and_sets_modal_axis():
    tp = read(SW)
    np.testing.assert_allclose(tp.points[-2:] / MM, [[120, 24.9625, -30.35], [97.5, 24.9625, -30.35]], atol=1e-12)
    # Before the tilted CSYS the axis is its local z = +Z (not given); after, (1,0,0) = CSYS column z.
    np.testing.assert_allclose(tp.axes[:5], [[0, 0, 1]] * 5, atol=0)
    np.testing.assert_allclose(tp.axes[5:], [[1, 0, 0]] * 2, atol=0)
    assert tp.axis_given.tolist() == [False] * 5 + [True, False]
    assert tp.rapid.tolist() == [True, True, False, False, False, True, True]
    kinds = [e.kind for e in tp.events]
    assert kinds.count("frame") == 4 and kinds.count("machine") == 2 and kinds.count("cutcom") == 2
    assert [e.name for e in tp.events_of("cutcom")] == ["LEFT", "OFF"]
    assert tp.events_of("coolant")[0].name == "FLOOD"
    assert tp.events_of("end")[0].line == 31
    assert tp.events_of("insert")[1].name == "Stock Size X95. Y150. Z120."


def test_solidworks_circle_is_kept_with_its_end_point():
    tp = read(SW)
    (arc,) = tp.arcs
    assert (arc.line, arc.start, arc.index) == (22, 3, 4)
    assert arc.centre == pytest.approx((95e-3, 44.249705e-3, -3e-3), abs=1e-15)
    assert arc.axis == (0.0, 0.0, -1.0) and math.isnan(arc.radius)
    r0 = np.linalg.norm(tp.points[arc.start] - arc.centre)
    r1 = np.linalg.norm(tp.points[arc.index] - arc.centre)
    assert r0 == pytest.approx(3.25e-3, rel=1e-6) and r1 == pytest.approx(3.25e-3, rel=1e-6)
    # The CUTCOM/LEFT before the arc's start point applies from that point on.
    assert tp.events_of("cutcom")[0].index == 3


def test_circle_linearised_on_request_stays_on_the_circle_and_goes_clockwise():
    tol = 1e-6
    tp = read(SW, arc_tolerance=tol)
    (arc,) = tp.arcs
    seg = tp.points[arc.start : arc.index + 1]
    c = np.array(arc.centre)
    assert seg.shape[0] > 2
    np.testing.assert_allclose(np.linalg.norm(seg - c, axis=1), 3.25e-3, rtol=1e-6)
    ang = np.unwrap(np.arctan2(seg[:, 1] - c[1], seg[:, 0] - c[0]))
    assert np.all(np.diff(ang) < 0)  # axis -Z: clockwise seen from +Z, the short way (26 deg)
    assert ang[0] - ang[-1] == pytest.approx(math.radians(26.25), abs=0.01)
    mid = (seg[:-1] + seg[1:]) / 2  # chord midpoints: sagitta within the tolerance
    assert np.all(3.25e-3 - np.linalg.norm(mid - c, axis=1) <= tol * (1 + 1e-9))
    assert np.all(~tp.axis_given[arc.start + 1 : arc.index])


def test_csys_without_trntyp_world_is_applied_to_points_and_axes():
    rot = Rotation.from_euler("zyx", [30, -20, 50], degrees=True).as_matrix()
    t = np.array([10.0, -5.0, 2.5])
    m = np.column_stack([rot, t]).ravel()
    text = "CSYS/" + ",".join(f"{v:.15g}" for v in m) + "\nGOTO/1,2,3\nGOTO/4,5,6,0,0.6,0.8\n"
    tp = read(text)
    np.testing.assert_allclose(tp.points / MM, [rot @ [1, 2, 3] + t, rot @ [4, 5, 6] + t], atol=1e-12)
    np.testing.assert_allclose(tp.axes, [rot[:, 2], rot @ [0, 0.6, 0.8]], atol=1e-14)
    raw = read(text, frames="none")
    np.testing.assert_allclose(raw.points / MM, [[1, 2, 3], [4, 5, 6]], atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(
    q=st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda v: np.linalg.norm(v) > 0.1),
    origin=st.lists(st.floats(-500, 500), min_size=3, max_size=3),
    pts=st.lists(st.lists(st.floats(-300, 300), min_size=3, max_size=3), min_size=1, max_size=6),
)
def test_msys_maps_mcs_to_absolute_frame(q, origin, pts):
    rot = Rotation.from_quat(q).as_matrix()
    x, y = rot[:, 0], rot[:, 1]
    msys = ",".join(f"{v:.17g}" for v in [*origin, *x, *y])
    text = f"MSYS/{msys}\n" + "".join("GOTO/" + ",".join(f"{v:.17g}" for v in p) + ",0,0,1\n" for p in pts)
    tp = read(text)
    want = (np.array(origin) + np.array(pts) @ rot.T) * MM
    np.testing.assert_allclose(tp.points, want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tp.axes, np.broadcast_to(rot[:, 2], (len(pts), 3)), atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    ops=st.lists(
        st.one_of(
            st.just(("RAPID",)),
            st.just(("RAPID/",)),
            st.tuples(st.just("GOTO3"), st.integers(-50, 50)),
            st.tuples(st.just("GOTO6"), st.integers(-50, 50), st.sampled_from([(1, 0, 0), (0, 0.6, 0.8)])),
        ),
        min_size=1,
        max_size=25,
    )
)
def test_modal_axis_and_one_shot_rapid_match_a_simple_model(ops):
    lines, axes, given_flags, rapid = [], [], [], []
    axis, pending = (0.0, 0.0, 1.0), False
    for op in ops:
        if op[0].startswith("RAPID"):
            lines.append(op[0])
            pending = True
            continue
        if op[0] == "GOTO6":
            axis = op[2]
            lines.append(f"GOTO/{op[1]},1,2,{axis[0]},{axis[1]},{axis[2]}")
        else:
            lines.append(f"GOTO/{op[1]},1,2")
        axes.append(axis)
        given_flags.append(op[0] == "GOTO6")
        rapid.append(pending)
        pending = False
    if not axes:
        return
    lines.insert(0, "GOTO/0,0,0,0,0,1")  # make sure the file gives an axis
    tp = read("\n".join(lines) + "\n")
    np.testing.assert_allclose(tp.axes[1:], axes, atol=1e-15)
    assert tp.axis_given[1:].tolist() == given_flags
    assert tp.rapid[1:].tolist() == rapid


def test_bom_and_listing_header_are_skipped_with_true_line_numbers():
    text = "\ufeffInformation listing created by me\nDate\t15-Apr-2023\n\nGOTO/1,2,3\n"
    tp = read(text)
    assert tp.lines.tolist() == [4]
    assert tp.events[0].kind == "listing"


def test_paint_is_ignored_and_unknown_records_warn_with_their_line():
    with pytest.warns(InputFileWarning, match=r"t\.apt line 2: unknown record 'FOO/1,2' skipped"):
        tp = read_apt(io.StringIO("PAINT/COLOR,211\nFOO/1,2\nGOTO/1,2,3\n"), source="t.apt")
    assert len(tp) == 1 and tp.events == ()


def test_many_unknown_records_are_summarised_not_dropped():
    text = "".join(f"BAR/{k}\n" for k in range(12)) + "GOTO/1,2,3\n"
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        read_apt(io.StringIO(text), source="t.apt")
    msgs = [str(w.message) for w in rec if issubclass(w.category, InputFileWarning)]
    assert [m.split(":")[0] for m in msgs[:5]] == [f"t.apt line {k}" for k in range(1, 6)]
    assert msgs[5] == "t.apt: 7 more 'BAR' records (last at line 12) not listed"


def test_records_after_fini_warn():
    with pytest.warns(InputFileWarning, match=r"line 3: 1 non-blank line\(s\) after FINI ignored"):
        tp = read_apt(io.StringIO("GOTO/1,2,3\nFINI\nGOTO/4,5,6\n"), source="t.apt")
    assert len(tp) == 1


def test_from_and_godlta():
    tp = read("FROM/0,0,10\nGOTO/1,0,10,0,0,1\nGODLTA/0,0,-5\nGODLTA/2\n")
    np.testing.assert_allclose(tp.points / MM, [[0, 0, 10], [1, 0, 10], [1, 0, 5], [1, 0, 7]], atol=1e-12)
    assert tp.rapid.tolist() == [True, False, False, False]


# ---------------------------------------------------------------------------- broken files
@pytest.mark.parametrize(
    "text, line, field, problem",
    [
        ("GOTO/1,2,3\nGOTO/1.0,x1.5,3\n", 2, "field 2 of GOTO", "'x1.5' is not a number"),
        ("GOTO/1.0,,3.0\n", 1, "field 2 of GOTO", "value is missing"),
        ("GOTO/1,2\n", 1, "GOTO record", "has 2 values, expected 3 (x,y,z) or 6"),
        ("GOTO/1,2,3,4\n", 1, "GOTO record", "has 4 values"),
        ("GOTO/1,2,3,0,0,1,7\n", 1, "GOTO record", "has 7 values"),
        ("GOTO/0,0,0\nGOTO/1,2,3,0,0,2\n", 2, "fields 4-6 of GOTO", "is not a unit vector (length 2"),
        ("GOTO/1,2,3,0,0,0\n", 1, "fields 4-6 of GOTO", "is not a unit vector (length 0"),
        ("GOTO/0,0,0\n\nGOTO/1,nan,3\n", 3, "field 2 of GOTO", "nan is not a finite number"),
        ("GOTO/1,2,inf\n", 1, "field 3 of GOTO", "inf is not a finite number"),
        ("GOTO/1,2,3,0,nan,1\n", 1, "fields 4-6 of GOTO", "is not a unit vector"),
        ("GOTO / 1, 2, 3x\n", 1, "field 3 of GOTO", "'3x' is not a number"),
        ("GOTO/1_0,2,3\n", 1, "field 1 of GOTO", "'1_0' is not a number"),
        ("FEDRAT/MMPM\n", 1, "FEDRAT record", "has no feed value"),
        ("FEDRAT/100,FURLONGS\n", 1, "field 2 of FEDRAT", "'FURLONGS' is neither a number nor a feed unit"),
        ("FEDRAT/-5\n", 1, "FEDRAT record", "must be positive"),
        ("UNITS/FEET\n", 1, "field 1 of UNITS", "unknown unit 'FEET'"),
        ("CIRCLE/0,0,0,0,0,1\nGOTO/1,0,0\n", 1, "CIRCLE record", "has no start point"),
        ("GOTO/1,0,0\nCIRCLE/0,0,0,0,0,1\n", 2, "CIRCLE record", "has no end point"),
        ("GOTO/1,0,0\nCIRCLE/0,0,0,0,0,1\nCIRCLE/0,0,0,0,0,1\n", 2, "CIRCLE record", "has no end point"),
        ("GOTO/1,0,0\nCIRCLE/0,0,0,0,0\nGOTO/0,1,0\n", 2, "CIRCLE record", "has 5 values"),
        ("GOTO/1,0,0\nCIRCLE/0,0,0,0,0,3\nGOTO/0,1,0\n", 2, "fields 4-6 of CIRCLE", "is not a unit vector"),
        ("CSYS/1,0,0,0,0,1,0,0,0,0,1\n", 1, "CSYS record", "has 11 values, expected 12"),
        ("CSYS/1,0,0,0,0,2,0,0,0,0,1,0\n", 1, "CSYS matrix", "is not a rotation"),
        ("MSYS/0,0,0,1,0,0,0.5,0.8,0\n", 1, "fields 7-9 of MSYS", "is not a unit vector"),
        ("MSYS/0,0,0,1,0,0,0.6,0.8,0\n", 1, "fields 4-9 of MSYS", "not perpendicular"),
        ("GOTO/1,2,$\n3,4,5,6,7\n", 1, "GOTO record", "has 7 values"),
        ("GOTO/1,2,$\n3,0,0,$\nq\n", 3, "field 6 of GOTO", "'q' is not a number"),
        ("GOTO/1,2,$\n", 1, "record", "continuation ('$') at the end of the file"),
        ("NURBS/1,2,3\n", 1, "NURBS record", "not supported"),
        ("GODLTA/1,2,3\n", 1, "GODLTA record", "no point precedes it"),
        ("/1,2,3\n", 1, "record", "no major word"),
    ],
)
def test_broken_records_name_file_line_and_field(text, line, field, problem):
    with pytest.raises(InputFileError) as exc:
        read(text)
    err = exc.value
    assert isinstance(err, PlannerError) and isinstance(err, ValueError)
    assert (err.source, err.line, err.field) == ("t.apt", line, field)
    assert str(err).startswith(f"t.apt line {line}, {field}: ")
    assert problem in str(err)


def test_file_without_motion_is_an_error():
    with pytest.raises(InputFileError, match=r"^t\.apt: holds no motion"):
        read("$$ nothing\nPARTNO/X\n")


def test_error_message_format_of_the_brief():
    with pytest.raises(InputFileError, match=r"^part\.apt line 12, field 3 of GOTO: 'x1\.5' is not a number$"):
        read_apt(io.StringIO("\n" * 11 + "GOTO/1,2,x1.5\n"), source="part.apt")
