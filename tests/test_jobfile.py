"""The saved-job file (planner.jobfile): named arrays and a JSON manifest that load back to the identical job.

A job saved and loaded gives the same exports byte for byte (CSV, JSON, URScript, ``describe()``, ``summary()``)
for every kind of move and frame the planner makes; ``tests/data/demo.job``, written by this version, loads and
gives the exports of the demo job planned now; a damaged or hostile file (truncated at every length, foreign,
of another version, with crafted JSON, absurd sizes, a zip bomb, a pickle) is refused with one line, runs
nothing and allocates within the bounds the file's size sets. ``tests/test_fuzz_jobfile.py`` mutates files at
random.

``python -m tests.test_jobfile`` writes ``tests/data/demo.job`` again (after a change of the planner's figures
or of the format: the test below says which).
"""

from __future__ import annotations

import gzip
import io
import json
import pickle
import re
import struct
import sys
import tracemalloc
import zipfile
from itertools import zip_longest
from pathlib import Path

import numpy as np
import pytest

from planner import PlannerError, PlanSettings, load_job, plan
from planner.export import job_program, write_csv, write_json, write_script
from planner.job import JOB_TYPES
from planner.jobfile import VERSION, describe_types

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"
DEMO_JOB = DATA / "demo.job"
NX_PART = (0.4, 0.9965, -0.1, 0.0, 0.0, 0.0)
DEMO_SETTINGS = PlanSettings(robot="ur5e", cut_output=("standard", 0), part_frame=NX_PART)
#: A drill cycle with a dwell at every hole (tests/test_cam_dwell.py).
APT_DRILL = """FEDRAT/MMPM,500
GOTO/0,0,50
CYCLE/DRILL,FEDTO,-10,RAPTO,3,RTRCTO,5,DWELL,0.5,MMPM,120
GOTO/10,0,0
GOTO/20,0,0
GOTO/30,5,-2
CYCLE/OFF
"""
#: Turns in place (zero-length moves that change the tool axis), rapids, corners and a DELAY.
APT_TURNS = """UNITS/MM
FEDRAT/MMPM,600
GOTO/0,0,10,0,0,1
GOTO/0,0,0
GOTO/20,0,0
GOTO/20,0,0,0,0.7071068,0.7071068
GOTO/40,0,0
GOTO/40,0,0,0,0,1
RAPID
GOTO/40,0,20
RAPID
GOTO/0,30,20
GOTO/0,30,0
GOTO/30,30,0
DELAY/0.5
GOTO/30,30,5
"""


def plan_demo():
    return plan(ROOT / "examples" / "nx_first_pass.cls", DEMO_SETTINGS)


def bead() -> np.ndarray:
    t = np.linspace(0.0, 1.0, 25)
    return np.c_[0.3 * t, 0.05 * np.sin(2 * np.pi * t), 0.02 * np.cos(3 * np.pi * t)]


@pytest.fixture(scope="module")
def demo():
    return plan_demo()


def _drill(tmp):
    path = tmp / "drill.apt"
    path.write_text(APT_DRILL)
    return plan(path, PlanSettings(path="cam", robot="ur5e", part_frame=(0.4, 0.1, 0.2, 0.0, 0.0, 0.0)))


def _turns(tmp):
    """The turns job, with the placement part_frame='auto' finds for it (the search itself takes seconds: the
    frame it gives and its figures are what the job holds)."""
    from dataclasses import replace

    from planner.cam.placement import Placement

    path = tmp / "turns.apt"
    path.write_text(APT_TURNS)
    frame = (0.808548, -0.019975, 0.060217, 0.0, 0.0, 1.57244)
    job = plan(path, PlanSettings(robot="ur5e", part_frame=frame))
    return replace(job, placement=Placement(frame, 0.888, 3.2534, (0.888, 0.992, 0.888), 2, 400, 881, 2.5))


