"""`planner plan FILE` on whole CAM jobs: the JSON pose stream, the movep/movel URScript program and the
plot, parsed back and checked against the planned job (real NX data: the bundled example and the first
300 lines of shared/data's NX job)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from planner import PlanSettings, plan
from planner.frontends.cli.main import DEMO_PART, DEMO_PART_FRAME, EXAMPLE_CLS, example_path, main
from planner.frontends.cli.options import parse_pose
from planner.kinematics import forward_matrix, get_model
from planner.motion import poses_at_length, tool_orientation
from planner.motion.stream import as_transform
from tests.cam_excerpts import NX
from tests.conftest import SHARED_DATA

NX_JOB = SHARED_DATA / "nx_clsf_variable_contour_ust_a2.cls"
PART = DEMO_PART
TOL = 1e-5  # the CLI's default --tolerance 0.01 mm
NUM = r"-?\d+\.\d+"
VEC = rf"\[({NUM}(?:, {NUM})*)\]"


@pytest.fixture(scope="module")
def nx_excerpt(tmp_path_factory):
    """The first 300 lines of the real NX job (7 passes, 7 rapids), verbatim (from its excerpt in tests/data)."""
    f = tmp_path_factory.mktemp("cam") / "ust_a2_head.cls"
    f.write_text(NX.head(300))
    return f


def _source(name, nx_excerpt):
    if name == "example":
        return example_path(EXAMPLE_CLS)
    return nx_excerpt


def _job(path, rate=500.0, robot="ur5e", part=PART):
    """The job the CLI plans for ``path`` with its defaults."""
    return plan(path, PlanSettings(path="cam", tolerance=TOL, part_frame=part, robot=robot, feed=0.05, rate=rate))


def _strict_json(text):
    def bad(token):
        raise AssertionError(f"not JSON: {token}")

    return json.loads(text, parse_constant=bad)


def _matrices(poses):
    return Rotation.from_rotvec(np.asarray(poses)[:, 3:]).as_matrix()


def parse_program(text):
    """Statements of a generated program: [(kind, args...)]; every line must be understood."""
    lines = text.splitlines()
    assert lines[0] == "def planner_job():" and lines[-1] == "end"
    out = []
    for line in lines[1:-1]:
        assert line.startswith("  "), line
        body = line.strip()
        if body.startswith("#"):
            out.append(("comment", body[1:].strip()))
        elif m := re.fullmatch(rf"movep\(p{VEC}, a=({NUM}), v=({NUM}), r=({NUM})\)", body):
            out.append(("movep", np.array(m[1].split(", "), float), float(m[2]), float(m[3]), float(m[4])))
        elif m := re.fullmatch(rf"movel\(p{VEC}, a=({NUM}), v=({NUM})(?:, t=({NUM}))?, r=({NUM})\)", body):
            t = None if m[4] is None else float(m[4])
            out.append(("movel", np.array(m[1].split(", "), float), float(m[2]), float(m[3]), t, float(m[5])))
        elif m := re.fullmatch(rf"movej\({VEC}, a=({NUM}), v=({NUM})(?:, t=({NUM}))?\)", body):
            t = None if m[4] is None else float(m[4])
            out.append(("movej", np.array(m[1].split(", "), float), float(m[2]), float(m[3]), t))
        elif m := re.fullmatch(rf"set_tcp\(p{VEC}\)", body):
            out.append(("set_tcp", np.array(m[1].split(", "), float)))
        else:
            raise AssertionError(f"unexpected URScript line: {line!r}")
    return out


def _polyline_distance(p, a, b):
    """Distance (n,) of points p (n, 3) from the polyline through a[0], b[0] = a[1], ..., b[-1]."""
    d = b - a
    lam = np.clip(np.einsum("nmi,mi->nm", p[:, None, :] - a[None], d) / np.einsum("mi,mi->m", d, d), 0.0, 1.0)
    return np.linalg.norm(p[:, None, :] - a[None] - lam[..., None] * d[None], axis=2).min(axis=1)


@pytest.mark.parametrize("name, rate", [("example", 500.0), ("nx", 125.0)])
def test_whole_job_json_is_the_pose_stream_with_joints(name, rate, nx_excerpt, tmp_path, capsys):
    src = _source(name, nx_excerpt)
    out = tmp_path / "job.json"
    assert main(["plan", str(src), "--pass", "all", "--robot", "ur5e", "--part-frame", DEMO_PART_FRAME, "--rate",
                 f"{rate:g}", "-o", str(out)]) == 0
    assert "with joints" in capsys.readouterr().out
    doc = _strict_json(out.read_text())
    assert list(doc) == ["format", "parameters", "moves", "columns", "samples"]
    p = doc["parameters"]
    assert p["generator"].startswith("ph-toolpath-planner") and p["input"] == src.name
    st = p["settings"]
    assert p["rate_hz"] == rate and st["tolerance"] == TOL and st["robot"] == "ur5e" and p["reachable"] is True
    assert st["path"] == "cam" and st["axes"] == "file"
    np.testing.assert_allclose(st["part_frame"], PART, atol=1e-15)
    assert doc["columns"] == ["t", "x", "y", "z", "rx", "ry", "rz", "kind", "move", "pass", "line",
                              "q0", "q1", "q2", "q3", "q4", "q5"]
    rows = doc["samples"]
    assert len(rows) == p["samples"] == sum(m["samples"] for m in doc["moves"])

    job = _job(src, rate)
    chunks = list(job.trajectory(rate).chunks(joints=False))
    t = np.array([r[0] for r in rows])
    poses = np.array([r[1:7] for r in rows])
    q = np.array([r[11:17] for r in rows])
    np.testing.assert_allclose(t, np.concatenate([c.times for c in chunks]), rtol=0, atol=5e-7)
    np.testing.assert_allclose(poses, np.concatenate([c.poses for c in chunks]), rtol=0, atol=1e-8)
    assert [r[7] for r in rows] == [c.kind for c in chunks for _ in range(c.times.size)]
    assert [r[8:11] for r in rows] == [[c.move, c.pass_index, int(x)] for c in chunks for x in c.lines]
    assert {r[7] for r in rows} == {"cut", "rapid"} and max(r[9] for r in rows) == len(job.passes) - 1
    # each row's line lies within its move's lines, and the move table matches the job
    for mv in doc["moves"]:
        m = job.moves[mv["move"]]
        assert (mv["kind"], mv["pass"]) == (m.kind, m.pass_index)
    firsts = {mv["move"]: (mv["first_line"], mv["last_line"]) for mv in doc["moves"]}
    assert all(firsts[r[8]][0] <= r[10] <= firsts[r[8]][1] for r in rows)
    # the joints put the tool on the poses (forward kinematics), within the limits, on one branch
    T = forward_matrix("ur5e", q)
    np.testing.assert_allclose(T[:, :3, 3], poses[:, :3], rtol=0, atol=1e-7)
    np.testing.assert_allclose(T[:, :3, :3], _matrices(poses), rtol=0, atol=1e-7)
    m = get_model("ur5e")
    assert np.all(q >= m.q_min) and np.all(q <= m.q_max)
    assert np.abs(np.diff(q, axis=0)).max() < 0.05  # rad per sample: no branch switch


@pytest.mark.parametrize("name", ["example", "nx"])
def test_whole_job_script_follows_every_pass_within_tolerance(name, nx_excerpt, tmp_path, capsys):
    src = _source(name, nx_excerpt)
    out = tmp_path / "job.script"
    args = ["plan", str(src), "--pass", "all", "--robot", "ur5e", "--part-frame", DEMO_PART_FRAME, "-o", str(out)]
    if name == "nx":  # 7 passes make a program of about 140 kB: over a CB-Series controller's 100 kB
        assert main([*args, "--max-program-bytes", "100000"]) == 2 and not out.exists()
        assert "over the 100000 bytes a UR controller is known to take in one program" in capsys.readouterr().err
    assert main(args) == 0
    counts = re.search(r"wrote .*job\.script \((\d+) movep, (\d+) movel, (\d+) movej\)", capsys.readouterr().out)
    text = out.read_text()
    assert counts and [int(c) for c in counts.groups()] == [text.count(f"  {c}(") for c in ("movep", "movel", "movej")]
    stmts = parse_program(text)
    comments = [s[1] for s in stmts if s[0] == "comment"]
    assert comments[0].startswith("whole-job movep/movel program generated by ph-toolpath-planner")
    settings = next(c for c in comments if c.startswith("settings: "))
    assert f'input: "{src.name}"' in comments and '"tolerance": 1e-05' in settings and '"robot": "ur5e"' in settings
    kinds = [s[0] for s in stmts if s[0] != "comment"]
    assert kinds[:2] == ["set_tcp", "movej"] and set(kinds[2:]) <= {"movep", "movel"}

    job = _job(src)
    Tb = as_transform(PART, "part")
    first = next(iter(job.trajectory().chunks(joints=False)))
    start = forward_matrix("ur5e", next(s[1] for s in stmts if s[0] == "movej"))
    np.testing.assert_allclose(start[:3, 3], first.poses[0, :3], atol=1e-9)
    np.testing.assert_allclose(start[:3, :3], _matrices(first.poses[:1])[0], atol=1e-9)
    moving = [m for m in job.moves if m.profile is not None]
    assert kinds.count("movel") == sum(m.kind != "cut" for m in moving)
    n_poses = job.n_samples(500.0)
    assert len(kinds) < n_poses / 50  # compact: one statement per target, not per pose

    # walk the program: every pass is a run of movep after its comment, starting where the tool is
    here = first.poses[0]
    i = 0
    motions = [s for s in stmts if s[0] in ("movep", "movel") or (s[0] == "comment" and re.match(
        r"(pass \d+\b|rapid, line \d+|turn in place, line \d+)", s[1]))]
    for m in moving:
        head = motions[i]
        assert head[0] == "comment"
        i += 1
        if m.kind == "cut":
            assert re.match(rf"pass {m.pass_index}\b", head[1])
            assert f"lines {m.item.first_line}-{m.item.last_line}:" in head[1]
            run = []
            while i < len(motions) and motions[i][0] == "movep":
                run.append(motions[i])
                i += 1
            targets = np.vstack([here[None, :3]] + [r[1][None, :3] for r in run])
            # the CAM points and the planned path lie within tolerance of the polyline of targets
            cam = m.item.points @ Tb[:3, :3].T + Tb[:3, 3]
            assert _polyline_distance(cam, targets[:-1], targets[1:]).max() <= 0.5 * TOL * 1.05
            s = np.linspace(0.0, m.path.length, 4001)
            dense, _, _ = poses_at_length(m.path, tool_orientation(m.frames), s, base=Tb)
            assert _polyline_distance(dense, targets[:-1], targets[1:]).max() <= 0.5 * TOL * 1.05
            np.testing.assert_allclose(targets[-1], cam[-1], atol=1e-9)
            # blends: r = 0 at the pass end, no overlap, corner cut within the tolerance
            r = np.array([x[4] for x in run])
            chord = np.diff(targets, axis=0)
            ell = np.linalg.norm(chord, axis=1)
            cosang = np.einsum("ni,ni->n", chord[:-1], chord[1:]) / (ell[:-1] * ell[1:])
            assert r[-1] == 0.0 and np.all(r >= 0.0)
            assert np.all(r[:-1] <= 0.5 * np.minimum(ell[:-1], ell[1:]) * (1 + 1e-9) + 1e-12)
            assert np.all(r[:-1] * np.sin(0.5 * np.arccos(np.clip(cosang, -1, 1))) <= TOL * (1 + 1e-6))  # 12 decimals
            # the speed is the pass's feed: FEDRAT/MMPM,250 of the NX file
            np.testing.assert_allclose([x[3] for x in run], 0.25 / 60.0, rtol=1e-9)
            assert all(x[2] == job.settings.limits.acceleration for x in run)
            here = run[-1][1]
        else:
            st = motions[i]
            assert st[0] == "movel" and st[5] == 0.0
            i += 1
            end = m.item.end if m.kind == "rapid" else m.item.point
            np.testing.assert_allclose(st[1][:3], Tb[:3, :3] @ end + Tb[:3, 3], atol=1e-9)
            z = _matrices(st[1][None])[0][:, 2]
            np.testing.assert_allclose(z, Tb[:3, :3] @ m.end_frame[:, 2], atol=1e-9)
            assert 0.0 < st[3] <= job.settings.rapid_speed
            here = st[1]
    assert i == len(motions)


def test_turn_in_place_is_a_timed_movel_about_the_tool_tip(tmp_path):
    src = tmp_path / "turn.apt"  # a 30 degree tool-axis change at (40, 0, 0) between two cuts
    src.write_text("UNITS/MM\nFEDRAT/MMPM,600\nGOTO/0,0,0,0,0,1\nGOTO/40,0,0,0,0,1\nGOTO/40,0,0,0,0.5,0.8660254\n"
                   "GOTO/80,0,0\nRAPID\nGOTO/80,0,50\n")
    out = tmp_path / "turn.script"
    part = "400mm,0,200mm,0,0,0"
    assert main(["plan", str(src), "--pass", "all", "--robot", "ur5e", "--part-frame", part, "-o", str(out)]) == 0
    stmts = [s for s in parse_program(out.read_text()) if s[0] in ("movep", "movel")]
    assert [s[0] for s in stmts] == ["movep", "movel", "movep", "movel"]
    job = plan(src, PlanSettings(tolerance=TOL, part_frame=parse_pose(part), robot="ur5e"))
    turn = next(m for m in job.moves if m.kind == "reorientation")
    before, spin, after = stmts[0][1], stmts[1], stmts[2][1]
    np.testing.assert_allclose(spin[1][:3], before[:3], atol=1e-12)  # in place
    assert spin[4] == pytest.approx(turn.duration, abs=1e-11)  # timed as planned
    R0, R1 = _matrices(np.vstack((before, spin[1])))
    assert np.degrees(np.arccos(np.clip(R0[:, 2] @ R1[:, 2], -1, 1))) == pytest.approx(30.0, abs=1e-5)
    np.testing.assert_allclose(R1[:, 2], -np.array([0.0, 0.5, 0.8660254]) / np.linalg.norm([0, 0.5, 0.8660254]),
                               atol=1e-12)
    np.testing.assert_allclose(after[:3], [0.48, 0.0, 0.2], atol=1e-9)
    assert stmts[3][4] is None  # the rapid does not turn the tool: speed-limited, not timed


def test_whole_job_script_is_refused_naming_pass_and_line(nx_excerpt, tmp_path, capsys):
    nx_excerpt = _source("nx", nx_excerpt)
    part = "800mm,-1396.5mm,-100mm,0,0,3.14159265rad"  # turned half round: the far end of the passes is out of reach
    out = tmp_path / "job.script"
    assert main(["plan", str(nx_excerpt), "--robot", "ur5e", "--part-frame", part, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("planner: error: not writing job.script: the robot cannot make the job:")
    assert re.search(r"pass 0 \(VARIABLE_CONTOUR\) \(lines 14-53\), line \d+: pose has no inverse kinematics", err)
    assert not out.exists()
    # the pose stream is still written, with null joints where there is no solution
    js = tmp_path / "job.json"
    assert main(["plan", str(nx_excerpt), "--robot", "ur5e", "--part-frame", part, "--rate", "125", "-o", str(js)]) == 0
    doc = _strict_json(js.read_text())
    assert doc["parameters"]["reachable"] is False and doc["parameters"]["problems"] >= 1
    assert "pass 0" in doc["parameters"]["problem_list"][0]
    unreachable = [r for r in doc["samples"] if r[11] is None]
    assert unreachable and all(all(x is None for x in r[11:]) for r in unreachable)
    assert all(all(isinstance(x, float) for x in r[11:]) for r in doc["samples"] if r[11] is not None)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["-o", "job.docx"], "-o job.docx: unknown output type"),
        (["--robot", "none", "-o", "job.script"], "needs the reachability check: give --robot MODEL"),
        (["--pass", "everything"], "--pass everything: must be pass numbers K[,K...], 'longest' or 'all'"),
        (["--plot", "job.xyz"], "--plot job.xyz: unknown image type '.xyz'"),
        (["--cut-output", "spray"], "--cut-output spray: must be KIND:PIN"),
        (["-o", "INPUT"], "is the input file; refusing to overwrite it"),
    ],
)
def test_whole_job_outputs_are_checked_before_planning(argv, message, nx_excerpt, tmp_path, capsys, monkeypatch):
    nx_excerpt = _source("nx", nx_excerpt)
    monkeypatch.chdir(tmp_path)
    argv = [str(nx_excerpt) if a == "INPUT" else a for a in argv]
    before = nx_excerpt.read_bytes()
    assert main(["plan", str(nx_excerpt), *argv]) == 2
    captured = capsys.readouterr()
    assert message in captured.err and "planning" not in captured.out
    assert nx_excerpt.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == []


def test_whole_job_plot_is_one_picture_of_every_pass(nx_excerpt, tmp_path, capsys):
    from PIL import Image

    from planner.plot import plot_job

    nx_excerpt = _source("nx", nx_excerpt)
    png = tmp_path / "job.png"
    assert main(["plan", str(nx_excerpt), "--robot", "ur5e", "--part-frame", DEMO_PART_FRAME, "--rate", "125", "--plot",
                 str(png)]) == 0
    assert re.search(r"wrote .*job\.png \(speeds from all \d+ poses, joints from 1 in \d+\)", capsys.readouterr().out)
    with Image.open(png) as im:
        assert im.format == "PNG" and im.size == (1870, 1100)
        pixels = np.asarray(im.convert("RGB")).reshape(-1, 3)
    assert len(np.unique(pixels, axis=0)) > 500 and (pixels < 250).any(axis=1).mean() > 0.05  # drawn, not blank
    # what the panels show, read from the whole stream in bounded pieces
    job = _job(nx_excerpt, 125.0)
    digest = plot_job(job, tmp_path / "again.png", max_points=5000)
    assert digest.samples == job.n_samples(125.0) and digest.step == int(np.ceil(digest.samples / 5000))
    assert 5000 * 0.9 < digest.times.size < 5000 + 2 * len(job.moves)
    cut_hi, rapid_hi = np.nanmax(digest.speed["cut"][1]), np.nanmax(digest.speed["other"][1])
    assert cut_hi == pytest.approx(0.25 / 60.0, rel=1e-6)  # the file's feed, 250 mm/min
    assert 0.25 / 60.0 < rapid_hi <= job.settings.rapid_speed * (1 + 1e-9)
    T = forward_matrix("ur5e", digest.joints)
    np.testing.assert_allclose(T[:, :3, 3], digest.poses[:, :3], atol=1e-9)


@pytest.mark.slow
def test_whole_nx_job_plot_and_program(tmp_path, capsys):
    """The whole real NX job (867 passes, 12.9 million poses at 500 Hz): plot, then the program, with the one
    change of the arm configuration the job needs."""
    if not NX_JOB.is_file():
        pytest.skip(f"{NX_JOB} not present")
    png, script = tmp_path / "job.png", tmp_path / "job.script"
    # (the whole job's program, 11 MB, is more than a controller takes in one program: written with no limit)
    code = main(["plan", str(NX_JOB), "--robot", "ur5e", "--part-frame", DEMO_PART_FRAME, "-o", str(script), "--plot",
                 str(png), "--max-program-bytes", "0"])
    captured = capsys.readouterr()
    from PIL import Image

    with Image.open(png) as im:
        assert im.size == (1870, 1100)
    passes = int(re.search(r"-> (\d+) pass(es)?, ", captured.out).group(1))
    # pass 768 runs the configuration the arm inherits out of reach (line 20413): the arm changes configuration
    # in the rapid before passes 766-768 (joined at corners), and the robot makes the whole job
    assert code == 0, captured.err
    assert "1 change of the arm configuration" in captured.out and "every move reachable" in captured.out
    assert re.search(r"before passes 766-768 \(lines 20357-20416\), at the end of the rapid at line 20357: joint move",
                     captured.out)
    stmts = parse_program(script.read_text())
    assert sum(1 for s in stmts if s[0] == "comment" and re.match(r"pass \d+\b", s[1])) == passes
    (i,) = [k for k, s in enumerate(stmts) if s[0] == "comment" and s[1].startswith("change of the arm configuration")]
    assert stmts[i][1].startswith("change of the arm configuration for pass 766, line 20357 (at the end of the rapid")
    assert stmts[i + 1][0] == "movej" and stmts[i + 1][4] > 0.0  # timed
    assert re.match(r"pass 766\b", next(s[1] for s in stmts[i + 1 :] if s[0] == "comment"))
