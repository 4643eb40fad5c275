"""The core install runs a single bench; PostgreSQL's driver ([postgres]) and Dask ([cluster]) are extras,
and a feature that needs a missing one says, in one line (exit code 2 on the CLI), which extra to install.
Also `shockbench --version`.

A missing module is simulated as Python does for a module set to None in sys.modules: its import raises
ModuleNotFoundError naming it, exactly what a fresh core install gives."""

from __future__ import annotations

import sys
from importlib.metadata import version
from pathlib import Path

import pytest

from service.cli.main import main
from service.extras import MissingExtraError, extra_needed, require_extra
from service.store.database import Database, DatabaseError

POSTGRES_URL = "postgresql+psycopg://lane:hunter2@central.example/shockbench"


def without(monkeypatch: pytest.MonkeyPatch, *modules: str) -> None:
    """Make `modules` (and their submodules already loaded) impossible to import, as on a core install."""
    for name in list(sys.modules):
        if name.partition(".")[0] in modules:
            monkeypatch.setitem(sys.modules, name, None)
    for name in modules:
        monkeypatch.setitem(sys.modules, name, None)


def assert_names_the_extra(line: str, extra: str) -> None:
    assert "\n" not in line.strip()
    assert f"pip install 'shockbench[{extra}]'" in line
    assert "hunter2" not in line


def test_a_postgres_url_without_the_driver_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    without(monkeypatch, "psycopg")
    with pytest.raises(DatabaseError) as caught:
        Database(POSTGRES_URL)
    assert str(caught.value).startswith("database postgresql+psycopg://lane:***@central.example/shockbench")
    assert_names_the_extra(str(caught.value), "postgres")


def test_sqlite_needs_no_extra(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    without(monkeypatch, "psycopg", "dask", "distributed")
    database = Database(f"sqlite:///{tmp_path / 'db.sqlite3'}")
    database.upgrade_schema()
    database.dispose()


def test_the_cli_says_the_postgres_extra_in_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    without(monkeypatch, "psycopg")
    assert main(["history", "WVW123", "--database", POSTGRES_URL]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("shockbench history: error: database postgresql+psycopg://lane:***@")
    assert_names_the_extra(captured.err, "postgres")


def test_reanalyse_without_dask_names_the_cluster_extra_before_any_work(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    without(monkeypatch, "dask", "distributed")
    archive, out = tmp_path / "archive", tmp_path / "out"
    archive.mkdir()
    assert main(["reanalyse", str(archive), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith(
        "shockbench reanalyse: error: shockbench reanalyse (on dask.distributed) needs"
    )
    assert_names_the_extra(captured.err, "cluster")
    assert not out.exists()


def test_the_dask_client_itself_names_the_extra(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from service.reanalyse.run import RunSettings, dask_client

    without(monkeypatch, "dask", "distributed")
    with pytest.raises(MissingExtraError) as caught, dask_client(RunSettings(out=tmp_path)):
        pass
    assert_names_the_extra(str(caught.value), "cluster")


def test_another_missing_module_is_not_blamed_on_an_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    without(monkeypatch, "not_a_shockbench_extra")
    with pytest.raises(ModuleNotFoundError) as caught, extra_needed("cluster", "reanalyse"):
        import not_a_shockbench_extra  # noqa: F401
    assert not isinstance(caught.value, MissingExtraError)
    require_extra("cluster", "reanalyse")  # installed here (the test environment has every extra)


def test_version_is_the_installed_distributions(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["--version"])
    assert exited.value.code == 0
    assert capsys.readouterr().out == f"shockbench {version('shockbench')}\n"


def test_version_of_an_uninstalled_source_tree_is_its_pyproject(monkeypatch: pytest.MonkeyPatch) -> None:
    import tomllib

    from service import version as module

    monkeypatch.setattr(module, "DISTRIBUTION", "shockbench-never-installed")
    pyproject = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text(encoding="utf-8"))
    assert module.shockbench_version() == pyproject["project"]["version"]
    monkeypatch.setattr(module, "PYPROJECT", Path("/nonexistent/pyproject.toml"))
    assert module.shockbench_version() == module.UNKNOWN
