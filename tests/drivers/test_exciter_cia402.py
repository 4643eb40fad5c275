"""CiA 402 back end against the simulated CiA 402 drive (canopen LocalNode) on python-can's virtual bus:
state machine, sweep start/stop as controlwords and objects, quick stop, fault reset, the drive's
heartbeat, NMT. What every back end promises (start, sweep, stops, the watchdog, drive faults, silence):
test_exciter_contract.py. A drive that takes its time per transition: test_exciter_cia402_transitions.py.
The rig (tests/drivers/cia402_rig.py) runs supervision and the back end's waits on the simulated clock."""

from __future__ import annotations

import asyncio

import can
import pytest

from daq.bench_config import BenchConfigError, ExciterConfig
from drivers.exciter import cia402_objects as objects
from drivers.exciter.cia402 import Cia402Exciter
from drivers.exciter.cia402_objects import DriveState
from drivers.exciter.codes import CommandCode, ExciterState
from drivers.exciter.errors import (
    ExciterConfigError,
    ExciterConnectionLostError,
    ExciterDeviceExceptionError,
    ExciterDeviceFaultError,
    ExciterEncodingError,
    ExciterHeartbeatLostError,
    ExciterTimeoutError,
)
from drivers.exciter.urls import Cia402Target, open_exciter, parse_exciter_url
from estimator.sweep import SweepLaw, SweepSettings
from simulators.devices.cia402_exciter import SimulatedCia402Exciter
from simulators.plate import EmptyPlate
from tests.drivers.cia402_rig import HALT, NODE, SWEEP, fresh_channel, rig, stored, wait_until

# ---- statusword -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("statusword", "state"),
    [
        (0x0000, DriveState.NOT_READY_TO_SWITCH_ON),
        (0x0250, DriveState.SWITCH_ON_DISABLED),
        (0x0631, DriveState.READY_TO_SWITCH_ON),
        (0x0633, DriveState.SWITCHED_ON),
        (0x1237, DriveState.OPERATION_ENABLED),
        (0x0617, DriveState.QUICK_STOP_ACTIVE),
        (0x221F, DriveState.FAULT_REACTION_ACTIVE),
        (0x0608, DriveState.FAULT),
    ],
)
def test_statusword_states(statusword: int, state: DriveState) -> None:
    assert DriveState.of_statusword(statusword) is state
    assert DriveState.of_statusword(state.state_bits) is state


# ---- bring-up, sweep, stops ------------------------------------------------------------------------------


def test_first_operation_brings_the_drive_up() -> None:
    async def scenario() -> None:
        async with rig() as (sim, exciter):
            assert sim.nmt_state == "PRE-OPERATIONAL"
            assert sim.heartbeats_sent == 0  # 0x1017 is 0 until the host sets it
            status = await exciter.status()
            assert (status.state, status.fault_code) == (ExciterState.IDLE, 0)
            assert sim.nmt_state == "OPERATIONAL"
            assert stored(sim, objects.PRODUCER_HEARTBEAT_TIME) == 100
            assert stored(sim, objects.ABORT_CONNECTION_OPTION) == objects.ABORT_CONNECTION_FAULT
            assert stored(sim, objects.MODES_OF_OPERATION) == objects.SINE_SWEEP_MODE
            assert sim.state is DriveState.SWITCH_ON_DISABLED  # nothing is powered by a status read
            for _ in range(3):
                sim.advance(0.1)
            await exciter.status()
            assert exciter.drive_nmt_state == 5  # operational, from the drive's heartbeat
            assert sim.heartbeats_sent == 4  # at 0.0 (when 0x1017 was set), 0.1, 0.2, 0.3
            sim.advance(0.35)
            assert sim.heartbeats_sent == 5  # a late tick sends one, not a backlog

    asyncio.run(scenario())


