"""HDF5 recordings: appends, metadata, gaps, partial files while writing and after a crash, CSV export."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import load_vehicle_file
from daq.storage.hdf5_recording import (
    FLAG_GAP,
    NOT_CLOSED_REASON,
    RecordingFileError,
    RecordingGapError,
    RecordingWriter,
    export_csv,
    load_recording,
    read_recording,
)
from estimator.recording import AXLE_CHANNELS, QUARTER_CAR_CHANNELS

DT = 0.001
REPO = Path(__file__).resolve().parents[2]


def signals(n: int, channels: tuple[str, ...] = QUARTER_CAR_CHANNELS, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {c: 0.004 * rng.standard_normal(n) for c in channels}


def write_blocks(
    writer: RecordingWriter, data: dict[str, np.ndarray], block: int, t0: float = 0.0
) -> np.ndarray:
    n = next(iter(data.values())).size
    t = t0 + np.arange(n) * DT
    for start in range(0, n, block):
        stop = min(n, start + block)
        writer.append(t[start:stop], {c: v[start:stop] for c, v in data.items()})
    return t


def test_round_trip_in_several_appends(tmp_path: Path) -> None:
    path = tmp_path / "rec.h5"
    data = signals(2345)
    with RecordingWriter(path, QUARTER_CAR_CHANNELS, DT) as writer:
        t = write_blocks(writer, data, block=100, t0=0.5)
        writer.close(complete=True)
    recording, meta, flags = read_recording(path)
    np.testing.assert_array_equal(recording.time_s, t)
    for c in QUARTER_CAR_CHANNELS:
        np.testing.assert_array_equal(recording.channels[c], data[c])
    assert flags.dtype == np.uint8 and not flags.any()
    assert meta["status"] == "complete" and meta["reason"] == ""
    assert meta["samples"] == 2345 and meta["gaps"] == 0
    with h5py.File(path, "r") as f:  # a closed file opens without SWMR too, and with units on the datasets
        assert f["channels/x_s"].attrs["unit"] == "m" and f["time"].attrs["unit"] == "s"
        assert f["channels/x_s"].chunks == (1000,)


def test_axle_channels_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "axle.h5"
    data = signals(50, AXLE_CHANNELS)
    with RecordingWriter(path, AXLE_CHANNELS, DT) as writer:
        write_blocks(writer, data, block=7)
        writer.close(complete=True)
    recording, _, _ = read_recording(path)
    assert recording.is_axle
    np.testing.assert_array_equal(recording.channels["x_r_r"], data["x_r_r"])


def test_metadata_round_trip(tmp_path: Path) -> None:
    vehicle = tmp_path / "car.toml"
    vehicle.write_text('[vehicle]\nmodel = "quarter-car"  # test car\nmass_kg = 350.0\n', encoding="utf-8")
    path = tmp_path / "rec.h5"
    metadata = {
        "bench": "bench-2",
        "sweep": "0-20 Hz, 4 mm, 20 s",
        "laser_model": "optoNCDT 1420",
        "laser_firmware": "v3.1",
        "exciter_model": "plate-x",
        "operator": "A. Müller",
        "start_time": "2024-05-01T10:00:00.000+00:00",
        "software_version": "9.9.9",
        "plate_mass_kg": 12.5,
        "laser_count": 3,
    }
    writer = RecordingWriter(
        path,
        QUARTER_CAR_CHANNELS,
        DT,
        metadata,
        vehicle=load_vehicle_file(vehicle),
        rates_Hz={"laser": 1000.0, "exciter": 500},
    )
    write_blocks(writer, signals(10), block=10)
    writer.close(complete=True, rates_Hz={"laser": 999.7, "exciter": 500.2})
    _, meta, _ = read_recording(path)
    for key, value in metadata.items():
        assert meta[key] == value, key
    assert meta["vehicle_file"] == str(vehicle)
    assert meta["vehicle_text"] == vehicle.read_text(encoding="utf-8")
    assert meta["rate_Hz.laser"] == 999.7 and meta["rate_Hz.exciter"] == 500.2
    assert meta["sample_time_s"] == DT and meta["channels"] == "x_s,x_t,x_r"
    assert meta["end_time"].endswith("+00:00")


def test_default_start_time_is_iso_utc(tmp_path: Path) -> None:
    with RecordingWriter(tmp_path / "r.h5", QUARTER_CAR_CHANNELS, DT) as writer:
        write_blocks(writer, signals(5), block=5)
        writer.close(True)
    meta = load_recording(tmp_path / "r.h5").metadata
    assert str(meta["start_time"]).endswith("+00:00") and str(meta["start_time"])[4] == "-"
    assert meta["software_version"]


def test_bad_metadata_and_undeclared_rates_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="written by the recorder"):
        RecordingWriter(tmp_path / "a.h5", QUARTER_CAR_CHANNELS, DT, {"status": "x"})
    with pytest.raises(ValueError, match="not str, int or float"):
        RecordingWriter(tmp_path / "b.h5", QUARTER_CAR_CHANNELS, DT, {"x": [1, 2]})
    writer = RecordingWriter(tmp_path / "c.h5", QUARTER_CAR_CHANNELS, DT, rates_Hz={"laser": 1000.0})
    write_blocks(writer, signals(5), block=5)
    with pytest.raises(ValueError, match="exciter"):
        writer.close(True, rates_Hz={"exciter": 500.0})
    writer.close(True, rates_Hz={"laser": 1000.1})  # the refused close changed nothing
    assert load_recording(tmp_path / "c.h5").metadata["rate_Hz.laser"] == 1000.1


def test_gaps_are_nan_flagged_and_counted(tmp_path: Path) -> None:
    path = tmp_path / "gaps.h5"
    data = signals(300)
    data["x_s"][[10, 11, 12, 99, 100]] = np.nan  # 99-100 spans two appends of 100: one gap
    data["x_r"][200] = np.nan
    extra = np.zeros(300, dtype=np.uint8)
    extra[150] = 0x04  # another bit passes through
    with RecordingWriter(path, QUARTER_CAR_CHANNELS, DT) as writer:
        t = np.arange(300) * DT
        for s in range(0, 300, 100):
            writer.append(t[s : s + 100], {c: v[s : s + 100] for c, v in data.items()}, extra[s : s + 100])
        assert writer.gaps == 3
        writer.close(True)
    stored = load_recording(path)
    expected = np.zeros(300, dtype=bool)
    expected[[10, 11, 12, 99, 100, 200]] = True
    np.testing.assert_array_equal(stored.gap_mask, expected)
    assert stored.flags[150] == 0x04
    assert np.isnan(stored.channels["x_s"][11]) and np.isfinite(stored.channels["x_t"][11])
    assert stored.metadata["gaps"] == 3 and stored.metadata["gap_samples"] == 6
    assert stored.metadata["first_gap_s"] == pytest.approx(0.010)
    with h5py.File(path, "r") as f:
        assert f.attrs["gaps"] == 3 and f.attrs["gap_samples"] == 6
    with pytest.raises(RecordingGapError, match=r"3 gap\(s\) .*first at t = 0\.010 s"):
        read_recording(path)


def test_a_gap_flag_without_nan_is_refused(tmp_path: Path) -> None:
    writer = RecordingWriter(tmp_path / "r.h5", QUARTER_CAR_CHANNELS, DT)
    flags = np.zeros(5, dtype=np.uint8)
    flags[2] = FLAG_GAP
    with pytest.raises(ValueError, match="flagged as a gap but has a value"):
        writer.append(np.arange(5) * DT, signals(5), flags)
    assert writer.samples == 0
    writer.close(False, "test")


def test_appends_off_the_grid_or_with_wrong_channels_are_refused(tmp_path: Path) -> None:
    writer = RecordingWriter(tmp_path / "r.h5", QUARTER_CAR_CHANNELS, DT)
    writer.append(np.arange(5) * DT, signals(5))
    with pytest.raises(ValueError, match="not on the 1 ms grid"):
        writer.append(0.006 + np.arange(5) * DT, signals(5))  # skips 0.005
    with pytest.raises(ValueError, match="channels"):
        writer.append(0.005 + np.arange(5) * DT, signals(5, ("x_s", "x_t")))
    with pytest.raises(ValueError, match="infinite"):
        writer.append(0.005 + np.arange(5) * DT, {**signals(5), "x_t": np.full(5, np.inf)})
    writer.append(0.005 + np.arange(5) * DT, signals(5))
    writer.close(True)
    assert load_recording(tmp_path / "r.h5").time_s.size == 10


def test_partial_file_is_readable_while_the_writer_is_open(tmp_path: Path) -> None:
    path = tmp_path / "live.h5"
    data = signals(2550)
    writer = RecordingWriter(path, QUARTER_CAR_CHANNELS, DT)
    write_blocks(writer, data, block=150)
    assert writer.samples - writer.flushed_samples < 1000  # less than one second not yet on disk
    copy = tmp_path / "copy.h5"
    shutil.copy(path, copy)  # what a crash right now would leave on disk
    for partial in (path, copy):
        stored = load_recording(partial)
        n = stored.time_s.size
        assert 2550 - 1000 < n <= 2550
        assert stored.metadata["status"] == "incomplete" and stored.metadata["reason"] == NOT_CLOSED_REASON
        for c in QUARTER_CAR_CHANNELS:
            np.testing.assert_array_equal(stored.channels[c], data[c][:n])
    writer.close(True)
    assert load_recording(path).time_s.size == 2550


def test_file_left_by_a_killed_writer_holds_everything_but_the_last_second(tmp_path: Path) -> None:
    path = tmp_path / "crash.h5"
    script = textwrap.dedent(
        f"""
        import os, numpy as np
        from daq.storage.hdf5_recording import RecordingWriter
        w = RecordingWriter({str(path)!r}, ("x_s", "x_t", "x_r"), 0.001, {{"operator": "crash test"}})
        t = np.arange(2700) * 0.001
        for s in range(0, 2700, 100):
            b = t[s:s + 100]
            w.append(b, {{c: np.sin(b * (i + 1)) for i, c in enumerate(("x_s", "x_t", "x_r"))}})
        os._exit(0)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    stored = load_recording(path)
    n = stored.time_s.size
    assert 2700 - 1000 < n <= 2700
    np.testing.assert_array_equal(stored.channels["x_t"], np.sin(np.arange(n) * 0.001 * 2))
    assert stored.metadata["operator"] == "crash test"
    assert stored.metadata["status"] == "incomplete" and stored.metadata["samples"] == n


