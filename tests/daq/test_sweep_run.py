"""Sweep orchestration end to end on a simulated bench (real transports, manual clock): a complete sweep,
then every way a sweep can end early, each leaving the plate stopped and the partial recording kept and
marked incomplete with its reason."""

from __future__ import annotations

import asyncio
import dataclasses
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import load_vehicle_file, write_vehicle
from daq.storage.hdf5_recording import export_csv, load_recording
from daq.sweep.model import StopKind, SweepOutcome, SweepProgress, SweepRequest
from daq.sweep.pacing import SimulatedPacing
from daq.sweep.plan import plan_sweep
from daq.sweep.run import SweepError, run_sweep
from drivers.exciter.codes import CommandCode
from estimator.bandwidth import InsufficientBandwidthError, check_bandwidth
from estimator.sweep import SweepSettings
from service.simulated_bench import SimulatedBench
from simulators.devices.laser_amplifier import FaultKind
from simulators.excitation import sweep_position_m
from simulators.vehicle_sim import default_axle, default_quarter_car

SHORT = SweepSettings(duration_s=2.0)
EXCITER_FAULT = 0x0021


@pytest.fixture
def bench() -> Iterator[SimulatedBench]:
    with SimulatedBench(seed=5) as started:
        yield started


@pytest.fixture
def vehicle_file(tmp_path: Path) -> Path:
    path = tmp_path / "vehicle.toml"
    write_vehicle(path, default_quarter_car().known)
    return path


def sweep(
    bench: SimulatedBench,
    out: Path,
    request: SweepRequest,
    when: Callable[[SweepProgress], None] | None = None,
    abort: threading.Event | None = None,
) -> SweepOutcome:
    return asyncio.run(
        run_sweep(
            bench.config,
            plan_sweep(bench.config, request),
            out,
            pacing=SimulatedPacing(bench),
            progress=when,
            abort=abort,
        )
    )


def at(time_s: float, action: Callable[[], None]) -> Callable[[SweepProgress], None]:
    """A progress hook that runs `action` once, at the first report at or after time_s into the sweep."""
    done = threading.Event()

    def hook(progress: SweepProgress) -> None:
        if progress.phase == "sweeping" and progress.elapsed_s >= time_s and not done.is_set():
            done.set()
            action()

    return hook


def test_a_complete_sweep_records_every_channel_without_a_gap(
    bench: SimulatedBench, vehicle_file: Path, tmp_path: Path
) -> None:
    out = tmp_path / "run.h5"
    request = SweepRequest(SHORT, vehicle=load_vehicle_file(vehicle_file), operator="ada", settle_s=0.5)
    outcome = sweep(bench, out, request)
    assert outcome.complete and outcome.stop is StopKind.END_OF_SWEEP
    assert outcome.gap_rows == 0 and outcome.overrun_samples == 0
    assert all(s.lost_samples == 0 and s.failed_reads == 0 for s in outcome.sources)
    assert bench.exciter.commands == [CommandCode.START, CommandCode.STOP]
    stored = load_recording(out)
    assert stored.complete and stored.time_s.size == outcome.rows == 2501
    meta = stored.metadata
    assert (
        meta["operator"] == "ada" and meta["sweep_duration_s"] == 2.0 and meta["bench_model"] == "quarter-car"
    )
    assert "mass_kg" in str(meta["vehicle_text"])
    assert meta["device_model.laser-x_s"] == "ZX-LDA11-N" and meta["clock.x_t"] == "device"
    assert all(meta[f"rate_Hz.{c}"] == pytest.approx(1000.0) for c in ("x_s", "x_t", "x_r"))
    # t = 0 is the start command: the plate channel follows the sweep law from there
    truth = sweep_position_m(SHORT, stored.time_s)
    during = stored.time_s <= SHORT.duration_s
    residual = stored.channels["x_r"][during] - truth[during]
    assert np.sqrt(np.mean(residual**2)) < 5e-6  # the ZX-LD40 noise and resolution, nothing more
    assert np.ptp(stored.channels["x_s"]) > 1e-3  # the body moved
    csv = tmp_path / "run.csv"
    export_csv(out, csv)
    assert read_recording_csv(csv).time_s.size == 2501