def test_sweep_start_stop_and_emergency_stop() -> None:
    async def scenario() -> None:
        async with rig() as (sim, exciter):
            await exciter.configure_sweep(
                SweepSettings(
                    start_Hz=1.0, stop_Hz=16.0, amplitude_m=0.003, duration_s=8.0, law=SweepLaw.LOGARITHMIC
                )
            )
            assert [stored(sim, objects.SWEEP, sub) for sub in range(1, 6)] == [1000, 16000, 3000, 8000, 1]
            await exciter.start()
            assert sim.controlwords == [0x06, 0x07, 0x0F, 0x1F]  # bit 4 was low: 0x1F is its rising edge
            assert sim.state is DriveState.OPERATION_ENABLED
            assert stored(sim, objects.CONSUMER_HEARTBEAT_TIME, 1) == (127 << 16) | 500
            bench = sim.bench
            for _ in range(10):
                sim.advance(0.2)
                status = await exciter.status()
            assert status.state is ExciterState.RUNNING
            assert status.frequency_Hz == pytest.approx(2.0, abs=0.001)  # 16 ** (2 / 8)
            assert status.position_m == pytest.approx(bench.position_m("x_r"), abs=1e-6)
            assert exciter.velocity_m_per_s != 0.0
            assert sim.host_heartbeats_received >= 8  # the start's, then one per supervision step

            await exciter.stop()  # halt, the plate's 0.5 s ramp to rest, then disable operation
            assert sim.controlwords[-2:] == [HALT, objects.CW_SWITCH_ON]
            assert sim.state is DriveState.SWITCHED_ON
            assert stored(sim, objects.CONSUMER_HEARTBEAT_TIME, 1) == 0  # watchdog off, the drive disabled
            rest = await exciter.status()
            assert (rest.state, rest.position_m, exciter.velocity_m_per_s) == (ExciterState.IDLE, 0.0, 0.0)

            await exciter.start()  # from SWITCHED ON: enable operation, then the rising edge of bit 4
            assert sim.controlwords[-2:] == [0x0F, 0x1F]
            sim.advance(0.3)
            assert (await exciter.status()).state is ExciterState.RUNNING
            await exciter.emergency_stop()
            assert sim.controlwords[-2:] == [objects.CW_QUICK_STOP, objects.CW_DISABLE_VOLTAGE]
            assert sim.state is DriveState.SWITCH_ON_DISABLED
            halted = await exciter.status()
            assert halted.state is ExciterState.IDLE and halted.position_m != 0.0
            sim.advance(0.3)
            assert (await exciter.status()).position_m == halted.position_m  # held where it stopped

            await exciter.start()  # from SWITCH ON DISABLED: the whole power-up again
            assert sim.controlwords[-4:] == [0x06, 0x07, 0x0F, 0x1F]

    asyncio.run(scenario())


def test_sweep_out_of_the_drive_range_is_refused_before_any_write() -> None:
    async def scenario() -> None:
        async with rig() as (sim, exciter):
            await exciter.status()
            writes = len(sim.node.data_store.get(objects.SWEEP, {}))
            with pytest.raises(ExciterEncodingError, match=r"duration: 4000000 is outside 0\.\.3600000"):
                await exciter._write_sweep(SweepSettings(duration_s=4000.0))
            assert len(sim.node.data_store.get(objects.SWEEP, {})) == writes == 0

    asyncio.run(scenario())


def test_start_without_a_sweep_on_the_drive_is_an_sdo_abort() -> None:
    async def scenario() -> None:
        async with rig() as (sim, exciter):
            with pytest.raises(ExciterDeviceExceptionError) as info:
                await exciter._send_command(CommandCode.START)
            assert info.value.exception_code == 0x08000022  # data cannot be stored: device state
            assert sim.controlwords[-1] == objects.CW_ENABLE_OPERATION | objects.CW_START_SWEEP  # the refused
            assert (await exciter.status()).state is ExciterState.IDLE

    asyncio.run(scenario())


def test_a_fault_is_refused_by_the_drive_itself_and_reset_by_the_controlword() -> None:
    """CiA 402's side of a drive fault (the refused start and the reset: test_exciter_contract.py)."""

    async def scenario() -> None:
        async with rig() as (sim, exciter):
            await exciter.configure_sweep(SWEEP)
            await exciter.start()
            sim.inject_drive_fault(0x7310)
            with pytest.raises(ExciterDeviceFaultError):  # past the interface's pre-check: the same
                await exciter._send_command(CommandCode.START)
            await exciter.reset_fault()
            assert sim.controlwords[-2:] == [0x00, objects.CW_FAULT_RESET]
            assert sim.state is DriveState.SWITCH_ON_DISABLED and sim.error_code == 0

    asyncio.run(scenario())


# ---- the drive's heartbeat, supervised by the host ---------------------------------------------------------


def test_drive_heartbeat_loss_is_a_typed_error_then_recovers() -> None:
    async def scenario() -> None:
        async with rig() as (sim, exciter):
            await exciter.status()
            sim.advance(0.3)
            await exciter.status()
            sim.go_silent()
            sim.advance(0.6)
            with pytest.raises(ExciterHeartbeatLostError) as info:
                await exciter.status()
            assert info.value.silent_s == pytest.approx(0.6, abs=0.11)
            sim.resume()
            sim.advance(0.1)
            assert (await exciter.status()).state is ExciterState.IDLE

    asyncio.run(scenario())


