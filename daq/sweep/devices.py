"""How a sweep reaches its devices: the lines and amplifiers of its lasers and its plate exciter.

`run_sweep` asks a `Devices` for them and then talks to them only through drivers.interfaces (LaserLine,
LaserAmplifier, Exciter). Two implementations:

* `DriverDevices` (the default): the real drivers, from the bench configuration's URLs: a CompowayFPort
  per line (`open_port`, which a simulated bench on a manual clock replaces to reach its amplifiers in
  process), a ZxlAmplifier per node, the exciter back end its URL names.
* `MockDevices`: in-process mocks (drivers.mock), one per laser and one exciter, built from a bench
  configuration, for unit tests of the orchestration: no pty, socket or CAN bus, time on a ManualClock.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

from daq.bench_config import BenchConfig, ExciterConfig
from drivers.compowayf.amplifier import ZxlAmplifier
from drivers.compowayf.layout import AmplifierConfig
from drivers.compowayf.transport import CompowayFPort
from drivers.compowayf.urls import parse_device_url
from drivers.exciter.envelope import SafetyEnvelope
from drivers.interfaces import Exciter, LaserAmplifier, LaserLine
from drivers.mock import ManualClock, MockAmplifier, MockExciter, MockLine, Reading

Clock = Callable[[], float]


class Devices(Protocol):
    """Opens what a sweep talks to (see the module)."""

    def open_line(self, url: str) -> LaserLine:
        """The line a laser URL names (called once per line: lasers on it share it)."""
        ...

    def amplifier(self, line: LaserLine, node: int, config: AmplifierConfig) -> LaserAmplifier:
        """The amplifier at `node` on an open `line`, read as `config` says."""
        ...

    async def open_exciter(self, exciter: ExciterConfig, envelope: SafetyEnvelope, clock: Clock) -> Exciter:
        """The plate exciter, connected, checking sweeps against `envelope`, supervising on `clock`."""
        ...


@dataclass(frozen=True)
class DriverDevices:
    """The real drivers (see the module). open_port: opens a laser line from its URL."""

    open_port: Callable[[str], CompowayFPort] = CompowayFPort

    def open_line(self, url: str) -> CompowayFPort:
        return self.open_port(url)

    def amplifier(self, line: LaserLine, node: int, config: AmplifierConfig) -> ZxlAmplifier:
        if not isinstance(line, CompowayFPort):
            raise TypeError(f"a ZX-L amplifier needs a CompowayFPort line, got {type(line).__name__}")
        return ZxlAmplifier(line, node, config)

    async def open_exciter(self, exciter: ExciterConfig, envelope: SafetyEnvelope, clock: Clock) -> Exciter:
        return await exciter.open(envelope=envelope, clock=clock)


@dataclass
class MockDevices:
    """Mocks for every device of a bench configuration (see the module); build with `for_bench`.

    amplifiers: per channel; lines: per pyserial URL; exciter: the plate's. Script them (readings,
    status, faults) before or during the sweep; read what they were asked afterwards."""

    clock: ManualClock
    amplifiers: dict[str, MockAmplifier]
    lines: dict[str, MockLine]
    exciter: MockExciter
    _by_node: dict[tuple[str, int], MockAmplifier] = field(default_factory=dict)

    @classmethod
    def for_bench(
        cls,
        config: BenchConfig,
        clock: ManualClock | None = None,
        readings: Mapping[str, Reading] | None = None,
    ) -> MockDevices:
        """One MockAmplifier per laser (read as its configuration says; reading `readings[channel]`, else
        the laser's zero: the channel at rest) on one MockLine per line, and a MockExciter."""
        clock = clock or ManualClock()
        lines: dict[str, MockLine] = {}
        amplifiers: dict[str, MockAmplifier] = {}
        by_node: dict[tuple[str, int], MockAmplifier] = {}
        for laser in config.lasers:
            url, node = laser.device()
            line = lines.setdefault(url, MockLine(pyserial_url=url))
            reading = (readings or {}).get(laser.channel, laser.zero_m)
            amplifier = MockAmplifier(
                laser.amplifier_config(), reading_m=reading, clock=clock.now_s, line=line
            )
            amplifiers[laser.channel] = by_node[(url, node)] = amplifier
        return cls(clock, amplifiers, lines, MockExciter(clock=clock.now_s), by_node)

    def open_line(self, url: str) -> MockLine:
        line = self.lines[parse_device_url(url).pyserial_url]
        line.closed = False
        return line

    def amplifier(self, line: LaserLine, node: int, config: AmplifierConfig) -> MockAmplifier:
        amplifier = self._by_node[(line.pyserial_url, node)]
        if amplifier.config != config:
            raise ValueError(f"node {node} on {line.pyserial_url}: not the mock's configuration")
        return amplifier

    async def open_exciter(
        self, exciter: ExciterConfig, envelope: SafetyEnvelope, clock: Clock
    ) -> MockExciter:
        self.exciter.envelope = envelope
        self.exciter.clock = clock
        await self.exciter.open()
        return self.exciter
