"""The whole-job URScript program (planner.export.job_program) of the first 2000 GOTOs of shared/data's NX job
(55 passes, 55 rapids, about an hour of motion; 1.1 MB as one program) run by the simulated controller in
fast-forward, in the pieces a controller takes (planner.export.job_program_pieces: 5 programs under 250 kB), twice:

* by the simulator's core in this process, as fast as it goes (the interpreter and motion model of
  SimController, without sockets): the whole program refused as too large; the pieces, each loaded when the one
  before ended, every 20 ms of the actual TCP path within the program's tolerance of the planned path, the arm at
  rest at every seam, every output switched within 1 mm of its station, not one protective stop;
* by SimController at 150x through URDriver's program mode and real ur_rtde: the run ends ok in 5 programs, every
  recorded sample (one per ~0.3 s of job time) within the tolerance, no protective stop.

Reads the whole NX file beside the repository (../shared/data), skipped with the reason when it is absent as on
a clean clone (tests/conftest.py: SHARED_DATA). CPU: about 20 s for the first test and 30 s for the second on
this machine; the core runs the program at about 8 us of CPU per 2 ms control period (bench/bench_sim.py,
program table)."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.report import distance_to_polyline, planned_path
from drivers.ur import URDriver
from planner import PlanSettings, plan
from planner.export import MAX_PROGRAM_BYTES, job_program, job_program_pieces
from planner.frontends.cli.main import DEMO_PART
from planner.kinematics import forward
from sim.core import Core
from sim.io_state import IOState
from sim.programs import MAX_PROGRAM_BYTES as SIM_LIMIT
from tests import sim_fixtures
from tests.conftest import SHARED_DATA

make_sim = sim_fixtures.make_sim  # fixture

NX_JOB = SHARED_DATA / "nx_clsf_variable_contour_ust_a2.cls"
GOTOS = 2000
SPEED = 150.0  # simulated seconds per wall-clock second
EVERY = 10  # control periods between the checked TCP samples of the in-process run (20 ms, 1 mm at 50 mm/s)
FAST = {"approach_speed": 2.0, "approach_acceleration": 3.0}

pytestmark = [pytest.mark.slow, pytest.mark.realtime]


def first_gotos(text: str, n: int) -> str:
    """The file's lines up to and including its ``n``-th GOTO record (a ValueError if it has fewer)."""
    lines = text.split("\n")
    seen = 0
    for i, line in enumerate(lines):
        if line.startswith("GOTO/"):
            seen += 1
            if seen == n:
                return "\n".join(lines[: i + 1]) + "\n"
    raise ValueError(f"the file has {seen} GOTO records, fewer than {n}")


def test_first_gotos_cuts_after_the_nth_goto():
    text = "TOOL PATH/X\nGOTO/1,2,3\nRAPID\nGOTO/4,5,6\nGOTO/7,8,9\nEND-OF-PATH\n"
    assert first_gotos(text, 2) == "TOOL PATH/X\nGOTO/1,2,3\nRAPID\nGOTO/4,5,6\n"
    with pytest.raises(ValueError, match="3 GOTO records, fewer than 4"):
        first_gotos(text, 4)


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    if not NX_JOB.is_file():
        pytest.skip(f"the whole NX job is not beside the repository ({NX_JOB})")
    f = tmp_path_factory.mktemp("nx") / "ust_a2_first_2000_gotos.cls"
    f.write_text(first_gotos(NX_JOB.read_text(), GOTOS))
    part = DEMO_PART
    return plan(f, PlanSettings(path="cam", tolerance=1e-5, part_frame=part, robot="ur5e", feed=0.05,
                                cut_output=("standard", 0)))


def test_the_job(job):
    assert job.problems == ()
    assert len(job.passes) == 55 and job.count("rapid") == 55
    # no change of the arm configuration falls within these 2000 GOTOs on a UR5e in the demo's part frame
    # (the job's first is in its passes 757-768; tests/cam_excerpts.py)
    assert job.count("reconfiguration") == 0


@pytest.fixture(scope="module")
def pieces(job):
    return job_program_pieces(job)


def test_the_pieces(job, pieces):
    # the exporter keeps to the limit the simulated controller enforces
    assert MAX_PROGRAM_BYTES == SIM_LIMIT
    whole = job_program(job)
    assert len(whole.encode()) > 4 * MAX_PROGRAM_BYTES
    assert len(pieces) == 5 and all(p.size <= MAX_PROGRAM_BYTES for p in pieces)
    # the same statements in the same order (each piece sets the TCP again), every pass in exactly one piece, in order
    def statements(text):
        return [ln for ln in text.split("\n") if ln.startswith("  ") and not ln.lstrip().startswith(("#", "set_tcp"))]

    assert [x for p in pieces for x in statements(p.text)] == statements(whole)
    assert [k for p in pieces for k in p.passes] == [m.pass_index for m in job.moves if m.kind == "cut"]
    for a, b in zip(pieces, pieces[1:], strict=False):
        assert b.first_move == a.last_move + 1
        np.testing.assert_allclose(b.start, a.end, atol=1e-12)


