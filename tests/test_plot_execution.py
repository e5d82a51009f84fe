"""The execution report drawn into the job's plot: the run's bounded trace (actual TCP path, speed, outputs) over
the plan, in the part frame; ``planner run --plot``. The runs are real (SimDriver's motion model in-process)."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.sim import SimDriver
from planner import PlanSettings, plan
from planner.errors import PlannerError
from planner.export.plot import _execution_view, _path_lines, digest, plot_job
from planner.wording import pose_option

DEMO = "examples/nx_first_pass.cls"
PART = (0.4, 0.9965, -0.1, 0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def run():
    job = plan(DEMO, PlanSettings(robot="ur5e", part_frame=PART, cut_output=("standard", 0), feed_override=4.0))
    with SimDriver() as d:
        rep = d.execute(job, mode="stream")
    assert rep.ok, "\n".join(rep.describe())
    return job, rep


def _distance_to(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Brute-force distance of points (m, 3) from the polyline path (n, 3)."""
    a, b = path[:-1], path[1:]
    d = b - a
    w = np.clip(np.einsum("mkj,kj->mk", points[:, None] - a[None], d) / np.einsum("kj,kj->k", d, d), 0, 1)
    return np.linalg.norm(points[:, None] - (a[None] + w[..., None] * d[None]), axis=2).min(axis=1)


def test_trace_is_bounded_and_keeps_every_output_change(run):
    job, rep = run
    tr = rep.trace
    assert 100 < len(tr) <= min(20_000, rep.samples)
    assert np.all(np.diff(tr.t) > 0)
    # every switch the report found is in the trace: the output changes there, exactly twice (on, off)
    change = np.flatnonzero(tr.io[1:] != tr.io[:-1]) + 1
    assert len(change) == 2 and [int(tr.io[i]) for i in change] == [1, 0]
    for e, i in zip(rep.io_events, change, strict=True):
        assert tr.t[i - 1] <= e.actual_t <= tr.t[i]
    # the speed is the actual TCP's: near the planned cut speed (4 x 0.05 / 12 m/s at 4x feed) in the cut's middle
    v_cut = float(np.median(tr.speed[(tr.io == 1)]))
    assert v_cut == pytest.approx(0.05 / 12 * 4, rel=0.05)


def test_view_puts_the_actual_path_on_the_planned_one_in_the_part_frame(run):
    job, rep = run
    dg = digest(job.trajectory(), max_points=5000)
    view = _execution_view(job, rep, dg)
    cuts, _ = _path_lines(job, per_segment=64)
    planned = np.vstack(cuts)  # part frame, mm
    io = view["io"]
    cutting = view["xyz"][io == 1]
    # while the output is on the tool is on the cut: within the report's path error (+ the PH segment sampling)
    d = _distance_to(cutting, planned)
    assert d.max() <= 1e3 * rep.max_path_error + 0.01
    # the switches are drawn at the actual TCP, within the report's distances of the planned stations (+ sampling)
    assert view["switch_xyz"].shape == (2, 3) and view["planned_xyz"].shape == (2, 3)
    gaps = np.linalg.norm(view["switch_xyz"] - view["planned_xyz"], axis=1)
    step_mm = 1e3 * 0.05 / 12 * 4 / 500 * dg.step  # the digest keeps 1 pose in dg.step
    for g, e in zip(gaps, rep.io_events, strict=True):
        assert g <= e.distance_mm + e.resolution_mm + step_mm + 1e-6
    assert "ok" in view["title"] and "2 of 2 switches made" in view["title"]


def test_plot_with_the_run_is_written_atomically(run, tmp_path):
    job, rep = run
    out = tmp_path / "run.png"
    plot_job(job, out, execution=rep, max_points=5000)
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["run.png"]  # no temporary file left
    from PIL import Image

    with Image.open(out) as im:  # taller than the plan's own picture: the outputs' panel below
        w, h = im.size
    plain = tmp_path / "plain.png"
    plot_job(job, plain, max_points=5000)
    with Image.open(plain) as im:
        assert h > im.size[1] and w == im.size[0]


def test_execution_without_a_trace_is_refused_by_name(run, tmp_path):
    job, rep = run

    class NoTrace:
        ok, mode, reason, io_events, max_path_error = True, "stream", "", (), 0.0

    with pytest.raises(PlannerError, match="trace"):
        plot_job(job, tmp_path / "x.png", execution=NoTrace(), max_points=1000)

    class Ragged(NoTrace):
        class trace:  # noqa: N801 - a stand-in attribute
            t = np.zeros(3)
            xyz = np.zeros((2, 3))
            speed = np.zeros(3)
            io = np.zeros(3, int)

    with pytest.raises(PlannerError, match="differ in length"):
        plot_job(job, tmp_path / "x.png", execution=Ragged(), max_points=1000)
    assert not (tmp_path / "x.png").exists()


def test_planner_run_plot_writes_the_run(tmp_path, capsys):
    from planner.frontends.cli.run import main

    out = tmp_path / "run.png"
    rc = main(["run", DEMO, "--robot", "ur5e", "--part-frame", pose_option(PART), "--cut-output",
               "standard:0", "--sim", "--mode", "program", "--sim-speed", "20", "--plot", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert f"wrote {out}" in text and out.read_bytes()[:4] == b"\x89PNG"
    assert main(["run", DEMO, "--robot", "ur5e", "--sim", "--plot", str(tmp_path / "x.gif")]) == 2
    assert "unknown image type" in capsys.readouterr().err


def test_a_job_with_nothing_to_show_of_its_frames_gets_a_wide_path_panel(tmp_path):
    """The demo job holds the tool axis constant: no frame panel (once an empty panel of text), the 3D panel takes
    the row and says why; a job whose axes turn keeps the frames' figure."""
    import matplotlib.figure

    from planner.export import plot as plot_module

    made = []
    real = plot_module.new_figure

    def keep(*args, **kwargs):
        fig = real(*args, **kwargs)
        made.append(fig)
        return fig

    flat = plan(DEMO, PlanSettings(robot="ur5e", part_frame=PART))
    turning = plan("../shared/data/nx_clsf_variable_contour_ust_a2.cls", PlanSettings())
    assert plot_module._frames_note(flat) == "tool axis constant along every pass: no spin"
    assert plot_module._frames_note(turning) is None
    plot_module.new_figure = keep
    try:
        plot_job(flat, tmp_path / "flat.png", max_points=2000)
        plot_job(turning, tmp_path / "turning.png", max_points=2000)
    finally:
        plot_module.new_figure = real
    flat_fig, turning_fig = made
    assert isinstance(flat_fig, matplotlib.figure.Figure)
    for fig in made:
        assert all(a.get_title() for a in fig.axes)  # no panel of text only
    # the flat job: path (the whole row: 3 of 3 grid columns), speed, joints, fit; no frames' figure
    assert flat_fig.axes[0].get_subplotspec().colspan == range(0, 3)
    assert "tool axis constant along every pass" in flat_fig.axes[0].get_title()
    assert not any(a.get_title().startswith("tool axes") for a in flat_fig.axes)
    # the turning job: path in 2 columns and the frames' figure beside it
    assert turning_fig.axes[0].get_subplotspec().colspan == range(0, 2)
    assert turning_fig.axes[1].get_title().startswith("tool axes: spin about them")
