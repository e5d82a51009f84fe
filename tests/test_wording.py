"""planner.wording: counts with their nouns in the reports."""

from __future__ import annotations

import pytest

from planner.wording import counted


@pytest.mark.parametrize("n, noun, plural, text", [
    (1, "pass", None, "1 pass"), (2, "pass", None, "2 passes"), (0, "rapid", None, "0 rapids"),
    (1, "rapid", None, "1 rapid"), (3, "axis", "axes", "3 axes"), (1, "axis", "axes", "1 axis"),
    (5, "switch", None, "5 switches"),
])
def test_counted(n, noun, plural, text):
    assert counted(n, noun, plural) == text


def test_a_one_pass_job_reads_in_the_singular():
    from planner import plan

    line = plan("examples/nx_first_pass.cls").describe()[0]
    assert line.startswith("nx_first_pass.cls: 37 points -> 1 pass, 1 rapid, 0 reorientations, 0 skipped; 0 corners")
