"""Splitting CAM toolpaths into passes, rapids, reorientations (planner.cam.passes)."""

from __future__ import annotations

import io

import numpy as np
import pytest

from planner.cam import CamInputError, CutPass, RapidMove, Skipped, split_passes
from planner.io import Event, Toolpath, read_toolpath
from tests.cam_excerpts import NX_HEAD


def toolpath(points, axes=None, rapid=None, events=(), feeds=None, lines=None) -> Toolpath:
    """A Toolpath from plain lists (metres); lines default to 10, 11, 12, ..."""
    p = np.asarray(points, dtype=float)
    n = len(p)
    a = None if axes is None else np.asarray(axes, dtype=float)
    return Toolpath(
        points=p,
        axes=a,
        axis_given=None if a is None else np.ones(n, dtype=bool),
        feeds=np.full(n, 0.01) if feeds is None else np.asarray(feeds, float),
        rapid=np.zeros(n, dtype=bool) if rapid is None else np.asarray(rapid, bool),
        lines=np.arange(10, 10 + n) if lines is None else np.asarray(lines),
        events=tuple(events),
        source="test.apt",
    )


def kinds(seg) -> list[str]:
    return [m.kind for m in seg.moves]


def test_nx_excerpt_splits_at_every_rapid():
    tp = read_toolpath(io.StringIO(NX_HEAD), format="apt")
    seg = split_passes(tp)
    rapid_lines = [int(tp.lines[i]) for i in np.flatnonzero(tp.rapid) if i > 0]
    assert rapid_lines == [14, 56, 98]  # the GOTOs after the RAPID records on lines 13, 55 and 97
    assert [m.line for m in seg.moves if isinstance(m, RapidMove)] == rapid_lines
    passes = seg.passes
    assert [(p.first_line, p.last_line) for p in passes] == [(14, 53), (56, 95), (98, 100)]
    assert [p.start_reason for p in passes] == ["rapid", "rapid", "rapid"]
    for p in passes:  # no rapid motion inside a pass, and every point in file order
        assert not tp.rapid[p.source_index[1:]].any()
        assert np.all(np.diff(p.source_index) == 1)
    # every move alternates: rapid, cut, rapid, cut, ...
    assert kinds(seg) == ["rapid", "cut", "rapid", "cut", "rapid", "cut"]
    assert passes[0].operation == "VARIABLE_CONTOUR" and passes[0].tool == 2.0
    # the first pass: 90-degree arc, straight run, 90-degree arc: no corner sharper than 60 degrees
    assert seg.corners == 0 and len(passes[0]) == 36


def zigzag(turn_deg: float, legs: int = 4, step: float = 0.01) -> np.ndarray:
    """Points of a zig-zag whose legs turn by ``turn_deg`` at each vertex (in the xy plane)."""
    pts = [np.zeros(3)]
    heading = 0.0
    for k in range(legs):
        d = np.array([np.cos(heading), np.sin(heading), 0.0])
        pts += [pts[-1] + step * d * (i + 1) / 3 for i in range(3)]
        heading += np.radians(turn_deg) * (1 if k % 2 == 0 else -1)
    return np.array(pts)


def test_zigzag_turns_split_passes_and_gentle_turns_do_not():
    sharp = split_passes(toolpath(zigzag(150.0)))
    assert sharp.corners == 3 and len(sharp.passes) == 4
    for a, b in zip(sharp.passes[:-1], sharp.passes[1:], strict=True):
        # the corner point ends one pass and starts the next: the tool stops there, nothing is rounded
        assert np.array_equal(a.points[-1], b.points[0]) and a.last_line == b.first_line
        assert a.end_reason == "corner" and b.start_reason == "corner"
        assert b.start_corner_deg == pytest.approx(150.0, abs=1e-9)
    gentle = split_passes(toolpath(zigzag(30.0)))
    assert gentle.corners == 0 and len(gentle.passes) == 1 and len(gentle.passes[0]) == 13
    strict = split_passes(toolpath(zigzag(30.0)), corner_deg=20.0)
    assert strict.corners == 3 and strict.corner_deg == 20.0


def test_duplicates_merged_and_zero_length_moves_kept_with_a_reason():
    pts = [[0, 0, 0], [0.01, 0, 0], [0.01, 0, 0], [0.02, 0, 0], [0.02, 0, 0.05], [0.02, 0, 0.05], [0.02, 0, 0.05]]
    rapid = [False, False, False, False, True, False, False]
    seg = split_passes(toolpath(pts, rapid=rapid))
    assert kinds(seg) == ["cut", "rapid", "skipped"]
    cut = seg.passes[0]
    assert cut.merged == 1 and len(cut) == 3 and list(cut.lines) == [10, 11, 13]
    skipped = seg.moves[2]
    assert isinstance(skipped, Skipped) and "zero length" in skipped.reason
    assert (skipped.first_line, skipped.last_line) == (14, 16) and "14-16" in skipped.reason
    assert seg.counts["merged"] == 3 and seg.counts["degenerate"] == 1


