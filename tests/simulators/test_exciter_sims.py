"""Simulated plate drives: the shared drive logic (commands, watchdog, faults) and each protocol seen with
a plain client (raw pymodbus requests, raw CAN frames), independent of the shockbench drivers."""

from __future__ import annotations

import asyncio
import uuid

import can
import pytest
from pymodbus.client import AsyncModbusTcpClient

from drivers.exciter import can_frames as frames
from drivers.exciter.can_frames import CanResult, ExciterFrames
from drivers.exciter.codes import FAULT_WATCHDOG, CommandCode, ExciterState, LawCode, StateCode
from drivers.exciter.register_map import RegisterMap
from simulators.devices.can_exciter import SimulatedCanExciter
from simulators.devices.exciter import ExciterRefusalError, RefusalReason, SimulatedExciter
from simulators.devices.modbus_exciter import SimulatedModbusExciter
from simulators.plate import EmptyPlate

SWEEP_PARAMS = {"start_Hz": 0.0, "stop_Hz": 20.0, "amplitude_m": 0.004, "duration_s": 20.0, "law": 0}


# ---- drive logic ------------------------------------------------------------------------------------------


def started_drive(watchdog_timeout_s: float = 0.5) -> SimulatedExciter:
    drive = SimulatedExciter(EmptyPlate(), watchdog_timeout_s)
    drive.set_sweep_params(**SWEEP_PARAMS)
    drive.command(CommandCode.START)
    return drive


def test_drive_watchdog_is_fed_only_by_changing_keepalives() -> None:
    drive = started_drive()
    for counter in range(1, 8):  # 7 x 0.3 s with fresh counters: alive
        drive.clock.advance(0.3)
        drive.keepalive(counter)
    assert drive.status().state is ExciterState.RUNNING
    for _ in range(2):  # the same counter again is no sign of life
        drive.clock.advance(0.3)
        drive.keepalive(7)
    status = drive.status()
    assert (status.state, status.fault_code) == (ExciterState.STOPPING, FAULT_WATCHDOG)
    assert drive.watchdog_tripped


def test_drive_watchdog_trip_is_a_controlled_stop_latched_until_reset() -> None:
    drive = started_drive()
    drive.clock.advance(1.3)
    drive.tick()
    ramping = drive.status()
    assert ramping.state is ExciterState.STOPPING and ramping.frequency_Hz > 0  # not an emergency halt
    drive.clock.advance(0.2)
    assert drive.status().state is ExciterState.STOPPING  # still ramping 0.2 s into the 0.5 s ramp
    drive.clock.advance(0.4)
    rested = drive.status()
    assert (rested.state, rested.fault_code, rested.position_m) == (ExciterState.FAULT, FAULT_WATCHDOG, 0.0)
    with pytest.raises(ExciterRefusalError) as info:
        drive.command(CommandCode.START)
    assert info.value.reason is RefusalReason.FAULT
    drive.command(CommandCode.RESET_FAULT)
    drive.command(CommandCode.START)
    assert drive.status().state is ExciterState.RUNNING


def test_drive_watchdog_sleeps_when_no_sweep_runs() -> None:
    drive = started_drive()
    drive.command(CommandCode.STOP)
    drive.clock.advance(5.0)
    drive.tick()
    assert drive.status().fault_code == 0
    drive = started_drive()
    drive.clock.advance(21.0)  # the sweep has ended by itself
    drive.status()
    drive.tick()
    assert not drive.watchdog_tripped


@pytest.mark.parametrize(
    ("params", "reason"),
    [
        ({"start_Hz": 1.0}, RefusalReason.NOT_CONFIGURED),
        ({**SWEEP_PARAMS, "law": LawCode.LOGARITHMIC}, RefusalReason.INVALID_VALUE),  # log from 0 Hz
        ({**SWEEP_PARAMS, "law": 7}, RefusalReason.INVALID_VALUE),
    ],
)
def test_drive_refuses_bad_starts(params: dict[str, float], reason: RefusalReason) -> None:
    drive = SimulatedExciter(EmptyPlate())
    drive.set_sweep_params(**params)
    with pytest.raises(ExciterRefusalError) as info:
        drive.command(CommandCode.START)
    assert info.value.reason is reason
    with pytest.raises(ExciterRefusalError):
        drive.command(99)


def test_drive_fault_injection_needs_a_plate() -> None:
    class NoPlate:
        clock = EmptyPlate().clock

    with pytest.raises(TypeError, match="SimulatedPlate"):
        SimulatedExciter(NoPlate()).inject_fault(1)  # type: ignore[arg-type]


# ---- Modbus drive seen with a plain pymodbus client --------------------------------------------------------


