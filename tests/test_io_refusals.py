"""Readers refuse what they cannot mean (issue 17): G-code numbers in exponent notation, motion after the end of
the program, JSON keys given twice and JSON nested without end, tool axes with components beyond the float range;
each with the file and line. The readers' and plan()'s arguments: each bad one refused with a PlannerError naming it
(a named choice lists the known values), before any file is opened or any work is done."""

from __future__ import annotations

import io
import math
import numbers
import pickle
import re

import numpy as np
import pytest

from planner import PlanSettings, plan
from planner.errors import PlannerError
from planner.io import InputFileError, linearize_arcs, read_apt, read_csv, read_gcode, read_json, read_toolpath
from planner.io.options import ReaderArgumentError
from planner.validation import ArgumentError


def test_gcode_exponent_notation_is_refused_with_its_line(tmp_path):
    f = tmp_path / "exp.nc"
    f.write_text("G21\nG90\nG1 X0 Y0 Z0 F100\nG1 X1e3 Y0\n")
    with pytest.raises(InputFileError, match=r"exp.nc line 4, word X: 'X1e3' is in exponent notation"):
        read_toolpath(f)
    f.write_text("G21\nG90\nG1 X0 Y0 Z0 F1.5E-3\n")
    with pytest.raises(InputFileError, match=r"line 3, word F: 'F1.5E-3' is in exponent notation"):
        read_toolpath(f)


def test_gcode_motion_after_m30_is_not_planned_and_warned(tmp_path):
    f = tmp_path / "m30.nc"
    f.write_text("G21\nG90\nG1 X0 Y0 Z0 F100\nG1 X10 Y0\nM30\nG1 X5 Y5\n")
    job = plan(f)
    assert len(job.toolpath) == 2 and job.toolpath.points[-1][0] == pytest.approx(0.01)
    assert any("line 6: 1 non-blank line(s) after M30 (end of program) at line 5 ignored" in w for w in job.warnings)


def test_json_duplicate_keys_and_deep_nesting_are_refused(tmp_path):
    f = tmp_path / "dup.json"
    f.write_text('{"units": "mm", "points": [\n {"x": 0, "y": 0, "z": 0},\n {"x": 10, "y": 0, "z": 0, "x": 5}]}')
    with pytest.raises(InputFileError, match=r"dup.json line 3, key 'x': appears twice in one object"):
        read_toolpath(f)
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(InputFileError, match="nested too deeply"):
        read_toolpath(deep)


# ------------------------------------------------------------------ a tool axis component of 1e308 (issue 17)
def _cli(argv: list[str]) -> tuple[int, str]:
    """``planner.frontends.cli.main.main(argv)`` in-process: (exit status, stderr); any escaping exception fails the test."""
    import contextlib
    import io
    import traceback
    import warnings

    from planner.frontends.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            rc = main(argv)
        except BaseException:  # noqa: BLE001 - the contract: nothing escapes main
            pytest.fail(f"traceback from planner {' '.join(argv)}:\n{traceback.format_exc()}")
    return rc, err.getvalue()


