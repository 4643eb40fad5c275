"""How a sweep reaches its devices: the lines and amplifiers of its lasers and its plate exciter.

`run_sweep` asks a `Devices` for them and then talks to them only through drivers.interfaces (LaserLine,
LaserAmplifier, Exciter). Two implementations:

* `DriverDevices` (the default): the real drivers, from the bench configuration's URLs: a CompowayFPort
  per line (`open_port`, which a simulated bench on a manual clock replaces to reach its amplifiers in
  process), a ZxlAmplifier per node, the exciter back end its URL names.
* `MockDevices` (daq/sweep/mock_devices.py, apart so that a sweep on the hardware never loads the mocks):
  in-process mocks (drivers.mock), one per laser and one exciter, built from a bench configuration, for
  unit tests of the orchestration: no pty, socket or CAN bus, time on a ManualClock.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from daq.bench_config import ExciterConfig
from drivers.compowayf.amplifier import ZxlAmplifier
from drivers.compowayf.layout import AmplifierConfig
from drivers.compowayf.transport import CompowayFPort
from drivers.exciter.envelope import SafetyEnvelope
from drivers.interfaces import Exciter, LaserAmplifier, LaserLine

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
