"""`shockbench serve` for operations (issue 31, item 3): every option from a SHOCKBENCH_* variable (the
command line wins, a bad value is one line and exit 2, --help names each variable), and the logs: one
format with UTC timestamps for uvicorn's records and the service's, `--log-format json` one object per line,
the access log off unless switched on, and a job's end logged once."""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import re
import signal
import socket
import sqlite3
from pathlib import Path

import pytest
from live_server import SimulatedInputs, serve_process, wait_for_status, wait_until

from service.cli import main as cli
from service.cli.serve import env_name
from service.jobs.manager import JobManager, _Current
from service.store.database import Database
from service.store.job_queue import JobQueue
from service.store.jobs import JobFiles, JobStore
from service.store.models import JobStatus

ADMIN = "admin-key-0123456789abcdef"
TIMESTAMP = r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z"
TEXT_RECORD = re.compile(rf"^{TIMESTAMP} (DEBUG|INFO|WARNING|ERROR|CRITICAL) +[\w.]+: ")


def serve_parser() -> argparse.ArgumentParser:
    parser = cli.build_parser("serve")
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return commands.choices["serve"]  # type: ignore[no-any-return]


def parse_serve(*argv: str) -> argparse.Namespace:
    """The serve command line parsed with the environment applied, as the command does first."""
    from service.cli.serve import resolve_environment

    args = serve_parser().parse_args(list(argv))
    resolve_environment(args)
    return args


def test_help_names_the_variable_of_every_option() -> None:
    parser = serve_parser()
    text = " ".join(parser.format_help().split())
    options = [a for a in parser._actions if a.option_strings and a.dest != "help"]
    assert len(options) >= 28
    for action in options:
        assert f"[env {env_name(action.dest)}]" in text, action.option_strings
    assert (
        env_name("database") == "SHOCKBENCH_DATABASE_URL"
        and env_name("max_upload_mb") == "SHOCKBENCH_MAX_UPLOAD_MB"
    )


def test_the_choices_serve_names_itself_are_the_services() -> None:
    """serve stays light (it imports the service only when it runs): the choices it spells out are the
    service's own."""
    from service.api.logging_setup import LOG_FORMATS, LOG_LEVELS
    from service.api.settings import METRICS_ACCESS

    choices = {a.dest: tuple(a.choices or ()) for a in serve_parser()._actions}
    assert choices["metrics_access"] == METRICS_ACCESS
    assert choices["log_format"] == LOG_FORMATS and choices["log_level"] == LOG_LEVELS


