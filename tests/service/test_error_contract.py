"""The error contract (issue 16): bad input is a `UserError`, mapped once per edge; anything else is a bug
whose traceback is kept under an error id.

- API: every domain error class of the product answers the status of `service.api.errors.DOMAIN_ERRORS`;
  a bug answers 500 with an error id that the log holds with the traceback.
- CLI: a UserError is one line and exit 2; a bug is exit 1 and one line naming a log file with the traceback.
- Worker: a job failing on bad input fails with its one line; a bug fails naming an error id that the
  worker's log (stderr) holds with the traceback.
"""

from __future__ import annotations

import importlib
import logging
import pkgutil
import re
from pathlib import Path
from typing import Any

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from daq.bench_config import BenchConfigError
from daq.formats.recording_csv import RecordingFormatError
from daq.formats.vehicle_file import VehicleFileError
from daq.storage.hdf5_recording import RecordingFileError, RecordingGapError
from daq.sweep.run import SweepError
from drivers.compowayf.errors import DeviceUrlError
from drivers.exciter.errors import EnvelopeViolationError, ExciterConfigError, ExciterEncodingError
from estimator.bandwidth import InsufficientBandwidthError
from estimator.errors import ConflictError, InvalidValueError, NotFoundError, UserError, one_line
from estimator.model_io import ModelFormatError
from service.access import KeysFileError
from service.api.errors import DOMAIN_ERRORS, install_error_handlers, status_of
from service.bench_control import BenchBusyError
from service.cli.errors import CliError, run_command
from service.cli.main import main as cli_main
from service.jobs.context import InputError
from service.jobs.messages import FromWorker, JobFailed, RunJob
from service.store.database import DatabaseError

PRODUCT_PACKAGES = ("daq", "drivers", "estimator", "service", "simulators")

BAD_INPUT_CLASSES = (
    BenchConfigError,
    RecordingFormatError,
    VehicleFileError,
    RecordingFileError,
    RecordingGapError,
    SweepError,
    DeviceUrlError,
    EnvelopeViolationError,
    ExciterConfigError,
    ExciterEncodingError,
    InsufficientBandwidthError,
    ModelFormatError,
    InvalidValueError,
    KeysFileError,
    InputError,
    CliError,
    DatabaseError,
    BenchBusyError,
)
"""The bad-input classes of the product: each must have UserError as its root."""


def product_user_errors() -> list[type[UserError]]:
    """Every UserError subclass defined in the product (all its modules imported)."""
    for package_name in PRODUCT_PACKAGES:
        package = importlib.import_module(package_name)
        for module in pkgutil.walk_packages(package.__path__, f"{package_name}."):
            if not module.name.endswith("__main__"):
                importlib.import_module(module.name)
    found: list[type[UserError]] = []
    pending: list[type[UserError]] = [UserError]
    while pending:
        cls = pending.pop()
        found.append(cls)
        pending.extend(sub for sub in cls.__subclasses__() if sub.__module__.split(".")[0] != "tests")
    return sorted(set(found), key=lambda cls: f"{cls.__module__}.{cls.__qualname__}")


def expected_answer(cls: type[UserError]) -> tuple[int, str]:
    """The contract, written out independently of the table."""
    if issubclass(cls, BenchBusyError):
        return 409, "bench_busy"
    if issubclass(cls, ConflictError):
        return 409, "conflict"
    if issubclass(cls, NotFoundError):
        return 404, "not_found"
    if issubclass(cls, RecordingGapError):
        return 422, "recording_gaps"
    if issubclass(cls, RecordingFileError):
        return 422, "bad_recording"
    return 422, "invalid"


def instance_of(cls: type[UserError]) -> UserError:
    """An instance with a message (and a field when the class has one)."""
    special: dict[type[Any], UserError] = {
        BenchConfigError: BenchConfigError("lasers.1: bad channel", ("lasers", 1, "channel")),
        EnvelopeViolationError: EnvelopeViolationError("amplitude_m", 0.01, "max_amplitude_m", 0.005),
        InputError: InputError("points", "points: too many"),
    }
    for base, example in special.items():
        if cls is base:
            return example
    return cls(f"bad input of class {cls.__name__}\nsecond line never shown")


ALL_USER_ERRORS = product_user_errors()


def test_every_bad_input_class_has_the_root() -> None:
    missing = [cls.__name__ for cls in BAD_INPUT_CLASSES if not issubclass(cls, UserError)]
    assert missing == []
    assert set(BAD_INPUT_CLASSES) <= set(ALL_USER_ERRORS)


def test_the_table_holds_only_domain_errors_and_every_one_maps_as_the_contract_says() -> None:
    assert all(issubclass(cls, UserError) for cls in DOMAIN_ERRORS)
    wrong = {
        cls.__name__: (status_of(instance_of(cls)), expected_answer(cls))
        for cls in ALL_USER_ERRORS
        if status_of(instance_of(cls)) != expected_answer(cls)
    }
    assert wrong == {}


@pytest.fixture(scope="module")
def app_client() -> TestClient:
    app = FastAPI()
    install_error_handlers(app)

    @app.get("/raise/{index}")
    def raise_error(index: int) -> None:
        raise instance_of(ALL_USER_ERRORS[index])

    @app.get("/bug")
    def bug() -> None:
        raise KeyError("a bug with a secret in its message")

    return TestClient(app, raise_server_exceptions=False)


