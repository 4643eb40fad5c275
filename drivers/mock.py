"""In-process mock back ends of the devices, for unit tests (what ophyd-async calls a mock backend).

No transport, no thread, no physics: a mock reports what the test scripted and records what it was asked.

* `MockLine` (drivers.interfaces.LaserLine): a line that is never quiet unless told (`quiet_for_s`).
* `MockAmplifier` (drivers.interfaces.LaserAmplifier): its reading is a script, `reading_m` (a value, or a
  function of the clock's time), scaled to counts by its own AmplifierConfig, so LaserSource decodes it
  exactly as a real amplifier's. Streaming configurations sample the script on their sample grid
  (sample n at n x period) and keep the newest `buffer_length` samples, as the amplifier's ring does.
* `MockExciter` (drivers.interfaces.Exciter): the wire side of a PlateExciter held in memory. The envelope,
  supervision and keep-alive logic are the real ones (inherited): only the drive is a mock. It reports
  the status fields the test sets and changes state on a command as `state_after` says.
* `ManualClock`: the time every mock and the test share; it also satisfies daq.sweep.pacing's
  SteppedSimulation, so SimulatedPacing steps a sweep through mocks deterministically, without sleeping.

Faults are scripted: `fail(exc, count)` on an amplifier, `fail(operation, exc, count)` on an exciter makes
the next `count` calls (None: every call until `clear_faults()`) raise `exc`.

The pty/TCP/CAN simulators (simulators/devices/) stay for tests that need a real transport.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

from drivers.compowayf.amplifier import StreamRead
from drivers.compowayf.errors import MeasurementOutOfRangeError
from drivers.compowayf.layout import COUNTER_MODULUS, AmplifierConfig
from drivers.compowayf.service_data import StatusReport
from drivers.compowayf.transport import LinkCounters, LinkSettings
from drivers.exciter.codes import CommandCode, ExciterState, ExciterStatus
from drivers.exciter.envelope import SafetyEnvelope
from drivers.exciter.interface import DEFAULT_KEEPALIVE_INTERVAL_S, PlateExciter
from estimator.sweep import SweepSettings

__all__ = ["ExciterOperation", "ManualClock", "MockAmplifier", "MockExciter", "MockLine", "Reading"]

SAMPLE_NUMBER_TOLERANCE = 1e-9
"""A sample taken at exactly the clock's time counts as taken despite float rounding (in periods)."""


class ManualClock:
    """Seconds that pass only when told (`advance`). Also a daq.sweep.pacing.SteppedSimulation: pass it to
    SimulatedPacing, whose `wait` advances it; `on_advance` callbacks run after every step."""

    realtime = False

    def __init__(self, start_s: float = 0.0) -> None:
        self._now_s = start_s
        self.on_advance: list[Callable[[float], None]] = []
        """Called with the new time after every advance (a test's scripted events)."""

    @property
    def clock(self) -> ManualClock:
        return self

    def now_s(self) -> float:
        return self._now_s

    def advance(self, dt_s: float) -> None:
        if dt_s < 0:
            raise ValueError(f"time cannot go back: dt_s={dt_s}")
        self._now_s += dt_s
        for callback in list(self.on_advance):
            callback(self._now_s)


@dataclass
class _Faults:
    """Scripted failures: `exc` raised by the next `remaining` calls (None: until cleared)."""

    exc: BaseException | None = None
    remaining: int | None = None

    def arm(self, exc: BaseException, count: int | None) -> None:
        if count is not None and count < 1:
            raise ValueError(f"count must be >= 1 or None, got {count}")
        self.exc, self.remaining = exc, count

    def clear(self) -> None:
        self.exc, self.remaining = None, None

    def raise_if_armed(self) -> None:
        exc = self.exc
        if exc is None:
            return
        if self.remaining is not None:
            self.remaining -= 1
            if self.remaining == 0:
                self.clear()
        raise exc


@dataclass
class MockLine:
    """A line (drivers.interfaces.LaserLine) in memory. Set `quiet_for_s` for a line waiting out a late
    reply, `awaiting_reply` / `counters.unanswered` / `last_failure` for what it reports."""

    pyserial_url: str = "mock://line"
    link: LinkSettings = field(default_factory=LinkSettings)
    counters: LinkCounters = field(default_factory=LinkCounters)
    waits_for_late_replies: bool = True
    awaiting_reply: bool = False
    last_failure: str = ""
    quiet_for_s: float = 0.0
    closed: bool = False

    def quiet_s(self) -> float:
        return self.quiet_for_s

    def close(self) -> None:
        self.closed = True


Reading = float | Callable[[float], float]
"""A scripted reading in metres: a constant, or a function of the clock's time (NaN: out of range)."""


