"""Arm configurations of whole CAM jobs (planner.cam.configure, planner.cam.reach): the configuration is kept
while it can make the passes, and changed by a joint move at the safe point of a rapid before the run of passes
that needs it, never during a cut; the joint stream, the move list, the reports and the exports all carry it.

A constructed APT job shows the case from the start: pass 0 lies where only the branches with one wrist offset
reach, pass 1 runs out to where only the others do. Excerpts of the real NX job (its lines 20179-20416, kept
verbatim in tests/data, see tests/data/SOURCES.md) show it on real data: an inherited configuration that runs out of reach in a rapid, and a first run that the configuration of
least joint travel cannot make.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from planner import PlanSettings, plan
from planner.cam.configure import groups
from planner.frontends.cli.main import main
from planner.kinematics import forward, forward_matrix, get_model
from tests.cam_excerpts import NX
from tests.test_export_urscript import parse_program

NX_PART = (0.4, 0.9965, -0.1, 0.0, 0.0, 0.0)


def cam_job(source, **kw):
    """The CAM polyline model; the feed where the file gives none 10 mm/s (the former CAM default) unless given."""
    return plan(source, PlanSettings(**{"path": "cam", "feed": 0.01, **kw}))


def _cam_axis(tilt_deg: float) -> tuple[float, float, float]:
    """CAM tool axis (tip towards spindle) of a tool whose approach axis is tilted from straight down by tilt_deg
    towards +x (past 90 deg it points upwards)."""
    t = np.radians(tilt_deg)
    return (-np.sin(t), 0.0, np.cos(t))


def _goto(p, axis=None) -> str:
    return "GOTO/" + ",".join(f"{v:.4f}" for v in p) + ("" if axis is None else "," + ",".join(f"{v:.7f}" for v in axis))


#: Pass 0 (lines 3-5) ends 0.86 m out with the tool tilted 50 deg above horizontal, where a UR5e reaches only with
#: branches 2-5; after a retract (line 7, the tool axis turning 85 deg), a traverse (line 9) and an approach (line
#: 11), pass 1 (lines 11-14) runs out to 0.85 m with the tool tilted 45 deg below horizontal, where only branches
#: 0, 1, 6 and 7 reach (the wrist offset d5 lies on the other side of the wrist centre). Base frame = part frame.
TWO_REACHES = "\n".join([
    "UNITS/MM", "FEDRAT/MMPM,1200",
    _goto((800, -50, 300), _cam_axis(130)), _goto((830, 0, 300)), _goto((860, 50, 300)),
    "RAPID", _goto((700, 50, 420), _cam_axis(45)),
    "RAPID", _goto((550, 150, 420)),
    "RAPID", _goto((550, 150, 300)),
    "FEDRAT/MMPM,1200", _goto((700, 150, 300)), _goto((850, 150, 300)),
]) + "\n"


@pytest.fixture(scope="module")
def two_reaches(tmp_path_factory):
    src = tmp_path_factory.mktemp("cam") / "two_reaches.apt"
    src.write_text(TWO_REACHES)
    return src, cam_job(src, robot="ur5e")


def test_inherited_configuration_is_changed_in_the_rapids_before_the_pass_that_needs_it(two_reaches):
    _, job = two_reaches
    assert job.reachable and not job.problems and all(p.reachable for p in job.passes)
    assert [m.kind for m in job.moves] == ["cut", "rapid", "rapid", "reconfiguration", "rapid", "cut"]
    (r,) = job.reconfigurations
    # in the rapids, at their most retracted point along pass 1's tool axis: above the approach
    assert (r.pass_index, r.passes, r.line) == (1, (1,), 9)
    assert r.where == "between the rapids at lines 9 and 11"
    np.testing.assert_array_equal(r.point, [0.55, 0.15, 0.42])
    # what the inherited configuration could not do: pass 1 runs it out of reach at its end (line 14)
    assert r.reason.startswith("two_reaches.apt pass 1 (lines 11-14), line 14: joint")
    assert "where the arm is stretched out (elbow at" in r.reason
    # the same pose on both configurations, on another branch (not just whole turns)
    T0, T1 = forward_matrix("ur5e", np.vstack((r.q_from, r.q_to)))
    np.testing.assert_allclose(T0, T1, atol=1e-9)
    np.testing.assert_allclose(T0[:3, 3], r.point, atol=1e-9)  # part frame = base frame, no TCP offset
    assert "flipped" in r.change and r.tcp_excursion > 0.0
    # timed by the joint limits: the leading joint at 1.05 rad/s and 1.4 rad/s^2 (jerk-limited), not faster
    dq = float(np.abs(r.q_to - r.q_from).max())
    move = job.moves[3]
    assert dq / 1.05 + 1.05 / 1.4 <= move.duration <= dq / 1.05 + 1.05 / 1.4 + 0.2
    # the reports name it by pass and source line
    text = "\n".join(job.describe())
    assert "1 change of the arm configuration (joint moves in rapids)" in text
    assert re.search(r"two_reaches\.apt before pass 1 \(lines 11-14\), between the rapids at lines 9 and 11: joint "
                     r"move of \d\.\d\d s \(.*flipped.*\); the former configuration: two_reaches\.apt pass 1", text)
    s = job.summary()
    assert s["reconfigured_passes"] == [1] and len(s["reconfigurations"]) == 1
    assert job.duration == pytest.approx(sum(m.duration for m in job.moves), rel=1e-15)
    assert job.n_samples(500.0) == pytest.approx(job.duration * 500.0, abs=len(job.moves) + 1)


@pytest.mark.parametrize("rate", [500.0, 125.0])
def test_joint_stream_is_continuous_and_exact_across_the_change(two_reaches, rate):
    _, job = two_reaches
    chunks = list(job.trajectory(rate).chunks())  # with the robot's joints
    q = np.concatenate([c.joints for c in chunks])
    poses = np.concatenate([c.poses for c in chunks])
    kind = np.concatenate([np.full(c.times.size, c.kind) for c in chunks])
    assert len(q) == job.n_samples(rate) and np.isfinite(q).all()
    # every pose (cuts, rapids and the joint move) is the forward kinematics of its joints
    T = forward_matrix("ur5e", q)
    np.testing.assert_allclose(T[:, :3, 3], poses[:, :3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(T[:, :3, :3], Rotation.from_rotvec(poses[:, 3:]).as_matrix(), rtol=0, atol=1e-9)
    for p in job.passes:  # each pass on one branch, its joints on its poses
        on = np.concatenate([np.full(c.times.size, c.pass_index == p.index) for c in chunks])
        np.testing.assert_allclose(forward("ur5e", q[on])[:, :3], poses[on, :3], atol=1e-9)
    # continuous within the joint speed limits everywhere (no jump between branches anywhere)
    m = get_model("ur5e")
    qd = np.diff(q, axis=0) * rate
    assert (np.abs(qd) <= m.speed_limits * (1 + 1e-9)).all()
    # the tool turns by at most the joints' turns from sample to sample; the rotation vectors never jump
    R = Rotation.from_rotvec(poses[:, 3:])
    step = (R[1:] * R[:-1].inv()).magnitude()
    assert (step <= np.abs(np.diff(q, axis=0)).sum(axis=1) + 1e-9).all()
    assert np.abs(np.diff(poses[:, 3:], axis=0)).max() < 0.5
    # the joint move: within its speed and acceleration limits, at rest where it meets the rapids
    lim = job.settings.joint_limits
    jm = np.flatnonzero(kind == "reconfiguration")
    a, b = jm[0], jm[-1] + 1  # samples a..b: the move and the first sample after it (the same pose)
    assert np.abs(qd[a:b]).max() <= lim.speed * (1 + 1e-9)
    qdd = np.diff(qd, axis=0) * rate
    assert np.abs(qdd[a - 1 : b]).max() <= lim.acceleration * (1 + 1e-6)  # across both junctions too
    assert np.abs(qd[[a - 1, a, b - 1, b]]).max() < 2e-3  # at rest on both sides: no step in joint speed
    r = job.reconfigurations[0]
    np.testing.assert_array_equal(q[a], r.q_from)
    np.testing.assert_allclose(q[b], r.q_to, atol=1e-9)  # the rapid after it continues on the new branch
    # without IK, only the joint move carries joints (its own, not solved)
    bare = list(job.trajectory(rate).chunks(joints=False))
    assert bare[0].joints is None and next(c for c in bare if c.kind == "reconfiguration").joints is not None


def test_whole_job_program_and_stream_carry_the_joint_move(two_reaches, tmp_path, capsys):
    src, _ = two_reaches
    job = cam_job(src, tolerance=1e-5, part_frame=(0.0,) * 6, robot="ur5e", feed=0.05, rate=125.0)  # as the CLI
    script, stream = tmp_path / "job.script", tmp_path / "job.json"
    for out in (script, stream):
        assert main(["plan", str(src), "--pass", "all", "--robot", "ur5e", "--part-frame", "0,0,0,0,0,0",
                     "--rate", "125", "-o", str(out)]) == 0
    out = capsys.readouterr().out
    assert "1 change of the arm configuration" in out and "before pass 1 (lines 11-14)" in out
    stmts = parse_program(script.read_text())
    motions = [s for s in stmts if s[0] in ("movej", "movel", "movep")]
    kinds = [s[0] for s in motions]  # (a pass's movep targets, as many as its path needs, counted as one)
    assert [k for i, k in enumerate(kinds) if not (k == "movep" and i > 0 and kinds[i - 1] == "movep")] == [
        "movej", "movep", "movel", "movel", "movej", "movel", "movep"]
    i = [k for k, s in enumerate(stmts) if s[0] == "movej"][1]
    assert re.match(r"change of the arm configuration for pass 1, line 9 \(between the rapids at lines 9 and 11\)",
                    stmts[i - 1][1])
    r = job.reconfigurations[0]
    _, q_to, a, v, t = stmts[i]
    np.testing.assert_allclose(q_to, r.q_to, atol=1e-11)  # 12 decimals
    assert (a, v) == (1.4, 1.05) and t == pytest.approx(job.moves[3].duration, abs=1e-11)
    traverse = motions[[k for k, s in enumerate(motions) if s[0] == "movej"][1] - 1][1]  # where the tool is when
    # the movej starts: the joints put it there
    T = forward_matrix("ur5e", q_to)
    np.testing.assert_allclose(T[:3, 3], traverse[:3], atol=1e-9)
    np.testing.assert_allclose(T[:3, :3], Rotation.from_rotvec(traverse[3:]).as_matrix(), atol=1e-9)
    assert "movej_reconfigurations" in script.read_text()
    # the JSON stream: the move table names it with its joints, its rows carry them
    doc = json.loads(stream.read_text())
    (mv,) = [x for x in doc["moves"] if x["kind"] == "reconfiguration"]
    assert (mv["move"], mv["pass"], mv["for_pass"], mv["first_line"]) == (3, -1, 1, 9)
    np.testing.assert_allclose(mv["q_from"], r.q_from, atol=1e-15)
    np.testing.assert_allclose(mv["q_to"], r.q_to, atol=1e-15)
    rows = [x for x in doc["samples"] if x[7] == "reconfiguration"]
    assert len(rows) == mv["samples"] and all(x[10] == 9 for x in rows)
    np.testing.assert_allclose(rows[0][11:], r.q_from, atol=1e-8)
    assert doc["parameters"]["reconfigurations"] == job.reconfiguration_lines()


def _nx_excerpt(first: int, last: int) -> str:
    """Lines 1-9 (header, MSYS) and first..last of the real NX job, the lines between them as $$ comments (so the
    source lines stay the file's), the modal tool axis and feed carried into the excerpt. The lines come from the
    job's verbatim excerpt in tests/data, which reads like the whole job at every line it keeps (same modal axis and
    feed), so the axis and feed carried are the whole job's."""
    kept = NX.lines()  # the whole job's line number -> text
    missing = [k for k in (*range(1, 10), *range(first, last + 1)) if k not in kept]
    assert not missing, f"lines {missing[0]}.. of the NX job are not in {NX.path}"
    lines = [kept.get(k, "$$") for k in range(1, last + 1)]
    axis = feed = None
    for ln in [kept[k] for k in sorted(kept) if 10 <= k < first]:
        if ln.startswith("GOTO/") and ln.count(",") == 5:
            axis = ln.split(",", 3)[3]
        elif ln.startswith("FEDRAT/"):
            feed = ln
    body = lines[first - 1 : last]
    k = next(i for i, ln in enumerate(body) if ln.startswith("GOTO/"))
    if body[k].count(",") == 2:
        body[k] += "," + axis
    pad = ["$$"] * (first - 11) + [feed or "$$"]  # the body starts at line `first`
    return "\n".join(lines[:9] + pad + body) + "\n"