#: id -> a planned job: every frame method, the CAM models, rapids, dwells, turns in place, a change of arm
#: configuration, a placement found by the planner.
JOBS = {
    "waypoints-grm": lambda tmp: plan(bead(), PlanSettings(frame="grm", feed=0.02, cut_output=("standard", 0))),
    "waypoints-juttler": lambda tmp: plan(bead(), PlanSettings(frame="juttler", feed=0.02)),
    "waypoints-er": lambda tmp: plan(bead(), PlanSettings(frame="er", feed=0.02, robot="ur5e",
                                                          part_frame=(0.3, 0.2, 0.1, 0.0, 0.0, 0.0))),
    "waypoints-double-reflection": lambda tmp: plan(bead(), PlanSettings(frame="double-reflection", feed=0.02)),
    "waypoints-rmf-cam": lambda tmp: plan(bead(), PlanSettings(path="cam"), axes=np.tile([0.0, 0.0, 1.0], (25, 1))),
    "drill-dwells": _drill,
    "turns-placed": _turns,
    # the excerpt's passes 16-22 (lines 20238-20416 of the whole job): a change of arm configuration in a rapid,
    # the records of the passes left out kept as skipped moves
    "nx-clsf-excerpt-reconfiguration": lambda tmp: plan(
        DATA / "nx_clsf_ust_a2_excerpt.cls", PlanSettings(robot="ur5e", part_frame=NX_PART, passes=tuple(range(16, 23)))),
}


def exports(job, folder: Path, tag: str, rate: float | None = None) -> dict[str, bytes]:
    """Every export of a job: CSV and JSON (at ``rate``, default the job's), URScript (with a robot), describe()
    and summary() (as JSON)."""
    out = {}
    write_csv(job.trajectory(rate), folder / f"{tag}.csv")
    write_json(job.trajectory(rate), folder / f"{tag}.json")
    out["csv"], out["json"] = (folder / f"{tag}.csv").read_bytes(), (folder / f"{tag}.json").read_bytes()
    if job.settings.robot is not None:
        write_script(job_program(job), folder / f"{tag}.script")
        out["script"] = (folder / f"{tag}.script").read_bytes()
    out["describe"] = "\n".join(job.describe()).encode()
    out["summary"] = json.dumps(job.summary()).encode()
    return out


def assert_same(a: dict, b: dict, what: str) -> None:
    assert a.keys() == b.keys()
    for k in a:
        if a[k] != b[k]:
            pairs = list(zip_longest(a[k].splitlines(), b[k].splitlines(), fillvalue=b""))
            line = next(i for i, (x, y) in enumerate(pairs) if x != y)
            raise AssertionError(f"{what}: the {k} export differs from line {line}:\n{pairs[line][0][:300]!r}\n"
                                 f"{pairs[line][1][:300]!r}")


# ---------------------------------------------------------------------------------------------------- round trips
def test_the_demo_job_loads_back_to_identical_exports(demo, tmp_path):
    size = demo.save(tmp_path / "demo.job")
    assert size == (tmp_path / "demo.job").stat().st_size < 40_000
    back = load_job(tmp_path / "demo.job")
    assert_same(exports(demo, tmp_path, "a"), exports(back, tmp_path, "b"), "demo")
    assert back.duration == demo.duration and back.n_samples() == demo.n_samples()
    assert load_job((tmp_path / "demo.job").read_bytes()).describe() == demo.describe()  # bytes in, too


@pytest.mark.parametrize("name", sorted(JOBS))
def test_every_kind_of_job_loads_back_to_identical_exports(name, tmp_path):
    job = JOBS[name](tmp_path)
    job.save(tmp_path / "x.job")
    back = load_job(tmp_path / "x.job")
    kinds = {m.kind for m in job.moves}
    rate = 50.0 if name.startswith("nx-") else None  # every move sampled, fewer poses: 3 min of motion
    assert_same(exports(job, tmp_path, "a", rate), exports(back, tmp_path, "b", rate), name)
    assert [m.kind for m in back.moves] == [m.kind for m in job.moves]
    if name == "drill-dwells":
        assert {"dwell", "rapid", "cut"} <= kinds
    if name.startswith("nx-clsf"):
        assert {"reconfiguration", "skipped"} <= kinds and back.reconfiguration_lines() == job.reconfiguration_lines()
    if name == "turns-placed":
        assert {"reorientation", "dwell"} <= kinds and back.placement == job.placement is not None


