"""Inputs that ran past a minute or ended in a traceback (issue 27), each refused by ``planner`` with one line naming
its place and exit 2, nothing written: a unit mistake (a CLSF in mm read as metres, a unit switch inside a pass)
and numbers too long for a double (a 400-digit rotary word, a 5000-digit JSON integer). Fits of a CLSF scaled by
1e-9..1e9 complete with finite figures."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from planner.frontends.cli.main import main
from planner.io import read_toolpath

ROOT = Path(__file__).resolve().parents[1]
NX_PASS = ROOT / "examples" / "nx_first_pass.cls"
BOSS = Path(__file__).resolve().parent / "data" / "solidworks_cam_apt_boss_excerpt.apt"


def refused(argv: list[str], capsys, folder: Path) -> str:
    before = sorted(folder.iterdir())
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err and err.count("\n") == 1, err
    assert sorted(folder.iterdir()) == before  # nothing written
    return err


def test_a_clsf_in_mm_read_as_metres_is_refused_before_planning(tmp_path, capsys):
    err = refused(["plan", str(NX_PASS), "--units", "m", "-o", str(tmp_path / "job.csv")], capsys, tmp_path)
    assert re.fullmatch(r"planner: error: nx_first_pass.cls line 11: coordinate 1.2e\+03 m is beyond any robot cell "
                        r"\(100 m from the part origin\): are the units right\? \(the file says m\)\n", err), err


@pytest.mark.parametrize("unit, factor", [("M", 1000), ("INCH", 25.4), ("CM", 10)])
def test_an_apt_unit_switch_inside_a_pass_is_refused(unit, factor, tmp_path, capsys):
    lines = BOSS.read_text().splitlines(keepends=True)
    assert lines[20].startswith("GOTO/89.2375,33.799705") and lines[21].startswith("GOTO/")  # inside a cut
    src = tmp_path / "boss.apt"
    src.write_text("".join(lines[:21] + [f"UNITS/{unit}\n"] + lines[21:]))
    err = refused(["plan", str(src), "-o", str(tmp_path / "job.csv")], capsys, tmp_path)
    want = {"M": "m", "INCH": "inch", "CM": "cm"}[unit]
    assert err == (f"planner: error: boss.apt line 22, UNITS: switches the units from mm to {want} in the middle of a "
                   f"pass (a {factor:g}x jump in scale): state the units before the first motion or between "
                   f"passes\n")


def test_a_unit_switch_between_passes_is_read(tmp_path, capsys):
    """After a rapid the switch is a new operation's units: the points after it are read in inches."""
    src = tmp_path / "two.apt"
    src.write_text("UNITS/MM\nFEDRAT/MMPM,600\nGOTO/0,0,10\nGOTO/0,0,0\nGOTO/20,0,0\nRAPID\nGOTO/20,0,10\n"
                   "UNITS/INCH\nRAPID\nGOTO/1,0,0.4\nFEDRAT/IPM,20\nGOTO/1,0,0\nGOTO/2,0,0\n")
    tp = read_toolpath(src)
    assert tp.units == "mm,inch"
    np.testing.assert_allclose(tp.points[3:], [[0.02, 0, 0.01], [0.0254, 0, 0.4 * 0.0254],
                                                          [0.0254, 0, 0], [0.0508, 0, 0]], rtol=0, atol=1e-15)
    assert main(["plan", str(src)]) == 0


def test_a_gcode_unit_switch_inside_a_pass_is_refused(tmp_path, capsys):
    src = tmp_path / "mid.nc"
    src.write_text("G21 G90\nG0 X0 Y0 Z5\nG1 Z0 F100\nG1 X10\nG20\nG1 X20\n")
    err = refused(["plan", str(src)], capsys, tmp_path)
    assert err == ("planner: error: mid.nc line 5, word G: G20 switches the units from mm to inch in the middle of "
                   "a pass: state the units before the first motion or between passes\n")


@pytest.mark.parametrize("machine", [[], ["--machine", "haas-umc-750"]])
def test_a_400_digit_rotary_word_is_refused_by_its_word(machine, tmp_path, capsys):
    src = tmp_path / "rot.nc"
    src.write_text("G1 X10 Y0 Z0 B1" + "9" * 400 + " F100\nG1 X20 Y0 Z0 B0\nG1 X30 Y5 Z0 B0\n")
    err = refused(["plan", str(src)] + machine, capsys, tmp_path)
    assert err == ("planner: error: rot.nc line 1, word B: a number of 401 characters (199999999999...): not a "
                   "coordinate, feed or code a post-processor writes\n")


@pytest.mark.parametrize("number", ["1" + "0" * 5000, "1" + "0" * 5000 + ".5", "1e400"])
def test_a_json_number_beyond_a_double_is_refused_by_its_place(number, tmp_path, capsys):
    src = tmp_path / "points.json"
    src.write_text('{"points": [\n[0, 0, 0],\n[' + number + ', 0, 0],\n[2, 1, 0]\n]}\n')
    err = refused(["plan", str(src)], capsys, tmp_path)
    assert err == ("planner: error: points.json line 3, points[1][0]: an infinite number (or one too large to be a "
                   "coordinate or feed)\n")


@pytest.mark.parametrize("factor", [1e-9, 1e-6, 1e6, 1e9])
def test_fits_of_a_scaled_clsf_give_finite_figures(factor, tmp_path, capsys):
    def scaled(m: re.Match) -> str:
        v = m.group(2).split(",")
        return m.group(1) + ",".join(f"{float(x) * factor:.12g}" if i < 3 else x for i, x in enumerate(v))

    src = tmp_path / "scaled.cls"
    src.write_text(re.sub(r"^(GOTO/)(.*)$", scaled, NX_PASS.read_text(), flags=re.M))
    assert main(["fit", str(src)]) == 0
    out = capsys.readouterr().out
    lengths = [float(x) for x in re.findall(r"length (\S+) mm", out)]
    assert len(lengths) == 3 and all(math.isfinite(x) and x >= 0.0 for x in lengths)
    # the three fits agree with the polyline's length scaled (lengths printed in mm with 6 decimals)
    assert lengths[0] == pytest.approx(328.917448 * factor, rel=1e-5, abs=1e-6)
