"""planner.plan on each real CAM file (the CAM polyline model, the default for APT/CLSF and G-code): its verbatim
excerpt in tests/data (default suite, under a second) and the whole file of ../shared/data (about 40 s in all: marked
``slow``; skipped with that reason when shared/data is not next to the repository, as on a clean clone).
"""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest

from planner import PlanSettings, plan
from planner.io import read_toolpath
from tests.cam_excerpts import EXCERPTS
from tests.conftest import SHARED_DATA

WHOLE = [
    pytest.mark.slow,
    pytest.mark.skipif(not SHARED_DATA.is_dir(), reason=f"the shared CAM files are not at {SHARED_DATA}"),
]

FILES = {
    "nx_clsf_variable_contour_ust_a2.cls": {},
    "nx2022_haas_umc750_5axis_gcode.txt": {"machine": "haas-umc-750"},
    "solidworks_cam_apt_boss_3plus2.apt": {},
}


CASES = [pytest.param(e.path, FILES[e.source], 0, id=e.name) for e in EXCERPTS.values()] + [
    pytest.param(SHARED_DATA / name, kw, 100, id=name, marks=WHOLE) for name, kw in FILES.items()
]


@pytest.mark.parametrize("path, kw, more_passes_than", CASES)
def test_file_plans_within_tolerance(path, kw, more_passes_than):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tp = read_toolpath(path, **kw)
    job = plan(tp, PlanSettings(feed=0.01))  # the former CAM default feed, where the file gives none
    s = job.summary()
    assert s["path_model"] == "cam" and s["axes"] == ("file" if tp.axes is not None else "fixed")
    assert s["passes"] > more_passes_than and s["max_deviation_mm"] <= 0.01 and s["max_axis_error_deg"] < 0.05
    # at least one pass after every rapid that a cut follows (corners and axis jumps split more)
    assert s["passes"] >= int((tp.rapid[:-1] & ~tp.rapid[1:]).sum())
    # every rapid record of the file is a rapid move (the first one only positions the tool)
    assert s["rapids"] + s["skipped"] + s["reorientations"] >= int(tp.rapid[1:].sum())
    assert s["corners"] == sum(p.start_reason == "corner" for p in job.passes)
    # passes are in file order and never cross a rapid
    firsts = [p.first_line for p in job.passes]
    assert firsts == sorted(firsts)
    for m in job.moves:
        if m.kind == "cut":
            assert not job.toolpath.rapid[m.item.source_index[1:]].any()
    # the stream of the first moves is continuous and starts where the file starts
    chunks = list(itertools.islice(job.trajectory().chunks(), 6))
    poses = np.concatenate([c.poses for c in chunks])
    assert np.abs(poses[0, :3] - job.toolpath.points[0]).max() <= 1e-12
    assert np.linalg.norm(np.diff(poses[:, :3], axis=0), axis=1).max() <= 0.25 / 500.0 * (1 + 1e-6)
    text = "\n".join(job.describe())
    assert f"{s['passes']} passes" in text and "largest deviation" in text
