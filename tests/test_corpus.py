"""The regression corpus (tests/corpus.py, tests/data/corpus.json): every real CAM file and waypoint set the project
has planned must plan again, each frozen figure within its tolerance; a failure names the file and the figure.

The whole CAM files of ../shared/data are ``slow`` and skipped with a reason where that folder is absent (a clean
clone without it); their excerpts in tests/data run in every suite.
"""

from __future__ import annotations

import copy

import pytest

from tests import corpus

CASES = corpus.load_cases()


def _param(case: dict):
    marks = []
    if case["input"].startswith("shared:"):
        path = corpus.input_path(case["input"])
        marks = [pytest.mark.slow,
                 pytest.mark.skipif(not path.is_file(), reason=f"{path} is not here (the whole shared CAM files)")]
    return pytest.param(case, id=case["id"], marks=marks)


@pytest.mark.parametrize("case", [_param(c) for c in CASES])
def test_case_plans_with_its_frozen_figures(case):
    assert "figures" in case, f"{case['id']}: not frozen (python -m tests.corpus --update {case['id']})"
    problems = corpus.compare(case, corpus._jsonable(corpus.figures(case)))
    assert not problems, "\n".join(problems)


def test_every_case_names_an_input_and_unique_id():
    ids = [c["id"] for c in CASES]
    assert len(ids) == len(set(ids))
    for c in CASES:
        assert c["kind"] in ("plan", "fit")
        if not c["input"].startswith("shared:"):
            assert corpus.input_path(c["input"]).is_file(), c["input"]
        for name, value in c.get("figures", {}).items():
            kinds = value.keys() if isinstance(value, dict) else [name]
            assert all(k in corpus.FIGURE_KINDS for k in kinds), (c["id"], name)


def test_a_moved_figure_fails_naming_file_and_figure():
    case = next(c for c in CASES if c["id"] == "demo")
    now = copy.deepcopy(case["figures"])
    now["passes"] += 1
    now["cut_length_mm"] *= 1 + 1e-6
    now["first_pose"][0] += 1e-6
    now["max_deviation_mm"] += 0.5e-6  # within its tolerance (1e-6 mm)
    problems = corpus.compare(case, now)
    assert len(problems) == 3
    assert all(p.startswith("demo (examples/nx_first_pass.cls): ") for p in problems)
    assert {p.split(": ")[1].split(" =")[0] for p in problems} == {"passes", "cut_length_mm", "first_pose"}
    del now["samples"]
    assert any("samples is no longer measured" in p for p in corpus.compare(case, now))


def test_a_fit_case_compares_each_method():
    case = next(c for c in CASES if c["kind"] == "fit")
    now = copy.deepcopy(case["figures"])
    now["C2"]["length"] = float("nan")
    assert corpus.compare(case, now) == [
        f"{case['id']} ({case['input']}): C2.length = nan, frozen {case['figures']['C2']['length']!r} "
        "(tolerance rel 1e-09)"]
