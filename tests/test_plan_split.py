"""A job fitted in pieces (:func:`planner.plan.fit_batches`, :func:`planner.plan.fit_passes_of`, each piece's fits
through their bytes, as between machines) and planned with the fits given (``plan(fits=...)``) is the job planned in
one process: CSV, JSON and URScript byte for byte, the arm configurations chosen over the whole sequence alike."""

from __future__ import annotations

import importlib
import json
from pathlib import Path

import numpy as np
import pytest

from planner import PlannerError, PlanSettings, plan
from planner.export import stream
from planner.job import fits_from_bytes, fits_to_bytes, piece_from_bytes, piece_to_bytes

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


# -- the moves planned in pieces too (plan_piece), joined by plan(pieces=...) ------------------------------------------
NX = DATA / "nx_clsf_ust_a2_excerpt.cls"
NX_PASSES = tuple(range(3, 15))


def _summary(job) -> dict:
    """The summary's figures but its timings (wall times), as JSON text (NaN equal to NaN)."""
    return json.dumps({k: v for k, v in job.summary().items() if k != "planning_s"},
                      sort_keys=True, default=str)


@pytest.mark.parametrize(("source", "settings", "spans"), [
    (NX, PlanSettings(passes=NX_PASSES), 60),  # tool axes from the file: each pass's frames from the move before
    (NX, PlanSettings(axes="path", frame="rmf", passes=NX_PASSES), 60),  # the tool normal to the path
    (APT, PlanSettings(passes=tuple(range(10))), 4),  # the CAM default axis
    (APT, PlanSettings(robot="ur5e", part_frame="auto", passes=(0, 1, 2, 3, 4, 5)), 4),
], ids=["nx file axes", "nx axes path", "apt", "apt robot placed"])
def test_a_job_planned_in_pieces_is_the_job_planned_at_once(monkeypatch, source, settings, spans):
    monkeypatch.setattr(P, "FIT_BATCH_SPANS", spans)  # small batches: several pieces in a short test
    whole = plan(source, settings)
    parts = P.plan_pieces(source, settings, 3)  # balanced, each piece ending where its chords say (not a fit batch)
    assert len(parts) == 3 and parts[0][0] == 0 and parts[-1][1] == whole.summary()["passes"]
    assert all(a[1] == b[0] for a, b in zip(parts, parts[1:], strict=False))
    assert {b for _, b, *_ in parts[:-1]} - {b for _, b in P.fit_batches(source, settings)}  # not only batch bounds
    pieces = [P.plan_piece(source, settings, a, b) for a, b, *_ in parts]
    sent = [piece_from_bytes(piece_to_bytes(p)) for p in pieces]  # as between machines
    assert [p.first for p in sent] == [0, pieces[0].stop, pieces[1].stop]
    assert sent[-1].stop == len(whole.moves) - len(whole.reconfigurations)
    joined = plan(source, settings, pieces=sent)
    for fmt in ("csv", "json") + (("script",) if settings.robot else ()):
        assert _bytes(joined, fmt) == _bytes(whole, fmt), fmt
    assert _summary(joined) == _summary(whole)
    assert joined.warnings == whole.warnings
    assert [m.kind for m in joined.moves] == [m.kind for m in whole.moves]
    for a, b in zip(joined.moves, whole.moves, strict=True):  # every frame bit for bit, not only the exported ones
        assert np.array_equal(a.start_frame, b.start_frame) and np.array_equal(a.end_frame, b.end_frame)


