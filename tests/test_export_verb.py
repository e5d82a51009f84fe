"""The export verb (planner.export.verb): the one source of a job's exports. The CLI's files, the service's
downloads and the verb's bytes are the same bytes for the demo job; every format is written atomically by its
suffix; refusals are one line naming the file; the trajectory is streamed (the first piece is the header only)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from planner import PlannerError, PlanSettings, load_job, plan
from planner.export import (
    FORMATS,
    MAX_PROGRAM_BYTES,
    export,
    file_name,
    format_of,
    job_program,
    job_program_pieces,
    plot_title,
    stream,
    write,
)
from planner.frontends.cli.main import DEMO_PART_FRAME, EXAMPLE_CLS, example_path
from planner.frontends.cli.main import main as cli_main

DEMO = example_path(EXAMPLE_CLS)
DEMO_OPTIONS = ["--robot", "ur5e", "--cut-output", "standard:0", "--part-frame", DEMO_PART_FRAME]


@pytest.fixture(scope="module")
def demo_job():
    """The demo's job, planned as ``planner plan nx_first_pass.cls DEMO_OPTIONS`` plans it."""
    from planner.frontends.cli.main import build_parser
    from planner.frontends.cli.options import settings_from_args

    settings = settings_from_args(build_parser().parse_args(["plan", str(DEMO), *DEMO_OPTIONS]))
    return plan(DEMO, settings)


@pytest.fixture(scope="module")
def bare_job():
    """The demo pass planned without a robot (no program can be made of it)."""
    return plan(DEMO, PlanSettings())


def test_cli_files_service_downloads_and_the_verb_are_the_same_bytes(demo_job, tmp_path):
    """csv, json and script of the demo job: ``planner plan -o`` == ``GET .../trajectory?format=`` == export()."""
    from tests.test_service_jobs import cli_settings, submit_file
    from tests.test_service_server import ServiceProcess, wait_state

    params = {"input": DEMO.name}
    verb = {fmt: export(demo_job, fmt, parameters=params) for fmt in ("csv", "json", "script")}
    cli = {}
    for fmt in verb:
        target = tmp_path / f"cli.{fmt}"
        assert cli_main(["plan", str(DEMO), *DEMO_OPTIONS, "-o", str(target)]) == 0
        cli[fmt] = target.read_bytes()
    server = ServiceProcess(tmp_path / "service", workers=1).start()
    try:
        with server.client() as client:
            r = submit_file(client, DEMO, cli_settings(*DEMO_OPTIONS))
            assert r.status_code == 202, r.text
            view = wait_state(client, r.json()["id"])
            assert view["state"] == "done", view["error"]
            for fmt in verb:
                got = client.get(f"/v1/jobs/{view['id']}/trajectory", params={"format": fmt})
                assert got.status_code == 200, got.text
                assert got.headers["content-disposition"] == f'attachment; filename="{file_name(DEMO.name, fmt)}"'
                assert got.content == verb[fmt] == cli[fmt], (
                    f"{fmt}: service {len(got.content)}, verb {len(verb[fmt])}, CLI {len(cli[fmt])} bytes")
    finally:
        assert server.stop() == 0, server.log.read_text()
    assert verb["csv"].startswith(b"# generator: ") and b'# input: "nx_first_pass.cls"' in verb["csv"]
    assert verb["script"].startswith(b"def ") and b"movep(" in verb["script"]


def test_the_plot_is_the_clis_picture(demo_job, tmp_path):
    """``planner plan --plot x.png`` and export(job, "png") with the same input name: the same picture."""
    target = tmp_path / "cli.png"
    assert cli_main(["plan", str(DEMO), *DEMO_OPTIONS, "--plot", str(target)]) == 0
    assert export(demo_job, "png", parameters={"input": DEMO.name}) == target.read_bytes()
    title = plot_title(demo_job, DEMO.name)
    s = demo_job.summary()
    assert title.startswith("nx_first_pass.cls: 1 pass, ") and f"{s['duration_s']:.1f} s" in title