def test_exciter_fault_gives_an_emergency_stop_and_keeps_the_recording_so_far(
    bench: SimulatedBench, tmp_path: Path
) -> None:
    out = tmp_path / "run.h5"
    outcome = sweep(
        bench, out, SweepRequest(SHORT), at(1.0, lambda: bench.exciter.inject_fault(EXCITER_FAULT))
    )
    assert not outcome.complete and outcome.reason == f"exciter fault 0x{EXCITER_FAULT:04X}"
    assert outcome.stop is StopKind.EMERGENCY
    assert bench.exciter.commands[-1] is CommandCode.EMERGENCY_STOP
    assert bench.physics.plate_status().state == "fault"  # halted where it was
    stored = load_recording(out)
    assert stored.metadata["status"] == "incomplete" and "exciter fault" in str(stored.metadata["reason"])
    assert 1.0 <= stored.time_s[-1] <= 1.2 and not stored.gap_runs  # everything up to the fault, no gap


def test_a_silent_laser_stops_the_plate_and_marks_its_channel_missing_from_then_on(
    bench: SimulatedBench, tmp_path: Path
) -> None:
    out = tmp_path / "run.h5"
    silence = at(0.8, lambda: bench.laser_lines["x_t"].inject_fault(FaultKind.GARBAGE))
    outcome = sweep(bench, out, SweepRequest(SHORT), silence)
    assert not outcome.complete and outcome.reason.startswith("sensor silence: laser 'laser-x_t' (x_t)")
    assert "MalformedFrameError" in outcome.reason
    assert outcome.stop is StopKind.CONTROLLED and CommandCode.STOP in bench.exciter.commands
    assert bench.physics.plate_status().state == "idle"  # ramped down and at rest
    stored = load_recording(out)
    missing = np.isnan(stored.channels["x_t"])
    assert missing.any() and stored.time_s[missing].min() == pytest.approx(0.8, abs=0.03)
    assert not np.isnan(stored.channels["x_s"]).any()  # the others kept recording through the stop
    assert stored.time_s[-1] > stored.time_s[missing].min() + 0.5


def test_abort_gives_a_controlled_stop_and_the_ramp_down_is_recorded(
    bench: SimulatedBench, tmp_path: Path
) -> None:
    out = tmp_path / "run.h5"
    abort = threading.Event()
    outcome = sweep(bench, out, SweepRequest(SHORT), at(0.6, abort.set), abort=abort)
    assert not outcome.complete and outcome.reason == "aborted by the operator"
    assert outcome.stop is StopKind.CONTROLLED and bench.exciter.commands[-1] is CommandCode.STOP
    stored = load_recording(out)
    assert stored.metadata["reason"] == "aborted by the operator"
    assert not stored.gap_runs
    assert np.max(np.abs(stored.channels["x_r"][-5:])) < 1e-5  # recorded until the plate came to rest
    assert stored.time_s[-1] > 0.6 + 0.4  # ... through the ramp-down after the abort
    assert bench.physics.plate_status().state == "idle"


def test_a_host_error_still_stops_the_plate_and_keeps_the_data(bench: SimulatedBench, tmp_path: Path) -> None:
    def broken_display() -> None:
        raise RuntimeError("display crashed")

    out = tmp_path / "run.h5"
    outcome = sweep(bench, out, SweepRequest(SHORT), at(0.5, broken_display))
    assert outcome.reason == "host error: RuntimeError: display crashed"
    assert CommandCode.STOP in bench.exciter.commands and bench.physics.plate_status().state == "idle"
    assert load_recording(out).metadata["status"] == "incomplete"