def test_whole_job_program_in_the_simulators_core_every_period(job, pieces):
    pt, pp, pio, _, _ = planned_path(job)
    stations = np.flatnonzero(np.diff(pio) != 0) + 1  # planned output switches (sample index)
    core = Core("ur5e", IOState())
    core.motion.q = np.array(job.start_joints, dtype=float)  # where URDriver's approach puts the arm
    # the whole program is refused, as too large, and nothing of it runs
    assert not core.load_program(job_program(job))
    assert core.program is None and "program too large" in core.log[-1][2], list(core.log)[-3:]
    assert np.array_equal(core.motion.q, job.start_joints)
    qs, switches, seams = [], [], []
    out = core.io.digital_out
    for n, piece in enumerate(pieces):
        if n:  # the seam: the piece before ended at rest on its last pose, the outputs off
            seams.append((core.time, np.abs(core.motion.qd).max(), core.io.digital_out,
                          float(np.linalg.norm(core.tcp_pose()[:3] - piece.start[:3]))))
        assert core.load_program(piece.text), list(core.log)[-3:]
        while core.program is not None:
            core.tick()
            if core.steps % EVERY == 0:
                qs.append(core.motion.q)
            if core.io.digital_out != out:
                out = core.io.digital_out
                switches.append((out, core.tcp_pose()[:3].copy()))
            assert core.time < 2 * pt[-1], "the program did not end"
    assert core.safety_mode == 1 and not [m for m in core.log if m[1] == "Safety"], list(core.log)[-5:]
    assert core.time == pytest.approx(pt[-1], rel=0.02)
    assert len(seams) == len(pieces) - 1
    for _, speed, bits, gap in seams:
        assert speed < 1e-9 and bits == 0 and gap < 1e-6, seams
    # the actual TCP path within the program's tolerance of the planned one (distance to the path)
    tcp = forward("ur5e", np.array(qs))[:, :3]
    d, _ = distance_to_polyline(tcp, pp[:, :3])
    assert 0.0 < d.max() <= job.settings.tolerance, d.max()
    # every output switch, in order, within 1 mm of its station
    assert [w for w, _ in switches] == [int(pio[k]) for k in stations]
    gaps = [float(np.linalg.norm(x - pp[k, :3])) for (_, x), k in zip(switches, stations, strict=True)]
    assert max(gaps) <= 1e-3, max(gaps)
    assert out == 0


def test_whole_job_program_of_2000_gotos_through_urdriver_at_150x(make_sim, job, pieces):
    # the approach onto the start joints at the controller's own pace; fast-forward once the program runs
    # (URDriver reads the joints right after moveJ returns: at 150x its receive interface's latest data package
    # can be 0.3 s of motion old, and the approach is then refused as ending off the start joints)
    sim = make_sim(speed=1.0)

    def fast_forward(stage, done, total):
        if sim.speed != SPEED:
            sim.set_speed(SPEED)

    with URDriver(sim.host, "ur5e", **FAST) as d:
        rep = d.execute(job, mode="program", progress=fast_forward)
        assert d.state().safety_mode == 1
    assert rep.ok, rep.describe()
    # in the 5 programs a controller takes, one after the other, the arm at rest at each of the 4 seams
    assert rep.programs == len(pieces) == 5 and rep.program_bytes == MAX_PROGRAM_BYTES
    assert [sm.program for sm in rep.seams] == list(range(2, 6))
    assert [sm.line for sm in rep.seams] == [p.line for p in pieces[1:]]
    assert any(f"5 programs of at most {MAX_PROGRAM_BYTES} bytes" in line for line in rep.describe())
    assert rep.planned_duration > 3000.0
    # (each seam waits for the next program a few ms of wall time: at 150x, about a second of simulated time, more on
    # a loaded machine)
    waits = sum(sm.wait for sm in rep.seams)
    assert 0.0 < waits < 0.05 * rep.planned_duration, rep.describe()
    assert rep.duration == pytest.approx(rep.planned_duration + waits, rel=0.02)
    # every recorded TCP sample (one per ~0.3 s of job time at this speed) within the tolerance of the planned path
    assert rep.samples > 5000
    assert 0.0 < rep.max_path_error <= job.settings.tolerance, rep.describe()
    # (where each output switched is checked by the in-process run: at one sample per ~0.3 s the report cannot
    # place a switch of the 0.24 s rapids between passes)
    assert len(rep.io_events) == 2 * len(job.passes)
    st = sim.state()
    assert st["digital_out"] == 0
    assert st["safety_mode"] == "NORMAL"
    assert not [m for m in st["log"] if "Protective stop" in m[2] or "Runtime error" in m[2]], st["log"]