def test_stale_heartbeat_is_reported_even_when_the_drive_answers() -> None:
    async def scenario() -> None:
        async with rig() as (sim, exciter):
            await exciter.status()
            sim.clock.advance(0.7)  # time passes, no tick: no heartbeat goes out
            with pytest.raises(ExciterHeartbeatLostError):
                await exciter.status()
            sim.tick()
            await exciter.status()

    asyncio.run(scenario())


def test_emergency_stop_goes_out_whole_before_a_heartbeat_fault_is_reported() -> None:
    async def scenario() -> None:
        async with rig({"quick_stop_ramp_s": 0.0}, heartbeat_timeout_s=0.3) as (sim, exciter):
            await exciter.configure_sweep(SWEEP)
            await exciter.start()
            sim.advance(0.2)
            await exciter.status()  # ends with a keep-alive, which is not answered:
            await exciter.status()  # an answered request after it means the drive has taken it
            sim.clock.advance(0.4)  # the drive's heartbeat goes stale (no tick), its watchdog (0.5 s) holds
            with pytest.raises(ExciterHeartbeatLostError):
                await exciter.emergency_stop()
            assert sim.controlwords[-2:] == [objects.CW_QUICK_STOP, objects.CW_DISABLE_VOLTAGE]
            assert stored(sim, objects.CONSUMER_HEARTBEAT_TIME, 1) == 0
            assert sim.state is DriveState.SWITCH_ON_DISABLED

    asyncio.run(scenario())


def test_sdo_transfers_leave_the_event_loop_running() -> None:
    async def scenario() -> None:
        async with rig() as (sim, exciter):
            await exciter.status()
            sim.go_silent()  # the next SDO request waits its whole reply timeout in canopen
            status = asyncio.get_running_loop().create_task(exciter.status())
            ticks = 0
            for _ in range(20):
                await asyncio.sleep(0)
                ticks += 1
            assert ticks == 20 and not status.done()
            with pytest.raises(ExciterTimeoutError):
                await status

    asyncio.run(scenario())


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_reader_error_fails_the_call_then_a_new_bus_is_opened() -> None:
    def reader_fails(timeout: float | None) -> tuple[can.Message | None, bool]:
        raise can.CanOperationError("interface went down")

    async def scenario() -> None:
        async with rig() as (sim, exciter):
            assert (await exciter.status()).state is ExciterState.IDLE
            network = exciter._network
            assert network is not None and network.bus is not None and network.notifier is not None
            sim.go_silent()  # the status request below stays unanswered while the reader fails
            heard = sim.network.frames_ignored
            status = asyncio.get_running_loop().create_task(exciter.status())
            await asyncio.to_thread(wait_until, lambda: sim.network.frames_ignored > heard, "the request")
            network.bus._recv_internal = reader_fails  # type: ignore[method-assign]
            with pytest.raises(ExciterConnectionLostError, match="interface went down"):
                await status
            sim.resume()
            assert (await exciter.status()).state is ExciterState.IDLE  # on a new bus, brought up again
            assert exciter._network is not network and network.bus is None  # the old one shut down
            assert sim.nmt_state == "OPERATIONAL"

    asyncio.run(scenario())


# ---- NMT ---------------------------------------------------------------------------------------------------


def test_nmt_stop_by_another_master_faults_a_running_drive_and_the_host_restarts_it() -> None:
    async def scenario() -> None:
        async with rig() as (sim, exciter):
            await exciter.configure_sweep(SWEEP)
            await exciter.start()
            sim.advance(0.2)
            await exciter.status()
            with can.Bus(interface="virtual", channel=sim.channel) as other_master:
                other_master.send(can.Message(arbitration_id=0, data=[0x02, NODE], is_extended_id=False))
                wait_until(
                    lambda: sim.error_code == objects.ERROR_NMT_STOPPED, "the drive's NMT stop reaction"
                )
            assert sim.nmt_state == "STOPPED"
            assert sim.state is DriveState.FAULT_REACTION_ACTIVE  # 0x6007 = 1: abort connection -> fault
            sim.advance(0.1)  # its heartbeat now says STOPPED; SDO requests go unanswered
            with pytest.raises(ExciterConnectionLostError, match="NMT STOPPED"):
                await exciter.status()
            status = await exciter.status()  # brought up again: NMT start first
            assert sim.nmt_state == "OPERATIONAL"
            assert status.fault_code == objects.ERROR_NMT_STOPPED
            assert status.state in (ExciterState.STOPPING, ExciterState.FAULT)

    asyncio.run(scenario())


