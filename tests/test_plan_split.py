"""A job fitted in pieces (:func:`planner.plan.fit_batches`, :func:`planner.plan.fit_passes_of`, each piece's fits
through their bytes, as between machines) and planned with the fits given (``plan(fits=...)``) is the job planned in
one process: CSV, JSON and URScript byte for byte, the arm configurations chosen over the whole sequence alike."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

from planner import PlannerError, PlanSettings, plan
from planner.export import stream
from planner.job import fits_from_bytes, fits_to_bytes

P = importlib.import_module("planner.plan")  # (the package's name plan is the function)
DATA = Path(__file__).resolve().parent / "data"
APT = DATA / "solidworks_cam_apt_boss_excerpt.apt"


def _bytes(job, fmt: str) -> bytes:
    return b"".join(stream(job, fmt, parameters={"input": APT.name}))


@pytest.mark.parametrize("settings", [PlanSettings(passes=(0, 1, 2, 3, 4, 5, 6, 7, 8, 9)),
                                      PlanSettings(robot="ur5e", part_frame="auto", passes=(0, 1, 2, 3, 4, 5))],
                         ids=["no robot", "robot, placed"])
def test_a_job_fitted_in_pieces_is_the_job_planned_at_once(monkeypatch, settings):
    monkeypatch.setattr(P, "FIT_BATCH_SPANS", 3)  # small batches: several pieces in a short test
    batches = P.fit_batches(APT, settings)
    assert len(batches) >= 3 and batches[0][0] == 0
    assert all(a[1] == b[0] for a, b in zip(batches, batches[1:], strict=False))  # consecutive, whole
    whole = plan(APT, settings)
    assert batches[-1][1] == whole.summary()["passes"]
    fits = []
    for start, stop in batches:  # each piece as another machine makes it: fitted, sent as bytes, read back
        fits += fits_from_bytes(fits_to_bytes(P.fit_passes_of(APT, settings, start, stop)))
    joined = plan(APT, settings, fits=fits)
    for fmt in ("csv", "json") + (("script",) if settings.robot else ()):
        assert _bytes(joined, fmt) == _bytes(whole, fmt), fmt
    if settings.robot:
        assert [m.kind for m in joined.moves] == [m.kind for m in whole.moves]  # reconfigurations alike


def test_pieces_and_fits_that_do_not_belong_are_refused(monkeypatch):
    monkeypatch.setattr(P, "FIT_BATCH_SPANS", 3)
    settings = PlanSettings(passes=(0, 1, 2, 3))
    batches = P.fit_batches(APT, settings)
    start, stop = batches[0]
    with pytest.raises(PlannerError, match=r"are not whole fit batches of its \d+ passes"):
        P.fit_passes_of(APT, settings, start, stop + 1 if stop + 1 not in {b for r in batches for b in r} else 0)
    fits = [f for a, b in batches for f in P.fit_passes_of(APT, settings, a, b)]
    with pytest.raises(PlannerError, match=r"fits: \d+ given for \d+ cutting passes"):
        plan(APT, settings, fits=fits[:-1])
    with pytest.raises(PlannerError, match="fits: fit 0 is not of pass 0"):
        plan(APT, settings, fits=[fits[1], fits[0], *fits[2:]])
    with pytest.raises(PlannerError, match="the fits: the saved job is damaged: not a readable archive"):
        fits_from_bytes(b"PK\x03\x04 not a zip at all")
    with pytest.raises(PlannerError, match="the fits: .*FitChunk"):  # a whole job is not a chunk of fits
        fits_from_bytes(plan(APT, settings).to_bytes())
