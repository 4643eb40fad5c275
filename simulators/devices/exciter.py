"""The simulated plate exciter (the drive controller that moves the plate), whatever protocol it speaks.

One name for the plate's drive across the layers: "exciter" (drivers/exciter/, daq's ExciterConfig, this
module); "plate" is only the moving table itself and its motion (simulators/plate.py).

`SimulatedExciter` holds the protocol-independent behaviour: sweep settings written piecewise, commands
(start, controlled stop, emergency stop, fault reset), the host watchdog, latched faults and the status
snapshot. The Modbus (modbus_exciter.py) and CAN (can_exciter.py) simulators translate their frames to
these calls and `ExciterRefusalError` to their own error answers.

Watchdog: a START arms it; from then on, while the plate runs, the host must send a keep-alive with a
changing counter at least every `watchdog_timeout_s` of simulated time. The check runs on every `tick()`
and before every request, like a drive's cyclic check: when it finds the host silent for longer, it makes
a controlled stop and latches FAULT_WATCHDOG until RESET_FAULT. Reported state: STOPPING while the plate
ramps down, FAULT once it rests.
"""

from __future__ import annotations

import threading
from enum import Enum
from typing import Any

from drivers.exciter.codes import (
    FAULT_NONE,
    FAULT_WATCHDOG,
    CommandCode,
    ExciterState,
    ExciterStatus,
    LawCode,
)
from estimator.sweep import SETTING_NAMES, SweepSettings
from simulators.coupling import PlatePhysics, PlateState

DEFAULT_WATCHDOG_TIMEOUT_S = 0.5

SWEEP_FIELDS = SETTING_NAMES
"""Sweep settings as the drive stores them (law as its numeric code)."""


class RefusalReason(Enum):
    FAULT = "drive in fault"
    NOT_CONFIGURED = "sweep settings incomplete"
    INVALID_VALUE = "invalid value"


class ExciterRefusalError(Exception):
    """The drive refuses a request; each protocol answers with its own code for `reason`."""

    def __init__(self, reason: RefusalReason, detail: str = "") -> None:
        super().__init__(f"{reason.value}{': ' + detail if detail else ''}")
        self.reason = reason


class SimulatedExciter:
    """Drive controller logic on top of a PlatePhysics. Thread-safe (CAN frames arrive on a reader
    thread while tests advance the clock)."""

    def __init__(self, bench: PlatePhysics, watchdog_timeout_s: float = DEFAULT_WATCHDOG_TIMEOUT_S) -> None:
        self.bench = bench
        self.clock = bench.clock
        self.watchdog_timeout_s = watchdog_timeout_s
        self.commands: list[CommandCode] = []
        """Every command received, accepted or not (for tests)."""
        self.keepalives_received = 0
        self._lock = threading.RLock()
        self._params: dict[str, float] = {}
        self._latched_fault = FAULT_NONE
        self._watchdog_armed = False
        self._last_keepalive_s = 0.0
        self._last_keepalive_counter: int | None = None

    # ---- host requests ------------------------------------------------------------------------------

    def set_sweep_params(self, **values: float) -> None:
        """Store some of start_Hz, stop_Hz, amplitude_m, duration_s, law (code); checked at START."""
        unknown = set(values) - set(SWEEP_FIELDS)
        if unknown:
            raise ValueError(f"unknown sweep field(s) {sorted(unknown)}")
        with self._lock:
            self._params.update(values)

    def command(self, code: int) -> None:
        """Execute a command code; ExciterRefusalError if the drive will not."""
        with self._lock:
            self.tick()
            try:
                command = CommandCode(code)
            except ValueError:
                raise ExciterRefusalError(
                    RefusalReason.INVALID_VALUE, f"unknown command code {code}"
                ) from None
            self.commands.append(command)
            if command is CommandCode.START:
                self._start()
            elif command in (CommandCode.STOP, CommandCode.EMERGENCY_STOP):
                self._watchdog_armed = False
                self.bench.stop(emergency=command is CommandCode.EMERGENCY_STOP)
            elif command is CommandCode.RESET_FAULT:
                self._latched_fault = FAULT_NONE
                plate = getattr(self.bench, "plate", None)
                if plate is not None:
                    plate.reset_fault()

    def keepalive(self, counter: int) -> None:
        """Host keep-alive: feeds the watchdog when the counter changed since the last one."""
        with self._lock:
            self.keepalives_received += 1
            self.tick()  # a keep-alive that comes too late does not undo the trip
            if counter != self._last_keepalive_counter:
                self._last_keepalive_counter = counter
                self._last_keepalive_s = self.clock.now_s()

    def status(self) -> ExciterStatus:
        """What the drive reports now."""
        with self._lock:
            plate = self.bench.plate_status()
            if plate.state is PlateState.FAULT:
                return ExciterStatus(ExciterState.FAULT, plate.fault_code, 0.0, plate.position_m)
            state = ExciterState(plate.state.value)
            if self._latched_fault:
                moving = state in (ExciterState.RUNNING, ExciterState.STOPPING)
                state = ExciterState.STOPPING if moving else ExciterState.FAULT
            return ExciterStatus(state, self._latched_fault, plate.frequency_Hz, plate.position_m)

    # ---- time and faults ----------------------------------------------------------------------------

    def tick(self) -> None:
        """Cyclic check at clock.now_s(): trips the watchdog when the host has been silent too long."""
        with self._lock:
            if not self._watchdog_armed:
                return
            if self.bench.plate_status().state is not PlateState.RUNNING:
                self._watchdog_armed = False  # sweep over (or stopped): nothing to guard
                return
            if self.clock.now_s() - self._last_keepalive_s > self.watchdog_timeout_s:
                self._watchdog_armed = False
                self._latched_fault = FAULT_WATCHDOG
                self.bench.stop(emergency=False)

    def inject_fault(self, code: int) -> None:
        """The drive trips with `code` (the plate halts at once) until RESET_FAULT."""
        plate = getattr(self.bench, "plate", None)
        if plate is None or not hasattr(plate, "set_fault"):
            raise TypeError("drive fault injection needs a bench with a SimulatedPlate as .plate")
        with self._lock:
            self._watchdog_armed = False
            plate.set_fault(code)

    @property
    def watchdog_tripped(self) -> bool:
        return self._latched_fault == FAULT_WATCHDOG

    # ---- internals ----------------------------------------------------------------------------------

    def _start(self) -> None:
        if self.status().state is ExciterState.FAULT or self._latched_fault:
            raise ExciterRefusalError(RefusalReason.FAULT)
        missing = [f for f in SWEEP_FIELDS if f not in self._params]
        if missing:
            raise ExciterRefusalError(RefusalReason.NOT_CONFIGURED, f"missing {missing}")
        settings = self._settings()
        try:
            self.bench.start_sweep(settings)
        except RuntimeError as exc:  # the plate itself refuses (in fault)
            raise ExciterRefusalError(RefusalReason.FAULT, str(exc)) from exc
        self._watchdog_armed = True
        self._last_keepalive_s = self.clock.now_s()

    def _settings(self) -> SweepSettings:
        p: dict[str, Any] = dict(self._params)
        try:
            p["law"] = LawCode(int(p["law"])).to_law()
            return SweepSettings(**p)
        except ValueError as exc:
            raise ExciterRefusalError(RefusalReason.INVALID_VALUE, str(exc)) from exc