def test_drive_reset_is_reported_once_then_the_drive_is_set_up_again() -> None:
    async def scenario() -> None:
        async with rig() as (sim, exciter):
            await exciter.status()
            sim.advance(0.1)
            with can.Bus(interface="virtual", channel=sim.channel) as other_master:
                other_master.send(can.Message(arbitration_id=0, data=[0x81, NODE], is_extended_id=False))
                wait_until(
                    lambda: sim.nmt_state == "PRE-OPERATIONAL" and not sim.node.data_store, "the reset"
                )
            with pytest.raises(ExciterConnectionLostError, match="restarted"):
                await exciter.status()
            assert (await exciter.status()).state is ExciterState.IDLE
            assert stored(sim, objects.PRODUCER_HEARTBEAT_TIME) == 100  # set again
            assert sim.nmt_state == "OPERATIONAL"

    asyncio.run(scenario())


# ---- configuration ---------------------------------------------------------------------------------------


def test_canopen_urls_and_node_ids() -> None:
    assert parse_exciter_url("canopen://virtual/vcan0?node=5") == Cia402Target("virtual", "vcan0", 5)
    target = parse_exciter_url(
        "canopen://socketcan/can0?node=12&host_node=100&bitrate=500000&timeout=0.3&heartbeat_timeout=0.4"
        "&watchdog_timeout=0.8"
    )
    assert target == Cia402Target("socketcan", "can0", 12, 100, 500000, 0.3, 0.4, 0.8)
    assert (target.transition_timeout_s, target.ramp_timeout_s) == (0.5, 2.0)  # the defaults
    slow = parse_exciter_url("canopen://socketcan/can0?node=12&transition_timeout=1.5&ramp_timeout=4")
    assert isinstance(slow, Cia402Target)
    assert (slow.transition_timeout_s, slow.ramp_timeout_s) == (1.5, 4.0)
    with pytest.raises(ExciterConfigError, match="transition_timeout and ramp_timeout must be > 0"):
        parse_exciter_url("canopen://socketcan/can0?node=12&transition_timeout=0")
    with pytest.raises(ExciterConfigError, match="canopen:// needs node="):
        parse_exciter_url("canopen://virtual/vcan0")
    with pytest.raises(ExciterConfigError, match=r"node and host_node must be two different ids 1\.\.127"):
        parse_exciter_url("canopen://virtual/vcan0?node=127")
    with pytest.raises(ExciterConfigError, match=r"must be 1\.\.127, got 200"):
        Cia402Exciter("virtual", "x", node_id=200)
    with pytest.raises(ExciterConfigError, match="cannot both be CANopen node 127"):
        Cia402Exciter("virtual", "x", node_id=127)
    with pytest.raises(ExciterConfigError, match="transition_timeout_s must be > 0 s, got 0"):
        Cia402Exciter("virtual", "x", node_id=5, transition_timeout_s=0)


def test_bench_config_takes_a_canopen_drive() -> None:
    assert ExciterConfig("plate", "canopen://socketcan/can0?node=5").kind == "canopen"
    assert ExciterConfig("plate", "canopen://socketcan/can0?node=5&transition_timeout=1").kind == "canopen"
    with pytest.raises(BenchConfigError, match="transition_timeout and ramp_timeout must be > 0"):
        ExciterConfig("plate", "canopen://socketcan/can0?node=5&ramp_timeout=-1")
    assert ExciterConfig("plate", "can://socketcan/can0?base_id=0x6A0").kind == "can"
    with pytest.raises(BenchConfigError, match=r"bad exciter URL: .*canopen:// needs node="):
        ExciterConfig("plate", "canopen://socketcan/can0")


def test_opened_from_a_url() -> None:
    async def scenario() -> None:
        bench = EmptyPlate()
        channel = fresh_channel()
        with SimulatedCia402Exciter(bench, channel=channel, node_id=9) as sim:
            exciter = await open_exciter(
                f"canopen://virtual/{channel}?node=9&timeout=0.2&transition_timeout=0.8&ramp_timeout=3",
                clock=bench.clock.now_s,
            )
            try:
                assert isinstance(exciter, Cia402Exciter)
                assert (exciter.transition_timeout_s, exciter.ramp_timeout_s) == (0.8, 3.0)
                assert (await exciter.status()).state is ExciterState.IDLE
                assert sim.nmt_state == "OPERATIONAL"
            finally:
                await exciter.close()

    asyncio.run(scenario())


def test_a_node_that_is_not_a_drive_is_refused() -> None:
    async def scenario() -> None:
        async with rig() as (sim, exciter):
            sim.node.data_store.setdefault(objects.DEVICE_TYPE, {})[0] = (0x0191).to_bytes(4, "little")  # I/O
            with pytest.raises(ExciterConfigError, match=r"not a CiA 402 drive \(device type 0x00000191\)"):
                await exciter.status()

    asyncio.run(scenario())
