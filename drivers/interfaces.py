"""What the acquisition (daq/) needs of a device, as small structural interfaces (typing.Protocol).

daq/ talks to a laser amplifier, to the line it shares with other amplifiers and to the plate exciter only
through these, so the same orchestration runs on the real drivers (drivers.compowayf.amplifier.ZxlAmplifier
on a CompowayFPort, drivers.exciter's PlateExciter back ends), on the simulators behind real transports,
and on the in-process mock back ends of drivers/mock.py (unit tests: no pty, socket or CAN bus).

The protocols hold only what daq uses; each driver has more (configuration, diagnostics), reached through
its own class where a caller needs it. They are runtime-checkable, so a test can assert that a driver or a
mock has every member (isinstance checks names, not signatures). Nothing here has behaviour: the shared
exciter logic (envelope, supervision, keep-alive) stays in drivers/exciter/interface.py, which every
exciter back end inherits.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from drivers.compowayf.layout import AmplifierConfig
from drivers.compowayf.service_data import StatusReport
from drivers.compowayf.transport import LinkCounters, LinkSettings
from drivers.exciter.codes import ExciterStatus
from drivers.exciter.interface import StatusCheck
from estimator.sweep import SweepSettings

__all__ = ["Exciter", "LaserAmplifier", "LaserLine", "StreamReading"]


@runtime_checkable
class StreamReading(Protocol):
    """One read of a streaming amplifier (drivers.compowayf.amplifier.StreamRead): the sample counter
    (modulo COUNTER_MODULUS) and the newest samples' raw counts, newest first."""

    @property
    def counter(self) -> int: ...

    @property
    def counts(self) -> list[int]: ...


@runtime_checkable
class LaserLine(Protocol):
    """The line (serial port) one or more amplifiers share, as the acquisition sees it: OMRON's wait after
    an unanswered request (nothing may be sent on the line until a late reply can no longer come), and
    what failed last. drivers.compowayf.transport.CompowayFPort implements it."""

    pyserial_url: str
    """Identifies the line: lasers with the same one share it (and take turns on it)."""
    waits_for_late_replies: bool
    """True: a request waits out a late reply itself; False: the caller skips polls instead (quiet_s)."""
    awaiting_reply: bool
    """A request is on the line and its reply not yet in."""
    last_failure: str
    """The newest failure of any request on the line ("ErrorClass: message"), "" if none."""

    @property
    def link(self) -> LinkSettings: ...

    @property
    def counters(self) -> LinkCounters: ...

    def quiet_s(self) -> float:
        """Seconds the line must still stay quiet (0: a request may go out now)."""
        ...

    def close(self) -> None: ...


@runtime_checkable
class LaserAmplifier(Protocol):
    """A laser displacement amplifier (one node on a LaserLine): who it is, its status, its measured value
    as raw counts (polled: the present value; streaming: the sample counter and the newest samples).
    drivers.compowayf.amplifier.ZxlAmplifier implements it."""

    @property
    def port(self) -> LaserLine: ...

    @property
    def config(self) -> AmplifierConfig:
        """Where the measured value lives and how its counts scale to metres."""
        ...

    def read_model(self) -> str: ...

    def read_status(self) -> StatusReport: ...

    def read_position_m(self) -> float:
        """The present measured value in metres (MeasurementOutOfRangeError on an out-of-range marker)."""
        ...

    def read_counts(self, count: int = 1) -> list[int]:
        """The newest `count` samples as raw counts, newest first."""
        ...

    def read_stream(self, count: int, since: int | None = None) -> StreamReading:
        """Streaming layout: the counter, then the newest samples (with `since`, only those after it)."""
        ...


@runtime_checkable
class Exciter(Protocol):
    """A plate drive as the sweep drives it: write a sweep, start it, supervise it every cycle (the only
    thing that feeds the drive's watchdog), stop it (controlled or emergency), close. Every back end of
    drivers/exciter (PlateExciter: Modbus, CAN, CiA 402) implements it, and so does drivers.mock's."""

    async def configure_sweep(self, settings: SweepSettings) -> None:
        """Check the sweep against the safety envelope, then write it (the plate does not move)."""
        ...

    async def start(self) -> None: ...

    async def stop(self) -> None:
        """Controlled stop (the amplitude ramps down)."""
        ...

    async def emergency_stop(self) -> None: ...

    async def reset_fault(self) -> None: ...

    async def status(self) -> ExciterStatus:
        """Read the status; while a sweep runs this is a supervision step without a check of the caller's."""
        ...

    async def supervise(self, check: StatusCheck | None = None) -> ExciterStatus:
        """One supervision step: read, check (envelope, then `check`), and only then feed the watchdog."""
        ...

    async def close(self) -> None:
        """Stop a plate this driver started and did not stop, then release the link."""
        ...
