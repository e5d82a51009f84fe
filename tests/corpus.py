"""The regression corpus: every real CAM file and waypoint set the project has planned, with its figures frozen.

``tests/data/corpus.json`` holds one case per input and way of planning it (``plan`` with given settings, or ``fit``
with the spline methods), and the figures the current code gave when the case was frozen: counts (passes, moves,
rapids, corners, ...), lengths, deviations, the duration, the first and last poses, and for the small inputs the
SHA-256 of the exports' data rows (CSV, URScript). ``tests/test_corpus.py`` plans every case again and compares,
each figure within the tolerance of its kind (:data:`TOLERANCES`); a failure names the case's file and the figure.

A figure that moves on purpose is frozen again in the same commit, with the reason in the commit message::

    .venv/bin/python -m tests.corpus --update                # every case
    .venv/bin/python -m tests.corpus --update reversal_aba   # the cases named
    .venv/bin/python -m tests.corpus                         # compare only: what moved, per case and figure

Inputs are named relative to the repository (``examples/...``, ``tests/data/...``) or, for the whole CAM files that
are not in the repository, as ``shared:<name>`` (``../shared/data``; those cases are ``slow`` and need that folder).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import re
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
CORPUS_FILE = REPO / "tests" / "data" / "corpus.json"
SHARED_DATA = REPO.parent / "shared" / "data"

#: How far a figure may move before the corpus fails, by kind: ``("exact",)``, ``("rel", r)`` relative,
#: ``("abs", a)`` absolute in the figure's own unit (mm, s, deg, m, rad).
TOLERANCES: dict[str, tuple] = {
    "count": ("exact",),
    "hash": ("exact",),
    "flag": ("exact",),
    "length_mm": ("rel", 1e-9),
    "duration_s": ("rel", 1e-9),
    "deviation_mm": ("abs", 1e-6),
    "angle_deg": ("abs", 1e-6),
    "pose": ("abs", 1e-9),
}

#: The kind of every figure a case can have (a figure not listed here is refused when freezing).
FIGURE_KINDS: dict[str, str] = {
    "points": "count", "passes": "count", "moves": "count", "rapids": "count", "reorientations": "count",
    "skipped": "count", "dwells": "count", "corners": "count", "knots_added": "count", "samples": "count",
    "problems": "count", "slowed_passes": "count", "reconfigurations": "count",
    "reachable": "flag",
    "cut_length_mm": "length_mm", "duration_s": "duration_s", "dwell_s": "duration_s",
    "max_deviation_mm": "deviation_mm", "max_waypoint_error_mm": "deviation_mm",
    "max_twist_vs_exact_rmf_deg": "angle_deg", "max_axis_error_deg": "angle_deg", "spin_deg": "angle_deg",
    "first_pose": "pose", "last_pose": "pose",
    "csv_rows_sha256": "hash", "script_sha256": "hash",
    # fit cases: one entry per method
    "length": "length_mm", "waypoint_error_mm": "deviation_mm", "segments": "count",
}


def input_path(name: str) -> Path:
    """The file a case reads: ``shared:<name>`` in ../shared/data, anything else relative to the repository."""
    if name.startswith("shared:"):
        return SHARED_DATA / name.removeprefix("shared:")
    return REPO / name


def load_cases(path: Path = CORPUS_FILE) -> list[dict]:
    """The cases of the corpus file, in order."""
    data = json.loads(path.read_text(encoding="utf-8"))
    if data.get("format") != "planner-corpus/1":
        raise ValueError(f"{path}: not a corpus file of format planner-corpus/1")
    return data["cases"]


def _settings(case: dict):
    from planner import PlanSettings

    kw = dict(case.get("settings", {}))
    for key in ("part_frame", "tcp", "cut_output", "passes"):
        if isinstance(kw.get(key), list):
            kw[key] = tuple(kw[key])
    return PlanSettings(**kw)


def _data_rows_sha256(text: str, comment: str) -> str:
    """SHA-256 of an export's lines that are not its comment header (the header names the version)."""
    rows = [line for line in text.splitlines() if not line.lstrip().startswith(comment)]  # URScript: indented
    return hashlib.sha256("\n".join(rows).encode()).hexdigest()


def plan_figures(case: dict) -> dict:
    """Plan a case as its settings say and measure it (figures in mm, s, deg; poses in m, rad)."""
    from planner import plan
    from planner.export import job_program, write_csv

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        job = plan(input_path(case["input"]), _settings(case), read_options=case.get("read") or None)
    s = job.summary()
    out = {k: s[k] for k in ("points", "passes", "rapids", "reorientations", "skipped", "dwells", "corners",
                             "knots_added", "cut_length_mm", "duration_s", "dwell_s", "max_deviation_mm",
                             "max_waypoint_error_mm", "max_twist_vs_exact_rmf_deg", "max_axis_error_deg",
                             "spin_deg")}
    out["moves"] = len(job.moves)
    tr = job.trajectory()
    out["samples"] = tr.n_samples
    if job.settings.robot is not None:
        out["reachable"] = bool(s["reachable"])
        out["problems"] = len(job.problems)
        out["slowed_passes"] = len(s["slowed_passes"])
        out["reconfigurations"] = len(s["reconfigurations"])
    first = last = None
    for chunk in tr.chunks(joints=False):
        if first is None:
            first = chunk.poses[0]
        last = chunk.poses[-1]
    out["first_pose"] = [float(x) for x in first] if first is not None else None
    out["last_pose"] = [float(x) for x in last] if last is not None else None
    exports = case.get("exports", [])
    if exports:
        with tempfile.TemporaryDirectory() as tmp:
            if "csv" in exports:
                target = Path(tmp) / "job.csv"
                write_csv(tr, target)
                out["csv_rows_sha256"] = _data_rows_sha256(target.read_text(), "#")
            if "script" in exports:
                out["script_sha256"] = _data_rows_sha256(job_program(job), "#")
    return out


