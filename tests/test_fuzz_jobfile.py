"""Fuzz of the saved-job reader: mutated versions of valid ``.job`` files through ``load_job``.

The contract, for any bytes: ``load_job`` returns a job or raises one :class:`~planner.errors.PlannerError` of one
line; never another exception, never a hang, never an allocation beyond what the file's size bounds (a few times
the file, checked with tracemalloc). A job that loads is usable: ``summary()``, ``describe()``, its trajectory (CSV,
at a low rate, when it is not longer than a real job's) and its URScript program each give a result or one
PlannerError.

Mutations of the bytes (truncation, flipped and inserted bytes; the archive's checksums catch most of them) and,
to reach the reader behind the checksums, of the contents, written back into a valid archive: a value anywhere in
the manifest replaced by a nasty one (wrong types, huge and negative numbers, NaN strings, lists and objects, deep
nesting), two values swapped, a key or list entry deleted, array elements set to NaN, infinities or huge values,
an array pool cut short (with or without its manifest size), an entry removed.

Seeds: the committed demo job (tests/data/demo.job: a CAM pass with its rapid, a robot, the cut output) and a
waypoint job with GRM frames. ``HYPOTHESIS_PROFILE=fuzz`` (``./run fuzz``) runs the long campaign.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import math
import re
import tempfile
import tracemalloc
import warnings
import zipfile
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from planner import PlannedJob, PlannerError, PlanSettings, load_job, plan
from planner.export import job_program
from planner.export.tables import csv_text
from tests.test_fuzz import EXAMPLES, FUZZ, Hang, deadline

DATA = Path(__file__).resolve().parent / "data"
#: A loaded job's trajectory is exported when it has at most this many poses at RATE (a real job's size).
MAX_POSES = 20_000
RATE = 10.0
DEADLINE = 60.0 if FUZZ else 30.0


@cache
def seed(name: str) -> bytes:
    if name == "demo":
        return (DATA / "demo.job").read_bytes()
    t = np.linspace(0.0, 1.0, 12)
    bead = np.c_[0.3 * t, 0.05 * np.sin(2 * np.pi * t), 0.02 * np.cos(3 * np.pi * t)]
    job = plan(bead, PlanSettings(frame="grm", feed=0.02, cut_output=("standard", 0)))
    with tempfile.TemporaryDirectory() as tmp:
        job.save(Path(tmp) / "grm.job")
        return (Path(tmp) / "grm.job").read_bytes()


NASTY = [-1, 0, 1, 3, 2**31, 2**63, -(2**63), 10**30, 1e308, -1e308, 1e-308, 0.5, -0.0, "nan", "inf", "-inf", "", "x",
         "PlannedJob", None, True, False, [], {}, [0], [0, 0], [0, 1, 1], [0, 3, 3], [-1, 3], [2**40, 3], [0, 2**40, 0],
         {"a": 1}, [[[[[[[[[[[]]]]]]]]]]]]
fraction = st.floats(min_value=0.0, max_value=1.0, allow_nan=False)
element = st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, 0.0, -1.0, 1e-300, 2.0**62])
mutation = st.one_of(
    st.tuples(st.just("truncate"), fraction),
    st.tuples(st.just("flip"), fraction, st.integers(0, 255)),
    st.tuples(st.just("insert"), fraction, st.binary(min_size=1, max_size=8)),
    st.tuples(st.just("json"), fraction, st.sampled_from(NASTY)),
    st.tuples(st.just("json"), fraction, st.sampled_from(NASTY)),  # the most fruitful: twice the weight
    st.tuples(st.just("swap"), fraction, fraction),
    st.tuples(st.just("remove"), fraction),
    st.tuples(st.just("element"), fraction, fraction, element),
    st.tuples(st.just("cut"), fraction, fraction, st.booleans()),
    st.tuples(st.just("entry"), fraction),
)


def _entries(data: bytes) -> dict[str, bytes] | None:
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as z:
            return {i.filename: z.read(i) for i in z.infolist()}
    except Exception:  # noqa: BLE001 - a mutation made it unreadable: the contents mutations leave it so
        return None


def _pack(files: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for name, data in files.items():
            z.writestr(zipfile.ZipInfo(name, (1980, 1, 1, 0, 0, 0)), data, compress_type=zipfile.ZIP_DEFLATED)
    return buf.getvalue()


def _places(node, out: list) -> list:
    """Every (container, key) of a JSON document, in document order."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in items:
        out.append((node, k))
        _places(v, out)
    return out


def _pick(seq, f: float):
    return seq[min(int(f * len(seq)), len(seq) - 1)]


