"""In-process mock devices for a whole bench configuration (drivers.mock behind daq.sweep.devices' Devices
protocol), for unit tests of the sweep's orchestration: no pty, socket or CAN bus, time on a ManualClock.
Kept apart from daq/sweep/devices.py so that a sweep on the hardware never imports the mocks."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from daq.bench_config import BenchConfig, ExciterConfig
from daq.sweep.devices import Clock
from drivers.compowayf.layout import AmplifierConfig
from drivers.compowayf.urls import parse_device_url
from drivers.exciter.envelope import SafetyEnvelope
from drivers.interfaces import LaserLine
from drivers.mock import ManualClock, MockAmplifier, MockExciter, MockLine, Reading


@dataclass
class MockDevices:
    """Mocks for every device of a bench configuration (see daq.sweep.devices); build with `for_bench`.

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