def test_zero_length_rapid_is_skipped_or_turns_in_place():
    z, x = [0, 0, 1.0], [1.0, 0, 0]
    pts = [[0, 0, 0], [0.01, 0, 0], [0.01, 0, 0], [0.01, 0, 0], [0.02, 0, 0]]
    seg = split_passes(toolpath(pts, axes=[z, z, z, x, x], rapid=[False, False, True, True, False]))
    assert kinds(seg) == ["cut", "skipped", "reorientation", "cut"]
    turn = seg.moves[2]
    assert turn.reason == "turn in place" and turn.line == 13
    assert turn.angle == pytest.approx(np.pi / 2, abs=1e-15)
    assert "rapid move of zero length to line 12" in seg.moves[1].reason


def test_axis_jump_along_a_chord_becomes_a_reorientation_at_the_pass_start():
    z = np.array([0.0, 0.0, 1.0])
    tilted = np.array([np.sin(1.2), 0.0, np.cos(1.2)])  # 68.8 degrees from z
    pts = [[0, 0, 0], [0.01, 0, 0], [0.02, 0, 0], [0.03, 0, 0]]
    seg = split_passes(toolpath(pts, axes=[z, z, tilted, tilted]), axis_jump_deg=45.0)
    assert kinds(seg) == ["cut", "reorientation", "cut"]
    first, turn, second = seg.moves
    assert first.end_reason == "axis jump" and len(first) == 2
    assert np.array_equal(turn.point, pts[1]) and turn.line == 12
    assert np.array_equal(second.points[0], pts[1]) and np.array_equal(second.axes[0], tilted)
    assert np.array_equal(second.axes[1:], [tilted, tilted]) and second.start_reason == "axis jump"
    # below the threshold the axis turns along the chord: one pass
    assert kinds(split_passes(toolpath(pts, axes=[z, z, tilted, tilted]))) == ["cut"]


def test_axis_flip_across_a_rapid_turns_in_place_after_it():
    z = np.array([0.0, 0.0, 1.0])
    pts = [[0, 0, 0], [0.01, 0, 0], [0.01, 0.05, 0], [0.02, 0.05, 0]]
    seg = split_passes(toolpath(pts, axes=[z, z, -z, -z], rapid=[False, False, True, False]))
    assert kinds(seg) == ["cut", "rapid", "reorientation", "cut"]
    rapid, turn = seg.moves[1], seg.moves[2]
    assert np.array_equal(rapid.end_axis, z)  # the rapid keeps its axis; the flip happens at its end
    assert np.array_equal(turn.point, pts[2]) and turn.angle == pytest.approx(np.pi)
    assert seg.counts["axis_jumps"] == 1


def test_tool_change_and_operation_split_passes():
    pts = [[0.01 * i, 0, 0] for i in range(6)]
    events = [Event("operation", 5, 0, "ROUGH"), Event("tool_change", 20, 2, "", 7.0),
              Event("operation", 30, 4, "FINISH")]
    seg = split_passes(toolpath(pts, events=events))
    assert kinds(seg) == ["cut", "rapid", "cut", "cut"]
    a, change, b, c = seg.moves
    assert a.operation == "ROUGH" and change.reason == "tool change" and change.line == 12
    assert b.tool == 7.0 and b.operation == "ROUGH" and b.end_reason == "operation"
    assert c.operation == "FINISH" and c.start_reason == "operation" and np.array_equal(c.points[0], pts[3])


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("corner_deg", 0.0, "corner_deg must be in (0, 180]"),
        ("corner_deg", 200.0, "corner_deg must be in (0, 180]"),
        ("corner_deg", "sharp", "corner_deg must be a number"),
        ("axis_jump_deg", 120.0, "axis_jump_deg must be in (0, 90]"),
        ("duplicate_tol", -1.0, "duplicate_tol must be in (0, inf]"),
    ],
)
def test_bad_thresholds_are_named(option, value, message):
    with pytest.raises(CamInputError, match=message.replace("(", r"\(").replace("[", r"\[").replace("]", r"\]")):
        split_passes(toolpath([[0, 0, 0], [1, 0, 0]]), **{option: value})


def test_empty_toolpath_is_refused_naming_the_file():
    with pytest.raises(CamInputError, match="test.apt: the toolpath has no points"):
        split_passes(toolpath(np.zeros((0, 3))))


def test_every_point_belongs_to_a_move():
    """Nothing is dropped: every point is in a pass or is a rapid's target, but the merged duplicate."""
    rng = np.random.default_rng(3)
    pts = np.cumsum(rng.normal(size=(200, 3)) * 0.01, axis=0)
    pts[50] = pts[49]  # a duplicate inside a cutting run
    rapid = rng.random(200) < 0.1
    rapid[49:52] = False
    seg = split_passes(toolpath(pts, rapid=rapid), corner_deg=90.0)
    covered = {0}
    for m in seg.moves:
        if isinstance(m, CutPass):
            covered.update(m.source_index.tolist())
        elif isinstance(m, RapidMove):
            covered.add(m.source_index)
    assert set(range(200)) - covered == {50}
    assert seg.counts["merged"] == 1 and sum(p.merged for p in seg.passes) == 1
