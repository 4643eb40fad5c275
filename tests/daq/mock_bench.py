"""A quarter-car bench of in-process mocks (drivers/mock.py through daq.sweep.mock_devices.MockDevices): the
sweep orchestration's unit tests run on it with no pty, socket or CAN bus, on a ManualClock that
SimulatedPacing advances (deterministic, nothing sleeps)."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from daq.bench_config import BenchConfig, parse_bench_config
from daq.sweep.mock_devices import MockDevices
from daq.sweep.model import SweepOutcome, SweepProgress, SweepRequest
from daq.sweep.pacing import SimulatedPacing
from daq.sweep.plan import plan_sweep
from daq.sweep.run import run_sweep
from drivers.mock import ManualClock

CHANNELS = ("x_s", "x_t", "x_r")


def bench_toml(*, streaming: bool = True, channels: tuple[str, ...] = CHANNELS) -> str:
    """A quarter-car bench: one laser per channel, each on a line of its own (URLs never opened)."""
    period = "sample_period_s = 0.001\nbuffer_length = 1000\n" if streaming else ""
    lasers = "".join(
        f'[[lasers]]\nname = "laser-{channel}"\nurl = "socket://127.0.0.1:{9000 + node}?node={node}"\n'
        f'channel = "{channel}"\nhead = "ZX-LD40"\nzero_m = 0.001\n{period}\n'
        for node, channel in enumerate(channels, start=1)
    )
    return (
        '[bench]\nname = "mock"\nmodel = "quarter-car"\n\n'
        '[exciter]\nname = "plate-exciter"\nurl = "modbus-tcp://127.0.0.1:5020?unit=1"\n\n' + lasers
    )


@dataclass
class MockBench:
    """A bench configuration and the mocks behind it, on one clock."""

    config: BenchConfig
    devices: MockDevices

    @property
    def clock(self) -> ManualClock:
        return self.devices.clock

    def sweep(
        self,
        out: Path,
        request: SweepRequest,
        progress: Callable[[SweepProgress], None] | None = None,
        *,
        abort: threading.Event | None = None,
        emergency: threading.Event | None = None,
    ) -> SweepOutcome:
        """Plan and run one sweep on the mocks (SweepError before the start propagates)."""
        return asyncio.run(
            run_sweep(
                self.config,
                plan_sweep(self.config, request),
                out,
                pacing=SimulatedPacing(self.clock),
                progress=progress,
                abort=abort,
                emergency=emergency,
                devices=self.devices,
            )
        )


def mock_bench(*, streaming: bool = True, channels: tuple[str, ...] = CHANNELS) -> MockBench:
    config = parse_bench_config(bench_toml(streaming=streaming, channels=channels))
    return MockBench(config, MockDevices.for_bench(config))


def at(time_s: float, action: Callable[[], None]) -> Callable[[SweepProgress], None]:
    """A progress hook that runs `action` once, at the first report at or after time_s into the sweep."""
    done = threading.Event()

    def hook(progress: SweepProgress) -> None:
        if progress.phase == "sweeping" and progress.elapsed_s >= time_s and not done.is_set():
            done.set()
            action()

    return hook