def test_write_picks_the_format_by_suffix(demo_job, tmp_path):
    """Every format written by its suffix holds export()'s bytes (a saved plan: one that loads to the same
    exports); pictures of each type carry their magic number."""
    params = {"input": DEMO.name}
    for name, detail in (("t.csv", "poses, with joints"), ("t.JSON", "poses, with joints"), ("t.urscript", "movep")):
        assert detail in write(demo_job, tmp_path / name, parameters=params)
        assert (tmp_path / name).read_bytes() == export(demo_job, format_of(name), parameters=params)
    assert write(demo_job, tmp_path / "t.job") == f"{(tmp_path / 't.job').stat().st_size} bytes"
    again = load_job(tmp_path / "t.job")
    assert export(again, "csv", parameters=params) == export(demo_job, "csv", parameters=params)
    assert load_job(export(demo_job, "job")).summary() == demo_job.summary()
    magic = {"png": b"\x89PNG\r\n", "svg": b"<?xml", "pdf": b"%PDF-"}
    for fmt, head in magic.items():
        assert export(demo_job, fmt).startswith(head)
        detail = write(demo_job, tmp_path / f"p.{fmt}")
        assert (tmp_path / f"p.{fmt}").read_bytes().startswith(head) and detail.startswith("speeds from all ")
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []  # no temporary file left
    assert set(FORMATS) == {format_of(f"x.{fmt}") for fmt in FORMATS}


def test_refusals_are_one_line_naming_the_file(bare_job, tmp_path):
    with pytest.raises(PlannerError, match=r"^notes\.txt: unknown output type '\.txt' \(use \.csv, "):
        format_of(tmp_path / "notes.txt")
    with pytest.raises(PlannerError, match=r"^format must be one of csv, json, script, png, svg, pdf, job, got 'xml'"):
        export(bare_job, "xml")
    with pytest.raises(PlannerError, match=r"^job must be a PlannedJob"):
        export(bare_job.trajectory(), "csv")
    with pytest.raises(PlannerError, match=r"^not writing nx_first_pass\.script: .*robot") as caught:
        stream(bare_job, "script")  # refused before a first byte is given
    assert "\n" not in str(caught.value)
    with pytest.raises(PlannerError, match=r"^not writing prog\.script: .*robot"):
        write(bare_job, tmp_path / "prog.script")
    assert not (tmp_path / "prog.script").exists() and os.listdir(tmp_path) == []
    with pytest.raises(PlannerError, match=r"^parameters: key 'samples' is reserved"):
        stream(bare_job, "csv", parameters={"samples": 1})


def test_the_trajectory_is_streamed_one_move_at_a_time(demo_job):
    """stream() gives the header first, before any chunk is read; then one piece per move; memory bounded by one
    move's samples (the service sends a whole NX job of 12.9 million poses this way)."""
    seen = []
    pieces = stream(demo_job, "csv", progress=lambda stage, done, total: seen.append(done))
    first = next(pieces)
    assert first.startswith(b"# generator: ") and first.endswith(b"\n")
    assert first.count(b"\n") == first.count(b"# ") + 1 and not seen  # header and column line only, nothing read
    rest = list(pieces)
    assert len(rest) == len(demo_job.trajectory().moves())
    assert sum(piece.count(b"\n") for piece in rest) == demo_job.trajectory().n_samples


def test_file_name_of_a_download():
    assert file_name("part.cls", "csv") == "part.csv"
    assert file_name("<waypoints>", "json") == "<waypoints>.json"
    assert file_name("", "json") == "job.json"
    assert Path(file_name("a.b.nc", "script")).suffix == ".script"


def test_a_program_larger_than_a_controller_takes_is_refused_naming_the_limit(demo_job, tmp_path):
    whole = export(demo_job, "script")  # the demo pass: one program well under the limit
    assert len(whole) < MAX_PROGRAM_BYTES
    size = len(whole)
    with pytest.raises(PlannerError) as caught:
        write(demo_job, tmp_path / "job.script", max_program_bytes=size - 1)
    text = str(caught.value)
    assert text.startswith(f"not writing job.script: the program is {size} bytes (")
    assert f"over the {size - 1} bytes a UR controller is known to take in one program" in text
    assert "planner run --mode program" in text and "--max-program-bytes" in text and "\n" not in text
    assert os.listdir(tmp_path) == []  # nothing written
    with pytest.raises(PlannerError, match=r"^not writing nx_first_pass\.script: the program is \d+ bytes"):
        stream(demo_job, "script", max_program_bytes=4096)  # refused before a first byte, as the service downloads
    assert export(demo_job, "script", max_program_bytes=size) == whole  # at the limit: written
    assert export(demo_job, "script", max_program_bytes=None) == whole  # no limit
    with pytest.raises(PlannerError, match=r"^max_program_bytes must be a number of bytes > 0 or None, got -1"):
        export(demo_job, "script", max_program_bytes=-1)
    # the command line: --max-program-bytes N, 0 for none
    out = tmp_path / "cli.script"
    assert cli_main(["plan", str(DEMO), *DEMO_OPTIONS, "-o", str(out), "--max-program-bytes", "4096"]) == 2
    assert not out.exists()
    assert cli_main(["plan", str(DEMO), *DEMO_OPTIONS, "-o", str(out), "--max-program-bytes", "0"]) == 0
    assert out.read_bytes().count(b"movep(") == whole.count(b"movep(")


