"""The CiA 402 back end against a simulated drive that takes its time, as real drives do: each state
transition 10, 50 or 200 ms (electronics only, a contactor closing, a brake releasing), halt and quick stop
with a ramp. The drive starts, stops disabled, an emergency stop waits for QUICK STOP ACTIVE and the ramp
before it disables the voltage, and a transition that times out names the state the drive reached; all
read from the simulated drive's own records (controlwords received, state timeline), on simulated time."""

from __future__ import annotations

import asyncio

import pytest

from drivers.exciter import cia402_objects as objects
from drivers.exciter.cia402 import Cia402Exciter
from drivers.exciter.cia402_objects import DriveState, plate_at_rest
from drivers.exciter.cia402_sequences import DriveStateTimeoutError
from drivers.exciter.codes import CommandCode, ExciterState
from simulators.devices.cia402_exciter import SimulatedCia402Exciter
from simulators.plate import EmptyPlate
from tests.drivers.cia402_rig import HALT, NODE, START, SWEEP, entered_at, fresh_channel, rig, states, stored

TRANSITION_TIMES_S = [0.01, 0.05, 0.2]
"""A real drive's time per state transition: electronics only, a contactor closing, a brake releasing."""


@pytest.mark.parametrize("transition_s", TRANSITION_TIMES_S)
def test_a_slow_drive_starts_then_stops_disabled(transition_s: float) -> None:
    async def scenario() -> None:
        async with rig({"transition_s": transition_s}) as (sim, exciter):
            await exciter.configure_sweep(SWEEP)
            await exciter.start()
            # each command written once, in the state the previous transition reached: none re-sent or
            # sent ahead while the drive worked
            assert sim.controlwords == [0x06, 0x07, 0x0F, START]
            assert [word.state for word in sim.received] == [
                DriveState.SWITCH_ON_DISABLED,
                DriveState.READY_TO_SWITCH_ON,
                DriveState.SWITCHED_ON,
                DriveState.OPERATION_ENABLED,
            ]
            assert states(sim) == [
                DriveState.SWITCH_ON_DISABLED,
                DriveState.READY_TO_SWITCH_ON,
                DriveState.SWITCHED_ON,
                DriveState.OPERATION_ENABLED,
            ]
            for command, (entered_s, _) in zip(sim.received[:3], sim.timeline[1:], strict=True):
                assert entered_s - command.time_s >= transition_s - 1e-9  # the drive's own transition time
            sim.advance(0.3)
            assert (await exciter.status()).state is ExciterState.RUNNING
            assert sim.error_code == 0  # the waits fed the watchdog: 3 x 200 ms did not trip its 500 ms

            await exciter.stop()
            halt, disable = sim.received[-2:]
            assert (halt.word, disable.word) == (HALT, objects.CW_SWITCH_ON)
            assert disable.state is DriveState.OPERATION_ENABLED and plate_at_rest(disable.statusword)
            assert disable.time_s - halt.time_s >= 0.5 - 1e-9  # the plate's whole controlled-stop ramp
            assert sim.state is DriveState.SWITCHED_ON and states(sim)[-1] is DriveState.SWITCHED_ON
            assert stored(sim, objects.CONSUMER_HEARTBEAT_TIME, 1) == 0  # unsupervised only once disabled
            assert (sim.ramps_cut_short, sim.error_code) == (0, 0)
            assert (await exciter.status()).state is ExciterState.IDLE

    asyncio.run(scenario())


@pytest.mark.parametrize(
    "option",
    [objects.QUICK_STOP_RAMP_THEN_DISABLED, objects.QUICK_STOP_RAMP_THEN_STAY],
    ids=["to-SOD", "stay"],
)
@pytest.mark.parametrize("transition_s", TRANSITION_TIMES_S)
def test_emergency_stop_awaits_quick_stop_and_its_ramp_before_disable_voltage(
    transition_s: float, option: int
) -> None:
    ramp_s = 0.15

    async def scenario() -> None:
        drive = {"transition_s": transition_s, "quick_stop_ramp_s": ramp_s}
        async with rig(drive) as (sim, exciter):
            sim.node.sdo[objects.QUICK_STOP_OPTION].raw = option
            await exciter.configure_sweep(SWEEP)
            await exciter.start()
            sim.advance(0.3)
            assert (await exciter.status()).state is ExciterState.RUNNING

            await exciter.emergency_stop()
            quick_stop, disable = sim.received[-2:]
            assert (quick_stop.word, disable.word) == (objects.CW_QUICK_STOP, objects.CW_DISABLE_VOLTAGE)
            assert quick_stop.state is DriveState.OPERATION_ENABLED
            quick_stop_active_s = entered_at(sim, DriveState.QUICK_STOP_ACTIVE)
            assert quick_stop_active_s - quick_stop.time_s >= transition_s - 1e-9
            assert disable.time_s - quick_stop_active_s >= ramp_s - 1e-9  # the ramp ran its course
            if option == objects.QUICK_STOP_RAMP_THEN_DISABLED:  # the drive left quick stop by itself
                assert disable.state is DriveState.SWITCH_ON_DISABLED
            else:  # it stays in quick stop: the plate at rest is the end of the ramp
                assert disable.state is DriveState.QUICK_STOP_ACTIVE and plate_at_rest(disable.statusword)
            assert states(sim)[-3:] == [
                DriveState.OPERATION_ENABLED,
                DriveState.QUICK_STOP_ACTIVE,
                DriveState.SWITCH_ON_DISABLED,
            ]
            assert sim.ramps_cut_short == 0
            assert stored(sim, objects.CONSUMER_HEARTBEAT_TIME, 1) == 0
            assert (await exciter.status()).state is ExciterState.IDLE

    asyncio.run(scenario())