def test_incomplete_recording_keeps_its_reason(tmp_path: Path) -> None:
    path = tmp_path / "fault.h5"
    writer = RecordingWriter(path, QUARTER_CAR_CHANNELS, DT)
    write_blocks(writer, signals(40), block=40)
    with pytest.raises(ValueError, match="needs a reason"):
        writer.close(complete=False)
    writer.close(complete=False, reason="exciter fault 0x0010")
    _, meta, _ = read_recording(path)
    assert meta["status"] == "incomplete" and meta["reason"] == "exciter fault 0x0010"
    with pytest.raises(ValueError, match="already closed"):
        writer.close(True)


def test_leaving_the_with_block_by_an_exception_marks_the_file_incomplete(tmp_path: Path) -> None:
    path = tmp_path / "boom.h5"
    with pytest.raises(RuntimeError), RecordingWriter(path, QUARTER_CAR_CHANNELS, DT) as writer:
        write_blocks(writer, signals(10), block=10)
        raise RuntimeError("laser timeout")
    meta = load_recording(path).metadata
    assert meta["status"] == "incomplete" and meta["reason"] == "RuntimeError: laser timeout"


def test_export_csv_equals_the_data(tmp_path: Path) -> None:
    vehicle = tmp_path / "car.toml"
    vehicle.write_text('[vehicle]\nmodel = "quarter-car"\nmass_kg = 350.0\n', encoding="utf-8")
    path = tmp_path / "rec.h5"
    data = signals(1200)
    with RecordingWriter(
        path, QUARTER_CAR_CHANNELS, DT, {"bench": "b1\nsecond line"}, vehicle=load_vehicle_file(vehicle)
    ) as w:
        t = write_blocks(w, data, block=500)
        w.close(True)
    csv = tmp_path / "rec.csv"
    export_csv(path, csv)
    back = read_recording_csv(csv)
    np.testing.assert_allclose(back.time_s, t, atol=1e-9)
    for c in QUARTER_CAR_CHANNELS:
        np.testing.assert_allclose(back.channels[c], data[c], rtol=1e-8, atol=0)
    assert back.metadata["bench"] == "b1 second line"
    assert back.metadata["status"] == "complete" and back.metadata["vehicle_file"] == str(vehicle)
    assert back.metadata["source"] == str(path) and "vehicle_text" not in back.metadata