def test_the_environment_gives_the_defaults_and_the_command_line_wins(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("SHOCKBENCH_PORT", "9100")
    monkeypatch.setenv("SHOCKBENCH_MAX_UPLOAD_MB", "12.5")
    monkeypatch.setenv("SHOCKBENCH_SIMULATED", "yes")
    monkeypatch.setenv("SHOCKBENCH_LOG_FORMAT", "json")
    monkeypatch.setenv("SHOCKBENCH_DATABASE_URL", "postgresql+psycopg://bench:secret@central/shockbench")
    monkeypatch.setenv("SHOCKBENCH_LANE", "")  # empty: unset
    args = parse_serve()
    assert (args.port, args.max_upload_mb, args.simulated, args.log_format) == (9100, 12.5, True, "json")
    assert args.database == "postgresql+psycopg://bench:secret@central/shockbench"
    assert args.lane is None
    args = parse_serve("--port", "9200", "--log-format", "text", "--database", "sqlite:///given.sqlite3")
    assert (args.port, args.log_format, args.database) == (9200, "text", "sqlite:///given.sqlite3")
    monkeypatch.setenv("SHOCKBENCH_SIMULATED", "off")
    assert parse_serve().simulated is False


@pytest.mark.parametrize(
    ("variable", "raw", "message"),
    [
        ("SHOCKBENCH_PORT", "eighty", "SHOCKBENCH_PORT='eighty' (for --port): not a whole number"),
        (
            "SHOCKBENCH_BODY_TIMEOUT_S",
            "5s",
            "SHOCKBENCH_BODY_TIMEOUT_S='5s' (for --body-timeout-s): not a number",
        ),
        (
            "SHOCKBENCH_ACCESS_LOG",
            "sometimes",
            "SHOCKBENCH_ACCESS_LOG='sometimes' (for --access-log): must be one of",
        ),
        ("SHOCKBENCH_METRICS_ACCESS", "all", "(for --metrics-access): must be one of admin, key, open"),
    ],
)
def test_a_bad_value_in_the_environment_is_one_line_and_exit_2(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], variable: str, raw: str, message: str
) -> None:
    monkeypatch.setenv(variable, raw)
    assert cli.main(["serve"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("shockbench serve: error: "), err
    assert message in err


def held_port() -> socket.socket:
    """A listening socket on a loopback port (a serve told to use it could not listen)."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(1)
    return sock


def test_serve_from_the_environment_logs_json_lines_and_a_job_once(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, inputs: SimulatedInputs
) -> None:
    """Everything from the environment (database URL, keys, data, log format, access log); the port the
    environment names is taken, and the command line's (serve_process: --port 0) wins."""
    keys = tmp_path / "keys.toml"
    keys.write_text(f'admin = ["{ADMIN}"]\n')
    central = tmp_path / "central.sqlite3"
    taken = held_port()
    environment = {
        "SHOCKBENCH_DATABASE_URL": f"sqlite:///{central}",
        "SHOCKBENCH_KEYS": str(keys),
        "SHOCKBENCH_DATA": str(tmp_path / "data"),
        "SHOCKBENCH_PORT": str(taken.getsockname()[1]),
        "SHOCKBENCH_LOG_FORMAT": "json",
        "SHOCKBENCH_ACCESS_LOG": "1",
    }
    for name, value in environment.items():
        monkeypatch.setenv(name, value)
    service = serve_process(tmp_path, "serve")
    try:
        wait_until(lambda: service.answers(ADMIN), 180, "service ready")
        with service.client(ADMIN) as client:
            files = {
                "recording": ("recording.csv", inputs.recording.read_bytes(), "text/csv"),
                "vehicle": ("vehicle.toml", inputs.vehicle.read_bytes(), "application/toml"),
            }
            submitted = client.post("/api/v1/jobs", files=files)
            assert submitted.status_code == 201, submitted.text
            job = wait_for_status(client, submitted.headers["location"], "succeeded", "failed", timeout_s=300)
            assert client.get("/healthz").status_code == 200
        wait_until(lambda: "GET /healthz" in service.log.read_text(), 30, "the access log's line")
        # uvicorn shuts down gracefully, then re-raises the signal it caught
        assert service.terminate() == -signal.SIGTERM
    finally:
        service.stop()
        taken.close()

    records = [json.loads(line) for line in service.log.read_text().splitlines() if line.strip()]
    assert all({"time", "level", "logger", "message"} <= set(r) for r in records)
    assert all(re.fullmatch(TIMESTAMP, r["time"]) for r in records)
    loggers = {r["logger"] for r in records}
    assert {"uvicorn.error", "uvicorn.access", "shockbench.jobs", "shockbench.serve"} <= loggers
    messages = [r["message"] for r in records]
    ended = [m for m in messages if m.startswith(f"job {job['id']} ")]
    assert len(ended) == 1 and ended[0].startswith(f"job {job['id']} (identify) {job['status']} after ")
    assert any(m.startswith("listening on http://127.0.0.1:") for m in messages)
    assert any(f"synced to the central database sqlite:///{central}" in m for m in messages)
    assert any('"POST /api/v1/jobs HTTP/1.1" 201' in m for m in messages)
    assert not any(ADMIN in m for m in messages)  # keys travel in a header the access log does not show
    with sqlite3.connect(central) as db:  # the central database of the environment was brought up to date
        assert ("jobs",) in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'").fetchall()


def test_serve_logs_text_with_timestamps_and_no_access_log_by_default(tmp_path: Path) -> None:
    service = serve_process(tmp_path, "serve", "--data", str(tmp_path / "data"))
    try:
        key = wait_until(lambda: re.search(r"^    (\S{16,})$", service.log.read_text(), re.M), 60, "key")[1]
        wait_until(lambda: service.answers(key), 180, "service ready")
        with service.client(key) as client:
            assert client.get("/healthz").status_code == 200
    finally:
        service.stop()
    lines = service.log.read_text().splitlines()
    records = [line for line in lines if TEXT_RECORD.match(line)]
    assert any(" uvicorn.error: Started server process" in line for line in records)
    assert any(" shockbench.api: shockbench service up" in line for line in records)
    assert any(" shockbench.jobs: worker 1 started" in line for line in records)
    assert not any(line.startswith(("INFO:", "WARNING:", "ERROR:")) for line in lines)  # uvicorn's own format
    assert not any("GET /" in line for line in lines)  # no access log unless asked for


def test_a_jobs_end_is_logged_once_and_not_by_an_instance_that_lost_its_claim(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The end of a job is one line. An instance whose claim was taken over (the shared queue) said both
    "job N succeeded here, but ... not written" and "job N succeeded", and the new owner says it once more:
    now it says only the first, and its metrics do not count the run."""
    database = Database(f"sqlite:///{tmp_path / 'queue.sqlite3'}")
    database.upgrade_schema()
    store = JobStore(database, lane="north")
    files = JobFiles(tmp_path / "r.csv", tmp_path / "v.toml", tmp_path)
    ours, taken = (store.create("identify", {}, lambda _i: files).id for _ in range(2))
    assert JobQueue(database, "north").claim_next().id == ours  # type: ignore[union-attr]
    assert JobQueue(database, "south").claim_next().id == taken  # type: ignore[union-attr]
    counted: list[tuple[str, str, float]] = []
    manager = JobManager(store, on_finished=lambda *run: counted.append(run))

    async def finish(job_id: int) -> None:
        current = _Current(job_id, "identify", 1, asyncio.get_running_loop().create_future())
        manager._current = current
        await manager._finish(current, JobStatus.SUCCEEDED, result={}, artefacts={})

    with caplog.at_level(logging.INFO, logger="shockbench.jobs"):
        asyncio.run(finish(ours))
        asyncio.run(finish(taken))
    database.dispose()
    lines = [r.getMessage() for r in caplog.records if r.name == "shockbench.jobs"]
    assert len(lines) == 2, lines
    assert re.fullmatch(rf"job {ours} \(identify\) succeeded after \d+\.\d s", lines[0])
    assert lines[1] == f"job {taken} succeeded here, but its claim was taken over meanwhile: not written"
    assert [run[:2] for run in counted] == [("identify", "succeeded")]