@pytest.mark.parametrize("transition_s", TRANSITION_TIMES_S)
def test_a_transition_timeout_names_the_state_reached_and_withdraws_the_power_up(transition_s: float) -> None:
    async def scenario() -> None:
        drive = {"transition_s": transition_s, "transition_s_to": {DriveState.OPERATION_ENABLED: 2.0}}
        async with rig(drive) as (sim, exciter):  # the brake never releases within the 0.5 s allowed
            await exciter.configure_sweep(SWEEP)
            with pytest.raises(DriveStateTimeoutError) as info:
                await exciter.start()
            message = str(info.value)
            assert "start: enable operation: OPERATION ENABLED not reached within 0.5 s" in message
            assert "the drive reports SWITCHED ON (statusword 0x" in message
            assert info.value.state is DriveState.SWITCHED_ON
            assert DriveState.of_statusword(info.value.statusword) is DriveState.SWITCHED_ON
            # enable operation re-sent once, halfway, the state unchanged; then withdrawn by disable voltage
            assert sim.controlwords == [0x06, 0x07, 0x0F, 0x0F, objects.CW_DISABLE_VOLTAGE]
            first, again = sim.received[2:4]
            assert again.state is DriveState.SWITCHED_ON and again.time_s - first.time_s >= 0.25 - 1e-9
            assert sim.state is DriveState.SWITCH_ON_DISABLED
            assert DriveState.OPERATION_ENABLED not in states(sim)
            assert stored(sim, objects.CONSUMER_HEARTBEAT_TIME, 1) == 0  # disarmed: the drive is disabled
            sim.advance(1.0)
            assert sim.state is DriveState.SWITCH_ON_DISABLED and sim.error_code == 0

    asyncio.run(scenario())


def test_a_stop_that_times_out_leaves_the_drive_supervised() -> None:
    async def scenario() -> None:
        async with rig({"halt_ramp_s": 1.0}, ramp_timeout_s=0.3) as (sim, exciter):
            await exciter.configure_sweep(SWEEP)
            await exciter.start()
            sim.advance(0.3)
            await exciter.status()
            with pytest.raises(
                DriveStateTimeoutError, match=r"stop: halt: plate at rest not reached within 0\.3 s"
            ):
                await exciter.stop()
            assert sim.controlwords[-1] == HALT  # no disable while the plate moves
            assert stored(sim, objects.CONSUMER_HEARTBEAT_TIME, 1) != 0  # still supervised by its watchdog
            sim.advance(0.6)  # nobody feeds it any more: the drive's own fault reaction stops the plate
            assert sim.error_code == objects.ERROR_HEARTBEAT
            assert sim.state in (DriveState.FAULT_REACTION_ACTIVE, DriveState.FAULT)
            sim.advance(1.0)
            assert sim.state is DriveState.FAULT and (await exciter.status()).state is ExciterState.FAULT

    asyncio.run(scenario())


def test_a_clock_that_does_not_move_still_ends_a_wait() -> None:
    async def scenario() -> None:
        bench = EmptyPlate()
        channel = fresh_channel()
        drive = SimulatedCia402Exciter(bench, channel=channel, node_id=NODE, transition_s=1.0)
        with drive:
            exciter = Cia402Exciter(  # a manual clock nobody advances, and real sleeps (asyncio.sleep)
                "virtual", channel, node_id=NODE, transition_timeout_s=0.05, clock=bench.clock.now_s
            )
            async with exciter:
                await exciter.configure_sweep(SWEEP)
                with pytest.raises(DriveStateTimeoutError, match="reports SWITCH ON DISABLED"):
                    await exciter._send_command(CommandCode.START)

    asyncio.run(scenario())
