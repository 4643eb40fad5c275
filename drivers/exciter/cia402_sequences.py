"""The CiA 402 power state machine as the host walks it (drivers/exciter/cia402.py): enable, stop, emergency
stop and fault reset, each transition awaited on the statusword.

A real drive takes its time per transition (a brake releasing, a contactor closing: 10..200 ms), so every
step writes its controlword once, then polls the statusword every `poll_interval_s` until the drive
reports the state asked for, at most `transition_timeout_s` on the back end's clock (a ramp to rest, at
most `ramp_timeout_s`). A controlword is a level, not an edge: the drive acts on it when it can, so it is
not written again while the drive works. It is re-sent once, halfway through the timeout, only if the
state is still the one it was written in and the word holds no edge-triggered bit (4: start, 7: fault
reset; re-sending those would need a falling edge first). A step that times out raises
DriveStateTimeoutError naming the state of the last statusword read, not the state it started from.

Between polls the host waits with the back end's `sleep` (asyncio.sleep; in tests one that advances the
simulated clock, so the waits are deterministic). Should the clock not move with that sleep (a manual
simulated clock nobody advances), a wait still ends after twice its timeout's worth of sleeps.

Every statusword read that shows neither FAULT nor FAULT REACTION ACTIVE is handed to `after_healthy_poll`
(the back end feeds the drive's watchdog there while it is armed): a start whose three transitions take
200 ms each, or a stop's 0.5 s ramp, would otherwise outlast the drive's 0.5 s watchdog.

Sequences:

    enable operation  shutdown -> switch on -> enable operation, from wherever the drive is (NOT READY TO
                      SWITCH ON: waits for its automatic transition; QUICK STOP ACTIVE: disable voltage
                      first, the long way round); FAULT -> ExciterDeviceFaultError
    stop              halt (bit 8), await the plate at rest (ramp), then disable operation: SWITCHED ON.
                      A drive found quick-stopping or in its fault reaction is finished as below
    emergency stop    quick stop, await QUICK STOP ACTIVE, await the end of its ramp (the plate at rest,
                      or the drive leaving QUICK STOP ACTIVE to SWITCH ON DISABLED per its quick-stop
                      option code 0x605A), then disable voltage, whatever failed before, and await
                      SWITCH ON DISABLED
    reset fault       bit 7 low then its rising edge, await the drive leaving FAULT
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass

from drivers.exciter import cia402_objects as objects
from drivers.exciter.cia402_objects import DriveState
from drivers.exciter.errors import ExciterDeviceFaultError, ExciterError, ExciterTimeoutError

DEFAULT_TRANSITION_TIMEOUT_S = 0.5
DEFAULT_RAMP_TIMEOUT_S = 2.0
"""A halt or quick-stop ramp to rest (the simulated plate's controlled stop takes 0.5 s)."""
STATE_POLL_INTERVAL_S = 0.01
"""Statusword poll spacing while a transition or a ramp is awaited."""
MAX_ENABLE_STEPS = 6
"""State changes the enable sequence follows before it gives up (the longest path has four)."""

EDGE_BITS = objects.CW_START_SWEEP | objects.CW_FAULT_RESET
"""Controlword bits that act on their rising edge: a word holding one is never re-sent."""
HALT_WORD = objects.CW_ENABLE_OPERATION | objects.CW_HALT

COMMAND_NAMES = {
    objects.CW_SHUTDOWN: "shutdown",
    objects.CW_SWITCH_ON: "switch on",
    objects.CW_ENABLE_OPERATION: "enable operation",
    objects.CW_DISABLE_VOLTAGE: "disable voltage",
    objects.CW_QUICK_STOP: "quick stop",
    objects.CW_FAULT_RESET: "fault reset",
    HALT_WORD: "halt",
}

_ENABLE_STEP: dict[DriveState, tuple[int | None, DriveState]] = {
    # automatic transition 1: nothing to command, only wait
    DriveState.NOT_READY_TO_SWITCH_ON: (None, DriveState.SWITCH_ON_DISABLED),
    DriveState.SWITCH_ON_DISABLED: (objects.CW_SHUTDOWN, DriveState.READY_TO_SWITCH_ON),
    DriveState.READY_TO_SWITCH_ON: (objects.CW_SWITCH_ON, DriveState.SWITCHED_ON),
    DriveState.SWITCHED_ON: (objects.CW_ENABLE_OPERATION, DriveState.OPERATION_ENABLED),
    # leave quick stop the long way round
    DriveState.QUICK_STOP_ACTIVE: (objects.CW_DISABLE_VOLTAGE, DriveState.SWITCH_ON_DISABLED),
}
_FAULTED = (DriveState.FAULT, DriveState.FAULT_REACTION_ACTIVE)
_VOLTAGE_OFF = (DriveState.SWITCH_ON_DISABLED, DriveState.NOT_READY_TO_SWITCH_ON, DriveState.FAULT)

StateDone = Callable[[DriveState, int], bool]
"""Whether a wait is over, given the state and the statusword just read."""


class DriveStateTimeoutError(ExciterTimeoutError):
    """The drive did not reach the state (or the rest) a step awaited within its timeout. `state` and
    `statusword` are those of the last statusword read: where the drive actually is."""

    def __init__(self, message: str, state: DriveState, statusword: int) -> None:
        super().__init__(message)
        self.state = state
        self.statusword = statusword


@dataclass(frozen=True)
class DriveAccess:
    """What the sequences need of the back end. `supervise` False: the back end's supervision checks
    (drive heartbeat) wait until a stop sequence has been sent whole."""

    where: str
    read_state: Callable[[bool], Awaitable[tuple[DriveState, int]]]
    """(supervise) -> the state and statusword now."""
    write_controlword: Callable[[str, int, bool], Awaitable[None]]
    """(what, word, supervise)."""
    read_error_code: Callable[[], Awaitable[int]]
    after_healthy_poll: Callable[[], Awaitable[None]]
    """Called after every statusword read showing no fault (the back end feeds its watchdog there)."""


@dataclass(frozen=True)
class StopOutcome:
    """How an emergency stop ended: the last state read (None: none could be read) and the first error,
    raised by the back end once it has dealt with its watchdog."""

    state: DriveState | None
    error: ExciterError | None


class Cia402Sequences:
    """The state-machine sequences of one drive, timed on `clock` (s), waiting with `sleep`."""

    def __init__(
        self,
        access: DriveAccess,
        *,
        clock: Callable[[], float],
        sleep: Callable[[float], Awaitable[None]],
        transition_timeout_s: float = DEFAULT_TRANSITION_TIMEOUT_S,
        ramp_timeout_s: float = DEFAULT_RAMP_TIMEOUT_S,
        poll_interval_s: float = STATE_POLL_INTERVAL_S,
    ) -> None:
        self.access = access
        self.clock = clock
        self.sleep = sleep
        self.transition_timeout_s = transition_timeout_s
        self.ramp_timeout_s = ramp_timeout_s
        self.poll_interval_s = poll_interval_s

    # ---- sequences ----------------------------------------------------------------------------------

    async def enable_operation(self) -> None:
        """Shutdown -> switch on -> enable operation, each transition awaited (DriveStateTimeoutError)."""
        state, statusword = await self._read(True)
        for _step in range(MAX_ENABLE_STEPS):
            if state is DriveState.OPERATION_ENABLED:
                return
            if state in _FAULTED:
                raise ExciterDeviceFaultError(await self.access.read_error_code())
            word, target = _ENABLE_STEP[state]
            what = f"start: {COMMAND_NAMES[word] if word is not None else 'power-up'}"
            if word is not None:
                await self._write(what, word, True)
            state, statusword = await self._await_change(what, state, target, word, True)
        raise DriveStateTimeoutError(
            f"{self.access.where} did not reach OPERATION ENABLED in {MAX_ENABLE_STEPS} state changes: "
            f"{_reported(state, statusword)}",
            state,
            statusword,
        )

    async def halt_then_disable(self) -> DriveState:
        """Controlled stop: halt, await the plate at rest, disable operation (SWITCHED ON). Returns the
        state reached; raises (DriveStateTimeoutError...) when a step fails, the drive maybe still
        enabled."""
        state, statusword = await self._read(False)
        if state is DriveState.OPERATION_ENABLED:
            await self._write("stop: halt", HALT_WORD, False)
            state, statusword = await self._await(
                "stop: halt", "plate at rest", _at_rest_or_left(state), self.ramp_timeout_s, False
            )
        if state is DriveState.OPERATION_ENABLED:
            await self._write("stop: disable operation", objects.CW_SWITCH_ON, False)
            state, statusword = await self._await_change(
                "stop: disable operation", state, DriveState.SWITCHED_ON, objects.CW_SWITCH_ON, False
            )
        if state in (DriveState.QUICK_STOP_ACTIVE, DriveState.FAULT_REACTION_ACTIVE):
            state, statusword = await self._await_ramp_end("stop", state, statusword)
            state = await self.disable_voltage("stop")
        return state

    async def quick_stop_then_disable(self) -> StopOutcome:
        """Emergency stop: quick stop, its ramp, then disable voltage -- sent even when an earlier step
        failed or timed out, so that the plate ends stopped. Never raises: the outcome holds the error."""
        error: ExciterError | None = None
        state: DriveState | None = None
        try:
            await self._write("emergency stop: quick stop", objects.CW_QUICK_STOP, False)
            state, statusword = await self._await_change(
                "emergency stop: quick stop",
                DriveState.OPERATION_ENABLED,
                DriveState.QUICK_STOP_ACTIVE,
                objects.CW_QUICK_STOP,
                False,
            )
            state, statusword = await self._await_ramp_end("emergency stop", state, statusword)
        except ExciterError as exc:
            error = exc
        try:
            state = await self.disable_voltage("emergency stop")
        except DriveStateTimeoutError as exc:
            state, error = exc.state, error or exc
        except ExciterError as exc:
            error = error or exc
        return StopOutcome(state, error)

    async def disable_voltage(self, what: str) -> DriveState:
        """Disable voltage (the power stage off), awaited until the drive reports SWITCH ON DISABLED (or
        FAULT, which a disable voltage does not leave)."""
        await self._write(f"{what}: disable voltage", objects.CW_DISABLE_VOLTAGE, False)
        state, _ = await self._await(
            f"{what}: disable voltage",
            str(DriveState.SWITCH_ON_DISABLED),
            lambda new, _: new in _VOLTAGE_OFF,
            self.transition_timeout_s,
            False,
            resend=objects.CW_DISABLE_VOLTAGE,
        )
        return state

    async def reset_fault(self) -> None:
        """In FAULT: bit 7 low, then its rising edge; the drive leaving FAULT awaited."""
        state, _ = await self._read(True)
        if state is not DriveState.FAULT:
            return
        await self._write("reset fault", objects.CW_DISABLE_VOLTAGE, True)
        await self._write("reset fault", objects.CW_FAULT_RESET, True)
        await self._await_change(
            "reset fault", state, DriveState.SWITCH_ON_DISABLED, objects.CW_FAULT_RESET, True
        )

    # ---- waiting ------------------------------------------------------------------------------------

    async def _await_ramp_end(self, what: str, state: DriveState, statusword: int) -> tuple[DriveState, int]:
        """A quick stop's ramp (until the plate rests or the drive leaves QUICK STOP ACTIVE) or a fault
        reaction's (until FAULT)."""
        if state not in (DriveState.QUICK_STOP_ACTIVE, DriveState.FAULT_REACTION_ACTIVE):
            return state, statusword
        return await self._await(
            f"{what}: {state.lower()}", "end of the ramp", _ramp_over, self.ramp_timeout_s, False
        )

    async def _await_change(
        self, what: str, old: DriveState, target: DriveState, word: int | None, supervise: bool
    ) -> tuple[DriveState, int]:
        """A transition out of `old` (normally to `target`), after `word` was written in it (None: an
        automatic transition). Any other state ends the wait too: the caller decides what it means."""
        return await self._await(
            what,
            str(target),
            lambda new, _: new is not old,
            self.transition_timeout_s,
            supervise,
            resend=word,
            written_in=old,
        )

    async def _await(
        self,
        what: str,
        wanted: str,
        done: StateDone,
        timeout_s: float,
        supervise: bool,
        *,
        resend: int | None = None,
        written_in: DriveState | None = None,
    ) -> tuple[DriveState, int]:
        """Poll the statusword until `done`, at most `timeout_s` on the clock; `resend` (a level without
        edge bits) is written once more halfway through if the state is still `written_in` (None: the
        state of the first poll)."""
        start_s = self.clock()
        slept_s = 0.0
        may_resend = resend is not None and not resend & EDGE_BITS
        while True:
            state, statusword = await self._read(supervise)
            if done(state, statusword):
                return state, statusword
            written_in = written_in or state
            waited_s = self.clock() - start_s
            if waited_s >= timeout_s or slept_s > 2 * timeout_s:
                raise DriveStateTimeoutError(
                    f"{self.access.where}: {what}: {wanted} not reached within {timeout_s:g} s: "
                    f"{_reported(state, statusword)}",
                    state,
                    statusword,
                )
            if may_resend and state is written_in and waited_s >= timeout_s / 2:
                assert resend is not None
                may_resend = False
                await self._write(f"{what} (again)", resend, supervise)
            await self.sleep(self.poll_interval_s)
            slept_s += self.poll_interval_s

    async def _read(self, supervise: bool) -> tuple[DriveState, int]:
        state, statusword = await self.access.read_state(supervise)
        if state not in _FAULTED:
            await self.access.after_healthy_poll()
        return state, statusword

    async def _write(self, what: str, word: int, supervise: bool) -> None:
        await self.access.write_controlword(what, word, supervise)


def _at_rest_or_left(state: DriveState) -> StateDone:
    return lambda new, statusword: new is not state or objects.plate_at_rest(statusword)


def _ramp_over(state: DriveState, statusword: int) -> bool:
    if state is DriveState.QUICK_STOP_ACTIVE:
        return objects.plate_at_rest(statusword)
    return state is not DriveState.FAULT_REACTION_ACTIVE


def _reported(state: DriveState, statusword: int) -> str:
    return f"the drive reports {state} (statusword 0x{statusword:04X})"
