"""The public names of version 0.1.0 (commit 5839d4a, in its README or its packages' ``__all__``) that the one planning
pipeline replaced: each still imports, warns with a DeprecationWarning naming its replacement, and works like it."""

from __future__ import annotations

import importlib
import math

import numpy as np
import pytest

import planner
from planner import PlannedJob, PlanSettings, plan
from planner._deprecated import REMOVED
from planner.export import trajectory_parameters, write_csv, write_json
from planner.trajectory import sample_counts
from tests.conftest import EXCERPT_DATA

SIDE_DRILL = EXCERPT_DATA / "solidworks_cam_apt_side_drill.apt"
ALL = [(module, name) for module, names in REMOVED.items() for name in names]


def old(module: str, name: str):
    """``from module import name`` as the old code wrote it, with the warning it gives (a class warns here)."""
    return getattr(importlib.import_module(module), name)


@pytest.fixture(scope="module")
def cam_job():
    return plan(SIDE_DRILL, PlanSettings(path="cam", feed=0.01))


@pytest.fixture(scope="module")
def robot_job():
    line = np.array([[0.40, 0.0, 0.20], [0.45, 0.02, 0.20], [0.50, 0.0, 0.20]])
    return plan(line, PlanSettings(robot="ur5e", part_frame=(0.0, 0.0, 0.0, math.pi, 0.0, 0.0), rate=125.0))


@pytest.mark.parametrize("module, name", ALL)
def test_every_removed_name_imports_and_warns_naming_its_replacement(module, name):
    replacement = REMOVED[module][name][0]
    with pytest.warns(DeprecationWarning) as rec:
        obj = old(module, name)
        if not isinstance(obj, type):
            with pytest.raises(Exception):  # noqa: B017 - any refusal of no arguments: the call is what warns
                obj()
    (w,) = [r for r in rec if r.category is DeprecationWarning]
    assert str(w.message).startswith(f"{module}.{name} is deprecated") and f"use {replacement}" in str(w.message)
    assert w.filename == __file__  # the warning points at the user's line
    assert not callable(obj) or isinstance(obj, type) or obj.__name__ == name  # a constant, a class or a function


def test_unknown_names_stay_unknown():
    import planner.cam

    with pytest.raises(AttributeError, match="'planner.cam' has no attribute 'nope'"):
        planner.cam.nope  # noqa: B018
    with pytest.raises(ImportError):
        from planner.export import servoj_program  # noqa: F401


def test_plan_cam_job_is_plan_with_path_cam_and_the_old_default_feed(cam_job):
    with pytest.warns(DeprecationWarning, match=r"planner\.plan\(toolpath, planner\.PlanSettings\(path='cam'"):
        job = old("planner.cam", "plan_cam_job")(SIDE_DRILL, tolerance=1e-5, corner_deg=60.0)
    assert isinstance(job, PlannedJob) and job.settings.path == "cam" and job.settings.feed == 0.01
    assert job.summary() | {"planning_s": 0} == cam_job.summary() | {"planning_s": 0}
    with pytest.warns(DeprecationWarning), pytest.raises(planner.PlannerError, match="tolerance"):
        old("planner.cam", "plan_cam_job")(SIDE_DRILL, tolerance=-1.0)


def test_the_classes_are_their_replacements(cam_job):
    from planner.job import PassReport, PlannedMove
    from planner.trajectory import Chunk

    with pytest.warns(DeprecationWarning):
        assert old("planner.cam", "CamJob") is PlannedJob and old("planner.cam", "CamSettings") is PlanSettings
        assert old("planner.cam", "PassReport") is PassReport and old("planner.cam", "PlannedMove") is PlannedMove
        assert old("planner.cam", "StreamChunk") is Chunk and old("planner.cam.stream", "JobStream") is Chunk
    assert isinstance(cam_job.passes[0], PassReport) and isinstance(cam_job.moves[0], PlannedMove)