def test_objects_shared_in_the_job_are_stored_once_and_shared_again(demo, tmp_path):
    demo.save(tmp_path / "demo.job")
    back = load_job(tmp_path / "demo.job")
    cut = next(m for m in back.moves if m.kind == "cut")
    assert cut.path is cut.fit.path is cut.frames.path  # one spline, as planned
    assert cut.item is back.segmentation.moves[cut.item.index + 1]  # the same CutPass in the move and the split
    with zipfile.ZipFile(tmp_path / "demo.job") as z:
        manifest = json.loads(z.read("manifest.json"))
    names = [o[0] for o in manifest["objects"]]
    assert names.count("PHSpline") == 2 and names[-1] == "PlannedJob" and manifest["version"] == VERSION


def test_saving_twice_gives_the_same_bytes(demo, tmp_path):
    a, b = demo.save(tmp_path / "a.job"), demo.save(tmp_path / "b.job")
    assert a == b and (tmp_path / "a.job").read_bytes() == (tmp_path / "b.job").read_bytes()


def test_the_committed_demo_job_gives_the_exports_of_the_demo_planned_now(demo, tmp_path):
    """tests/data/demo.job was written by this format version: loading it must give what planning gives now.

    A failure means either the planner's output moved (then the corpus test fails too: write the file again
    with ``python -m tests.test_jobfile``) or loading changed (a bug, or a format change that needs a version).
    """
    saved = load_job(DEMO_JOB)
    a, b = exports(saved, tmp_path, "saved"), exports(demo, tmp_path, "fresh")
    timing = re.compile(rb"planned in [0-9.]+ m?s")  # the wall time of planning is the one figure that moves
    a["describe"], b["describe"] = timing.sub(b"", a["describe"]), timing.sub(b"", b["describe"])
    a["summary"], b["summary"] = (json.dumps({**json.loads(x), "planning_s": 0}).encode() for x in (a["summary"],
                                                                                                    b["summary"]))
    assert_same(a, b, f"{DEMO_JOB.name} against the demo planned now")


def test_the_layout_in_the_docstring_lists_every_stored_type():
    import planner.jobfile

    table = "\n".join("    " + line for line in describe_types(JOB_TYPES).splitlines())
    assert table in planner.jobfile.__doc__, "planner/jobfile/__init__.py: paste describe_types(JOB_TYPES) again"


def test_a_job_holding_something_the_format_does_not_is_refused_on_saving(demo, tmp_path):
    from dataclasses import replace

    odd = replace(demo, moves=(*demo.moves, object()))
    with pytest.raises(PlannerError, match="cannot save the job: PlannedJob.moves is a object"):
        odd.save(tmp_path / "odd.job")
    assert not (tmp_path / "odd.job").exists() and list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------------------------ refusals