HUGE_AXIS = [
    ("a.csv", "x,y,z,i,j,k\n0,0,0,0,0,1\n1,0,0,1e308,0,1\n2,1,0,0,0,1\n",
     r"a\.csv line 3, columns i,j,k: tool axis \(1e\+308, 0, 1\) is not a unit vector \(length 1e\+308"),
    ("b.csv", "x,y,z,i,j,k\n0,0,0,0,0,1\n1,0,0,-1.5e308,-1.5e308,1\n2,1,0,0,0,1\n",
     r"b\.csv line 3, columns i,j,k: tool axis \(-1\.5e\+308, -1\.5e\+308, 1\) is not a unit vector \(length inf, "),
    ("a.json", '[{"x": 0, "y": 0, "z": 0, "i": 0, "j": 0, "k": 1},\n {"x": 1, "y": 0, "z": 0, "i": 1e308, "j": 0, '
     '"k": 1},\n {"x": 2, "y": 1, "z": 0, "i": 0, "j": 0, "k": 1}]\n',
     r"a\.json line 2, \[1\]: tool axis \(1e\+308, 0, 1\) is not a unit vector \(length 1e\+308\)"),
    ("b.json", '{"points": [[0, 0, 0], [1, 0, 0], [2, 1, 0]],\n "axes": [[0, 0, 1], null,\n [0, 1e308, 1e308]]}\n',
     r"b\.json line 3, axes\[2\]: tool axis \(0, 1e\+308, 1e\+308\) is not a unit vector \(length 1\.41421356e\+308"),
    ("a.apt", "GOTO/0,0,9\nCYCLE/DRILL,FEDTO,-4,RAPTO,1\nGOTO/0,0,0,1e308,0,1\n",
     r"a\.apt line 3, fields 4-6 of GOTO: tool axis \(1e\+308, 0\.0, 1\.0\) is not a unit vector \(length 1e\+308\)"),
    ("b.apt", "GOTO/0,0,9\nGOTO/0,0,0,1e308,0,1\n",
     r"b\.apt line 2, fields 4-6 of GOTO: tool axis \(1e\+308, 0, 1\) is not a unit vector \(length 1e\+308"),
]


@pytest.mark.parametrize("name, text, message", HUGE_AXIS, ids=[h[0] for h in HUGE_AXIS])
def test_a_tool_axis_component_of_1e308_is_refused_with_its_line(tmp_path, name, text, message):
    f = tmp_path / name
    f.write_text(text)
    with pytest.raises(InputFileError, match=message):
        read_toolpath(f)
    rc, err = _cli(["plan", str(f)])
    assert rc == 2 and len(err.splitlines()) == 1 and err.startswith("planner: error: "), err
    assert re.search(message, err), err
    if name.endswith(".json"):  # planner fit reads JSON points too
        rc, err = _cli(["fit", str(f)])
        assert rc == 2 and re.search(message, err) and len(err.splitlines()) == 1, err


def test_a_huge_axis_is_normalised_where_asked(tmp_path):
    """``normalize_axes``: a vector with a component of 1e308 has a direction; it is kept, not overflowed."""
    f = tmp_path / "n.csv"
    f.write_text("x,y,z,i,j,k\n0,0,0,0,0,1\n1,0,0,1e308,0,1e308\n2,1,0,0,0,3\n")
    tp = read_csv(f, normalize_axes=True)
    np.testing.assert_allclose(tp.axes, [[0, 0, 1], [2**-0.5, 0, 2**-0.5], [0, 0, 1]], rtol=0, atol=1e-15)
    g = tmp_path / "n.json"
    g.write_text('[{"x": 0, "y": 0, "z": 0, "i": -1.7e308, "j": 0, "k": 0}, {"x": 1, "y": 0, "z": 0}]')
    np.testing.assert_allclose(read_json(g, normalize_axes=True).axes, [[-1, 0, 0], [-1, 0, 0]], rtol=0, atol=0)


# ------------------------------------------------------------------ the readers' arguments (issue 17)
#: Valid small files of every format (1 mm steps; the G-code turns the Haas UMC-750's B axis).
FILES = {
    "apt": "GOTO/0,0,0,0,0,1\nGOTO/1,0,0\nCIRCLE/1,1,0,0,0,1,1\nGOTO/2,1,0\n",
    "csv": "x,y,z,i,j,k\n0,0,0,0,0,1\n1,0,0,0,0,1\n2,1,0,0,0,1\n",
    "json": '[{"x": 0, "y": 0, "z": 0}, {"x": 1, "y": 0, "z": 0}, {"x": 2, "y": 1, "z": 0}]',
    "nc": "G21 G90\nG1 X0 Y0 Z0 F100\nG1 X1\nG2 X2 Y1 I0 J1\n",
}
READER = {"apt": read_apt, "csv": read_csv, "json": read_json, "nc": read_gcode}
UNITS = r"'mm', 'm', 'inch'"
FEED_UNITS = r"'mm/min', 'mm/s', 'm/min', 'm/s', 'in/min', 'inch/min', 'in/s', 'inch/s'"
ARC = r"positive, a length in metres in \[1e-09, 1\]"

