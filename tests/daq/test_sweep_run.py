"""Sweep orchestration end to end: a complete sweep on the simulated bench (real transports, manual clock),
then every way a sweep can end early, or be refused before the start, on in-process mock devices
(tests/daq/mock_bench.py): each early end leaves the plate stopped and the partial recording kept and
marked incomplete with its reason. The drivers' faults on their real transports, and the time the plate
takes to stop: test_plate_always_stops.py and test_lost_laser_reply.py."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import load_vehicle_file, write_vehicle
from daq.storage.hdf5_recording import export_csv, load_recording
from daq.sweep.model import StopKind, SweepOutcome, SweepProgress, SweepRequest
from daq.sweep.pacing import SimulatedPacing
from daq.sweep.plan import plan_sweep
from daq.sweep.run import STOP_RECORD_LIMIT_S, SweepError, run_sweep
from drivers.compowayf.errors import MalformedFrameError, ResponseTimeoutError
from drivers.exciter.codes import CommandCode, ExciterState
from drivers.exciter.errors import ExciterConnectionLostError, ExciterDeviceExceptionError
from estimator.bandwidth import InsufficientBandwidthError, check_bandwidth
from estimator.sweep import SweepSettings
from service.simulated_bench import SimulatedBench
from simulators.excitation import sweep_position_m
from simulators.vehicle_sim import default_axle, default_quarter_car
from tests.daq.mock_bench import MockBench, at, mock_bench

SHORT = SweepSettings(duration_s=2.0)
EXCITER_FAULT = 0x0021


@pytest.fixture
def vehicle_file(tmp_path: Path) -> Path:
    path = tmp_path / "vehicle.toml"
    write_vehicle(path, default_quarter_car().known)
    return path


@pytest.fixture
def bench() -> MockBench:
    return mock_bench()


def sweep(
    bench: SimulatedBench,
    out: Path,
    request: SweepRequest,
    when: Callable[[SweepProgress], None] | None = None,
) -> SweepOutcome:
    return asyncio.run(
        run_sweep(
            bench.config, plan_sweep(bench.config, request), out, pacing=SimulatedPacing(bench), progress=when
        )
    )


# ---- on the simulated bench, over real transports ----------------------------------------------------------


def test_a_complete_sweep_records_every_channel_without_a_gap(vehicle_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "run.h5"
    request = SweepRequest(SHORT, vehicle=load_vehicle_file(vehicle_file), operator="ada", settle_s=0.5)
    with SimulatedBench(seed=5) as bench:
        outcome = sweep(bench, out, request)
        commands = bench.exciter.commands
    assert outcome.complete and outcome.stop is StopKind.END_OF_SWEEP
    assert outcome.gap_rows == 0 and outcome.overrun_samples == 0
    assert all(s.lost_samples == 0 and s.failed_reads == 0 for s in outcome.sources)
    assert commands == [CommandCode.START, CommandCode.STOP]
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


# ---- on mock devices ---------------------------------------------------------------------------------------


def test_a_complete_sweep_supervises_the_drive_every_cycle_and_stops_it_at_the_end(
    bench: MockBench, tmp_path: Path
) -> None:
    out = tmp_path / "run.h5"
    outcome = bench.sweep(out, SweepRequest(SHORT, settle_s=0.5))
    exciter = bench.devices.exciter
    assert outcome.complete and outcome.stop is StopKind.END_OF_SWEEP and outcome.rows == 2501
    assert outcome.gap_rows == 0 and all(s.lost_samples == 0 for s in outcome.sources)
    assert exciter.sweeps == [SHORT] and exciter.commands == [CommandCode.START, CommandCode.STOP]
    assert len(exciter.keepalive_counters) == 25  # every 0.1 s of the 2.5 s recorded, from supervision
    assert exciter.closed and all(line.closed for line in bench.devices.lines.values())
    assert load_recording(out).complete


def test_exciter_fault_gives_an_emergency_stop_and_keeps_the_recording_so_far(
    bench: MockBench, tmp_path: Path
) -> None:
    out = tmp_path / "run.h5"
    exciter = bench.devices.exciter
    exciter.state_after[CommandCode.EMERGENCY_STOP] = ExciterState.FAULT  # halted, the fault latched
    outcome = bench.sweep(out, SweepRequest(SHORT), at(1.0, lambda: exciter.inject_fault(EXCITER_FAULT)))
    assert not outcome.complete and outcome.reason == f"exciter fault 0x{EXCITER_FAULT:04X}"
    assert outcome.stop is StopKind.EMERGENCY
    assert exciter.commands == [CommandCode.START, CommandCode.EMERGENCY_STOP]
    stored = load_recording(out)
    assert stored.metadata["status"] == "incomplete" and "exciter fault" in str(stored.metadata["reason"])
    assert 1.0 <= stored.time_s[-1] <= 1.2 and not stored.gap_runs  # everything up to the fault, no gap


def test_a_silent_laser_stops_the_plate_and_marks_its_channel_missing_from_then_on(
    bench: MockBench, tmp_path: Path
) -> None:
    out = tmp_path / "run.h5"
    garbage = MalformedFrameError("no ETX in 40 bytes")
    silence = at(0.8, lambda: bench.devices.amplifiers["x_t"].fail(garbage, count=None))
    outcome = bench.sweep(out, SweepRequest(SHORT), silence)
    assert not outcome.complete and outcome.reason.startswith("sensor silence: laser 'laser-x_t' (x_t)")
    assert "(last error: MalformedFrameError: no ETX in 40 bytes)" in outcome.reason
    assert outcome.stop is StopKind.CONTROLLED and bench.devices.exciter.commands[-1] is CommandCode.STOP
    stored = load_recording(out)
    missing = np.isnan(stored.channels["x_t"])
    assert missing.any() and stored.time_s[missing].min() == pytest.approx(0.8, abs=0.03)
    assert not np.isnan(stored.channels["x_s"]).any()  # the others kept recording through the stop
    assert stored.time_s[-1] > stored.time_s[missing].min() + 0.5


def test_abort_gives_a_controlled_stop_and_the_ramp_down_is_recorded(
    bench: MockBench, tmp_path: Path
) -> None:
    out = tmp_path / "run.h5"
    abort = threading.Event()
    exciter = bench.devices.exciter
    exciter.state_after[CommandCode.STOP] = ExciterState.STOPPING
    rests_at_s: list[float] = []

    def ramp_down(now_s: float) -> None:  # the drive reports the plate at rest 0.5 s after the stop
        if exciter.commands[-1:] == [CommandCode.STOP] and not rests_at_s:
            rests_at_s.append(now_s + 0.5)
        if rests_at_s and now_s >= rests_at_s[0]:
            exciter.state = ExciterState.IDLE

    bench.clock.on_advance.append(ramp_down)
    outcome = bench.sweep(out, SweepRequest(SHORT), at(0.6, abort.set), abort=abort)
    assert not outcome.complete and outcome.reason == "aborted by the operator"
    assert outcome.stop is StopKind.CONTROLLED and exciter.commands[-1] is CommandCode.STOP
    stored = load_recording(out)
    assert stored.metadata["reason"] == "aborted by the operator" and not stored.gap_runs
    assert 0.6 + 0.5 <= stored.time_s[-1] <= 0.6 + 0.5 + 0.15  # recorded through the ramp-down, no longer


def test_a_drive_that_never_reports_rest_is_recorded_for_the_stop_limit_only(
    bench: MockBench, tmp_path: Path
) -> None:
    out = tmp_path / "run.h5"
    abort = threading.Event()
    bench.devices.exciter.state_after[CommandCode.STOP] = ExciterState.STOPPING
    outcome = bench.sweep(out, SweepRequest(SHORT), at(0.6, abort.set), abort=abort)
    assert outcome.stop is StopKind.CONTROLLED
    assert load_recording(out).time_s[-1] == pytest.approx(0.6 + STOP_RECORD_LIMIT_S, abs=0.1)


def test_a_host_error_still_stops_the_plate_and_keeps_the_data(bench: MockBench, tmp_path: Path) -> None:
    def broken_display() -> None:
        raise RuntimeError("display crashed")

    out = tmp_path / "run.h5"
    outcome = bench.sweep(out, SweepRequest(SHORT), at(0.5, broken_display))
    assert outcome.reason == "host error: RuntimeError: display crashed"
    assert bench.devices.exciter.commands[-1] is CommandCode.STOP
    assert load_recording(out).metadata["status"] == "incomplete"


@pytest.mark.parametrize(
    ("error", "reason"),
    [
        (ExciterConnectionLostError("connection reset"), "lost link to exciter: ExciterConnectionLostError"),
        (ExciterDeviceExceptionError(4, "read input registers"), "exciter refused the status read: "),
    ],
)
def test_a_status_the_drive_cannot_give_stops_the_sweep_with_a_controlled_stop(
    bench: MockBench, tmp_path: Path, error: Exception, reason: str
) -> None:
    out = tmp_path / "run.h5"
    exciter = bench.devices.exciter
    outcome = bench.sweep(
        out, SweepRequest(SHORT), at(0.7, lambda: exciter.fail("status", error, count=None))
    )
    assert not outcome.complete and outcome.reason.startswith(reason)
    assert outcome.stop is StopKind.CONTROLLED and exciter.commands[-1] is CommandCode.STOP
    assert load_recording(out).metadata["status"] == "incomplete"


@pytest.mark.parametrize(
    ("commands_lost", "stop", "sent"),
    [(1, StopKind.EMERGENCY, [CommandCode.EMERGENCY_STOP]), (None, StopKind.WATCHDOG, [])],
    ids=["stop lost", "every command lost"],
)
def test_a_stop_that_cannot_be_sent_falls_back_to_the_emergency_stop_then_to_the_watchdog(
    bench: MockBench, tmp_path: Path, commands_lost: int | None, stop: StopKind, sent: list[CommandCode]
) -> None:
    exciter = bench.devices.exciter
    lost = ExciterConnectionLostError("connection reset")

    def lose_the_link() -> None:
        exciter.fail("status", lost, count=None)
        exciter.fail("command", lost, count=commands_lost)

    outcome = bench.sweep(tmp_path / "run.h5", SweepRequest(SHORT), at(0.7, lose_the_link))
    assert outcome.stop is stop and exciter.commands == [CommandCode.START, *sent]
    assert outcome.reason.startswith("lost link to exciter: ExciterConnectionLostError: connection reset")
    watchdog = "; no stop command reached the drive (its watchdog stops the plate)"
    assert outcome.reason.endswith(watchdog) == (stop is StopKind.WATCHDOG)


def test_the_operators_emergency_stop_halts_the_plate_at_once(bench: MockBench, tmp_path: Path) -> None:
    out = tmp_path / "run.h5"
    emergency = threading.Event()
    outcome = bench.sweep(out, SweepRequest(SHORT), at(0.5, emergency.set), emergency=emergency)
    assert outcome.reason == "emergency stop by the operator" and outcome.stop is StopKind.EMERGENCY
    assert bench.devices.exciter.commands == [CommandCode.START, CommandCode.EMERGENCY_STOP]
    assert load_recording(out).metadata["status"] == "incomplete"


def test_polled_amplifiers_record_their_real_rate_and_identify_refuses_the_result(tmp_path: Path) -> None:
    bench = mock_bench(streaming=False)  # one value per read, read every 20 ms
    out = tmp_path / "run.h5"
    outcome = bench.sweep(out, SweepRequest(SweepSettings(duration_s=1.0), settle_s=0.2))
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


# ---- refused before the start: nothing moves, nothing is written ---------------------------------------


def _script(bench: MockBench, problem: str) -> None:
    devices = bench.devices
    if problem == "laser_silent":
        devices.amplifiers["x_t"].fail(ResponseTimeoutError("node 02: no reply within 0.5 s"))
    elif problem == "exciter_fault":
        devices.exciter.inject_fault(EXCITER_FAULT)
    elif problem == "plate_moving":
        devices.exciter.state = ExciterState.RUNNING
    elif problem == "out_of_range":
        devices.amplifiers["x_s"].reading_m = float("nan")
    elif problem == "moving_at_rest":
        devices.amplifiers["x_r"].reading_m = lambda t: 0.002 * np.sin(2 * np.pi * 3.0 * t)
    elif problem == "no_samples":
        silent = ResponseTimeoutError("node 03: no reply within 0.5 s")  # from the first poll on
        bench.clock.on_advance.append(lambda _: devices.amplifiers["x_r"].fail(silent, count=None))
    elif problem == "exciter_unreachable":
        devices.exciter.fail("open", ExciterConnectionLostError("cannot connect to 127.0.0.1:5020"))


@pytest.mark.parametrize(
    ("problem", "message"),
    [
        ("no_plate_laser", "has no laser for channel(s) x_r"),
        ("axle_vehicle", "a axle vehicle cannot be tested on the quarter-car bench"),
        ("too_big", "amplitude_m"),
        ("existing_file", "already exists"),
        (
            "laser_silent",
            "laser 'laser-x_t' (socket://127.0.0.1:9002?node=2): node 02: no reply within 0.5 s",
        ),
        (
            "exciter_unreachable",
            "exciter 'plate-exciter' (modbus-tcp://127.0.0.1:5020?unit=1): cannot connect",
        ),
        ("exciter_fault", "exciter in fault 0x0021: reset the drive first"),
        ("plate_moving", "the plate is not at rest (drive state running); stop it first"),
        ("out_of_range", "laser 'laser-x_s' (x_s): out of measuring range at rest"),
        ("moving_at_rest", "laser 'laser-x_r' (x_r): moves by 1.43 mm (std) at rest; is all still?"),
        ("no_samples", "laser 'laser-x_r' (x_r): 0 samples in 1 s at rest (ResponseTimeoutError: node 03"),
    ],
)
def test_problems_found_before_the_start_raise_and_nothing_moves_or_is_written(
    tmp_path: Path, problem: str, message: str
) -> None:
    bench = mock_bench(channels=("x_s", "x_t")) if problem == "no_plate_laser" else mock_bench()
    request = SweepRequest(SHORT)
    out = tmp_path / "run.h5"
    if problem == "axle_vehicle":
        write_vehicle(tmp_path / "axle.toml", default_axle().known)
        request = SweepRequest(SHORT, vehicle=load_vehicle_file(tmp_path / "axle.toml"))
    elif problem == "too_big":
        request = SweepRequest(SweepSettings(duration_s=2.0, amplitude_m=0.01))
    elif problem == "existing_file":
        out.write_bytes(b"precious")
    _script(bench, problem)
    with pytest.raises(SweepError) as info:
        bench.sweep(out, request)
    assert message in str(info.value) and "\n" not in str(info.value)
    assert bench.devices.exciter.commands == [] and bench.devices.exciter.sweeps == []
    assert (out.read_bytes() == b"precious") if problem == "existing_file" else not out.exists()