def test_the_export_wrappers_write_what_their_replacements_write(cam_job, tmp_path):
    for form, new in (("csv", write_csv), ("json", write_json)):
        with pytest.warns(DeprecationWarning, match=f"planner.export.write_{form}"):
            n_old = old("planner.export.job_tables", f"write_job_{form}")(cam_job, None, tmp_path / f"a.{form}", rate=50)
        with pytest.warns(DeprecationWarning):
            n_pkg = old("planner.export", f"write_job_{form}")(cam_job, None, tmp_path / f"b.{form}", rate=50)
        n_new = new(cam_job.trajectory(50), tmp_path / f"c.{form}")
        assert n_old == n_pkg == n_new == cam_job.n_samples(50) > 100
        body = [(tmp_path / f"{k}.{form}").read_text().replace('"generator"', "") for k in "abc"]
        assert body[0] == body[1] == body[2]
    with pytest.warns(DeprecationWarning, match="trajectory_parameters"):
        params = old("planner.export", "cam_job_parameters")(cam_job, 50, {"input": "x"})
    assert params == trajectory_parameters(cam_job.trajectory(50), {"input": "x"})


def test_the_stream_functions_give_the_trajectory(cam_job, robot_job):
    traj = cam_job.trajectory(50)
    with pytest.warns(DeprecationWarning):
        chunks = list(old("planner.cam.stream", "iter_stream")(cam_job, 50))
        whole = old("planner.cam.stream", "collect")(cam_job, 50)
        thin = old("planner.cam.stream", "thin_chunk")(whole, 7, 3)
        counts = old("planner.cam.stream", "sample_counts")(cam_job.moves, 50.0)
    new = list(traj.chunks(joints=False))
    assert len(chunks) == len(new) and all(np.array_equal(a.poses, b.poses) for a, b in zip(chunks, new, strict=True))
    assert np.array_equal(whole.poses, np.concatenate([c.poses for c in new]))
    assert np.array_equal(thin.times, whole.every(7, 3).times) and len(whole) > len(thin) > len(whole) // 8
    assert np.array_equal(counts, sample_counts(cam_job.moves, 50.0)) and len(whole) > 100
    with pytest.warns(DeprecationWarning, match="track_joints"):
        tracked = list(old("planner.cam.stream", "track_joints")(robot_job, robot_job.trajectory().chunks(joints=False)))
    joints = np.concatenate([c.joints for c in tracked])
    expect = np.concatenate([c.joints for c in robot_job.trajectory().chunks(joints=True)])
    assert joints.shape[1] == 6 and np.allclose(joints, expect, rtol=0, atol=1e-12)


def test_the_rotation_functions_of_planner_motion_are_those_of_planner_rotations():
    from planner import rotations

    rng = np.random.default_rng(24)
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    with pytest.warns(DeprecationWarning, match="planner.rotations"):
        R = old("planner.motion", "quaternion_to_matrix")(q)
        back = old("planner.motion", "matrix_to_quaternion")(R)
        r = old("planner.motion", "quaternion_to_rotvec")(q)
        angle = old("planner.motion", "rotation_angle")(R, R[::-1])
    assert np.array_equal(R, rotations.quaternion_to_matrix(q)) and np.array_equal(back, rotations.matrix_to_quaternion(R))
    assert np.allclose(np.abs(np.einsum("ij,ij->i", back, q)), 1.0, rtol=0, atol=1e-12)  # the same rotations
    assert np.array_equal(r, rotations.quaternion_to_rotvec(q))
    assert np.array_equal(angle, rotations.rotation_angle(R, R[::-1]))


def test_plot_cam_job_is_plot_job(cam_job, tmp_path):
    with pytest.warns(DeprecationWarning, match=r"planner\.plot\.plot_job"):
        old("planner.plot_cam", "plot_cam_job")(cam_job, tmp_path / "job.png", max_points=2000)
    assert (tmp_path / "job.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