def test_pieces_that_do_not_belong_are_refused(monkeypatch):
    settings = PlanSettings(passes=NX_PASSES)
    pieces = [P.plan_piece(NX, settings, a, b) for a, b, *_ in P.plan_pieces(NX, settings, 3)]
    with pytest.raises(PlannerError, match="pieces: piece 0 was planned with other settings than these"):
        plan(NX, PlanSettings(passes=NX_PASSES, feed=0.01), pieces=pieces)
    with pytest.raises(PlannerError, match="piece 1 starts at move"):
        plan(NX, settings, pieces=[pieces[0], *pieces[2:]])
    with pytest.raises(PlannerError, match=r"they end at move \d+ of the job's \d+"):
        plan(NX, settings, pieces=pieces[:-1])
    with pytest.raises(PlannerError, match="fits and pieces: .* not both"):
        plan(NX, settings, pieces=pieces, fits=[])
    with pytest.raises(PlannerError, match="expected planned pieces"):
        plan(NX, settings, pieces=[])
    sel = PlanSettings(passes=NX_PASSES[1:])
    other = P.plan_piece(NX, sel, *P.plan_pieces(NX, sel, 3)[0][:2])  # a piece of another job of the same file
    with pytest.raises(PlannerError, match="pieces: piece 0 was planned with other settings"):
        plan(NX, settings, pieces=[other, *pieces[1:]])
    with pytest.raises(PlannerError, match=r"passes 2..1 are not a range of its 12 passes"):
        P.plan_piece(NX, settings, 2, 2)
    with pytest.raises(PlannerError, match=r"passes 0..12 are not a range of its 12 passes"):
        P.plan_piece(NX, settings, 0, 13)
    with pytest.raises(PlannerError, match="start, stop: must be whole pass numbers"):
        P.plan_piece(NX, settings, 0.5, 2)
    a, b, *_ = P.plan_pieces(NX, settings, 3)[0]
    got = P.plan_piece(NX, settings, np.int64(a), np.int64(b))  # numpy's integers are pass numbers too
    assert (got.first, got.stop) == (pieces[0].first, pieces[0].stop)
    with pytest.raises(PlannerError, match="n: must be a whole number of pieces >= 1, got 0"):
        P.plan_pieces(NX, settings, 0)
    with pytest.raises(PlannerError, match="the piece: .*PlannedPiece"):  # a whole job is not a piece
        piece_from_bytes(plan(APT, PlanSettings(passes=(0,))).to_bytes())


def test_pieces_are_balanced_for_their_chain():
    cost = np.full(100, 10.0)
    assert P.balanced_pieces(cost, np.zeros(100), 2) == [(0, 50), (50, 100)]
    parts = P.balanced_pieces(cost, np.full(100, 2.0), 2)  # the second piece chains the first's frames: fewer passes
    largest = max(10.0 * (b - a) + 2.0 * a for a, b in parts)
    assert parts[0][1] in (55, 56) and largest == 560  # the least largest cost (55: 550 and 560; 56: 560 and 552)
    cost[:50] = 1.0  # cheap passes first (a constant tool axis): the first piece takes more of them
    assert P.balanced_pieces(cost, np.zeros(100), 2)[0][1] in (72, 73)  # 270 and 280, or 280 and 270
    assert P.balanced_pieces(np.array([5.0, 7.0]), np.zeros(2), 4) == [(0, 1), (1, 2)]  # no more pieces than passes
    assert P.balanced_pieces(np.array([5.0, 7.0, 9.0]), np.ones(3), 1) == [(0, 3)]


def test_dwells_that_start_a_piece_hold_the_frame_the_piece_before_ended_in(tmp_path):
    from tests.test_cam_dwell import APT_DWELL

    drill = tmp_path / "drill.apt"
    drill.write_text(APT_DWELL)
    whole = plan(drill)
    parts = P.plan_pieces(drill, None, 3)
    pieces = [piece_from_bytes(piece_to_bytes(P.plan_piece(drill, None, a, b))) for a, b, *_ in parts]
    assert len(pieces) == 3 and all(p.moves[0].kind == "dwell" for p in pieces[1:])  # (a drilled hole's dwell)
    joined = plan(drill, pieces=pieces)
    for fmt in ("csv", "json"):
        assert _bytes(joined, fmt) == _bytes(whole, fmt), fmt
    assert _summary(joined) == _summary(whole)