def mutate(data: bytes, ops) -> bytes:
    """``data`` with the mutations ``ops`` applied in turn (positions are fractions of the current size)."""
    for op in ops:
        kind = op[0]
        if kind == "truncate":
            data = data[:int(op[1] * len(data))]
        elif kind == "flip" and data:
            k = min(int(op[1] * len(data)), len(data) - 1)
            data = data[:k] + bytes([op[2]]) + data[k + 1:]
        elif kind == "insert":
            k = int(op[1] * len(data))
            data = data[:k] + op[2] + data[k:]
        else:
            files = _entries(data)
            if files is None:
                continue
            data = _pack(_mutate_contents(files, op))
    return data


def _mutate_contents(files: dict[str, bytes], op) -> dict[str, bytes]:
    kind = op[0]
    if kind == "entry" and files:
        del files[_pick(sorted(files), op[1])]
        return files
    pools = sorted(k for k in files if k.startswith("arrays/"))
    if kind in ("element", "cut") and pools:
        name = _pick(pools, op[1])
        try:
            a = np.load(io.BytesIO(files[name]), allow_pickle=False).copy()
        except Exception:  # noqa: BLE001 - an earlier mutation spoiled it
            return files
        if a.size == 0:
            return files
        if kind == "element":
            k = min(int(op[2] * a.size), a.size - 1)
            a[k] = op[3] if a.dtype.kind == "f" else int(max(-(2.0**62), min(2.0**62, op[3]))) if math.isfinite(
                op[3]) else -1
        else:
            a = a[:int(op[2] * a.size)]
            if op[3]:  # keep the manifest's size in step: the damage lies behind it
                _edit_manifest(files, lambda m: m["arrays"][name[7:-4]].__setitem__("size", int(a.size)))
        out = io.BytesIO()
        np.lib.format.write_array(out, a, allow_pickle=False)
        files[name] = out.getvalue()
        return files
    if kind in ("json", "swap", "remove"):
        _edit_manifest(files, lambda m: _mutate_json(m, op))
    return files


def _edit_manifest(files: dict, change) -> None:
    try:
        m = json.loads(files["manifest.json"])
    except Exception:  # noqa: BLE001 - no manifest, or an earlier mutation spoiled it
        return
    with contextlib.suppress(KeyError, TypeError, AttributeError):
        change(m)
    files["manifest.json"] = json.dumps(m).encode()


def _mutate_json(m, op) -> None:
    places = _places(m, [])
    if not places:
        return
    node, key = _pick(places, op[1])
    if op[0] == "json":
        node[key] = json.loads(json.dumps(op[2]))
    elif op[0] == "swap":
        other, k2 = _pick(places, op[2])
        node[key], other[k2] = other[k2], node[key]
    else:
        del node[key]


def check_load(data: bytes) -> str:
    """The contract for one file; returns what happened (for the statistics)."""
    tracemalloc.start()
    try:
        with deadline(DEADLINE), warnings.catch_warnings():
            warnings.simplefilter("error")  # a numpy warning in the reader is a bug too
            try:
                job = load_job(data)
            except PlannerError as exc:
                text = str(exc)
                assert "\n" not in text and text.startswith("the data: "), text
                return re.sub(r"\d+", "N", "refused: " + text.removeprefix("the data: "))[:70]
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 30 * len(data) + 64 * 2**20, f"loading {len(data)} bytes took {peak / 2**20:.0f} MB"
    assert isinstance(job, PlannedJob)
    with deadline(DEADLINE), warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        for use in (job.summary, job.describe, lambda: _csv(job), lambda: _program(job)):
            try:
                use()
            except PlannerError as exc:
                assert "\n" not in str(exc), str(exc)
    return "loaded"


def _csv(job) -> None:
    tr = job.trajectory(RATE)
    if tr.n_samples <= MAX_POSES:
        for _ in csv_text(tr):
            pass


def _program(job) -> None:
    if job.settings.robot is not None and sum(p.length for p in job.passes) < 10.0:
        job_program(job)


FUZZ_SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=not FUZZ,
                         suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@pytest.mark.parametrize("name", ["demo", "grm"])
def test_the_seeds_load(name):
    assert check_load(seed(name)) == "loaded"


@pytest.mark.parametrize("name", ["demo", "grm"])
@FUZZ_SETTINGS
@given(ops=st.lists(mutation, min_size=1, max_size=3))
def test_mutated_job_files_keep_the_contract(name, ops):
    data = mutate(seed(name), ops)
    try:
        event(check_load(data))
    except (AssertionError, Hang, Exception) as exc:  # noqa: BLE001 - every escape is the failure reported
        path = Path(tempfile.gettempdir()) / f"jobfile-fuzz-{hashlib.sha1(data).hexdigest()[:12]}.job"
        path.write_bytes(data)
        raise AssertionError(f"{type(exc).__name__}: {exc}\nreproducer: {path} (seed {name}, mutations {ops!r})") from exc
