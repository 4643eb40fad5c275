"""Files honour the umask: what the user asks for (recordings, exports, results, plots, the chain's heads
log) is created 0o666 less the umask, as any file the user writes; only secrets are 0600 whatever the umask
(the service's key-id secret, the CLI's bug logs, whose command line may hold a database password)."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest

from daq.formats.atomic import PRIVATE, atomic_write
from service.cli.main import main

UMASKS = [0o022, 0o027]
"""The usual umask (files 0644) and a stricter one (0640): the mode follows the umask, not a constant."""


@pytest.fixture(params=UMASKS, ids=lambda umask: f"umask-{umask:03o}")
def umask(request: pytest.FixtureRequest) -> Iterator[int]:
    before = os.umask(request.param)
    try:
        yield request.param
    finally:
        os.umask(before)


def mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_an_atomic_write_is_created_as_open_would_create_it(tmp_path: Path, umask: int) -> None:
    with atomic_write(tmp_path / "result.json") as handle:
        handle.write("{}")
    with atomic_write(tmp_path / "plot.png", "wb") as handle:
        handle.write(b"\x89PNG")
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    assert mode(tmp_path / "result.json") == mode(tmp_path / "plot.png") == mode(plain) == 0o666 & ~umask
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "plain.txt",
        "plot.png",
        "result.json",
    ]  # no leftovers


def test_a_secret_stays_private_whatever_the_umask(tmp_path: Path, umask: int) -> None:
    with atomic_write(tmp_path / "secret", "wb", permissions=PRIVATE) as handle:
        handle.write(b"s")
    assert mode(tmp_path / "secret") == 0o600


def test_a_failed_atomic_write_leaves_the_old_file_and_no_part(tmp_path: Path, umask: int) -> None:
    target = tmp_path / "rec.csv"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_write(target) as handle:
        handle.write("new")
        raise RuntimeError("cut off")
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["rec.csv"]


def test_the_commands_outputs_follow_the_umask(
    tmp_path: Path, umask: int, plate_offset_files: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from test_cli_export import make_recording

    h5 = tmp_path / "sweep.h5"
    make_recording(h5)  # the HDF5 writer `shockbench sweep` records with
    exported, plot = tmp_path / "sweep.csv", tmp_path / "curve.png"
    assert main(["export", str(h5), "--out", str(exported)]) == 0
    recording = tmp_path / "sim.csv"
    vehicle = plate_offset_files / "vehicle.toml"
    assert main(["simulate", "--vehicle", str(vehicle), "--out", str(recording), "--duration-s", "2"]) == 0
    rec = plate_offset_files / "rec.csv"
    assert main(["identify", str(rec), "--vehicle", str(vehicle), "--plot", str(plot)]) == 0, (
        capsys.readouterr()
    )
    for output in (h5, exported, recording, plot):
        assert mode(output) == 0o666 & ~umask, output.name


def test_the_bug_log_is_private_whatever_the_umask(
    tmp_path: Path, umask: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    from service.cli.errors import LOG_DIR_ENV, write_bug_log

    monkeypatch.setenv(LOG_DIR_ENV, str(tmp_path))
    try:
        raise RuntimeError("database postgresql+psycopg://lane:hunter2@central/db")
    except RuntimeError as exc:
        log = write_bug_log("serve", exc)
    assert mode(log) == 0o600 and "hunter2" in log.read_text()


def test_the_service_keeps_its_secret_private_and_its_heads_log_readable(tmp_path: Path, umask: int) -> None:
    from service.api.app import FINGERPRINT_SECRET_FILE, fingerprint_secret
    from service.store.chain_anchor import Head, HeadLog

    fingerprint_secret(tmp_path)
    assert mode(tmp_path / FINGERPRINT_SECRET_FILE) == 0o600
    heads = HeadLog.in_data_dir(tmp_path)
    heads.append(Head("lane-1", 1, 1, "ab"))
    assert mode(heads.path) == 0o666 & ~umask  # hashes, no secret: an auditor may read it