@pytest.mark.parametrize("index", range(len(ALL_USER_ERRORS)), ids=[c.__name__ for c in ALL_USER_ERRORS])
def test_every_domain_error_answers_its_status_over_http(app_client: TestClient, index: int) -> None:
    cls = ALL_USER_ERRORS[index]
    example = instance_of(cls)
    response = app_client.get(f"/raise/{index}")
    status, code = expected_answer(cls)
    assert response.status_code == status, response.text
    error = response.json()["error"]
    assert error["code"] == code
    assert error["message"] == one_line(example) and "\n" not in error["message"]
    assert error.get("field") == example.field


def test_a_bug_in_a_handler_is_a_500_with_an_error_id_that_the_log_holds(
    app_client: TestClient, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.ERROR, logger="shockbench.api"):
        response = app_client.get("/bug")
    assert response.status_code == 500
    error_id = response.headers["X-Error-Id"]
    assert error_id in response.json()["error"]["message"]
    assert "secret" not in response.text and "Traceback" not in response.text
    logged = [record for record in caplog.records if error_id in record.getMessage()]
    assert len(logged) == 1 and logged[0].exc_info is not None
    assert logged[0].exc_info[0] is KeyError


# ---- CLI ------------------------------------------------------------------------------------------------


@pytest.fixture
def log_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    folder = tmp_path / "logs"
    monkeypatch.setenv("SHOCKBENCH_LOG_DIR", str(folder))
    return folder


def test_cli_user_error_is_one_line_and_exit_2(
    tmp_path: Path, log_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recording = tmp_path / "recording.csv"
    recording.write_text("t,a,b\n0,1,2\n0.001,1,2\n0.002,1,2\n", encoding="utf-8")
    vehicle = tmp_path / "vehicle.toml"
    vehicle.write_text('[vehicle]\nmodel = "quarter-car"\nmass_kg = 400\n', encoding="utf-8")
    code = cli_main(["identify", str(recording), "--vehicle", str(vehicle)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("shockbench identify: error: ") and "Traceback" not in err
    assert not log_dir.exists()  # bad input is no bug: no log file


def test_cli_bug_is_exit_1_naming_a_log_file_with_the_traceback(
    tmp_path: Path, log_dir: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import daq.formats.recording_file

    def broken(_path: object, **_options: object) -> None:
        raise KeyError("a programming error")  # was taken for bad input (exit 2) before issue 16

    monkeypatch.setattr(daq.formats.recording_file, "load_recording_file", broken)
    code = cli_main(["identify", str(tmp_path / "any.csv"), "--vehicle", str(tmp_path / "any.toml")])
    err = capsys.readouterr().err
    assert code == 1
    assert err.count("\n") == 1 and "internal error" in err and "Traceback" not in err
    match = re.search(r"the traceback is in (\S+\.log)$", err.strip())
    assert match is not None, err
    log_file = Path(match.group(1))
    assert log_file.parent == log_dir
    text = log_file.read_text(encoding="utf-8")
    assert "Traceback" in text and "KeyError: 'a programming error'" in text and "broken" in text


def test_run_command_maps_user_errors_and_os_errors_to_2_and_the_rest_to_1(
    log_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    def raising(exc: BaseException) -> Any:
        def handler() -> int:
            raise exc

        return handler

    assert run_command("x", raising(InvalidValueError("mass_kg must be > 0"))) == 2
    assert run_command("x", raising(FileNotFoundError(2, "No such file", "a.csv"))) == 2
    assert run_command("x", raising(ValueError("a bug's ValueError"))) == 1
    assert run_command("x", lambda: 0) == 0
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == "shockbench x: error: mass_kg must be > 0"
    assert lines[1].startswith("shockbench x: error: [Errno 2] No such file")
    assert lines[2].startswith("shockbench x: internal error") and len(lines) == 3
    assert len(list(log_dir.glob("shockbench-error-*.log"))) == 1


# ---- worker ---------------------------------------------------------------------------------------------


def run_in_worker(tmp_path: Path, recording_text: str) -> JobFailed:
    from service.jobs.worker import run_job

    recording = tmp_path / "recording.csv"
    recording.write_text(recording_text, encoding="utf-8")
    vehicle = tmp_path / "vehicle.toml"
    vehicle.write_text('[vehicle]\nmodel = "quarter-car"\nmass_kg = 400\n', encoding="utf-8")
    sent: list[FromWorker] = []
    job = RunJob(7, "identify", str(recording), str(vehicle), str(tmp_path / "out"), {})
    import threading

    run_job(job, sent.append, threading.Event(), 0.2)
    failed = [message for message in sent if isinstance(message, JobFailed)]
    assert len(failed) == 1, sent
    return failed[0]


def test_worker_bad_input_fails_the_job_with_its_one_line(tmp_path: Path) -> None:
    failed = run_in_worker(tmp_path, "t,a,b\n0,1,2\n0.001,1,2\n0.002,1,2\n")
    assert "columns t,a,b are neither" in failed.reason and "error id" not in failed.reason
    assert "\n" not in failed.reason and str(tmp_path) not in failed.reason


def test_worker_bug_fails_the_job_naming_an_error_id_its_log_holds(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import daq.formats.recording_file

    def broken(_path: object) -> None:
        raise TypeError("a programming error")

    monkeypatch.setattr(daq.formats.recording_file, "read_recording_file", broken)
    failed = run_in_worker(tmp_path, "unused")
    match = re.search(r"error id ([0-9a-f]{12})", failed.reason)
    assert match is not None and "internal error in the worker" in failed.reason, failed.reason
    assert "Traceback" not in failed.reason
    log = capsys.readouterr().err
    assert f"error id {match.group(1)}" in log and "Traceback" in log
    assert "TypeError: a programming error" in log