class Trap:
    """Unpickled, it creates a file: whether anything ran is visible."""

    def __init__(self, path: Path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def refused(data: bytes, tmp_path: Path, pattern: str, name: str = "x.job") -> str:
    """load_job of ``data`` written to ``name``: a one-line PlannerError matching ``pattern``, naming the file."""
    path = tmp_path / name
    path.write_bytes(data)
    with pytest.raises(PlannerError) as err:
        load_job(path)
    text = str(err.value)
    assert "\n" not in text and text.startswith(f"{path}: "), text
    assert re.search(pattern, text), text
    return text


def entries(blob: bytes) -> dict[str, bytes]:
    with zipfile.ZipFile(io.BytesIO(blob)) as z:
        return {i.filename: z.read(i) for i in z.infolist()}


def repack(files: dict[str, bytes], method: int = zipfile.ZIP_DEFLATED) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for name, data in files.items():
            z.writestr(zipfile.ZipInfo(name, (1980, 1, 1, 0, 0, 0)), data, compress_type=method)
    return buf.getvalue()


def npy(a: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.lib.format.write_array(out, a, allow_pickle=True)
    return out.getvalue()


@pytest.fixture(scope="module")
def blob(demo, tmp_path_factory) -> bytes:
    path = tmp_path_factory.mktemp("job") / "demo.job"
    demo.save(path)
    return path.read_bytes()


def pool(files: dict, name: str) -> np.ndarray:
    return np.load(io.BytesIO(files[f"arrays/{name}.npy"]), allow_pickle=False)


def edited(blob: bytes, change) -> bytes:
    """The file with its manifest changed by ``change(manifest)`` (the archive otherwise intact)."""
    files = entries(blob)
    m = json.loads(files["manifest.json"])
    change(m)
    files["manifest.json"] = json.dumps(m).encode()
    return repack(files)


def state(m: dict, kind: str, k: int = 0) -> dict:
    """The state of the k-th object of type ``kind`` in manifest ``m``."""
    return [o[1] for o in m["objects"] if o[0] == kind][k]


def test_the_former_pickle_format_is_refused_without_unpickling(tmp_path):
    marker = tmp_path / "ran"
    old = b"planner-job\n" + (1).to_bytes(2, "big") + gzip.compress(pickle.dumps(Trap(marker)))
    refused(old, tmp_path, r"a saved job in the former pickle format \(version 1\), which this planner no longer "
                           r"reads .*: plan the job again")
    assert not marker.exists()


@pytest.mark.parametrize("data, pattern", [
    (b"", "not a saved planner job$"),
    (b"GOTO/1,2,3\n", "not a saved planner job$"),
    (b"\x89PNG\r\n\x1a\n" + bytes(100), "not a saved planner job$"),
    (b"PK\x03\x04" + bytes(100), "damaged: not a readable archive"),
    (repack({"readme.txt": b"hello"}), r"not a saved planner job \(a ZIP archive without manifest.json\)"),
    (repack({"manifest.json": b'{"format": "planner-trajectory/1"}'}), "not a saved planner job"),
])
def test_foreign_files_are_refused(data, pattern, tmp_path):
    refused(data, tmp_path, pattern)


@pytest.mark.parametrize("version, shown", [(3, "3"), (1, "1"), ("2", "'2'"), (None, "None"), (2.0, "2.0")])
def test_other_format_versions_are_refused_naming_both(blob, tmp_path, version, shown):
    def change(m):
        m["version"] = version

    refused(edited(blob, change), tmp_path, rf"saved job format version {re.escape(shown)}, this planner reads "
                                            rf"version {VERSION}$")


def test_a_file_truncated_at_any_length_is_refused(blob, tmp_path):
    for n in range(len(blob)):
        with pytest.raises(PlannerError) as err:
            load_job(blob[:n])
        text = str(err.value)
        assert "\n" not in text and re.match("the data: (the saved job is damaged|not a saved planner job)", text), n
    refused(blob[:len(blob) // 2], tmp_path, "the saved job is damaged: not a readable archive")


def test_an_entry_truncated_at_any_length_class_is_refused(blob, tmp_path):
    """Each entry cut inside the archive (whose directory is intact): at its start, in its header, in its data,
    one byte short."""
    files = entries(blob)
    for name, data in files.items():
        for n in sorted({0, 1, 9, 60, len(data) // 2, len(data) - 8, len(data) - 1}):
            if 0 <= n < len(data):
                with pytest.raises(PlannerError, match="the data: the saved job is damaged: ") as err:
                    load_job(repack({**files, name: data[:n]}))
                assert "\n" not in str(err.value)


def _deep(m):
    m["objects"][0][1] = json.loads("[" * 50 + "]" * 50)


def _set(kind: str, field: str, value, k: int = 0):
    def change(m):
        state(m, kind, k)[field] = value
    return change


def _forward(m):
    state(m, "PlannedMove")["path"] = len(m["objects"]) - 1


def _wrong_type(m):
    state(m, "PlannedMove", 1)["path"] = next(i for i, o in enumerate(m["objects"]) if o[0] == "FeedProfile")


def _type_name(name: str):
    def change(m):
        m["objects"][0][0] = name
    return change


def _extra_field(m):
    state(m, "PHSpline")["__class__"] = "os.system"


def _missing_field(m):
    del state(m, "PHSpline")["knots"]


def _root(m):
    m["root"] = 0


def _pool_size(m):
    m["arrays"]["f8"]["size"] += 1


@pytest.mark.parametrize("change, pattern", [
    (_deep, "expected a list of 2|expected \\[type, state\\]|expected an object"),
    (_set("PHSpline", "iterations", "3"), r"object \d+ \(PHSpline\) iterations: expected an integer"),
    (_set("PHSpline", "iterations", 2**70), r"iterations: expected an integer in \[0, "),
    (_set("CutPass", "index", 1.5), r"\(CutPass\) index: expected an integer"),
    (_set("FeedProfile", "length", True), "length: expected a finite number, got true"),
    (_set("FeedProfile", "length", "nan"), "length: expected a finite number, got 'nan'"),
    (_set("PlannedMove", "kind", "teleport"), "kind: expected one of cut, rapid"),
    (_set("PlannedMove", "start_frame", [0, 3]), r"start_frame: expected an array reference \[offset, n, n\]"),
    (_set("PlannedMove", "start_frame", [0, 4, 4]), r"start_frame: expected an array reference .* shape \(3,3\)"),
    (_set("PHSpline", "A", [0, 10**12, 3, 4]), r"\(PHSpline\) A: elements 0..12000000000000 lie beyond the \d+ of the f8 pool"),
    (_set("PHSpline", "A", [0, 0, 3, 2**61]), r"A: expected an array reference"),
    (_set("PHSpline", "knots", [-1, 3]), r"knots: expected an array reference"),
    (_set("PHSpline", "knots", [2**62, 3]), r"knots: elements"),
    (_set("PHSpline", "knots", [0, 1]), r"\(PHSpline\): 1 segments need 1 starts and 2 knots"),
    (_forward, r"path: expected the index of an earlier object"),
    (_wrong_type, r"path: object \d+ is a FeedProfile, expected PHSpline"),
    (_type_name("planner.job.PlannedJob"), r"object 0: unknown type 'planner.job.PlannedJob'"),
    (_type_name("__import__"), r"object 0: unknown type '__import__'"),
    (_type_name("SpinTable"), r"object 0: unknown type 'SpinTable'"),  # an inline part is no object
    (_extra_field, r"\(PHSpline\): fields do not match the format \(unknown '__class__'\)"),
    (_missing_field, r"\(PHSpline\): fields do not match the format \(missing knots\)"),
    (_root, "the root is not the last object"),
    (_pool_size, "array pool 'f8': the manifest and the entry disagree"),
    (_set("PlannedJob", "settings", {"rate": -5}), r"\(PlannedJob\): rate must be"),
    (_set("PlannedJob", "settings", {"robot": "ur99"}), r"\(PlannedJob\): .*ur99"),
    (_set("PlannedJob", "settings", {"bogus": 1}), r"\(PlannedJob\): unknown setting bogus"),
])
def test_crafted_manifests_are_refused_naming_the_place(blob, tmp_path, change, pattern):
    refused(edited(blob, change), tmp_path, "the saved job is damaged: .*" + pattern)


@pytest.mark.parametrize("text, pattern", [
    (b"[" * 100_000 + b"]" * 100_000, "manifest.json nests too deeply|the manifest"),
    (b'{"format": "planner-job", "format": "planner-job"}', "not valid JSON .*key twice"),
    (b'{"format": "planner-job", "version": NaN}', "not valid JSON .*NaN is not a JSON number"),
    (b'{"format": "planner-job", "version": ' + b"9" * 5000 + b"}", "not valid JSON"),
    (b'{"format": "planner-job", "version": 2, "x": 1e999}', "manifest fields"),
    (b"\xff\xfe{}", "not UTF-8"),
    (b"", "not valid JSON"),
])
def test_crafted_json_is_refused(blob, tmp_path, text, pattern):
    files = entries(blob)
    files["manifest.json"] = text
    refused(repack(files), tmp_path, pattern)


def test_values_the_kinds_allow_but_the_types_do_not_are_refused(blob, tmp_path):
    files = entries(blob)
    m = json.loads(files["manifest.json"])
    f8 = pool(files, "f8")
    knots = state(m, "PHSpline", 1)["knots"][0]  # the cut's spline
    for value, pattern in ((np.nan, r"\(PHSpline\) knots: holds a value that is not finite"),
                           (-1.0, r"\(PHSpline\): knots must strictly increase"),
                           (1e200, r"the f8 pool holds 1e\+200, beyond the format's 1e\+15")):
        bad = f8.copy()
        bad[knots + 3] = value
        refused(repack({**files, "arrays/f8.npy": npy(bad)}), tmp_path, pattern)
    offset, n = state(m, "FeedProfile", 1)["t"]
    bad = f8.copy()
    bad[offset + n - 1] = 1e14  # the cut takes 3 million years: a trajectory no job may have
    refused(repack({**files, "arrays/f8.npy": npy(bad)}), tmp_path,
            r"\(PlannedJob\): the trajectory would be 5e\+16 poses \(at most 1e\+12\)")


def test_arrays_that_are_not_plain_numbers_are_refused_and_never_unpickled(blob, tmp_path):
    marker = tmp_path / "ran"
    files = entries(blob)
    trap = np.empty(3, dtype=object)
    trap[:] = [Trap(marker)] * 3
    refused(repack({**files, "arrays/f8.npy": npy(trap)}), tmp_path, r"'arrays/f8.npy': dtype \|O")
    assert not marker.exists()
    for a, pattern in ((np.zeros(5, "<f4"), "dtype <f4"), (np.zeros(5, ">f8"), "dtype >f8"),
                       (np.zeros((2, 2)), r"shape \(2, 2\)"), (np.zeros(4, "<c16"), "dtype <c16")):
        refused(repack({**files, "arrays/f8.npy": npy(a)}), tmp_path, pattern)
    refused(repack({**files, "arrays/f8.npy": b"\x93NUMPY\x01\x00garbage"}), tmp_path, "not a NumPy array")
    refused(repack({**files, "arrays/PHSpline.A.npy": files["arrays/f8.npy"]}), tmp_path,
            "the manifest's arrays and the archive's array entries differ")
    refused(repack({**files, "arrays/evil.py": b"import os"}), tmp_path, "unexpected entry 'arrays/evil.py'")


def _header_only(shape) -> bytes:
    out = io.BytesIO()
    np.lib.format.write_array_header_1_0(out, {"descr": "<f8", "fortran_order": False, "shape": shape})
    return out.getvalue()


def test_absurd_sizes_are_refused_before_anything_is_allocated(blob, tmp_path):
    files = entries(blob)
    huge = repack({**files, "arrays/f8.npy": _header_only((10**12,)) + bytes(16)})  # 10^12 floats declared
    bomb = repack({**files, "arrays/f8.npy": _header_only((8 * 2**20,)) + bytes(64 * 2**20)})  # 64 MB of zeros
    assert len(bomb) < 150_000
    patched = _patch_sizes(blob, "manifest.json", 2**40)  # 1 TB declared for the manifest
    tracemalloc.start()
    try:
        refused(huge, tmp_path, r"the header declares 1000000000000 elements, the entry holds 16 bytes")
        refused(bomb, tmp_path, r"the entries declare \d+ bytes, more than the format allows for a file of")
        refused(patched, tmp_path, r"the entries declare \d+ bytes")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 8 * 2**20, f"refusing them took {peak / 2**20:.1f} MB"


def _patch_sizes(blob: bytes, name: str, size: int) -> bytes:
    """The archive with ``name``'s uncompressed size set to ``size`` in its ZIP64 extra or its 32-bit fields."""
    data = bytearray(blob)
    key = name.encode()
    at = data.rfind(b"PK\x01\x02", 0, data.rfind(key))  # its central directory record
    struct.pack_into("<I", data, at + 24, min(size, 0xFFFFFFFE))
    return bytes(data)


def test_unusual_archives_are_refused(blob, tmp_path):
    files = entries(blob)
    for method in (zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA):
        refused(repack(files, method), tmp_path, f"compression method {method}")
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z, pytest.warns(UserWarning, match="Duplicate name"):
        for name, data in [*files.items(), ("manifest.json", files["manifest.json"])]:
            z.writestr(name, data)
    refused(buf.getvalue(), tmp_path, "entry 'manifest.json' appears twice")
    data = bytearray(repack(files))
    at = data.find(b"PK\x01\x02")
    data[at + 8] |= 1  # the encryption flag of the first entry
    refused(bytes(data), tmp_path, "is encrypted")


def test_reading_a_missing_file_or_a_folder_is_one_line(tmp_path):
    with pytest.raises(PlannerError, match=r"nothing.job: cannot read the saved job \(No such file"):
        load_job(tmp_path / "nothing.job")
    with pytest.raises(PlannerError, match="cannot read the saved job"):
        load_job(tmp_path)
    with pytest.raises(PlannerError, match="load_job takes a path or the file's bytes, got int"):
        load_job(3)


def write_demo() -> None:
    """Write tests/data/demo.job from the demo job planned now."""
    size = plan_demo().save(DEMO_JOB)
    print(f"wrote {DEMO_JOB} ({size} bytes)")


if __name__ == "__main__":
    write_demo() if sys.argv[1:] in ([], ["--write-demo"]) else sys.exit("usage: python -m tests.test_jobfile")