def test_export_with_gaps_is_refused_unless_allowed(tmp_path: Path) -> None:
    path = tmp_path / "gaps.h5"
    data = signals(1000)
    data["x_t"][[300, 301, 800]] = np.nan
    with RecordingWriter(path, QUARTER_CAR_CHANNELS, DT) as writer:
        t = write_blocks(writer, data, block=250)
        writer.close(True)
    csv = tmp_path / "out.csv"
    with pytest.raises(RecordingGapError, match=r"^\S+gaps\.h5: 2 gap\(s\) .*first at t = 0\.300 s") as err:
        export_csv(path, csv)
    assert "\n" not in str(err.value)
    assert not csv.exists()
    recording = export_csv(path, csv, allow_gaps=True)
    back = read_recording_csv(csv)
    np.testing.assert_allclose(back.time_s, t[302:800], atol=1e-9)  # the longest of 0-299, 302-799, 801-999
    np.testing.assert_allclose(back.channels["x_t"], data["x_t"][302:800], rtol=1e-8)
    assert "longest of 3 gap-free stretches" in back.metadata["gap_free_stretch"]
    assert recording.time_s.size == 498


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: None, "no such file"),
        (lambda p: p.write_text("t,x_s,x_t,x_r\n"), "not an HDF5 file"),
        (lambda p: h5py.File(p, "w").close(), "no dataset 'time'"),
    ],
)
def test_errors_are_one_line(tmp_path: Path, make, message: str) -> None:
    path = tmp_path / "bad.h5"
    make(path)
    with pytest.raises(RecordingFileError, match=message) as err:
        read_recording(path)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_missing_channel_dataset_is_named(tmp_path: Path) -> None:
    path = tmp_path / "r.h5"
    with RecordingWriter(path, QUARTER_CAR_CHANNELS, DT) as writer:
        write_blocks(writer, signals(10), block=10)
        writer.close(True)
    with h5py.File(path, "r+") as f:
        del f["channels/x_t"]
    with pytest.raises(RecordingFileError, match="no dataset for channel"):
        load_recording(path)


def test_too_short_recording_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "short.h5"
    with RecordingWriter(path, QUARTER_CAR_CHANNELS, DT) as writer:
        write_blocks(writer, signals(2), block=2)
        writer.close(True)
    assert load_recording(path).time_s.size == 2
    with pytest.raises(RecordingFileError, match="only 2 usable samples"):
        read_recording(path)
    assert math.isnan(float(load_recording(path).metadata["first_gap_s"]))


def test_an_existing_file_is_never_overwritten(tmp_path: Path) -> None:
    path = tmp_path / "r.h5"
    path.write_bytes(b"precious")
    with pytest.raises(FileExistsError, match="never overwritten"):
        RecordingWriter(path, QUARTER_CAR_CHANNELS, DT)
    assert path.read_bytes() == b"precious"