#: (format, option, bad value, the message after "<option> ") for every reader option.
BAD_OPTIONS = [
    ("apt", "units", "bogus", f"must be one of {UNITS}, got 'bogus'"),
    ("csv", "units", 5, f"must be one of {UNITS}, got 5"),
    ("json", "units", "furlong", f"must be one of {UNITS}, got 'furlong'"),
    ("nc", "units", None, f"must be one of {UNITS}, got None"),
    ("csv", "feed_units", "mm/h", f"must be one of {FEED_UNITS}, got 'mm/h'"),
    ("json", "feed_units", 1.0, f"must be one of {FEED_UNITS}, got 1.0"),
    ("apt", "arc_tolerance", 0, f"must be {ARC}, got 0.0"),
    ("apt", "arc_tolerance", math.nan, f"must be {ARC}, got nan"),
    ("apt", "arc_tolerance", "x", f"must be {ARC}, got the string 'x'"),
    ("apt", "arc_tolerance", 1e-300, f"must be {ARC}, got 1e-300"),
    ("nc", "arc_tolerance", -1e-5, f"must be {ARC}, got -1e-05"),
    ("nc", "arc_tolerance", 1j, f"must be {ARC}, got the complex number 1j"),
    ("apt", "axis_tolerance", math.nan, r"must be a number in \[0, 0.5\], got nan"),
    ("csv", "axis_tolerance", math.nan, r"must be a number in \[0, 0.5\], got nan"),
    ("json", "axis_tolerance", math.inf, r"must be a number in \[0, 0.5\], got inf"),
    ("csv", "axis_tolerance", 1.0, r"must be a number in \[0, 0.5\], got 1.0"),
    ("csv", "axis_tolerance", True, r"must be a number in \[0, 0.5\], got the boolean True"),
    ("apt", "frames", "all", r"must be one of 'auto' or 'none', got 'all'"),
    ("nc", "dialect", "heidenhain", r"must be one of 'auto', 'iso' or 'sinumerik', got 'heidenhain'"),
    ("nc", "machine", "bogus", r"'bogus': unknown machine; presets: 'haas-umc-750' \(or give a TableTableKinematics\)"),
    ("nc", "machine", 5, r"must be a preset name \('haas-umc-750'\) or a TableTableKinematics, got 5"),
    ("nc", "peck_clearance", "x", r"must be a length in metres in \(0, 1\), got the string 'x'"),
    ("apt", "peck_clearance", 1.0, r"must be a length in metres in \(0, 1\), got 1.0"),
    ("csv", "delimiter", 5, r"must be one character such as .*, got 5"),
    ("csv", "delimiter", ",;", r"must be one character such as .*, got the string ',;'"),
    ("csv", "normalize_axes", "yes", r"must be True or False, got the string 'yes'"),
    ("json", "source", 5, r"must be a string \(the name messages use\) or None, got 5"),
]


@pytest.mark.parametrize("fmt, option, value, message", BAD_OPTIONS,
                         ids=[f"{f}-{o}-{v!r}" for f, o, v, _ in BAD_OPTIONS])
def test_a_bad_reader_option_is_refused_by_name_before_the_file_is_read(tmp_path, fmt, option, value, message):
    f = tmp_path / f"p.{fmt}"
    f.write_text(FILES[fmt])
    READER[fmt](f)  # valid as written
    for call in (lambda path: READER[fmt](path, **{option: value}),
                 lambda path: read_toolpath(path, **{option: value})):
        with pytest.raises(ReaderArgumentError, match=f"^{option} {message}$") as info:
            call(f)
        assert info.value.argument == option and isinstance(info.value, PlannerError)
        with pytest.raises(ReaderArgumentError, match=f"^{option} "):  # checked before the file is opened
            call(tmp_path / f"missing.{fmt}")
    # a value of the wrong type is also a TypeError (for callers that catch that); a bad value of the right type not
    if option in ("arc_tolerance", "axis_tolerance", "peck_clearance"):
        wrong_type = isinstance(value, bool) or not isinstance(value, numbers.Real)
    elif option == "normalize_axes":
        wrong_type = not isinstance(value, bool)
    else:
        wrong_type = not isinstance(value, str)
    assert isinstance(info.value, TypeError) == wrong_type
    assert pickle.loads(pickle.dumps(info.value)).args == info.value.args


