"""Free text (issue 30, item 6): control characters, bidirectional overrides and line separators in an
operator's name are refused (422 naming the field; `shockbench sweep --operator` exits 2), and stored text
an older database may hold is printed escaped by `shockbench history`."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from live_server import LiveServer
from pydantic import ValidationError

from daq.formats.vehicle_file import format_vehicle
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.api.sweep_launch import SweepIn
from service.cli.main import main
from service.free_text import escaped, json_escaped, problem
from service.store.database import Database
from service.store.models import SweepStatus
from service.store.sweeps import SweepStore
from simulators.vehicle_sim import default_quarter_car

ADMIN = "admin-key-0123456789"
VEHICLE_TOML = format_vehicle(default_quarter_car().known)
HOSTILE = "\x1b[31m"


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("\x1b[31mred", "U+001B (a control character) at position 0"),
        ("tab\there", "U+0009"),
        ("two\nlines", "U+000A"),
        ("del\x7f", "U+007F"),
        ("c1\x9b31m", "U+009B"),  # the one-byte CSI of C1
        ("evil\u202eexe.txt", "U+202E (right-to-left override) at position 4"),
        ("isolate\u2066x\u2069", "U+2066 (left-to-right isolate)"),
        ("line\u2028sep", "U+2028 (line separator)"),
    ],
)
def test_control_characters_and_bidi_overrides_are_refused(text: str, named: str) -> None:
    found = problem(text)
    assert found is not None and named in found
    assert "\x1b" not in found and "\u202e" not in found  # the message names it, never carries it


@pytest.mark.parametrize("text", ["Jürgen Müller", "Zoë O'Brien-Ng", "山田 太郎", "mechanic 👩\u200d🔧"])
def test_names_in_any_script_are_accepted(text: str) -> None:
    assert problem(text) is None and escaped(text) == text
    assert SweepIn(vehicle_toml=VEHICLE_TOML, operator_name=text).operator_name == text


def test_escaped_writes_what_it_refuses_as_python_escapes() -> None:
    assert escaped("\x1b[31mEve\u202e\n\x85") == "\\x1b[31mEve\\u202e\\n\\x85"
    document = json.dumps({"name": "\x1b\u202e\x85", "n": [1]}, ensure_ascii=False, indent=2)
    shown = json_escaped(document)
    assert json.loads(shown) == json.loads(document)  # the same document
    assert not any(c in shown for c in "\x1b\u202e\x85")


def test_the_sweep_request_refuses_it_naming_the_field() -> None:
    with pytest.raises(ValidationError) as caught:
        SweepIn(vehicle_toml=VEHICLE_TOML, operator_name=HOSTILE)
    assert caught.value.errors()[0]["loc"] == ("operator_name",)


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    settings = ServiceSettings(
        data_dir=tmp_path_factory.mktemp("free-text"), keys=KeyRing({ADMIN: Role.ADMIN}), simulated=True
    )
    with LiveServer(create_app(settings)) as server, server.client(ADMIN) as c:
        yield c


@pytest.mark.parametrize("path", ["/api/v1/sweeps", "/api/v1/schedules"])
@pytest.mark.parametrize("name", [HOSTILE, "Eve\u202etxt.exe", "a\x00b"])
def test_the_api_answers_422_naming_the_operator_name(client: httpx.Client, path: str, name: str) -> None:
    before = client.get(path).json()["total"]
    response = client.post(path, json={"vehicle_toml": VEHICLE_TOML, "operator_name": name})
    assert response.status_code == 422, response.text
    error = response.json()["error"]
    assert error["code"] == "invalid" and error["field"] == "operator_name"
    assert error["message"].startswith("operator_name: must not contain control characters")
    assert name not in response.text  # not echoed back either
    assert client.get(path).json()["total"] == before  # nothing stored, nothing moved


def test_the_sweep_command_refuses_it_with_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    vehicle = tmp_path / "vehicle.toml"
    vehicle.write_text(VEHICLE_TOML)
    out = tmp_path / "run.h5"
    with pytest.raises(SystemExit) as exited:
        main(["sweep", "--simulated", "--vehicle", str(vehicle), "--out", str(out), "--operator", HOSTILE])
    assert exited.value.code == 2
    stderr = capsys.readouterr().err
    assert "argument --operator: the operator's name must not contain control characters" in stderr
    assert "\x1b" not in stderr and not out.exists()


def test_history_prints_a_stored_escape_sequence_escaped(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A name stored before the check (written to the database directly) reaches no terminal raw."""
    database = Database(f"sqlite:///{tmp_path / 'shockbench.sqlite3'}")
    database.upgrade_schema()
    try:
        store = SweepStore(database, lane="lane\x1b]0;owned\x07")
        settings = {"vehicle_id": "AB-1", "operator_name": "\x1b[1mE\u202e"}
        sweep = store.create("bench", settings, lambda i: (tmp_path / f"{i}.h5", tmp_path / f"{i}.toml"))
        assert store.finish(sweep.id, SweepStatus.COMPLETE, complete=True, reason=None)
    finally:
        database.dispose()

    assert main(["history", "AB-1", "--data", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "\\x1b[1mE\\u202e" in text and "lane\\x1b]0;" in text
    assert not any(c in text for c in "\x1b\x07\u202e")

    assert main(["history", "AB-1", "--data", str(tmp_path), "--json"]) == 0
    shown = capsys.readouterr().out
    assert not any(c in shown for c in "\x1b\x07\u202e")
    assert json.loads(shown)["tests"][0]["operator_name"] == "\x1b[1mE\u202e"  # the same value
