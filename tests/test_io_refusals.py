"""Readers refuse what they cannot mean (issue 17): G-code numbers in exponent notation, motion after the end of
the program, JSON keys given twice and JSON nested without end; each with the file and line."""

from __future__ import annotations

import pytest

from planner import plan
from planner.io import InputFileError, read_toolpath


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