def test_program_pieces_under_a_limit(demo_job):
    whole = job_program(demo_job)
    (one,) = job_program_pieces(demo_job)  # under the limit: the program itself, in one piece
    assert one.text == whole and one.size == len(whole.encode())
    # one pass alone needs more than a small limit: refused naming the pass, its lines, the size and the limit
    with pytest.raises(PlannerError, match=r"pass 0 \(lines \d+-\d+\) alone needs a program of \d+ bytes, over the "
                                           r"limit of 8000 bytes per program"):
        job_program_pieces(demo_job, max_bytes=8000)
    with pytest.raises(PlannerError, match=r"max_bytes must be at least 4096 bytes, got 100"):
        job_program_pieces(demo_job, max_bytes=100)


def test_passes_joined_at_a_corner_are_cut_at_the_corner_only_when_they_need_two_programs(tmp_path):
    """Two passes joined at a 90-degree corner (the cut output on through it): one program under the limit; over
    it, two programs cut at the corner, where the arm is at rest; the output stays on through the seam (the second
    program sets it on again first). Run piece after piece by the simulated controller's core."""
    import numpy as np

    from sim.core import Core
    from sim.io_state import IOState

    t = np.linspace(0.0, 1.0, 200)
    a = np.c_[0.1 * t, 0.005 * np.sin(6 * np.pi * t), 0 * t]
    b = np.c_[0.1 + 0.005 * np.sin(6 * np.pi * t[1:]), -0.1 * t[1:], 0 * t[1:]]
    src = tmp_path / "corner.csv"
    src.write_text("x,y,z\n" + "\n".join(f"{x * 1e3:.4f},{y * 1e3:.4f},{z * 1e3:.4f}" for x, y, z in np.vstack((a, b))))
    job = plan(src, PlanSettings(path="cam", feed=0.02, robot="ur5e", part_frame=(0.4, -0.1, 0.2, 0, 0, 0),
                                 cut_output=("standard", 0)))
    assert [m.kind for m in job.moves] == ["cut", "cut"]
    whole = job_program(job)
    (one,) = job_program_pieces(job, max_bytes=len(whole))
    assert one.text == whole
    first, second = job_program_pieces(job, max_bytes=len(whole) - 1)
    assert (first.passes, second.passes) == ((0,), (1,)) and max(first.size, second.size) < len(whole)
    assert first.text.count("set_standard_digital_out(0, True)") == 1 and "(0, False)" not in first.text
    assert second.text.count("set_standard_digital_out(0, True)") == 1  # set on again, first
    assert second.text.count("set_standard_digital_out(0, False)") == 1
    core = Core("ur5e", IOState())
    core.motion.q = np.array(job.start_joints, dtype=float)
    assert core.load_program(first.text)
    while core.program is not None:
        core.tick()
    assert np.abs(core.motion.qd).max() < 1e-12 and core.io.digital_out & 1  # at rest on the corner, the output on
    np.testing.assert_allclose(core.tcp_pose()[:3], second.start[:3], atol=1e-6)
    assert core.load_program(second.text)
    bits = [core.io.digital_out & 1]
    while core.program is not None:
        core.tick()
        bits.append(core.io.digital_out & 1)
    assert np.count_nonzero(np.diff(bits)) == 1 and bits[-1] == 0  # on through the second pass, off at its end
    assert core.safety_mode == 1
    # one pass alone over the limit: a seam in it would stop the tool in the cut: refused, naming the pass
    with pytest.raises(PlannerError, match=r"corner\.csv: pass 0 \(lines 2-201\) alone needs a program of \d+ bytes, "
                                           r"over the limit of 30000 bytes per program"):
        job_program_pieces(job, max_bytes=30000)