@pytest.fixture(scope="module")
def nx_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("nx")

    def write(first: int, last: int):
        f = folder / f"ust_a2_{first}.cls"
        f.write_text(_nx_excerpt(first, last))
        return f

    return write


def test_real_job_changes_configuration_at_the_rapid_the_inherited_one_cannot_make(nx_file):
    """Real NX passes 758-768 (lines 20238-20416): the configuration they inherit runs out of reach in the rapid
    at line 20299 (the arm stretched out); the arm changes configuration at that rapid's start (the end of the
    pass before it, a safe point: no rapid comes earlier) and makes every move."""
    src = nx_file(20238, 20416)
    job = cam_job(src, part_frame=NX_PART, robot="ur5e", feed=0.05)
    assert job.reachable and not job.problems
    (r,) = job.reconfigurations
    assert r.where == "at the start of the rapid at line 20299" and r.line == 20299
    assert r.reason.startswith(f"{src.name} rapid at line 20299: joint") and "stretched out" in r.reason
    k = next(i for i, m in enumerate(job.moves) if m.kind == "reconfiguration")
    assert job.moves[k - 1].kind == "cut" and job.moves[k + 1].kind == "rapid" and job.moves[k + 1].line == 20299
    first = job.moves[k + 2]  # the pass after the rapid: the run the new configuration is for
    assert first.kind == "cut" and (first.pass_index, first.item.first_line) == (r.pass_index, 20299)
    # runs: the passes the CAM system joins at corners share one configuration (no rapid between them)
    runs = [[job.moves[i].pass_index for i in g.run if job.moves[i].kind == "cut"] for g in groups(job.moves)]
    assert [p.index for p in job.passes] == [p for run in runs for p in run]
    assert any(len(run) == 3 for run in runs)  # e.g. passes 766-768 (lines 20357-20416), joined at two corners
    chunks = list(job.trajectory(125.0).chunks())
    q = np.concatenate([c.joints for c in chunks])
    poses = np.concatenate([c.poses for c in chunks])
    T = forward_matrix("ur5e", q)
    np.testing.assert_allclose(T[:, :3, 3], poses[:, :3], atol=1e-9)
    np.testing.assert_allclose(T[:, :3, :3], Rotation.from_rotvec(poses[:, 3:]).as_matrix(), atol=1e-9)
    assert (np.abs(np.diff(q, axis=0)) * 125.0 <= get_model("ur5e").speed_limits * (1 + 1e-9)).all()