def test_modbus_sim_registers_follow_the_map() -> None:
    async def scenario() -> None:
        regmap = RegisterMap.default()
        bench = EmptyPlate()
        async with SimulatedModbusExciter(bench, watchdog_timeout_s=0.5) as sim:
            client = AsyncModbusTcpClient(sim.host, port=sim.port, timeout=1.0, retries=0, reconnect_delay=0)
            assert await client.connect()
            try:
                words = regmap.encode_holding(
                    {
                        "sweep_start_Hz": 0.0,
                        "sweep_stop_Hz": 20.0,
                        "sweep_amplitude_m": 0.004,
                        "sweep_duration_s": 20.0,
                        "sweep_law": 0,
                    }
                )
                await client.write_registers(2, [words[a] for a in range(2, 8)], device_id=1)
                response = await client.write_register(0, CommandCode.START, device_id=1)
                assert not response.isError()
                assert (await client.read_holding_registers(0, count=1, device_id=1)).registers == [0]

                sim.advance(0.4)
                await client.write_register(1, 1, device_id=1)  # keep-alive
                sim.advance(0.4)
                block = (await client.read_input_registers(0, count=5, device_id=1)).registers
                values = regmap.decode_inputs(0, block)
                assert values["state"] == StateCode.RUNNING and values["fault_code"] == 0
                assert values["frequency_Hz"] == pytest.approx(0.8, abs=0.01)
                assert values["position_m"] == pytest.approx(bench.position_m("x_r"), abs=1e-6)

                sim.advance(0.2)  # 0.6 s since the last keep-alive
                values = regmap.decode_inputs(0, (await client.read_input_registers(0, count=5)).registers)
                assert (values["state"], values["fault_code"]) == (StateCode.STOPPING, FAULT_WATCHDOG)

                refused = await client.write_register(0, CommandCode.START, device_id=1)
                assert refused.isError() and refused.exception_code == 4  # slave device failure: in fault
                unmapped = await client.read_input_registers(20, count=1, device_id=1)
                assert unmapped.isError() and unmapped.exception_code == 2  # illegal data address
                sim.inject_exception(6)
                busy = await client.read_input_registers(0, count=5, device_id=1)
                assert busy.isError() and busy.exception_code == 6
                reset = await client.write_register(0, CommandCode.RESET_FAULT, device_id=1)
                assert not reset.isError()
                values = regmap.decode_inputs(0, (await client.read_input_registers(0, count=5)).registers)
                assert values["fault_code"] == 0
                assert sim.writes[0] == (2, [words[a] for a in range(2, 8)])
            finally:
                client.close()

    asyncio.run(scenario())


# ---- CAN drive seen with a plain python-can bus ------------------------------------------------------------


def test_can_sim_heartbeats_follow_simulated_time_and_answers_requests() -> None:
    codec = ExciterFrames()
    bench = EmptyPlate()
    channel = f"sim-test-{uuid.uuid4().hex}"
    with (
        SimulatedCanExciter(bench, channel=channel) as sim,
        can.Bus(interface="virtual", channel=channel) as bus,
    ):

        def next_frame() -> tuple[str, dict[str, float]]:
            msg = bus.recv(timeout=2.0)  # waiting on the drive, bounded
            assert msg is not None
            if msg.is_error_frame:
                return "error", {}
            decoded = codec.decode(msg)
            assert decoded is not None
            return decoded

        sim.advance(0.35)  # due at 0.0, 0.1, 0.2, 0.3
        beats = [next_frame() for _ in range(4)]
        assert [b[1]["Counter"] for b in beats] == [0, 1, 2, 3]
        assert {b[0] for b in beats} == {frames.HEARTBEAT}
        assert bus.recv(timeout=0) is None

        sim.go_silent()
        sim.advance(1.0)
        sim.resume()
        sim.advance(0.1)  # no backlog of skipped heartbeats, counting goes on
        name, signals = next_frame()
        assert (name, signals["Counter"]) == (frames.HEARTBEAT, 4)

        bus.send(
            codec.encode(
                frames.SWEEP_FREQUENCIES, {"StartFrequency": 0, "StopFrequency": 20, "Law": 0, "Sequence": 6}
            )
        )
        assert next_frame() == (
            frames.STATUS,
            pytest.approx(
                {
                    "State": 0,
                    "Result": 0,
                    "Sequence": 6,
                    "FaultCode": 0,
                    "ActualFrequency": 0,
                    "ActualPosition": 0,
                }
            ),
        )
        bus.send(codec.encode(frames.COMMAND, {"Command": CommandCode.START, "Sequence": 7}))
        name, signals = next_frame()
        assert signals["Result"] == CanResult.NOT_CONFIGURED  # amplitude and duration still missing
        assert frames.COMMAND in {n for n, _ in sim.received}

        sim.inject_error_frame()
        assert next_frame() == ("error", {})

        sim.inject_drive_fault(0x77)
        bus.send(codec.encode(frames.COMMAND, {"Command": 0, "Sequence": 8}))
        name, signals = next_frame()
        assert (signals["State"], signals["FaultCode"]) == (StateCode.FAULT, 0x77)
        bus.send(codec.encode(frames.HOST_KEEPALIVE, {"Counter": 1}))  # never answered
        sim.advance(0.1)
        assert next_frame()[0] == frames.HEARTBEAT
