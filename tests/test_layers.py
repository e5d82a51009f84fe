"""The layers of pyproject.toml's import contracts cover the whole tree, and the deprecated names of the former
layout still work for one release, each with a DeprecationWarning naming its new home."""

from __future__ import annotations

import importlib
import subprocess
import sys
import tomllib
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONFIG = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
SHIMS = {"planner.cli", "planner.service", "drivers.cli", "planner._deprecated", "planner.plot_cam"}


def _contract(name_start: str) -> dict:
    return next(c for c in CONFIG["contracts"] if c["name"].startswith(name_start))


def test_every_module_of_planner_is_core_front_end_or_a_shim():
    core = set(_contract("The planning core")["source_modules"])
    tops = {p.stem if p.suffix == ".py" else p.name for p in (ROOT / "planner").iterdir()
            if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").is_file()}
    named = {f"planner.{t}" for t in tops}
    assert named - core - SHIMS == {"planner.frontends"}, "a new module of planner/ must be named in a contract"
    assert core - named == set(), "a contract names a module that is not there"


def test_the_contracts_hold():
    lint = Path(sys.executable).with_name("lint-imports")
    out = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-3000:]
    assert f"{len(CONFIG['contracts'])} kept, 0 broken" in out.stdout


@pytest.mark.parametrize("old, name, home", [
    ("planner.cli", "main", "planner.frontends.cli.main"),
    ("planner.cli", "settings_from_args", "planner.frontends.cli.options"),
    ("drivers.cli", "execute_job", "drivers.execute"),
    ("drivers.cli", "main", "planner.frontends.cli.run"),
    ("planner.service", "app", "planner.frontends.service.app"),
])
def test_former_names_warn_and_are_the_new_ones(old, name, home):
    sys.modules.pop(old, None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        module = importlib.import_module(old)
    assert any(issubclass(w.category, DeprecationWarning) and home.rsplit(".", 1)[0] in str(w.message)
               for w in caught), [str(w.message) for w in caught]
    new = importlib.import_module(home)
    assert getattr(module, name) is (new if name == "app" else getattr(new, name))
    with pytest.raises(AttributeError, match="deprecated|see planner.frontends"):
        module.no_such_name  # noqa: B018


def test_python_m_planner_service_still_runs_the_service_cli():
    out = subprocess.run([sys.executable, "-W", "error::DeprecationWarning:__main__", "-m", "planner.service", "keys",
                          "--help"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "create,list,revoke" in out.stdout, out.stderr
