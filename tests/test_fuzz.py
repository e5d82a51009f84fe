"""Fuzz suite of issue 17: mutated versions of every input format, and option values, through ``planner plan``; of
issue 24: every format in UTF-16 (either byte-order mark, or none), UTF-32 and UTF-8 with a mark, planning like its
UTF-8 text, and CYCLE records of random words in a real SOLIDWORKS CAM file.

The contract, for any input file and any options, checked through ``planner.frontends.cli.main.main([...])`` in-process (and a
few examples through a subprocess, where stderr is the real one):

- exit 0 with a valid, complete output at ``-o`` (parsed back: every row finite, as many poses as reported,
  times increasing; a URScript program compiled by the simulator's parser; a saved job loaded back), or
- exit 2 (the user's mistake) or 3 (a numerical failure of ours) with exactly one line on stderr and nothing
  written: the output directory holds the input file alone (no partial file, no temporary file);
- never a traceback (an exception escaping ``main``), never a hang (a per-example deadline).

Inputs: the bundled examples (examples/), the heads of the verbatim excerpts of the shared CAM files
(tests/data: NX CLSF, SolidWorks APT, NX G-code for a Haas UMC-750), a Sinumerik 840D program (.mpf) and JSON
waypoints built from the example CSV; mutations: truncation, byte flips, NaN/inf/1e308/1e-300/huge fields (digit
strings of thousands of characters), coordinates scaled by 1e-9..1e9, unit switches (APT ``UNITS/``, G20/G21/G70)
inserted anywhere, duplicated, deleted and swapped lines (issue 27: each ran past a minute or gave a traceback).

Fits and plans (issue 24): waypoints that turn back on themselves (exact and near reversals, cusps, antiparallel
steps, runs along a line) through ``fit_ph_spline`` C1 and C2 with both member rules, and ``planner fit`` once in a
subprocess; random waypoints scaled by 1e-9..1e9 (sub-micrometre ones often) through the fits and ``planner.plan``.

Bounded so the default run takes well under a minute. ``HYPOTHESIS_PROFILE=fuzz`` selects the long profile
(1000 examples per format, fresh random ones each run, a longer deadline per example): ``./run fuzz``;
``FUZZ_EXAMPLES=N`` sets the number of examples per format.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import math
import os
import re
import signal
import subprocess
import sys
import tempfile
import traceback
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from planner.frontends.cli.main import main
from tests.conftest import waypoint_sets

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"

#: The long profile (``./run fuzz``): selected by HYPOTHESIS_PROFILE=fuzz.
FUZZ = os.environ.get("HYPOTHESIS_PROFILE") == "fuzz"
settings.register_profile("fuzz", deadline=None, max_examples=1000, print_blob=True,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
if FUZZ:
    settings.load_profile("fuzz")
#: Examples per input format: default suite, long profile (FUZZ_EXAMPLES=N sets it for a run of its own).
EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", 1000 if FUZZ else 12))
#: Wall-clock limit of one planner run (s): a run past it is a hang. Generous: 2 shared cores, other tests beside.
DEADLINE = 60.0 if FUZZ else 30.0
#: Every fuzz run is capped at this many poses (unless the options draw a smaller cap): the default 2e8 is a valid
#: job of minutes of writing, not a hang, and not what the fuzz is for.
MAX_POSES = "300000"


def _head(path: Path, n: int) -> bytes:
    return b"".join(path.read_bytes().splitlines(keepends=True)[:n])


SINUMERIK = b"""%_N_PART_MPF
;$PATH=/_N_MPF_DIR
; NX post, Sinumerik 840D
N10 DEF REAL _camtolerance
N20 DEF REAL _X0=10, _Z_HOME=300
N30 _camtolerance=.02
N40 G40 G17 G710 G94 G90 G60 G601 FNORM
N50 CYCLE800(1,"TC1",0,57,0,0,0,0,0,0,0,0,0,-1,100,1)
N60 CYCLE832(_camtolerance,_ORI_FINISH,1)
N70 SUPA G0 Z=_Z_HOME D0
N80 TRAFOOF
N100 MSG("ROUGHING ; FLOOR")
N110 T="MILL_10" ; tool by name
N120 M6
N140 S5000 M3
N150 G0 X=_X0 Y=2*5 Z=_X0/2
N160 G1 Z=-1 F=100*2
N170 X=IC(20) Y=(_X0-5)*2 G64
N180 G2 X=_X0+30 Y=20 CR=10
N190 G3 X40 Y40 I=AC(40) J=AC(30)
N200 R1=SQRT(POT(3)+POT(4)) R2=7 DIV 2 R3=7 MOD 2
N210 G1 X=40+R1*R2 Y=40-R3 F=300
N230 X=ROUND(SIN(30)*100) Y=ATAN2(1,1)
N240 G0 Z50
N250 M30
"""


def _json_seed() -> bytes:
    """The example CSV's waypoints as JSON (rows shape, one point per line so that line mutations bite)."""
    rows = [r for r in (ROOT / "examples" / "nx_first_pass.csv").read_text().splitlines()
            if r and not r.startswith("#") and r[0] in "-0123456789"]
    pts = [[float(x) for x in r.split(",")] for r in rows]
    body = ",\n".join(f'  {{"x": {p[0]!r}, "y": {p[1]!r}, "z": {p[2]!r}, "i": {p[3]!r}, "j": {p[4]!r}, '
                      f'"k": {p[5]!r}' + (', "feed": 600' if k == 0 else "") + "}" for k, p in enumerate(pts))
    return ('{"units": "mm", "feed_units": "mm/min", "points": [\n' + body + "\n]}\n").encode()


