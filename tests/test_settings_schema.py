"""One settings schema (issue 25, step 2): every PlanSettings field is declared once (planner.settings.SETTINGS), and
the Python API, the command line and the REST service refuse the same bad value naming the same field: the error's
``field``, the CLI option of that field, the 422 ``loc``. Parametrized over the declaration, so a new setting is
covered without a line here."""

from __future__ import annotations

import argparse
import json
import math
import pickle

import pytest

from planner.errors import PlannerError
from planner.frontends.cli.main import build_parser
from planner.frontends.cli.options import settings_from_args
from planner.frontends.service.config import ServiceConfig
from planner.frontends.service.schemas import SettingsModel
from planner.settings import SETTINGS, PlanSettings, Setting, describe_settings
from tests.test_service_server import ServiceProcess

#: A file that does not exist: the options are refused before any file is read.
MISSING = "no-such-dir/no-such-file.csv"
WAYPOINTS = [[0.0, 0.0, 0.0], [0.1, 0.02, 0.0], [0.2, 0.0, 0.0]]


def _bad_numbers(s: Setting) -> list[float]:
    """Values just outside a number setting's range (SI): its open lower end or below its closed one, above its upper
    end, and NaN."""
    assert s.lo is not None and s.hi is not None
    below = s.lo / 2.0 if s.lo_closed and s.lo > 0 else (s.lo - 1.0 if s.lo_closed else s.lo)
    return [below, s.hi * 10.0 if s.hi > 0 else s.hi + 1.0, math.nan]


#: Per kind: a bad value for the Python API and REST (JSON), and the text a user would type for it (None: the
#: command line cannot say it wrongly in a way the option's parser lets through).
_BAD = {
    "choice": ("sideways", None),  # argparse refuses it itself, naming the option (test_cli_options)
    "limits": ({"speed": -1.0, "acceleration": 1.0, "jerk": 1.0}, None),
    "robot": ("ur99", "ur99"),
    "pose": ([0.0, 0.0, 0.0, 0.0, 0.0], "0,0,0,0,0"),
    "output": (["tool", 2], "tool:2"),
    "passes": ([-1], "-1"),
}


def _cases():
    """(setting, SI value as JSON, typed text or None) for every setting: several per number."""
    for s in SETTINGS:
        if s.kind == "number":
            for v in _bad_numbers(s):
                yield pytest.param(s, v, None if math.isnan(v) else repr(v * s.per_si), id=f"{s.name}={v!r}")
        else:
            value, text = _BAD[s.kind]
            yield pytest.param(s, value, text, id=f"{s.name}={value!r}")


CASES = list(_cases())


def test_every_setting_is_declared_once_with_what_the_front_ends_need():
    names = [s.name for s in SETTINGS]
    assert names == list(PlanSettings().to_dict())  # the dataclass fields, in order
    assert list(SettingsModel.model_fields) == names  # the REST model is generated from the same table
    for s in SETTINGS:
        assert s.kind in _BAD or s.kind == "number", s
        assert s.doc and s.doc == s.doc.strip() and "\n" not in s.doc
        if s.kind == "number":
            assert s.lo is not None and s.hi is not None and s.lo < s.hi, s
            if s.default is not None:  # the default is a valid value
                assert (s.lo <= s.default if s.lo_closed else s.lo < s.default) and s.default <= s.hi, s
        if s.flag is not None:
            assert s.flag.startswith("--") and (s.per_si == 1.0) == (s.typed in ("", s.unit)), s
    table = describe_settings().splitlines()
    assert len(table) == len(SETTINGS) + 1 and all(t.split()[0] == s.name for t, s in zip(table[1:], SETTINGS,
                                                                                        strict=True))


@pytest.mark.parametrize("s, value, text", CASES)
def test_the_python_api_names_the_field(s, value, text):
    kw = {s.name: value}
    if s.kind == "limits":
        with pytest.raises(PlannerError) as err:
            PlanSettings.from_dict(kw)
    else:
        with pytest.raises(PlannerError) as err:
            PlanSettings(**kw).checked()
    assert err.value.field == s.name, (err.value, err.value.field)
    if s.kind == "number":
        assert str(err.value).startswith(f"{s.name} must be in "), err.value
        assert err.value.value is value or err.value.value == value