class MockAmplifier:
    """A laser amplifier (drivers.interfaces.LaserAmplifier) in memory; see the module.

    config: where the value lives and how counts scale (streaming when its layout has a sample counter).
    reading_m: the script; clock: seconds (a ManualClock's now_s); model: what read_model answers."""

    def __init__(
        self,
        config: AmplifierConfig | None = None,
        *,
        reading_m: Reading = 0.0,
        clock: Callable[[], float] = time.monotonic,
        line: MockLine | None = None,
        model: str = "ZX-LDA11-N",
        status: StatusReport = StatusReport(0, 0),  # noqa: B008 (a frozen dataclass)
    ) -> None:
        self.config = config or AmplifierConfig()
        self.reading_m: Reading = reading_m
        self.clock = clock
        self.port = line or MockLine()
        self.model = model
        self.status = status
        self.reads = 0
        """Measured-value reads answered (read_counts, read_stream, read_position_m)."""
        self._faults = _Faults()

    # ---- scripting ------------------------------------------------------------------------------------

    def fail(self, exc: BaseException, count: int | None = 1) -> None:
        """The next `count` requests of any kind raise `exc` (None: every one until clear_faults)."""
        self._faults.arm(exc, count)

    def clear_faults(self) -> None:
        self._faults.clear()

    def value_m(self, time_s: float) -> float:
        """The script's reading at time_s."""
        reading = self.reading_m
        return float(reading(time_s) if callable(reading) else reading)

    def _counts(self, time_s: float) -> int:
        measured = self.config.measured
        value_m = self.value_m(time_s)
        return measured.out_of_range_marker if math.isnan(value_m) else measured.m_to_counts(value_m)

    # ---- drivers.interfaces.LaserAmplifier ------------------------------------------------------------

    def read_model(self) -> str:
        self._faults.raise_if_armed()
        return self.model

    def read_status(self) -> StatusReport:
        self._faults.raise_if_armed()
        return self.status

    def read_position_m(self) -> float:
        counts = self.read_counts(1)[0]
        if self.config.measured.is_out_of_range(counts):
            raise MeasurementOutOfRangeError(f"mock amplifier: out of measuring range ({counts})")
        return self.config.measured.counts_to_m(counts)

    def read_counts(self, count: int = 1) -> list[int]:
        if self.config.measured.is_streaming:
            return self.read_stream(count).counts
        self._faults.raise_if_armed()
        self.reads += 1
        return [self._counts(self.clock())] * count

    def read_stream(self, count: int, since: int | None = None) -> StreamRead:
        measured = self.config.measured
        period_s = measured.sample_period_s
        if not measured.is_streaming or period_s is None:
            raise ValueError("this amplifier's configuration has no sample counter (not a streaming layout)")
        self._faults.raise_if_armed()
        self.reads += 1
        taken = math.floor(self.clock() / period_s + SAMPLE_NUMBER_TOLERANCE) + 1  # sample 0 at time 0
        counter = taken % COUNTER_MODULUS
        new = count if since is None else min(count, (counter - since) % COUNTER_MODULUS)
        new = min(new, taken, measured.buffer_length)
        counts = [self._counts((taken - 1 - k) * period_s) for k in range(new)]
        return StreamRead(counter, counts)


ExciterOperation = Literal["open", "sweep", "command", "keepalive", "status", "close"]
"""The wire operations of a PlateExciter back end a fault can be scripted on."""

DEFAULT_STATE_AFTER: dict[CommandCode, ExciterState] = {
    CommandCode.START: ExciterState.RUNNING,
    CommandCode.STOP: ExciterState.IDLE,
    CommandCode.EMERGENCY_STOP: ExciterState.IDLE,
    CommandCode.RESET_FAULT: ExciterState.IDLE,
}
"""What the mock drive reports after each command (a real drive ramps down through STOPPING)."""


class MockExciter(PlateExciter):
    """A plate exciter whose drive is a mock (drivers.interfaces.Exciter); see the module.

    The status it reports is its fields `state`, `fault_code`, `frequency_Hz`, `position_m` (set them, or
    give `motion`, a function of the clock's time returning (frequency Hz, position m) while RUNNING).
    Recorded: `sweeps` written, `commands` sent, `keepalive_counters` sent, `opened`, `closed`."""

    def __init__(
        self,
        *,
        envelope: SafetyEnvelope | None = None,
        keepalive_interval_s: float | None = DEFAULT_KEEPALIVE_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
        motion: Callable[[float], tuple[float, float]] | None = None,
    ) -> None:
        super().__init__(envelope=envelope, keepalive_interval_s=keepalive_interval_s, clock=clock)
        self.state = ExciterState.IDLE
        self.fault_code = 0
        self.frequency_Hz = 0.0
        self.position_m = 0.0
        self.motion = motion
        self.state_after = dict(DEFAULT_STATE_AFTER)
        self.sweeps: list[SweepSettings] = []
        self.commands: list[CommandCode] = []
        self.keepalive_counters: list[int] = []
        self.opened = self.closed = False
        self._faults: dict[ExciterOperation, _Faults] = {}

    # ---- scripting ------------------------------------------------------------------------------------

    def fail(self, operation: ExciterOperation, exc: BaseException, count: int | None = 1) -> None:
        """The next `count` calls of `operation` (None: every one until clear_faults) raise `exc`."""
        self._faults.setdefault(operation, _Faults()).arm(exc, count)

    def clear_faults(self) -> None:
        self._faults.clear()

    def inject_fault(self, code: int) -> None:
        """The drive reports a fault (`code`) from now on, until a RESET_FAULT command."""
        self.state, self.fault_code = ExciterState.FAULT, code

    def _wire(self, operation: ExciterOperation) -> None:
        faults = self._faults.get(operation)
        if faults is not None:
            faults.raise_if_armed()

    # ---- the wire side of PlateExciter ----------------------------------------------------------------

    async def open(self) -> None:
        self._wire("open")
        self.opened = True

    async def _write_sweep(self, settings: SweepSettings) -> None:
        self._wire("sweep")
        self.sweeps.append(settings)

    async def _send_command(self, command: CommandCode) -> None:
        self._wire("command")
        self.commands.append(command)
        if command is CommandCode.RESET_FAULT:
            self.fault_code = 0
        if command in self.state_after:
            self.state = self.state_after[command]

    async def _send_keepalive(self, counter: int) -> None:
        self._wire("keepalive")
        self.keepalive_counters.append(counter)

    async def _read_status(self) -> ExciterStatus:
        self._wire("status")
        if self.motion is not None and self.state is ExciterState.RUNNING:
            self.frequency_Hz, self.position_m = self.motion(self.clock())
        return ExciterStatus(self.state, self.fault_code, self.frequency_Hz, self.position_m)

    async def _close_transport(self) -> None:
        self._wire("close")
        self.closed = True