def test_valid_options_still_work(tmp_path):
    """The checks accept every documented value: the limits of the ranges and the aliases."""
    f = tmp_path / "p.apt"
    f.write_text(FILES["apt"])
    assert len(read_apt(f, arc_tolerance=1.0)) == 3
    assert len(read_apt(f, arc_tolerance=1e-9)) > 500  # the limit, 1 nm: a 1 mm quarter circle in 555 chords
    assert read_apt(f, units="inch", axis_tolerance=0).points[1, 0] == pytest.approx(0.0254)
    assert read_apt(f, frames="none", peck_clearance=np.float32(1e-3), source="x").source == "x"
    g = tmp_path / "p.csv"
    g.write_text(FILES["csv"].replace(",", ";"))
    assert read_csv(g, delimiter=";", units="m", feed_units="m/min", normalize_axes=np.True_).points[2, 1] == 1.0
    assert read_csv(g, delimiter=";", axis_tolerance=0.5).points[2, 1] == 1e-3
    h = tmp_path / "p.nc"
    h.write_text("G21 G90 G234\nG1 X0 Y0 Z0 B0 C0 F100\nG1 X1 B10\n")
    assert read_gcode(h, machine="Haas UMC-750", dialect="iso", arc_tolerance=1e-6).axes is not None
    assert len(read_toolpath(io.StringIO(FILES["json"]), format="json", units="mm", feed_units="mm/s")) == 3


@pytest.mark.parametrize("call, argument, message", [
    (lambda: read_apt(5), "src", "src must be a file path or a text stream, got 5"),
    (lambda: read_apt(None), "src", "src must be a file path or a text stream, got None"),
    (lambda: read_csv([1, 2, 3]), "src", "src must be a file path or a text stream, got a list"),
    (lambda: read_json(object()), "src", "src must be a file path or a text stream, got an object"),
    (lambda: read_gcode(b"p.nc"), "src", "src must be a file path or a text stream, got the string b'p.nc'"),
    (lambda: read_csv(io.BytesIO(b"0,0,0\n1,0,0\n")), "src", "src is a binary stream: open the file in text mode"),
    (lambda: read_json(io.BytesIO(b"[]")), "src", "src is a binary stream: open the file in text mode"),
    (lambda: read_apt(io.BytesIO(b"GOTO/0,0,0\n")), "src", "src is a binary stream: open the file in text mode"),
    (lambda: read_gcode(iter([b"G1 X0 Y0 Z0\n"])), "src", "src must be a file path or a text stream, got a "),
    (lambda: read_toolpath(5), "path", "path must be a file path or a text stream, got 5"),
    (lambda: read_toolpath(io.StringIO("GOTO/0,0,0\n")), "format", "reading a stream needs format='apt', 'gcode', "),
    (lambda: read_toolpath(io.StringIO("GOTO/0,0,0\n"), format="bogus"), "format",
     "format must be one of 'apt', 'gcode', 'csv' or 'json', got 'bogus'"),
    (lambda: read_toolpath("p.csv", format=5), "format", "format must be one of 'apt', 'gcode', 'csv' or 'json', got 5"),
    (lambda: read_toolpath("p.csv", machine="haas-umc-750"), "machine",
     "option 'machine' does not apply to csv files (it is for gcode files)"),
    (lambda: read_toolpath("p.json", colour="red"), "colour", "option 'colour' does not apply to json files"),
    (lambda: linearize_arcs("p.apt", 1e-5), "toolpath", "toolpath must be a Toolpath, got the string 'p.apt'"),
], ids=["apt-5", "apt-None", "csv-list", "json-object", "gcode-bytes-path", "csv-binary", "json-binary",
        "apt-binary", "gcode-bytes-lines", "toolpath-5", "stream-no-format", "format-bogus", "format-5",
        "machine-for-csv", "unknown-option", "linearize-not-a-toolpath"])