def test_lost_exciter_link_stops_the_sweep_and_the_plate(bench: SimulatedBench, tmp_path: Path) -> None:
    modbus = bench.modbus
    assert modbus is not None
    out = tmp_path / "run.h5"
    outcome = sweep(bench, out, SweepRequest(SHORT), at(0.7, modbus.drop_connection_on_next_request))
    assert not outcome.complete and outcome.reason.startswith("lost link to exciter")
    assert outcome.stop in (StopKind.CONTROLLED, StopKind.EMERGENCY, StopKind.WATCHDOG)
    for _ in range(100):  # whichever way: a stop command got through, or the watchdog acts
        if bench.physics.plate_status().state == "idle":
            break
        bench.advance(0.05)
    assert bench.physics.plate_status().state in ("idle", "fault")
    assert load_recording(out).metadata["status"] == "incomplete"


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ("no_plate_laser", "has no laser for channel(s) x_r"),
        ("axle_vehicle", "a axle vehicle cannot be tested on the quarter-car bench"),
        ("too_big", "amplitude_m"),
        ("existing_file", "already exists"),
    ],
)
def test_problems_found_before_the_start_raise_and_nothing_moves_or_is_written(
    bench: SimulatedBench, tmp_path: Path, change: str, message: str
) -> None:
    config = bench.config
    request = SweepRequest(SHORT)
    out = tmp_path / "run.h5"
    if change == "no_plate_laser":
        config = dataclasses.replace(
            config, lasers=tuple(laser for laser in config.lasers if laser.channel != "x_r")
        )
    elif change == "axle_vehicle":
        write_vehicle(tmp_path / "axle.toml", default_axle().known)
        request = SweepRequest(SHORT, vehicle=load_vehicle_file(tmp_path / "axle.toml"))
    elif change == "too_big":
        request = SweepRequest(dataclasses.replace(SHORT, amplitude_m=0.01))
    else:
        out.write_bytes(b"precious")
    with pytest.raises(SweepError, match=message.replace("(", r"\(").replace(")", r"\)")):
        asyncio.run(run_sweep(config, plan_sweep(config, request), out, pacing=SimulatedPacing(bench)))
    assert bench.exciter.commands == []
    assert (out.read_bytes() == b"precious") if change == "existing_file" else not out.exists()


def test_polled_amplifiers_record_their_real_rate_and_identify_refuses_the_result(
    vehicle_file: Path, tmp_path: Path
) -> None:
    with SimulatedBench(laser_sample_period_s=None) as bench:  # one value per read, read every 20 ms
        out = tmp_path / "run.h5"
        outcome = sweep(bench, out, SweepRequest(SweepSettings(duration_s=1.0), settle_s=0.2))
    assert outcome.complete
    assert all(s.achieved_rate_Hz == pytest.approx(50.0, rel=0.01) for s in outcome.sources)
    stored = load_recording(out)
    assert stored.metadata["rate_Hz.x_t"] == pytest.approx(50.0, rel=0.01)
    assert stored.metadata["clock.x_t"] == "host_monotonic"
    csv = tmp_path / "run.csv"
    recording = export_csv(out, csv)
    with pytest.raises(InsufficientBandwidthError, match=r"sampled at 50\.0 Hz.*at least 100 Hz"):
        check_bandwidth(read_recording_csv(csv))
    assert recording.time_s.size == outcome.rows


def test_the_operators_emergency_stop_halts_the_plate_at_once(bench: SimulatedBench, tmp_path: Path) -> None:
    out = tmp_path / "run.h5"
    emergency = threading.Event()
    outcome = asyncio.run(
        run_sweep(
            bench.config,
            plan_sweep(bench.config, SweepRequest(SHORT)),
            out,
            pacing=SimulatedPacing(bench),
            progress=at(0.5, emergency.set),
            emergency=emergency,
        )
    )
    assert outcome.reason == "emergency stop by the operator" and outcome.stop is StopKind.EMERGENCY
    assert bench.exciter.commands[-1] is CommandCode.EMERGENCY_STOP
    assert bench.physics.plate_status().state == "idle"
    assert load_recording(out).metadata["status"] == "incomplete"