def test_real_job_starts_on_the_configuration_its_first_run_needs(nx_file):
    """Real NX passes 766-768 (lines 20357-20416, joined at corners) alone: on the configuration of least joint
    travel the arm runs out of reach at line 20413 (the feed floor cannot help); the job starts on one that can
    make them, and the stream and the program start there."""
    src = nx_file(20356, 20416)
    job = cam_job(src, part_frame=NX_PART, robot="ur5e", feed=0.05)
    assert job.reachable and not job.problems and not job.reconfigurations
    assert job.start_note.startswith("starts on the arm configuration that makes pass 0 (lines 20357-20416) "
                                     "feasible; the configuration of least joint travel fails: ")
    assert "pass 2 (VARIABLE_CONTOUR) (lines 20376-20416), line 20413: joint" in job.start_note
    assert "stretched out" in job.start_note and job.summary()["start"] == job.start_note
    assert any(line.startswith("  arm       starts on the arm configuration") for line in job.describe())
    chunk = next(iter(job.trajectory(125.0).chunks()))
    q = chunk.joints
    np.testing.assert_allclose(q[0], job.start_joints, atol=1e-9)
    T = forward_matrix("ur5e", q)
    np.testing.assert_allclose(T[:, :3, 3], chunk.poses[:, :3], atol=1e-9)