#: name -> (file name, bytes, options every run of it gets)
SEEDS = {
    "csv": ("nx_first_pass.csv", (ROOT / "examples" / "nx_first_pass.csv").read_bytes(), []),
    "cls": ("nx_first_pass.cls", (ROOT / "examples" / "nx_first_pass.cls").read_bytes(), []),
    "clsf": ("ust_a2.cls", _head(DATA / "nx_clsf_ust_a2_excerpt.cls", 90), []),
    "apt": ("boss.apt", _head(DATA / "solidworks_cam_apt_boss_excerpt.apt", 90), []),
    "gcode": ("haas.nc", _head(DATA / "nx2022_haas_umc750_excerpt.txt", 110), ["--machine", "haas-umc-750"]),
    "mpf": ("part.mpf", SINUMERIK, []),
    "json": ("points.json", _json_seed(), []),
}

NASTY = ["nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e-300", "-1e-300", "0", "-0", "0.0", "1e999", "9" * 400,
         "9" * 5000, "1" + "0" * 4400 + ".5",
         "", "-", ".", "1e3", "1E-3", "0x1F", "1_000", "\u0661\u0662", "12.5.3", "+-1", "1,5", '"5"', "null",
         "true", "[]", "{}"]
#: Number tokens (a coordinate, a feed, an axis component) the field and scale mutations act on.
#: Unit switches inserted anywhere (a pass read partly in mm and partly in m or inch must be refused, not planned).
UNIT_SWITCHES = [b"UNITS/M\n", b"UNITS/INCH\n", b"UNITS/MM\n", b"UNITS/CM\n", b"G20\n", b"G21\n", b"G70\n",
                 b"N5 G20 G1 X1.5\n"]
NUMBER = re.compile(rb"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")

fraction = st.floats(min_value=0.0, max_value=1.0, allow_nan=False)
mutation = st.one_of(
    st.tuples(st.just("truncate"), fraction),
    st.tuples(st.just("flip"), fraction, st.integers(0, 255)),
    st.tuples(st.just("field"), fraction, st.integers(0, 12), st.sampled_from(NASTY)),
    st.tuples(st.just("scale"), fraction, fraction,
              st.sampled_from([1e-9, 1e-6, 1e-3, -1.0, 10.0, 1e3, 1e6, 1e9])),
    st.tuples(st.just("insert"), fraction, st.sampled_from(UNIT_SWITCHES)),
    st.tuples(st.just("duplicate"), fraction, st.integers(1, 40)),
    st.tuples(st.just("delete"), fraction, st.integers(1, 40)),
    st.tuples(st.just("swap"), fraction, fraction),
)


def mutate(data: bytes, ops) -> bytes:
    """``data`` with the mutations ``ops`` applied in turn (positions are fractions of the current size)."""
    for op in ops:
        lines = data.splitlines(keepends=True) or [b""]
        at = min(int(op[1] * len(lines)), len(lines) - 1)
        if op[0] == "truncate":
            data = data[:int(op[1] * len(data))]
        elif op[0] == "flip" and data:
            k = min(int(op[1] * len(data)), len(data) - 1)
            data = data[:k] + bytes([op[2]]) + data[k + 1:]
        elif op[0] == "field":
            found = list(NUMBER.finditer(lines[at]))
            if found:
                m = found[op[2] % len(found)]
                lines[at] = lines[at][:m.start()] + op[3].encode() + lines[at][m.end():]
            data = b"".join(lines)
        elif op[0] == "scale":
            lo, hi = sorted((at, min(int(op[2] * len(lines)), len(lines) - 1)))
            for i in range(lo, hi + 1):
                lines[i] = NUMBER.sub(lambda m, f=op[3]: _scaled(m.group(), f), lines[i])
            data = b"".join(lines)
        elif op[0] == "duplicate":
            data = b"".join(lines[:at + 1] + lines[at:at + op[2]] + lines[at + 1:])
        elif op[0] == "delete":
            data = b"".join(lines[:at] + lines[at + op[2]:])
        elif op[0] == "insert":
            data = b"".join(lines[:at] + [op[2]] + lines[at:])
        elif op[0] == "swap":
            j = min(int(op[2] * len(lines)), len(lines) - 1)
            lines[at], lines[j] = lines[j], lines[at]
            data = b"".join(lines)
    return data


def _scaled(token: bytes, factor: float) -> bytes:
    if b"." not in token:  # G/M/N codes, line numbers and flags stay; coordinates and feeds have a point
        return token
    return repr(float(token) * factor).encode()


# option values: valid ones (edges included), and bad ones (each must be refused in one line)
GOOD_OPTIONS = {
    "--feed": ["0.001", "5", "50", "250", "10000"],
    "--tolerance": ["0.001", "0.01", "0.1", "2", "1000"],
    "--rate": ["125", "500", "0.5", "10000"],
    "--corner": ["1", "30", "60", "180"],
    "--axis-jump": ["1", "45", "90"],
    "--feed-override": ["0.5", "1", "10"],
    "--rapid-speed": ["10", "250", "10000"],
    "--max-poses": ["1", "1000", "50000"],
    "--path": ["auto", "interpolate", "cam"],
    "--axes": ["auto", "file", "approach", "fixed", "path"],
    "--frame": ["rmf", "grm", "juttler", "er", "double-reflection"],
    "--units": ["mm", "m", "inch"],
    "--pass": ["0", "1", "2,3", "longest", "all"],
    "--cut-output": ["standard:0", "tool:1"],
}
BAD_OPTIONS = {
    "--feed": ["-5", "0", "nan", "1e400", "1e-9", "abc"],
    "--tolerance": ["0", "-1", "inf"],
    "--rate": ["1e-9", "0", "1e7"],
    "--corner": ["0", "200"],
    "--axis-jump": ["91"],
    "--feed-override": ["11", "0", "-1"],
    "--rapid-speed": ["0.0001", "-1"],
    "--max-poses": ["0", "1e13"],
    "--path": ["bogus"],
    "--axes": ["bogus"],
    "--pass": ["-1", "99", "x"],
    "--cut-output": ["tool:2", "spray"],
    "--machine": ["haas-umc-750", "bogus"],
}
good_options = st.lists(st.sampled_from(sorted(GOOD_OPTIONS)), max_size=3, unique=True).flatmap(
    lambda flags: st.tuples(*[st.tuples(st.just(f), st.sampled_from(GOOD_OPTIONS[f])) for f in flags]))
