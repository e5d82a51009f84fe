"""Every numeric option of ``planner plan`` / ``run`` is checked in the user's units, named as typed, before the
input file is read: one line on stderr, exit 2 (issue 17)."""

from __future__ import annotations

import argparse

import pytest

from planner.errors import PlannerError
from planner.frontends.cli.main import build_parser, main
from planner.frontends.cli.options import Number, _numeric_options, settings_from_args
from planner.settings import PlanSettings

OPTIONS = {o.flag: o for o in _numeric_options()}
#: A file that does not exist: an option refused before reading names the option, not the missing file.
MISSING = "no-such-dir/no-such-file.csv"


def _subparser(name: str) -> argparse.ArgumentParser:
    ap = build_parser()
    sub = next(a for a in ap._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[name]


def _numeric_flags(name: str) -> set[str]:
    flags = set()
    for a in _subparser(name)._actions:
        if a.option_strings and a.type in (Number, float, int):
            flags.add(max(a.option_strings, key=len))
    return flags


def test_every_numeric_option_of_plan_run_and_fit_has_a_range():
    plan_flags, run_flags, fit_flags = _numeric_flags("plan"), _numeric_flags("run"), _numeric_flags("fit")
    assert {"--feed", "--tolerance", "--rate", "--max-poses"} <= plan_flags
    assert {"--lookahead", "--gain", "--sim-speed", "--modbus-port"} <= run_flags
    assert plan_flags | run_flags | fit_flags <= set(OPTIONS), (plan_flags | run_flags | fit_flags) - set(OPTIONS)


def _bad_values():
    for o in _numeric_options():
        below = o.lo - 1.0 if o.lo_closed else o.lo
        yield o.flag, str(int(below)) if o.flag == "--modbus-port" else f"{below:g}"
        if o.hi is not None:
            above = o.hi + 1.0 if o.flag == "--modbus-port" else o.hi * 10.0
            yield o.flag, str(int(above)) if o.flag == "--modbus-port" else f"{above:g}"
        if o.flag != "--modbus-port":  # an int option: argparse itself refuses nan
            yield o.flag, "nan"
            yield o.flag, "-inf"


@pytest.mark.parametrize("flag, text", list(_bad_values()))
def test_a_bad_value_is_refused_by_its_option_in_user_units(flag, text, capsys):
    opt = OPTIONS[flag]
    command = "run" if flag in _numeric_flags("run") - _numeric_flags("plan") else "plan"
    argv = [command, MISSING, f"{flag}={text}"]
    if command == "run":
        argv += ["--robot", "ur5e", "--sim", "--mode", "program"]
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and err.startswith(f"planner: error: {flag} {text}: must be "), err
    if opt.unit:
        assert f"{opt.unit} and" in err or "finite" in err, err
    assert "no-such-file" not in err and "planning" not in out  # refused before the file was touched


def test_the_feed_message_of_the_issue():
    err = _refusal(["plan", MISSING, "--feed", "-5"])
    assert err == "planner: error: --feed -5: must be at least 0.001 mm/s and at most 10000 mm/s\n"
    err = _refusal(["plan", MISSING, "--tolerance", "-0.5"])
    assert err == "planner: error: --tolerance -0.5: must be > 0 mm and at most 1000 mm\n"


def _refusal(argv):
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stderr(buf), contextlib.redirect_stdout(io.StringIO()):
        assert main(argv) == 2
    return buf.getvalue()


PLAN_OPTIONS = [o for o in _numeric_options() if o.dest in vars(_subparser("plan").parse_args([MISSING]))]


@pytest.mark.parametrize("opt", PLAN_OPTIONS, ids=lambda o: o.flag)
def test_the_ends_of_every_plan_range_are_valid_settings(opt):
    """The CLI range is the settings' range in the user's units (or inside it): both ends pass PlanSettings."""
    p = _subparser("plan")
    ends = [opt.hi] + ([opt.lo] if opt.lo_closed else [opt.lo + (opt.hi - opt.lo) * 1e-9])
    for x in ends:
        args = p.parse_args([MISSING, f"{opt.flag}={x!r}"])
        s = settings_from_args(args)
        assert isinstance(s, PlanSettings)
    if not opt.lo_closed:  # an open lower end that the settings refuse too
        args = p.parse_args([MISSING, f"{opt.flag}={opt.lo!r}"])
        with pytest.raises(PlannerError, match=f"^{opt.flag} "):
            settings_from_args(args)


def test_settings_in_si_from_user_units():
    args = _subparser("plan").parse_args([MISSING, "--feed", "20", "--tolerance", "0.02", "--rapid-speed", "300"])
    s = settings_from_args(args)
    assert s.feed == pytest.approx(0.02, rel=1e-15) and s.tolerance == pytest.approx(2e-5, rel=1e-15)
    assert s.rapid_speed == pytest.approx(0.3, rel=1e-15)


@pytest.mark.parametrize("argv, message", [
    (["--feed", "abc"], "planner plan: error: argument --feed: invalid number value: 'abc'"),
    (["--path", "sideways"], "planner plan: error: argument --path: invalid choice: 'sideways'"),
    (["--cut-output", "standard:8"], "planner: error: --cut-output standard:8: standard outputs have pins 0..7"),
    (["--cut-output", "valve:1"], "planner: error: --cut-output valve:1: unknown output kind 'valve'"),
    (["--pass", "-1"], "planner: error: --pass -1: pass numbers start at 0"),
    (["--part-frame", "0,0,0,0,0,1e308rad"], "planner: error: --part-frame 0,0,0,0,0,1e308rad: the rotation vector"),
    (["--part-frame", "0,0,0,0,nan,0"], "planner: error: --part-frame 0,0,0,0,nan,0: ry (number 5) must be finite"),
    (["--tcp", "0,0,6e3m,0,0,0"], "planner: error: --tcp 0,0,6e3m,0,0,0: z = 6e3m is beyond any robot cell"),
    (["--part-frame", "400m,0,0,0,0,0"], "planner: error: --part-frame 400m,0,0,0,0,0: x = 400m is beyond any robot "
                                          "cell (at most 100 m); did you mean 400mm?"),
    # issue 27: poses are typed in mm and deg; a bare number (m and rad before 0.2) is refused, never reinterpreted
    (["--part-frame", "0.4,0.9965,-0.1,0,0,0"], "planner: error: --part-frame 0.4,0.9965,-0.1,0,0,0: x = 0.4 has no "
     "unit: a bare number meant m before 0.2, and --part-frame is typed in mm now; write 0.4m for what it meant "
     "(400mm), or the value in mm with its unit"),
    (["--tcp", "0,0,0.2m,0,0,3.1416"], "planner: error: --tcp 0,0,0.2m,0,0,3.1416: rz = 3.1416 has no unit: a bare "
     "number meant rad before 0.2, and --tcp is typed in deg now; write 3.1416rad for what it meant (180.0004deg), "
     "or the value in deg with its unit"),
    (["--part-frame", "400ft,0,0,0,0,0"], "planner: error: --part-frame 400ft,0,0,0,0,0: x = 400ft: unknown unit "
     "'ft' (a length takes mm, cm, m, in)"),
    (["--part-frame", "400mm,0,0,90mm,0,0"], "planner: error: --part-frame 400mm,0,0,90mm,0,0: rx = 90mm: unknown "
     "unit 'mm' (an angle takes deg, rad)"),
    (["--machine", "bogus"], "planner: error: --machine bogus: unknown machine (known: haas-umc-750)"),
])
def test_other_options_refused_in_one_line(argv, message):
    err = _refusal(["plan", MISSING, *argv])
    assert err.startswith(message) and err.count("\n") == 1, err


def test_settings_hold_plain_floats_that_pickle():
    """The typed text stays with the option: a saved job's settings are plain floats (a job file loads back)."""
    import pickle

    args = _subparser("plan").parse_args([MISSING, "--corner", "45", "--rate", "125", "--max-poses", "1e6",
                                          "--feed-override", "0.5", "--axis-jump", "30"])
    s = settings_from_args(args)
    for name in ("corner_deg", "rate", "max_poses", "feed_override", "axis_jump_deg", "feed", "tolerance"):
        assert type(getattr(s, name)) is float, name
    assert pickle.loads(pickle.dumps(s)) == s
    assert type(pickle.loads(pickle.dumps(Number("2.5")))) is float


def test_part_frame_auto():
    p = _subparser("plan")
    assert settings_from_args(p.parse_args([MISSING, "--part-frame", "auto", "--robot", "ur5e"])).part_frame == "auto"
    with pytest.raises(PlannerError, match="places the part for a robot"):
        settings_from_args(p.parse_args([MISSING, "--part-frame", "auto"]))
    with pytest.raises(PlannerError, match="^--tcp auto: must be six values"):
        settings_from_args(p.parse_args([MISSING, "--tcp", "auto"]))
