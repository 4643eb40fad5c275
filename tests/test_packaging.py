"""Packaging as issue 31 asks: the core install runs a single bench, PostgreSQL's driver, Dask and the test
tools are extras; `run.py demo` installs the core alone and `run.py test` every extra, and CI runs the
README's test command; the README names every dependency; package-data names only files that exist."""

from __future__ import annotations

import importlib.util
import re
import tomllib
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
README = (REPO / "README.md").read_text(encoding="utf-8")


def name(requirement: str) -> str:
    """The distribution's name of a requirement string, normalised ("psycopg[binary]>=3.1" -> "psycopg")."""
    match = re.match(r"[A-Za-z0-9][A-Za-z0-9._-]*", requirement)
    assert match, requirement
    return re.sub(r"[-_.]+", "-", match.group(0)).lower()


CORE = {name(r) for r in PYPROJECT["project"]["dependencies"]}
EXTRAS = {
    extra: {name(r) for r in reqs} for extra, reqs in PYPROJECT["project"]["optional-dependencies"].items()
}


def run_py() -> ModuleType:
    spec = importlib.util.spec_from_file_location("run_py", REPO / "run.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_core_is_a_single_bench_and_the_rest_are_extras() -> None:
    assert {"psycopg", "dask", "pytest", "hypothesis", "selenium", "httpx"}.isdisjoint(CORE)
    assert EXTRAS["postgres"] == {"psycopg"}
    assert EXTRAS["cluster"] == {"dask", "threadpoolctl"}
    assert {"pytest", "hypothesis", "ruff", "selenium"} <= EXTRAS["test"]
    assert {"numpy", "scipy", "fastapi", "uvicorn", "sqlalchemy", "h5py", "matplotlib"} <= CORE


def test_each_extra_names_the_modules_its_missing_message_checks() -> None:
    from service.extras import EXTRAS as MODULES

    assert set(MODULES) == set(EXTRAS) - {"test"}


def test_demo_installs_the_core_and_test_every_extra() -> None:
    module = run_py()
    assert module.EXTRAS["demo"] == ""
    assert set(module.EXTRAS["test"].strip("[]").split(",")) == set(EXTRAS)


@pytest.mark.parametrize(
    ("stamp", "extras", "covered"),
    [
        ("D [test,postgres,cluster]", "", True),  # demo after test: the larger install has the core
        ("D [test,postgres,cluster]", "[test,postgres,cluster]", True),
        ("D", "[test,postgres,cluster]", False),  # test after demo: install the extras
        ("D", "", True),
        ("OLD [test,postgres,cluster]", "", False),  # pyproject.toml changed
    ],
)
def test_run_py_reinstalls_only_when_needed(stamp: str, extras: str, covered: bool) -> None:
    assert run_py()._covers(stamp, "D", extras) is covered


def test_ci_runs_the_readmes_test_command() -> None:
    assert "    python3 run.py test" in README and "    python3 run.py demo" in README
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8")
    commands = [line for line in ci.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    assert commands[-1] == "python3 run.py test"


def test_the_readme_names_every_dependency() -> None:
    start = README.index("\n## Dependencies and why\n")
    end = README.find("\n## ", start + 1)
    section = README[start:] if end < 0 else README[start:end]
    said = section.lower().replace("_", "-")
    for dependency in sorted(CORE | set().union(*EXTRAS.values())):
        assert re.search(rf"(?<![\w-]){re.escape(dependency)}(?![\w-])", said), (
            f"README leaves out {dependency}"
        )


def test_package_data_names_only_files_that_exist() -> None:
    package_data = PYPROJECT["tool"]["setuptools"]["package-data"]
    for pattern in package_data["service"]:
        assert list((REPO / "service").glob(pattern)), f"package-data service/{pattern} matches nothing"