def test_a_bad_source_or_format_is_refused_by_name(tmp_path, monkeypatch, call, argument, message):
    monkeypatch.chdir(tmp_path)  # "p.csv" and the others do not exist: the arguments are refused first
    with pytest.raises(ReaderArgumentError) as info:
        call()
    assert info.value.argument == argument and str(info.value).startswith(message), str(info.value)


def test_linearize_arcs_tolerance_is_checked():
    tp = read_apt(io.StringIO(FILES["apt"]))
    for bad in (0.0, -1.0, math.nan, math.inf, 1e-300, "1e-5", None, 2.0):
        with pytest.raises(ReaderArgumentError, match=r"^tolerance must be positive, a length in metres") as info:
            linearize_arcs(tp, bad)
        assert info.value.argument == "tolerance"
    assert len(linearize_arcs(tp, 1e-6)) > len(tp)


def test_a_unit_named_in_a_json_file_is_the_files_mistake(tmp_path):
    """A bad ``units`` in the document names the file, line and key; a bad option names the option."""
    f = tmp_path / "u.json"
    f.write_text('{\n "units": "furlong",\n "points": [[0, 0, 0], [1, 0, 0]]}')
    with pytest.raises(InputFileError, match=r"^u\.json line 2, units: units must be one of 'mm', 'm', 'inch', got "
                                             r"'furlong'$"):
        read_json(f)
    f.write_text('{\n "units": "mm",\n "feed_units": 5,\n "points": [[0, 0, 0], [1, 0, 0]]}')
    with pytest.raises(InputFileError, match=r"^u\.json line 3, feed_units: 5 is not a unit name$"):
        read_json(f)
    f.write_text('{\n "units": "mm",\n "feed_units": "mm/h",\n "points": [[0, 0, 0], [1, 0, 0]]}')
    with pytest.raises(InputFileError, match=r"^u\.json line 3, feed_units: feed_units must be one of .*'mm/h'$"):
        read_json(f)
    with pytest.raises(ReaderArgumentError, match=r"^feed_units must be one of .*, got 'mm/h'$"):
        read_json(f, units="mm", feed_units="mm/h")


# ------------------------------------------------------------------ plan()'s arguments (issue 17)
WAYPOINTS = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.2, 0.05, 0.0]])


@pytest.mark.parametrize("kwargs, argument, message", [
    ({"progress": 5}, "progress", "must be a function (stage, done, total) or None, got 5"),
    ({"progress": "bar"}, "progress", "must be a function (stage, done, total) or None, got the string 'bar'"),
    ({"read_options": 5}, "read_options", "must be a dict of reader options such as {'units': 'mm'}, got 5"),
    ({"read_options": [("units", "mm")]}, "read_options", "must be a dict of reader options"),
    ({"read_options": {1: "mm"}}, "read_options", "option names must be strings, got 1"),
], ids=["progress-int", "progress-str", "read_options-int", "read_options-list", "read_options-key"])
def test_plan_refuses_bad_arguments_before_any_work(tmp_path, kwargs, argument, message):
    missing = tmp_path / "missing.csv"  # never opened: the argument is refused first
    with pytest.raises(ArgumentError) as info:
        plan(missing, **kwargs)
    assert info.value.argument == argument and str(info.value).startswith(f"{argument}: {message}")


def test_plan_settings_must_be_plan_settings(tmp_path):
    for bad in (5, {"feed": 0.1}, "fast"):
        with pytest.raises(PlannerError, match=r"^settings must be a PlanSettings, got "):
            plan(tmp_path / "missing.csv", bad)


