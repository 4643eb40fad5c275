"""`shockbench export`: an HDF5 recording to the recording CSV, and one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from daq.formats.recording_csv import read_recording_csv
from daq.storage.hdf5_recording import RecordingWriter
from estimator.recording import QUARTER_CAR_CHANNELS
from service.cli.main import main


def make_recording(path: Path, gap: bool = False) -> dict[str, np.ndarray]:
    t = np.arange(500) * 0.001
    data = {c: np.sin(2 * np.pi * (i + 1) * t) * 1e-3 for i, c in enumerate(QUARTER_CAR_CHANNELS)}
    if gap:
        data["x_s"][100] = np.nan
    with RecordingWriter(path, QUARTER_CAR_CHANNELS, 0.001, {"bench": "cli test"}) as writer:
        writer.append(t, data)
        writer.close(complete=False, reason="exciter fault 0x0010")
    return data


def test_export_writes_the_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    h5 = tmp_path / "rec.h5"
    data = make_recording(h5)
    out = tmp_path / "rec.csv"
    assert main(["export", str(h5), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "wrote" in printed and "500 samples" in printed and "exciter fault 0x0010" in printed
    back = read_recording_csv(out)
    np.testing.assert_allclose(back.channels["x_r"], data["x_r"], rtol=1e-8)
    assert back.metadata["bench"] == "cli test" and back.metadata["status"] == "incomplete"


def test_export_with_gaps_needs_allow_gaps(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    h5 = tmp_path / "gap.h5"
    make_recording(h5, gap=True)
    out = tmp_path / "rec.csv"
    assert main(["export", str(h5), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "first at t = 0.100 s" in err and "--allow-gaps" in err
    assert not out.exists()
    assert main(["export", str(h5), "--out", str(out), "--allow-gaps"]) == 0
    assert read_recording_csv(out).time_s.size == 399
    assert "gaps left out" in capsys.readouterr().out


@pytest.mark.parametrize(("content", "message"), [(None, "no such file"), ("hello", "not an HDF5 file")])
def test_export_errors_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str | None, message: str
) -> None:
    h5 = tmp_path / "bad.h5"
    if content is not None:
        h5.write_text(content)
    assert main(["export", str(h5), "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("shockbench export: error:") and message in err