bad_option = st.sampled_from(sorted(BAD_OPTIONS)).flatmap(
    lambda f: st.tuples(st.just(f), st.sampled_from(BAD_OPTIONS[f])))
#: Mostly valid options (the mutated file decides), one run in six with a bad one beside them.
options = st.tuples(good_options, st.integers(0, 5), bad_option).map(
    lambda t: tuple(dict(t[0] + ((t[2],) if t[1] == 5 else ())).items()))
outputs = st.sampled_from([".csv", ".csv", ".json", ".json", ".job", ".script", ".txt"])


class Hang(BaseException):
    """A planner run past the deadline (BaseException: no ``except Exception`` in the planner swallows it)."""


@contextlib.contextmanager
def deadline(seconds: float):
    def alarm(signum, frame):
        raise Hang(f"no answer within {seconds:g} s")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, old)


def run_in_process(argv: list[str]) -> tuple[int, str, str]:
    """``planner.frontends.cli.main.main(argv)``: (exit status, stdout, stderr); an escaping exception or a hang fails the test."""
    out, err = io.StringIO(), io.StringIO()
    with (contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings(),
          np.errstate(all="ignore"), deadline(DEADLINE)):
        warnings.simplefilter("ignore")  # reader warnings are printed by the CLI; checked below on stdout
        try:
            rc = main(argv)
        except Hang as exc:
            pytest.fail(f"hang: planner {' '.join(argv)}: {exc}")
        except BaseException:  # noqa: BLE001 - the contract: nothing escapes main
            pytest.fail(f"traceback from planner {' '.join(argv)}:\n{traceback.format_exc()}")
    return rc, out.getvalue(), err.getvalue()


def check_output(path: Path, stdout: str) -> None:
    """The output file at ``path`` is valid and complete (parsed back whole)."""
    suffix = path.suffix
    if suffix == ".csv":
        text = path.read_text()
        assert text.endswith("\n")
        rows = [r for r in text.splitlines() if not r.startswith("#")]
        header = rows[0].split(",")
        assert header[:7] == ["t", "x", "y", "z", "rx", "ry", "rz"], header
        cols = [r.split(",") for r in rows[1:]]
        assert cols and all(len(c) == len(header) for c in cols)
        pose = np.array([[float(x) for x in c[:7]] for c in cols])
        _check_samples(pose, stdout, path)
    elif suffix == ".json":
        doc = json.loads(path.read_text())
        assert doc["format"] == "planner-trajectory/1"
        assert doc["columns"][:7] == ["t", "x", "y", "z", "rx", "ry", "rz"]
        samples = doc["samples"]
        assert doc["parameters"]["samples"] == len(samples)
        assert all(len(s) == len(doc["columns"]) for s in samples)
        _check_samples(np.array([s[:7] for s in samples], dtype=float), stdout, path)
    elif suffix == ".job":
        from planner.job import load_job

        job = load_job(path)
        assert f"wrote     {path} ({path.stat().st_size} bytes)" in stdout
        assert math.isfinite(job.duration) and job.duration >= 0.0
    elif suffix == ".script":
        from sim.urscript import compile_program

        text = path.read_text()
        assert text.startswith("def ") and text.rstrip().endswith("end")
        assert compile_program(text)  # every statement in the exporter's subset, numbers parsed
    else:
        raise AssertionError(f"exit 0 with an output type the planner has no writer for: {path.name}")


def _check_samples(pose: np.ndarray, stdout: str, path: Path) -> None:
    assert pose.ndim == 2 and pose.shape[1] == 7 and len(pose) >= 1
    assert np.isfinite(pose).all(), "non-finite pose in the output"
    assert np.all(np.diff(pose[:, 0]) > 0.0), "times not increasing"
    m = re.search(rf"wrote     {re.escape(str(path))} \((\d+) poses", stdout)
    assert m and int(m.group(1)) == len(pose), "the output holds fewer poses than reported"


#: What an output file holds before a run that should replace it on success and leave it untouched on failure.
PREVIOUS = b"an earlier output, kept unless the run succeeds\n"


def check_contract(input_path: Path, argv: list[str], out: Path, rc: int, stdout: str, stderr: str,
                   existed: bool = False) -> None:
    """The contract of the module docstring; ``existed``: the output file held :data:`PREVIOUS` before the run."""
    cmd = f"planner {' '.join(argv)}"
    left = sorted(p.name for p in out.parent.iterdir())
    assert "Traceback" not in stderr + stdout, cmd
    assert "encountered in" not in stdout, f"a numpy warning reached the user: {cmd}\n{stdout}"
    if rc == 0:
        assert left == sorted({input_path.name, out.name}), f"{cmd}: files left {left}"
        assert stderr == "", f"{cmd}: exit 0 with stderr {stderr!r}"
        check_output(out, stdout)
    else:
        assert rc in (2, 3), f"{cmd}: exit {rc}\n{stderr}"
        assert stderr.count("\n") == 1 and stderr.endswith("\n"), f"{cmd}: stderr is not one line:\n{stderr}"
        prefix = "planner: error: " if rc == 2 else "planner: internal error: "
        assert stderr.startswith(prefix) or (rc == 2 and stderr.startswith("planner plan: error: ")), stderr
        if existed:
            assert left == sorted({input_path.name, out.name}), f"{cmd}: exit {rc} and files left {left}"
            assert out.read_bytes() == PREVIOUS, f"{cmd}: exit {rc} and the existing output was changed"
        else:
            assert left == [input_path.name], f"{cmd}: exit {rc} and files left {left}"