def _plan_args(argv: list[str]) -> argparse.Namespace:
    return build_parser().parse_args(["plan", MISSING, *argv])


@pytest.mark.parametrize("s, value, text", [c for c in CASES if c.values[0].flag and c.values[2] is not None])
def test_the_command_line_option_refuses_the_same_value_naming_the_same_field(s, value, text):
    """The option of the setting, in the unit people type: refused in one line that starts with the option and the
    text as typed, with the error's ``field`` the setting's name."""
    with pytest.raises(PlannerError) as err:
        settings_from_args(_plan_args([f"{s.flag}={text}"]))
    assert err.value.field == s.name, (err.value, err.value.field)
    message = str(err.value)
    assert "\n" not in message
    if s.kind == "number":
        unit = f" {s.typed_unit}" if s.typed_unit else ""
        assert message.startswith(f"{s.flag} {text}: must be "), message
        assert (f"{unit} and" in message or "finite" in message) if unit else True, message


@pytest.mark.parametrize("s", [s for s in SETTINGS if s.kind == "number" and s.flag], ids=lambda s: s.name)
def test_the_options_range_and_default_are_the_declared_ones_in_typed_units(s):
    p = build_parser()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices["plan"]
    action = next(a for a in sub._actions if s.flag in a.option_strings)
    assert action.dest == s.name and action.default == pytest.approx(s.default * s.per_si, rel=1e-15)
    assert s.range_text(s.per_si) in action.help and (s.typed_unit in action.help if s.typed_unit else True)
    for x in (s.lo if s.lo_closed else (s.lo + s.hi) / 2.0, s.hi):  # the ends of the range pass every layer
        got = getattr(settings_from_args(_plan_args([f"{s.flag}={x * s.per_si!r}"])), s.name)
        assert got == pytest.approx(x, rel=1e-15)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    s = ServiceProcess(tmp_path_factory.mktemp("settings"), workers=1).start()
    yield s
    assert s.stop() == 0, s.log.read_text()


@pytest.fixture(scope="module")
def client(server):
    with server.client() as c:
        yield c


@pytest.mark.parametrize("s, value, text", CASES)
def test_rest_422_loc_is_the_field(client, s, value, text):
    """The 422's ``loc`` is ``["body", "settings", field]`` (taken from the error, not its text); a range refusal
    says exactly what the Python API says."""
    body = json.dumps({"waypoints": WAYPOINTS, "settings": {s.name: value}}, allow_nan=True)
    r = client.post("/v1/jobs", content=body, headers={"content-type": "application/json"})
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail[0]["loc"][:3] == ["body", "settings", s.name], detail
    if s.kind == "number" and not math.isnan(value):
        with pytest.raises(PlannerError) as err:
            PlanSettings(**{s.name: value}).checked()
        assert detail[0]["loc"] == ["body", "settings", s.name] and detail[0]["msg"] == str(err.value)


def test_rest_combinations_name_the_field_the_planner_blames(client):
    for settings, field in (({"frame": "grm", "axes": "fixed"}, "frame"), ({"part_frame": "auto"}, "part_frame"),
                            ({"axes": "file"}, "axes"), ({"frame": "juttler", "path": "cam", "axes": "path"}, "frame")):
        r = client.post("/v1/jobs", json={"waypoints": WAYPOINTS, "settings": settings})
        assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "settings", field], (settings, r.text)