@pytest.mark.parametrize("kwargs, argument, message", [
    ({"axes": [[0, 0, 1]]}, "axes", r"expected shape \(3, 3\) \(one per waypoint\), got \(1, 3\)"),
    ({"axes": np.zeros((3, 3), int) + [0, 0, 1]}, None, None),
    ({"axes": [["0", "0", "1"]] * 3}, "axes", r"must be numbers, got strings .*"),
    ({"axes": np.full((3, 3), 1j)}, "axes", r"must be real numbers, got complex numbers"),
    ({"axes": [[0, 0, 1], [0, 0, math.nan], [0, 0, 1]]}, "axes[1]", r"not a finite vector \(waypoint 1\)"),
    ({"axes": [[0, 0, 1], [0, 0, 1], [0, 0, 0]]}, "axes[2]", r"the tool axis is zero \(waypoint 2\)"),
    ({"axes": [[0, 0, 1], [0, 0, 1], [0, 0, 1, 0]]}, "axes", r"must be numbers in a rectangular array \(rows of equal length\)"),
    ({"feeds": ["a", "b", "c"]}, "feeds", r"must be numbers, got strings .*"),
    ({"feeds": [1j, 1j, 1j]}, "feeds", r"must be real numbers, got complex numbers"),
    ({"feeds": [[0.1, 0.1, 0.1]]}, "feeds", r"expected one feed per waypoint, shape \(3,\), got \(1, 3\)"),
    ({"feeds": 0.1}, "feeds", r"expected one feed per waypoint, shape \(3,\), got \(\)"),
    ({"feeds": [True, True, True]}, "feeds", r"must be numbers, got booleans"),
    ({"feeds": [0.1, -0.1, 0.1]}, "feeds[1]", r"a feed must be > 0 m/s \(or NaN for the job's feed\), got -0.1"),
    ({"feeds": [0.1, math.nan, 0.1]}, None, None),
], ids=["axes-shape", "axes-int-ok", "axes-strings", "axes-complex", "axes-nan", "axes-zero", "axes-ragged",
        "feeds-strings", "feeds-complex", "feeds-2d", "feeds-scalar", "feeds-bool", "feeds-negative", "feeds-nan-ok"])
def test_plan_refuses_bad_waypoint_arrays_by_name(kwargs, argument, message):
    if argument is None:  # valid: planned
        assert plan(WAYPOINTS, PlanSettings(rate=50.0), **kwargs).summary() is not None
        return
    with pytest.raises(ArgumentError) as info:
        plan(WAYPOINTS, **kwargs)
    assert info.value.argument == argument and re.fullmatch(f"{re.escape(argument)}: {message}", str(info.value))


def test_plan_progress_counts_passes_at_every_stage():
    calls = []
    plan(WAYPOINTS, PlanSettings(rate=50.0), progress=lambda stage, done, total: calls.append((stage, done, total)))
    assert calls[0] == ("fit", 0, 1) and calls[-1] == ("plan", 1, 1)
    assert all(isinstance(c[0], str) and 0 <= c[1] <= c[2] == 1 for c in calls)


def test_nurbs_sampling_tolerance_is_checked():
    from planner.io import Nurbs

    curve = Nurbs(1, 1, 0, 2, np.array([0.0, 0, 0, 1, 1, 1]), np.array([[0.0, 0, 0], [0.5, 0.5, 0], [1, 0, 0]]),
                  np.ones(3), None)
    for bad in (0.0, -1e-5, math.nan, "1e-5", 1e-300):
        with pytest.raises(ReaderArgumentError, match=r"^tolerance must be positive, a length in metres in "
                                                      r"\[2e-10, 1\], got "):
            curve.sample_parameters(bad)
    u = curve.sample_parameters(1e-4)
    mid = curve.evaluate((u[1:] + u[:-1]) / 2)
    chord_mid = (curve.evaluate(u[1:]) + curve.evaluate(u[:-1])) / 2
    assert u[0] == 0.0 and u[-1] == 1.0 and np.linalg.norm(mid - chord_mid, axis=1).max() <= 1e-4