def _fuzz_one(fmt: str, ops, opts, suffix: str, existing: bool = False) -> tuple[int, str]:
    name, seed, fixed = SEEDS[fmt]
    data = mutate(seed, ops)
    with tempfile.TemporaryDirectory(prefix="fuzz-") as tmp:
        src = Path(tmp) / name
        src.write_bytes(data)
        out = Path(tmp) / f"out{suffix}"
        if existing:
            out.write_bytes(PREVIOUS)
        flags = dict(opts)
        argv = ["plan", str(src), *fixed, "--max-poses", flags.pop("--max-poses", MAX_POSES), "-o", str(out)]
        for flag, value in flags.items():
            if flag == "--machine" and "--machine" in fixed:
                continue
            argv += [f"{flag}={value}"]
        if suffix == ".script":
            argv += ["--robot", "ur5e", "--part-frame", "400mm,996.5mm,-100mm,0,0,0"]
        try:
            rc, stdout, stderr = run_in_process(argv)
            check_contract(src, argv, out, rc, stdout, stderr, existing)
        except (AssertionError, pytest.fail.Exception) as exc:
            raise AssertionError(f"{exc}\n{_reproducer(fmt, ops, opts, data)}") from None
    return rc, stderr


def _reproducer(fmt: str, ops, opts, data: bytes) -> str:
    """Where the failing input is kept, and how it was made (this pytest/hypothesis setup prints the falsifying
    example's arguments empty, so the message carries them)."""
    folder = Path(tempfile.gettempdir()) / "planner-fuzz-failures"
    folder.mkdir(exist_ok=True)
    path = folder / f"{hashlib.sha1(data).hexdigest()[:12]}-{SEEDS[fmt][0]}"
    path.write_bytes(data)
    return f"reproducer: {path} (seed {fmt}, mutations {list(ops)!r}, options {list(opts)!r})"


FUZZ_SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=not FUZZ,
                         suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@pytest.mark.parametrize("fmt", sorted(SEEDS))
@FUZZ_SETTINGS
@given(ops=st.lists(mutation, max_size=4), opts=options, suffix=outputs, existing=st.booleans())
def test_mutated_inputs_keep_the_contract(fmt, ops, opts, suffix, existing):
    rc, stderr = _fuzz_one(fmt, ops, opts, suffix, existing)
    event(f"exit {rc}" + (f": {stderr.split(': ')[2][:40]}" if rc and stderr.count(": ") > 1 else ""))


@pytest.mark.parametrize("fmt", ["csv", "json", "cls"])
@FUZZ_SETTINGS
@given(ops=st.lists(mutation, max_size=4), method=st.sampled_from(["C1", "C2", "cubic", "all"] * 3 + ["C3"]),
       units=st.sampled_from([None, "mm", "m", "inch"] * 3 + ["km"]))
def test_planner_fit_keeps_the_contract(fmt, ops, method, units):
    """``planner fit`` on mutated waypoint files: exit 0 with the fit figures, or one line on stderr and exit 2."""
    name, seed, _ = SEEDS[fmt]
    with tempfile.TemporaryDirectory(prefix="fuzz-") as tmp:
        src = Path(tmp) / name
        src.write_bytes(mutate(seed, ops))
        argv = ["fit", str(src), "--method", method] + ([] if units is None else ["--units", units])
        try:
            rc, stdout, stderr = run_in_process(argv)
        except pytest.fail.Exception as exc:
            raise AssertionError(f"{exc}\n{_reproducer(fmt, ops, (), mutate(seed, ops))}") from None
        event(f"exit {rc}")
        cmd = f"planner {' '.join(argv)}"
        assert "Traceback" not in stdout + stderr and "encountered in" not in stdout, cmd
        assert sorted(p.name for p in Path(tmp).iterdir()) == [name], cmd  # fit writes nothing
        if rc == 0:
            assert stderr == "" and f"{name}: " in stdout and "waypoints" in stdout, cmd
            lengths = [float(x) for x in re.findall(r"length (\S+) mm", stdout)]
            assert lengths and all(math.isfinite(x) and x > 0.0 for x in lengths), cmd
        else:
            assert rc in (2, 3) and stderr.count("\n") == 1, f"{cmd}: exit {rc}\n{stderr}"


@pytest.mark.parametrize("fmt", sorted(SEEDS))
def test_every_seed_plans_unmutated(fmt):
    """The seeds themselves plan (exit 0): the mutations start from valid inputs."""
    _fuzz_one(fmt, [], (), ".csv")