def test_the_openapi_schema_carries_unit_range_and_option(client):
    props = client.get("/openapi.json").json()["components"]["schemas"]["SettingsModel"]["properties"]
    assert list(props) == [s.name for s in SETTINGS]
    for s in SETTINGS:
        p = props[s.name]
        if s.unit:
            assert p["x-unit"] == s.unit and f"unit: {s.unit}" in p["description"], (s.name, p)
        else:
            assert "x-unit" not in p
        assert p["description"].startswith(s.doc)
        if s.kind == "number":
            assert p["maximum"] == s.hi and p["minimum" if s.lo_closed else "exclusiveMinimum"] == s.lo, p
        if s.flag:
            assert p["x-cli"].startswith(s.flag) and (s.typed_unit in p["x-cli"] if s.typed_unit else True)
    assert props["tolerance"]["x-unit"] == "m" and props["tolerance"]["x-cli"] == "--tolerance (mm)"
    assert props["feed"]["x-unit"] == "m/s" and props["feed"]["x-cli"] == "--feed (mm/s)"


def test_a_refusal_keeps_its_field_through_pickle():
    """Worker processes send errors back pickled: the field and value survive."""
    with pytest.raises(PlannerError) as err:
        PlanSettings(rate=-1.0).checked()
    back = pickle.loads(pickle.dumps(err.value))
    assert (str(back), back.field, back.value) == (str(err.value), "rate", -1.0)
    assert PlannerError("plain").field is None


@pytest.mark.parametrize("env, overrides, message", [
    ({"PLANNER_WORKERS": "0"}, {}, "PLANNER_WORKERS must be at least 1, got '0'"),
    ({"PLANNER_WORKERS": "two"}, {}, "PLANNER_WORKERS: input should be a valid integer"),
    ({}, {"workers": 0}, "workers must be at least 1, got 0"),
    ({"PLANNER_JOB_TIMEOUT": "nan"}, {}, "PLANNER_JOB_TIMEOUT: input should be a finite number"),
    ({"PLANNER_MAX_WAYPOINTS": "1"}, {}, "PLANNER_MAX_WAYPOINTS must be at least 2, got '1'"),
    ({"PLANNER_ROBOTS": '{"c": {"sim": true, "modbus_port": 70000}}'}, {},
     "PLANNER_ROBOTS: robot 'c': modbus_port must be at most 65535, got 70000"),
    ({"PLANNER_ROBOTS": '{"c": {"sim": true, "sim_speed": true}}'}, {}, "robot 'c': sim_speed: input should be"),
    ({"PLANNER_ROBOTS": '{"c": {"sim": true, "approach_speed": 9}}'}, {},
     "robot 'c': approach_speed must be at most 3.14, got 9"),
    ({"PLANNER_ROBOTS": '{"c": {"sim": true, "modbus_port": "502"}}'}, {}, "robot 'c': modbus_port: input should be"),
    ({"PLANNER_QUEUE": "rq"}, {}, "PLANNER_QUEUE must be 'local' or 'celery', got 'rq'"),
    ({"PLANNER_QUEUE": "celery"}, {}, "PLANNER_BROKER (the broker's URL, redis://HOST:PORT/0) is needed with "
                                      "PLANNER_QUEUE=celery"),
    ({"PLANNER_QUEUE": "celery", "PLANNER_BROKER": "amqp://127.0.0.1"}, {},
     "PLANNER_BROKER must be redis://HOST:PORT/DB (or rediss://), got 'amqp://127.0.0.1'"),
])
def test_service_configuration_refusals_name_the_variable_and_field(env, overrides, message):
    with pytest.raises(PlannerError) as err:
        ServiceConfig.from_env(env, **overrides)
    assert message in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_service_configuration_from_the_environment(tmp_path):
    cfg = ServiceConfig.from_env({"PLANNER_WORKERS": "3", "PLANNER_JOB_TIMEOUT": "20", "PLANNER_DEV_NO_AUTH": "1",
                                  "PLANNER_DB": f"sqlite:///{tmp_path / 'j.sqlite'}", "PLANNER_MAX_ATTEMPTS": ""})
    assert (cfg.workers, cfg.job_timeout_s, cfg.dev_no_auth, cfg.max_attempts) == (3, 20.0, True, 2)
    assert cfg.data_dir == (tmp_path / "j.sqlite.data").resolve()
    assert ServiceConfig.from_env({"PLANNER_WORKERS": "3"}, workers=5, data_dir=str(tmp_path)).workers == 5
    assert set(ServiceConfig.env_names()) == set(ServiceConfig.model_fields)