def fit_figures(case: dict) -> dict:
    """Fit a case's waypoints with each of its methods ("C1", "C2": PH quintic splines, "cubic": the G1 PH cubic
    spline): length (mm), largest distance from a waypoint (mm), segments."""
    from planner.curves import fit_ph_cubic_spline, fit_ph_spline
    from planner.io import read_toolpath

    read = case.get("read") or {}
    points = read_toolpath(input_path(case["input"]), **read).points
    out = {}
    for method in case["methods"]:
        spline = fit_ph_cubic_spline(points) if method == "cubic" else fit_ph_spline(points, continuity=method)
        out[method] = {"length": 1e3 * spline.length,
                       "waypoint_error_mm": 1e3 * float(spline.interpolation_errors(points).max()),
                       "segments": spline.n_segments}
    return out


def figures(case: dict) -> dict:
    """The figures of a case as the code gives them now."""
    return fit_figures(case) if case["kind"] == "fit" else plan_figures(case)


def _differs(kind: str, frozen, now) -> str | None:
    """Why ``now`` is not ``frozen`` within the tolerance of ``kind`` (None when it is)."""
    tol = TOLERANCES[kind]
    if frozen is None or now is None or isinstance(frozen, str | bool) or tol[0] == "exact":
        return None if frozen == now else f"{now!r}, frozen {frozen!r}"
    a, b = np.asarray(frozen, dtype=float), np.asarray(now, dtype=float)
    if a.shape != b.shape:
        return f"{now!r}, frozen {frozen!r} (shape)"
    same_nan = np.isnan(a) & np.isnan(b)
    gap = np.where(same_nan, 0.0, np.abs(a - b))
    bound = tol[1] * (np.maximum(np.abs(a), np.abs(b)) if tol[0] == "rel" else 1.0)
    if np.all(gap <= bound) and not np.any(np.isnan(gap)):
        return None
    return f"{now!r}, frozen {frozen!r} (tolerance {tol[0]} {tol[1]:g})"


def compare(case: dict, now: dict) -> list[str]:
    """One line per figure of ``case`` that ``now`` moves beyond its tolerance, naming the file and the figure."""
    where = f"{case['id']} ({case['input']})"
    problems = []
    frozen_all = case["figures"]
    flat_frozen = {(k, None): v for k, v in frozen_all.items() if not isinstance(v, dict)}
    flat_now = {(k, None): v for k, v in now.items() if not isinstance(v, dict)}
    for k, v in frozen_all.items():
        if isinstance(v, dict):
            flat_frozen.update({(k, f): x for f, x in v.items()})
    for k, v in now.items():
        if isinstance(v, dict):
            flat_now.update({(k, f): x for f, x in v.items()})
    for key in sorted(set(flat_frozen) | set(flat_now), key=str):
        name = key[0] if key[1] is None else f"{key[0]}.{key[1]}"
        if key not in flat_now:
            problems.append(f"{where}: {name} is no longer measured (frozen {flat_frozen[key]!r})")
            continue
        if key not in flat_frozen:
            problems.append(f"{where}: {name} = {flat_now[key]!r} is new (freeze it with --update)")
            continue
        why = _differs(FIGURE_KINDS[key[1] or key[0]], flat_frozen[key], flat_now[key])
        if why is not None:
            problems.append(f"{where}: {name} = {why}")
    return problems


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else value
    if isinstance(value, np.generic):
        return _jsonable(value.item())
    return value


def _dumps(data: dict) -> str:
    """The corpus file's text: one line per figure, lists of numbers on one line (readable diffs)."""
    text = json.dumps(data, indent=1)
    return re.sub(r"\[\s*([^\[\]{}]*?)\s*\]", lambda m: "[" + re.sub(r"\s*\n\s*", " ", m.group(1)) + "]", text) + "\n"


def _write_atomically(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tests.corpus", description=__doc__.split("\n\n")[0])
    p.add_argument("ids", nargs="*", help="cases to measure (default: all)")
    p.add_argument("--update", action="store_true", help="freeze the figures measured now")
    args = p.parse_args(argv)
    data = json.loads(CORPUS_FILE.read_text(encoding="utf-8"))
    unknown = set(args.ids) - {c["id"] for c in data["cases"]}
    if unknown:
        p.error(f"no such case: {', '.join(sorted(unknown))}")
    moved = 0
    for case in data["cases"]:
        if args.ids and case["id"] not in args.ids:
            continue
        if not input_path(case["input"]).is_file():
            print(f"{case['id']}: {case['input']} is not here, not measured")
            continue
        now = _jsonable(figures(case))
        for k in [k for k, v in now.items() if not isinstance(v, dict)]:
            if k not in FIGURE_KINDS:
                raise SystemExit(f"{case['id']}: figure {k!r} has no kind in FIGURE_KINDS")
        problems = compare(case, now) if "figures" in case else [f"{case['id']}: not frozen yet"]
        moved += bool(problems)
        print("\n".join(problems) if problems else f"{case['id']}: unchanged")
        if args.update:
            case["figures"] = now
    if args.update:
        _write_atomically(CORPUS_FILE, _dumps(data))
        print(f"froze {CORPUS_FILE.relative_to(REPO)}")
    return 1 if moved and not args.update else 0


if __name__ == "__main__":
    sys.exit(main())
