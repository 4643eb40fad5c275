"""The readers of what a user hands the bench, fed arbitrary bytes (hypothesis): the recording reader
(daq.formats.recording_file, under an .h5 and a .csv name) and the vehicle file reader either return a
valid recording (vehicle) or raise a UserError whose one line names the file; nothing else, and never a
hang. Besides plain random bytes, the inputs are built to reach deep into each format: the bench's own
HDF5 files (closed, and one still open by its SWMR writer) truncated and with bytes changed, the HDF5
signature followed by junk, recording CSV text with junk rows, and TOML-ish vehicle text.

Deterministic: derandomize=True draws the same examples on every run; no deadline (file I/O on a shared
machine is no timing test).
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from daq.formats.hdf5_file import HDF5_SIGNATURE, swmr_state
from daq.formats.recording_file import read_recording_file
from daq.formats.vehicle_file import load_vehicle_file, parse_vehicle_file
from daq.storage.hdf5_recording import RecordingWriter
from estimator.errors import UserError
from estimator.recording import QUARTER_CAR_CHANNELS, Recording
from estimator.vehicle import VehicleParameters

FUZZ = settings(
    derandomize=True,
    deadline=None,
    max_examples=200,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
VEHICLE_TEXT = '[vehicle]\nmodel = "quarter-car"\nmass_kg = 420.0\nspring_stiffness_N_per_m = 26000\n'
CSV_HEADER = "# bench: fuzz\nt,x_s,x_t,x_r\n"


def _write_bench_file(path: Path, *, close: bool) -> bytes:
    """A recording as the bench writes it (a vehicle text inside); unclosed: the bytes a crash leaves."""
    t = np.arange(1500) * 0.001
    data = {c: 1e-3 * np.sin(2 * np.pi * (i + 1) * t) for i, c in enumerate(QUARTER_CAR_CHANNELS)}
    vehicle = parse_vehicle_file(VEHICLE_TEXT, "v.toml")
    writer = RecordingWriter(path, QUARTER_CAR_CHANNELS, 0.001, {"bench": "fuzz"}, vehicle=vehicle)
    writer.append(t, data)
    if close:
        writer.close(True)
        return path.read_bytes()
    content = path.read_bytes()  # flushed, the SWMR writer still holding it
    writer.close(True)
    return content


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    path = tmp_path_factory.mktemp("fuzz")
    yield path
    shutil.rmtree(path, ignore_errors=True)


@pytest.fixture(scope="module")
def bench_files(folder: Path) -> dict[str, bytes]:
    return {
        "closed": _write_bench_file(folder / "closed.h5", close=True),
        "open": _write_bench_file(folder / "open.h5", close=False),
    }


def assert_valid(recording: Recording) -> None:
    """What the estimator relies on: 3 or more finite, uniform samples, finite channels of that length."""
    t = recording.time_s
    assert t.size >= 3 and np.all(np.isfinite(t))
    assert np.isfinite(recording.sample_time_s) and recording.sample_time_s > 0
    for values in recording.channels.values():
        assert values.shape == t.shape and np.all(np.isfinite(values))


def read_or_user_error(folder: Path, content: bytes) -> None:
    """Read `content` under both names: a valid recording, or a one-line UserError naming the file."""
    for name in ("recording.h5", "recording.csv"):
        path = folder / name
        path.write_bytes(content)
        try:
            recording = read_recording_file(path)
        except UserError as exc:
            message = str(exc)
            assert str(path) in message and "\n" not in message.strip(), message
        else:
            assert_valid(recording)


def damaged(content: bytes, cut: int, changes: list[tuple[int, int]]) -> bytes:
    """`content` cut to `cut` bytes (at least 1), with byte changes (position modulo the length)."""
    out = bytearray(content[: max(1, cut)])
    for position, value in changes:
        out[position % len(out)] = value
    return bytes(out)


@FUZZ
@given(content=st.binary(max_size=4096))
def test_arbitrary_bytes_read_as_a_recording_or_a_user_error(folder: Path, content: bytes) -> None:
    read_or_user_error(folder, content)


@FUZZ
@given(junk=st.binary(max_size=4096))
def test_hdf5_signature_then_junk(folder: Path, junk: bytes) -> None:
    read_or_user_error(folder, HDF5_SIGNATURE + junk)


@FUZZ
@given(
    which=st.sampled_from(["closed", "open"]),
    cut=st.integers(min_value=0, max_value=200_000),
    changes=st.lists(st.tuples(st.integers(min_value=0), st.integers(0, 255)), max_size=12),
)
def test_the_bench_files_truncated_and_damaged(
    folder: Path, bench_files: dict[str, bytes], which: str, cut: int, changes: list[tuple[int, int]]
) -> None:
    read_or_user_error(folder, damaged(bench_files[which], cut, changes))


ROW = st.lists(
    st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.text(max_size=6)),
    max_size=5,
).map(",".join)


@FUZZ
@given(rows=st.lists(ROW, max_size=12), good_rows=st.integers(0, 8))
def test_recording_csv_with_junk_rows(folder: Path, rows: list[str], good_rows: int) -> None:
    good = [f"{k * 0.001:.6f},0.001,0.002,0.003" for k in range(good_rows)]
    read_or_user_error(folder, (CSV_HEADER + "\n".join(good + rows)).encode("utf-8", "surrogatepass"))


def test_the_bench_files_read_whole(folder: Path, bench_files: dict[str, bytes]) -> None:
    """The fuzzed files are good ones before they are damaged (and read alike under a .csv name); the
    open one is read in SWMR mode, the closed one as any HDF5 file."""
    for which, content in bench_files.items():
        for name in ("whole.h5", "whole.csv"):
            (folder / name).write_bytes(content)
            assert (swmr_state(folder / name) is not None) == (which == "open")
            recording = read_recording_file(folder / name)
            assert recording.time_s.size == 1500 and recording.metadata["vehicle_text"] == VEHICLE_TEXT


@pytest.mark.parametrize("which", ["closed", "open"])
def test_a_truncated_bench_file_is_refused_as_truncated(
    folder: Path, bench_files: dict[str, bytes], which: str
) -> None:
    """Not a hang: HDF5's SWMR reader retried a truncated file's metadata for hours before."""
    path = folder / f"cut-{which}.h5"
    path.write_bytes(bench_files[which][: len(bench_files[which]) // 2])
    with pytest.raises(UserError, match=r"truncated file") as refused:
        read_recording_file(path)
    assert str(refused.value).startswith(f"{path}: cannot read the recording")


def vehicle_or_user_error(folder: Path, content: bytes) -> None:
    path = folder / "vehicle.toml"
    path.write_bytes(content)
    try:
        vehicle = load_vehicle_file(path)
    except UserError as exc:
        message = str(exc)
        assert str(path) in message and "\n" not in message.strip(), message
    else:  # its values' bounds (an infinite stiffness...) are the submit checks' (service.jobs.bounds)
        assert isinstance(vehicle.parameters, VehicleParameters) and vehicle.parameters.mass_kg > 0


@FUZZ
@given(content=st.binary(max_size=2048))
def test_arbitrary_bytes_as_a_vehicle_file(folder: Path, content: bytes) -> None:
    vehicle_or_user_error(folder, content)


KEY = st.sampled_from(
    [
        "model",
        "mass_kg",
        "spring_stiffness_N_per_m",
        "tyre_stiffness_N_per_m",
        "tyre_viscoelastic_coefficient",
        "tyre_relaxation_time_s",
        "track_m",
        "anti_roll_bar_stiffness_N_per_m",
        "colour",
    ]
)
VALUE = st.one_of(
    st.sampled_from(
        ['"quarter-car"', '"axle"', "inf", "-inf", "nan", "true", "[1, 2]", "1e400", "9" * 400, "9" * 5000]
    ),
    st.integers().map(str),
    st.floats().map(repr),
    st.text(max_size=8),
)


@FUZZ
@given(
    table=st.sampled_from(["[vehicle]", "[car]", "", "[[vehicle]]"]),
    model=st.one_of(st.sampled_from(['"quarter-car"', '"axle"']), VALUE),
    mass=st.one_of(st.just("420"), VALUE),
    lines=st.lists(st.tuples(KEY, VALUE), max_size=4),
)
@example(table="[vehicle]", model='"quarter-car"', mass="420", lines=[("spring_stiffness_N_per_m", "inf")])
@example(table="[vehicle]", model='"quarter-car"', mass="9" * 400, lines=[])
@example(table="[vehicle]", model='"quarter-car"', mass="420", lines=[("tyre_relaxation_time_s", "inf")])
@example(table="[vehicle]", model='"quarter-car"', mass="9" * 5000, lines=[])
@example(table="[vehicle]", model='"quarter-car"', mass="[" * 100_000, lines=[])
def test_toml_like_vehicle_files(
    folder: Path, table: str, model: str, mass: str, lines: list[tuple[str, str]]
) -> None:
    """The required keys first (any value), then any keys: deep into the checks of the values."""
    body = [("model", model), ("mass_kg", mass), *lines]
    text = "\n".join([table, *(f"{key} = {value}" for key, value in body)])
    vehicle_or_user_error(folder, text.encode("utf-8", "surrogatepass"))