@pytest.mark.parametrize("fmt, ops, opts, suffix", [
    ("csv", [("field", 0.5, 0, "1e308")], (), ".json"),
    ("cls", [("truncate", 0.55)], (), ".csv"),
    ("gcode", [("scale", 0.3, 0.9, 1e6)], (), ".csv"),
    ("json", [("field", 0.3, 2, "nan")], (("--units", "m"),), ".csv"),
    ("apt", [("duplicate", 0.4, 3)], (("--feed", "-5"),), ".csv"),
])
def test_through_a_subprocess(fmt, ops, opts, suffix):
    """A few through ``python -m planner.frontends.cli.main``: stderr is the process's own (warnings, tracebacks, exit status)."""
    name, seed, fixed = SEEDS[fmt]
    with tempfile.TemporaryDirectory(prefix="fuzz-") as tmp:
        src = Path(tmp) / name
        src.write_bytes(mutate(seed, ops))
        out = Path(tmp) / f"out{suffix}"
        argv = ["plan", str(src), *fixed, "--max-poses", MAX_POSES, "-o", str(out), *[f"{k}={v}" for k, v in opts]]
        p = subprocess.run([sys.executable, "-m", "planner.frontends.cli", *argv], capture_output=True, text=True,
                           timeout=DEADLINE + 30, cwd=tmp, env={**os.environ, "PYTHONWARNINGS": "default"})
        check_contract(src, argv, out, p.returncode, p.stdout, p.stderr)


#: Where ``-o`` points (issue 24): links whose end gets the output, and targets refused before anything is read.
WRITTEN_THROUGH = ["link", "chain", "dangling link", "linked folder"]
REFUSED = ["dangling into a missing folder", "loop", "fifo", "device", "directory", "socket", "input by a link",
           "input by a hard link"]


def _output_target(folder: Path, kind: str, suffix: str, src: Path) -> tuple[Path, Path | None]:
    """The ``-o`` name of ``kind`` made in ``folder``, and the file the output must land in (None: refused)."""
    import socket

    name = folder / f"out{suffix}"
    store = folder / "store"
    store.mkdir()
    real = store / f"real{suffix}"
    if kind in ("link", "chain", "linked folder"):
        real.write_bytes(PREVIOUS)
    if kind == "link":
        name.symlink_to(f"store/real{suffix}")
    elif kind == "chain":
        (folder / f"mid{suffix}").symlink_to(real)
        name.symlink_to(f"mid{suffix}")
    elif kind == "dangling link":
        name.symlink_to(f"store/real{suffix}")
    elif kind == "linked folder":
        (folder / "linked").symlink_to("store")
        name = folder / "linked" / f"real{suffix}"
    elif kind == "dangling into a missing folder":
        name.symlink_to(f"missing/real{suffix}")
    elif kind == "loop":
        name.symlink_to(f"out{suffix}")
    elif kind == "fifo":
        os.mkfifo(name)
    elif kind == "device":
        try:
            os.mknod(name, 0o666 | 0o020000, os.makedev(1, 3))  # a character device: the null device
        except OSError:
            name.symlink_to("/dev/null")
    elif kind == "directory":
        name.mkdir()
    elif kind == "socket":
        with contextlib.closing(socket.socket(socket.AF_UNIX)) as s:
            s.bind(str(name))
    elif kind == "input by a link":
        name.symlink_to(src.name)
    elif kind == "input by a hard link":
        os.link(src, name)
    return name, (real if kind in WRITTEN_THROUGH else None)


def _tree(folder: Path) -> dict:
    return {str(p.relative_to(folder)): (os.lstat(p).st_mode, os.readlink(p) if p.is_symlink() else None)
            for p in sorted(folder.rglob("*"))}


@pytest.mark.parametrize("fmt", ["csv", "apt"])
@FUZZ_SETTINGS
@given(ops=st.lists(mutation, max_size=3), kind=st.sampled_from(WRITTEN_THROUGH + REFUSED),
       suffix=st.sampled_from([".csv", ".json", ".job"]))
def test_outputs_through_links_and_onto_special_files_keep_the_contract(fmt, ops, kind, suffix):
    """``-o`` through links (written at their end, the links kept) and onto what is not a regular file (a FIFO, a
    device, a socket, a directory, a loop, the input itself): refused in one line, exit 2, before reading anything,
    and left as it was. A mutated input that fails leaves the link's target as it was and no temporary file."""
    name_in, seed, fixed = SEEDS[fmt]
    data = mutate(seed, ops)
    with tempfile.TemporaryDirectory(prefix="fuzz-") as tmp:
        folder = Path(tmp)
        src = folder / name_in
        src.write_bytes(data)
        out, real = _output_target(folder, kind, suffix, src)
        before = _tree(folder)
        existed = real is not None and real.exists()
        argv = ["plan", str(src), *fixed, "--max-poses", MAX_POSES, "-o", str(out)]
        rc, stdout, stderr = run_in_process(argv)
        cmd = f"planner {' '.join(argv)} ({kind})"
        assert "Traceback" not in stdout + stderr, cmd
        assert src.read_bytes() == data, f"{cmd}: the input changed"
        links = {k: v for k, v in before.items() if v[1] is not None}
        assert {k: v for k, v in _tree(folder).items() if v[1] is not None} == links, f"{cmd}: a link changed"
        assert not list(folder.rglob(".*.part")), f"{cmd}: a temporary file was left"
        if real is None:
            assert rc == 2 and stdout == "", f"{cmd}: exit {rc}\n{stdout}{stderr}"
            assert stderr.startswith(f"planner: error: -o {out}: ") and stderr.count("\n") == 1, stderr
            assert _tree(folder) == before, f"{cmd}: the refused target changed"
            event(f"refused: {kind}")
        elif rc == 0:
            assert stderr == "", cmd
            check_output(out, stdout)  # read through the links: the output is at their end
            assert not real.is_symlink() and real.read_bytes() != PREVIOUS, cmd
            event(f"written through: {kind}")
        else:
            assert rc in (2, 3) and stderr.count("\n") == 1, f"{cmd}: exit {rc}\n{stderr}"
            assert (real.read_bytes() == PREVIOUS) if existed else not real.exists(), f"{cmd}: the target changed"
            event(f"input refused: {kind}")


