"""The 3D view's data (planner.frontends.service.view_data) without a browser: the fine path the planning task stores
(poses thinned first, joints solved only at the kept samples) is within its tolerance of the planner's own
trajectory at every sample, TCP and joints; reachability changes are kept exactly; the stored bytes read back and
refuse what is not theirs."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from planner import PlannerError, PlanSettings, plan
from planner.frontends.service import view_data

ROOT = Path(__file__).resolve().parents[1]
DEMO = {"robot": "ur5e", "part_frame": [0.4, 0.9965, -0.1, 0.0, 0.0, 0.0], "cut_output": ["standard", 0]}


@pytest.fixture(scope="module")
def demo():
    job = plan(ROOT / "examples" / "nx_first_pass.cls", PlanSettings.from_dict(DEMO))
    return job, job.trajectory().collect(), view_data.fine_path(job)


def interpolated(path: view_data.ViewPath, times: np.ndarray, values: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(times, path.t, values[:, k]) for k in range(values.shape[1])])


def test_the_fine_path_is_within_its_tolerance_of_every_planned_sample(demo):
    job, traj, fine = demo
    reach = view_data._reach(job)
    assert len(fine) < 0.05 * traj.times.size  # a few per cent of the poses (368 of 30,946)
    tcp = interpolated(fine, traj.times, fine.xyz)
    assert np.linalg.norm(tcp - traj.poses[:, :3], axis=1).max() < view_data.FINE_TOLERANCE + 1e-6  # float32
    q = interpolated(fine, traj.times, fine.q)
    assert np.abs(q - traj.joints).max() * reach < view_data.FINE_TOLERANCE + 1e-6
    assert np.array_equal(fine.io, traj.io[np.searchsorted(traj.times, fine.t)])
    for tolerance in (1e-4, 1e-3):  # a request's coarser path: within its tolerance too
        part = view_data.window(fine, tolerance, reach=reach)
        q = interpolated(part, traj.times, part.q)
        assert np.abs(q - traj.joints).max() * reach < tolerance + view_data.FINE_TOLERANCE + 1e-6
        assert len(part) < len(fine)


def test_an_unreachable_stretch_begins_between_two_kept_neighbours():
    x = np.linspace(0.3, 1.2, 10)  # a line that leaves the UR5e's reach (0.85 m) part way
    job = plan(np.c_[x, 0.15 + 0.02 * np.sin(6 * x), np.full_like(x, 0.2)],
               PlanSettings(robot="ur5e", feed=0.1, part_frame=(0, 0, 0, 0, 0, 0)))
    traj = job.trajectory().collect()
    bad = ~np.isfinite(traj.joints).all(axis=1)
    edges = np.flatnonzero(np.diff(bad.astype(np.int8)))
    assert edges.size == 1 and 0.1 < bad.mean() < 0.9
    fine = view_data.fine_path(job)
    k = np.searchsorted(traj.times, fine.t)
    assert np.array_equal(~np.isfinite(fine.q).all(axis=1), bad[k])  # NaN exactly where the planner has none
    assert {edges[0], edges[0] + 1} <= set(k.tolist())  # the last reachable sample and the first unreachable
    ok = ~bad
    q = interpolated(fine, traj.times[ok], np.nan_to_num(fine.q))
    reach = view_data._reach(job)
    assert np.abs(q - traj.joints[ok]).max() * reach < view_data.FINE_TOLERANCE + 1e-6
    assert any(p["kind"] == "no-ik" for p in view_data.problems(job, fine))


def test_the_stored_fine_path_reads_back_and_refuses_other_bytes(demo):
    _, _, fine = demo
    back = view_data.ViewPath.from_bytes(fine.to_bytes())
    for name in view_data.FIELDS:
        stored = np.asarray(getattr(fine, name), dtype=view_data.STORED[name])  # float32 but the times
        assert np.array_equal(getattr(back, name), stored, equal_nan=True), name
    with pytest.raises(PlannerError, match=r"^the stored view data cannot be read: ") as e:
        view_data.ViewPath.from_bytes(b"PK\x03\x04 not a zip")
    assert "\n" not in str(e.value)
    other = io.BytesIO()
    np.savez(other, format=np.array("planner-view 99"), t=fine.t)
    with pytest.raises(PlannerError, match=r"^stored view data of format 'planner-view 99'; this version reads "):
        view_data.ViewPath.from_bytes(other.getvalue())


def test_the_planning_task_makes_a_large_jobs_view_data_and_leaves_a_small_ones_to_its_first_request(monkeypatch):
    """plan_job stores the fine path with the plan above VIEW_AT_PLAN_POSES poses (its first view would wait for
    it), and nothing below (its first view request makes it in milliseconds; a job never viewed pays nothing)."""
    import json

    from planner.frontends.service.tasks import functions

    spec = functions.PlanSpec("v", "waypoints", "", {"feed": 0.01},
                              input_json=json.dumps({"waypoints": [[0, 0, 0], [0.1, 0.02, 0], [0.2, 0, 0.01]]}))
    stages: list[str] = []
    small = functions.plan_job(spec, lambda p: stages.append(p.stage))
    assert small.state == "done" and small.files == {} and "view" not in stages
    poses = json.loads(small.values["summary"])["duration_s"] * 500.0
    assert 5_000 < poses < functions.VIEW_AT_PLAN_POSES
    monkeypatch.setattr(functions, "VIEW_AT_PLAN_POSES", poses / 2)  # the same job counted as a large one
    stages.clear()
    large = functions.plan_job(spec, lambda p: stages.append(p.stage))
    assert large.state == "done" and set(large.files) == {"view"} and stages[-1] == "view"
    fine = view_data.ViewPath.from_bytes(large.files["view"])
    assert 2 < fine.t.size < poses / 10 and fine.t[0] == 0.0
    same = [{k: v for k, v in json.loads(o.values["summary"]).items() if k != "planning_s"} for o in (small, large)]
    assert same[0] == same[1]  # the same plan