# ---------------------------------------------------------------------------- encodings and cycle words (issue 24)
#: encoding -> how a text is written in it (as editors and CAM systems on Windows write UTF-16, with or without mark).
ENCODINGS = {
    "utf-8-bom": lambda t: "\ufeff".encode() + t.encode(),
    "utf-16-le-bom": lambda t: t.encode("utf-16"),  # little endian with its mark on this platform's codec
    "utf-16-be-bom": lambda t: b"\xfe\xff" + t.encode("utf-16-be"),
    "utf-16-le": lambda t: t.encode("utf-16-le"),
    "utf-16-be": lambda t: t.encode("utf-16-be"),
    "utf-32": lambda t: t.encode("utf-32"),
}
#: Fewer examples than the mutation fuzz (3 per format by default, 250 in the long profile): each plans twice.
ENCODED_SETTINGS = settings(max_examples=max(3, EXAMPLES // 4), deadline=None, derandomize=not FUZZ,
                            suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _plan_file(folder: Path, name: str, data: bytes, fixed: list[str]) -> tuple[int, str, str, Path]:
    """``planner plan`` of ``data`` saved as ``folder/name`` with a CSV output: (exit, stdout, stderr, input path),
    the contract checked."""
    src = folder / name
    src.write_bytes(data)
    out = folder / "out.csv"
    argv = ["plan", str(src), *fixed, "--max-poses", MAX_POSES, "-o", str(out)]
    rc, stdout, stderr = run_in_process(argv)
    check_contract(src, argv, out, rc, stdout, stderr)
    return rc, stdout, stderr, src


@pytest.mark.parametrize("fmt", sorted(SEEDS))
@ENCODED_SETTINGS
@given(ops=st.lists(mutation, max_size=3), encoding=st.sampled_from(sorted(ENCODINGS)))
def test_encoded_inputs_plan_like_their_utf8_text(fmt, ops, encoding):
    """A mutated seed written in UTF-16 (either mark, or none), UTF-32 or UTF-8 with a mark keeps the contract and
    gives what its text gives in UTF-8: the same exit status, the same one-line error (same line, same field) or the
    same summary. (Text holding NUL characters only keeps the contract: in UTF-8 it is binary data.)"""
    name, seed, fixed = SEEDS[fmt]
    text = mutate(seed, ops).decode("utf-8", errors="replace").lstrip("\ufeff")
    data = ENCODINGS[encoding](text)
    with tempfile.TemporaryDirectory(prefix="fuzz-") as a, tempfile.TemporaryDirectory(prefix="fuzz-") as b:
        try:
            rc, stdout, stderr, src = _plan_file(Path(a), name, data, fixed)
            event(f"{encoding}: exit {rc}")
            if "\x00" in text:
                return
            rc8, stdout8, stderr8, src8 = _plan_file(Path(b), name, text.encode(), fixed)
            assert rc == rc8, (stderr, stderr8)
            assert stderr.replace(a, "") == stderr8.replace(b, "")
            summary = [s.replace(a, "") for s in stdout.splitlines() if " -> " in s]
            assert summary == [s.replace(b, "") for s in stdout8.splitlines() if " -> " in s]
        except (AssertionError, pytest.fail.Exception) as exc:
            raise AssertionError(f"{exc}\n{_reproducer(fmt, ops, (('encoding', encoding),), data)}") from None


#: A real SOLIDWORKS CAM file whose line 16 is its first cycle record (CYCLE/DEEP2 with 1STPECK and SUBPECK).
SIDE_DRILL = (DATA / "solidworks_cam_apt_side_drill.apt").read_bytes().decode().splitlines(keepends=True)
CYCLE_LINE = 16
#: Every word a CYCLE record may hold, and the values they take.
CYCLE_KINDS = ["DRILL", "DEEP", "DEEP2", "BRKCHP", "TAP", "BORE", "REAM"]
CYCLE_WORDS = {"FEDTO": ["5.03163", "-4", "0.5"], "RAPTO": ["3.", "0"], "RTRCTO": ["25.", "AUTO", "63."],
               "STEP": ["2.", "0.7"], "INCR": ["1."], "1STPECK": ["5.", "1.5"], "SUBPECK": ["2.", "30."],
               "DWELL": ["0", "1.5", ""], "MMPM": ["382.27", "100"], "IPM": ["10."], "MMPR": ["0.1"],
               "DEEP": [""], "BRKCHP": [""], "DRAG": [""], "DEEP2": [""]}
KNOWN_CYCLE = set(CYCLE_KINDS) | set(CYCLE_WORDS) | {"OFF", "ON", "INIT", "CLEAR", "AUTO", "IPS", "MMPS", "IPR",
                                                     "NODRAG", "BACK", "MANUAL"}


def _is_number(word: str) -> bool:
    try:
        float(word.replace("D", "E"))
    except ValueError:
        return False
    return True


unknown_word = st.from_regex(r"\A[0-9]?[A-Z][A-Z0-9]{0,7}\Z").filter(
    lambda w: w not in KNOWN_CYCLE and not _is_number(w))
cycle_pair = st.sampled_from(sorted(CYCLE_WORDS)).flatmap(
    lambda w: st.tuples(st.just(w), st.sampled_from(CYCLE_WORDS[w])))
cycle_token = st.one_of(st.sampled_from(sorted(KNOWN_CYCLE)), unknown_word, st.sampled_from(NASTY),
                        st.floats(allow_nan=True, allow_infinity=True).map(repr))


def _cycle_file(record: str) -> bytes:
    lines = list(SIDE_DRILL)
    lines[CYCLE_LINE - 1] = record + "\n"
    return "".join(lines).encode()


@ENCODED_SETTINGS
@given(kind=st.one_of(st.sampled_from(CYCLE_KINDS + ["INIT", "OFF", "ON", "CLEAR"]), unknown_word),
       tokens=st.lists(cycle_token, max_size=10))
def test_cycle_records_with_random_words_keep_the_contract(kind, tokens):
    """CYCLE/<kind>,<random words and values> in a real SOLIDWORKS file: exit 0 with valid output, or one line."""
    record = "CYCLE/" + ",".join([kind, *tokens])
    with tempfile.TemporaryDirectory(prefix="fuzz-") as tmp:
        rc, _, stderr, _ = _plan_file(Path(tmp), "cycle.apt", _cycle_file(record), [])
        event(f"exit {rc}")
        if kind not in KNOWN_CYCLE:  # an unknown cycle is refused naming it, whatever follows
            assert rc == 2 and f"line {CYCLE_LINE}" in stderr and repr(kind) in stderr, (record, stderr)


@ENCODED_SETTINGS
@given(kind=st.sampled_from(CYCLE_KINDS), pairs=st.lists(cycle_pair, max_size=6), word=unknown_word,
       at=st.floats(0.0, 1.0))
def test_one_unknown_cycle_word_is_named_with_the_words_known(kind, pairs, word, at):
    """A readable cycle record (FEDTO first) with one unknown word put anywhere after its type: refused on its line,
    the message naming the word (and, where it stands as a keyword, the keywords the reader knows)."""
    fields = [kind, "FEDTO", "5.03163"] + [x for w, v in pairs for x in ((w, v) if v else (w,))]
    k = 1 + int(at * (len(fields) - 1))
    fields.insert(k, word)
    record = "CYCLE/" + ",".join(fields)
    with tempfile.TemporaryDirectory(prefix="fuzz-") as tmp:
        rc, _, stderr, _ = _plan_file(Path(tmp), "cycle.apt", _cycle_file(record), [])
    assert rc == 2 and stderr.startswith(f"planner: error: cycle.apt line {CYCLE_LINE}, field "), (record, stderr)
    assert repr(word) in stderr, (record, stderr)
    if "is neither a number nor a CYCLE keyword" in stderr:
        assert "1STPECK, SUBPECK" in stderr and "FEDTO" in stderr


# -- fits and plans through waypoints that turn back, and at any scale (issue 24) ---------------------------------
#
# Each example is bounded by design: at most 9 (fit) or 8 (plan) waypoints, the G1 PH cubic's halving stops at
# MAX_OPEN_PIECES pieces per span and level, a plan is capped at MAX_POSES poses (more is a BudgetError).

#: Shapes of waypoints that turn back on themselves.
TURNS = ("back", "short", "cusp", "line", "near", "aba")


@st.composite
def turning_back(draw):
    """(waypoints (n, 3) in metres, kind): a random polyline whose turns are made to turn back: exactly to the
    previous waypoint ("back"), short of it or beyond along the last step ("short": antiparallel steps), a cusp in
    the middle of a spatial path ("cusp"), every waypoint on one line with reversals ("line"), such a line off by
    1e-17..1e-9 of its size ("near", within and beyond round-off), or 0 / b / 0 / b ... ("aba"); then rotated,
    scaled by 1e-9..1e9 and moved by up to 100 times its size."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(3, 9))
    kind = draw(st.sampled_from(TURNS))
    p = np.cumsum(rng.normal(size=(n, 3)), axis=0)
    if kind in ("back", "short"):
        for k in sorted(rng.choice(np.arange(1, n - 1), size=rng.integers(1, n - 1), replace=False)):
            step = p[k] - p[k - 1]
            p[k + 1:] += (p[k] - (1.0 if kind == "back" else rng.uniform(0.1, 3.0)) * step) - p[k + 1]
    elif kind == "cusp":
        k = int(rng.integers(1, n - 1))
        p[k + 1:] += p[k] - rng.uniform(0.2, 2.0) * (p[k] - p[k - 1]) - p[k + 1]
    elif kind in ("line", "near"):
        x = np.cumsum(rng.choice([-1.0, 1.0], size=n) * np.exp(rng.normal(size=n)))
        p = x[:, None] * np.array([1.0, 0.0, 0.0])
        if kind == "near":
            p += rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-17, -9) * np.abs(x).max()
    else:
        p = np.array([np.zeros(3), rng.normal(size=3)] * n)[:n]
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    scale = 10.0 ** draw(st.floats(-9.0, 9.0))
    p = (p @ (q * np.sign(np.diag(r))).T) * scale + rng.normal(size=3) * scale * draw(st.sampled_from([0.0, 1.0, 100.0]))
    return p, kind


@contextlib.contextmanager
def member_rule(compiled: bool):
    """The compiled member rule (as built) or the numpy one (an install without a C compiler) for the block."""
    from planner.curves import ph_quintic

    kept = ph_quintic._hermite_member
    assert kept is not None, "the compiled member rule is not built"
    ph_quintic._hermite_member = kept if compiled else None
    try:
        yield
    finally:
        ph_quintic._hermite_member = kept


def _line_distance(points: np.ndarray, p: np.ndarray) -> float:
    """Largest distance (m) of ``points`` (..., 3) from the line through the first waypoint and the one furthest."""
    r = p - p[0]
    e = r[np.argmax(np.einsum("ij,ij->i", r, r))]
    e = e / np.linalg.norm(e)
    d = points.reshape(-1, 3) - p[0]
    return float(np.linalg.norm(d - np.outer(d @ e, e), axis=1).max())


@FUZZ_SETTINGS
@given(case=turning_back(), continuity=st.sampled_from(["C1", "C2"]))
def test_fits_through_waypoints_that_turn_back(case, continuity):
    """fit_ph_spline through reversals, cusps and antiparallel steps: a finite path through every waypoint (to
    round-off of the coordinates), or a PlannerError naming a waypoint; never nan, never a NumericalError. The
    compiled and the numpy member rules give the same path (but where the data are within a few ulps of a line
    that turns back: there members tie to round-off). On one line the C1 path is straight."""
    from planner.curves.spline import fit_ph_spline
    from planner.errors import PlannerError

    p, kind = case
    event(kind)
    size = float(np.abs(p).max())
    fits = []
    for compiled in (True, False):
        with member_rule(compiled), np.errstate(all="ignore"):
            try:
                s = fit_ph_spline(p, continuity=continuity)
            except PlannerError as exc:
                assert "waypoint" in str(exc), str(exc)
                event(f"refused: {str(exc)[:40]}")
                return
        assert np.isfinite(s.A).all() and math.isfinite(s.length) and s.length > 0.0
        assert s.interpolation_errors(p).max() <= 1e-12 * size
        if kind in ("line", "aba") and continuity == "C1":
            assert _line_distance(s.control_points, p) <= 1e-12 * size
        fits.append(s.control_points)
    if kind != "near":
        assert np.abs(fits[0] - fits[1]).max() <= 1e-9 * size


def test_planner_fit_through_a_reversal_in_a_subprocess():
    """The issue's file through ``python -m planner.frontends.cli fit``: C1 length 2 mm (it printed nan), C2 a finite length
    (it ended in an internal error), the G1 cubic refused in one line naming waypoint 1; no numpy warning."""
    with tempfile.TemporaryDirectory(prefix="fuzz-") as tmp:
        (Path(tmp) / "aba.csv").write_text("x,y,z\n0,0,0\n1,0,0\n0,0,0\n")
        p = subprocess.run([sys.executable, "-m", "planner.frontends.cli", "fit", "aba.csv"], capture_output=True, text=True,
                           timeout=DEADLINE + 30, cwd=tmp, env={**os.environ, "PYTHONWARNINGS": "default"})
    lengths = dict(re.findall(r"(C1|C2) PH quintic spline .* length (\S+) mm", p.stdout))
    assert float(lengths["C1"]) == 2.0 and 2.0 < float(lengths["C2"]) < 3.0, p.stdout
    assert "stops and turns back at waypoint 1" in p.stdout and "nan" not in p.stdout, p.stdout
    assert p.returncode == 2 and p.stderr.count("\n") == 1, p.stderr
    assert p.stderr.startswith("planner: error: waypoint 1: "), p.stderr


#: Scales of waypoints (steps of 0.05..2 before scaling): sub-micrometre ones drawn often, and 1e-9..1e9.
scales = st.one_of(st.sampled_from([1e-9, 3e-8, 1e-7, 1e-6, 2e-6]), st.floats(-9.0, 9.0).map(lambda e: 10.0**e))


@FUZZ_SETTINGS
@given(p=waypoint_sets(max_size=9), scale=scales, method=st.sampled_from(["C1", "C2", "cubic"]))
def test_scaled_waypoints_fit(p, scale, method):
    """Any scale a robot cell (or a float) holds: the fit of the scaled waypoints is the fit scaled, through every
    waypoint to round-off of the coordinates, with a finite length; the G1 cubic with at most MAX_OPEN_PIECES pieces
    per span and level (a refusal names the span)."""
    from planner.curves.ph_cubic_spline import fit_ph_cubic_spline
    from planner.curves.spline import fit_ph_spline
    from planner.errors import NoSolutionError

    event(f"scale 1e{math.floor(math.log10(scale)):d}")
    P = p * scale
    fit = fit_ph_cubic_spline if method == "cubic" else lambda q: fit_ph_spline(q, continuity=method)
    try:
        s, unit = fit(P), fit(p)
    except NoSolutionError as exc:
        assert method == "cubic" and re.search(r"between waypoints \d+ and \d+", str(exc)), str(exc)
        return
    assert np.isfinite(s.A).all() and math.isfinite(s.length) and s.length > 0.0
    assert s.interpolation_errors(P).max() <= 1e-12 * np.abs(P).max()
    if method != "cubic":  # (the shortest of the G1 cubics found may be another at another scale)
        assert s.length == pytest.approx(unit.length * scale, rel=1e-9)


@FUZZ_SETTINGS
@given(p=waypoint_sets(max_size=8), scale=scales, path=st.sampled_from(["interpolate", "cam"]))
def test_scaled_waypoints_plan(p, scale, path):
    """planner.plan of scaled waypoints: a finite duration and finite poses, or a PlannerError (coordinates beyond a
    robot cell: the budget, before any work; steps below a nanometre merge), never a sample count that explodes
    (capped: a BudgetError) or a traceback. Between 1e-6 and 100 times (steps of 50 nm to 200 m) it plans."""
    from planner import plan
    from planner.errors import PlannerError
    from planner.settings import PlanSettings

    event(f"scale 1e{math.floor(math.log10(scale)):d}")
    with np.errstate(all="ignore"), deadline(DEADLINE):
        try:
            job = plan(p * scale, PlanSettings(path=path, max_poses=float(MAX_POSES)))
        except PlannerError as exc:
            assert not 1e-6 <= scale <= 100.0, f"scale {scale:g}: {exc}"
            event(f"refused: {str(exc)[:40]}")
            return
        except Hang as exc:
            pytest.fail(f"hang: plan at scale {scale:g}: {exc}")
        trajectory = job.trajectory()
        assert math.isfinite(job.duration) and job.duration > 0.0
        assert 1 < trajectory.n_samples <= float(MAX_POSES) + len(job.moves) + 1
        for chunk in trajectory.chunks():
            assert np.isfinite(chunk.poses).all() and np.isfinite(chunk.times).all()
