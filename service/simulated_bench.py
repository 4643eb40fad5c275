"""A whole simulated bench served on real transports: a vehicle on the plate, one simulated ZX-L amplifier per
channel (TCP socket or pty), a Modbus or CAN plate drive, and the bench configuration that names them.

    with SimulatedBench(default_quarter_car(), exciter="modbus") as bench:   # start() on entering
        config = bench.config            # daq.bench_config.BenchConfig with the live URLs
        bench.advance(0.01)              # manual clock: move time, tick the exciter, sample the lasers

Time: by default the bench runs on a manual SimulatedClock that only `advance(dt_s)` moves, so a test (or
`shockbench sweep --simulated`) is deterministic. With `realtime=True` the clock follows the wall clock
and a background task calls `tick()` every `tick_period_s`: the drive's cyclic checks (watchdog), the CAN
heartbeat, and the vehicle integration kept up to date (VehicleOnPlate integrates lazily up to the present
on each read; ticking spreads that work instead of doing all of it on the first read after a long idle).

Threads: the Modbus server and the real-time ticker live on an asyncio loop in a thread of their own, so
start()/close() are plain calls usable from synchronous code and from inside another event loop; the
amplifier servers and the CAN drive have their own threads.

CAN: python-can's 'virtual' interface only connects buses of one process. For a client in another process
serve the drive on a real bus: can_interface="socketcan", can_channel="vcan0" (a Linux vcan interface).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import uuid
from collections.abc import Coroutine
from concurrent.futures import Future
from typing import Any, Literal, Self

import numpy as np

from daq.bench_config import BenchConfig, ExciterConfig, LaserConfig
from drivers.compowayf.layout import AmplifierConfig, streaming_measured_config
from drivers.exciter.envelope import EnvelopeLimits
from simulators.coupling import SimulatedClock
from simulators.devices.can_exciter import SimulatedCanExciter
from simulators.devices.exciter import SimulatedExciter
from simulators.devices.laser_amplifier import (
    AmplifierLine,
    PtyAmplifierServer,
    SimulatedAmplifier,
    TcpAmplifierServer,
)
from simulators.devices.modbus_exciter import SimulatedModbusExciter
from simulators.devices.sensor_heads import ZX_LD40, ZX_LD100, HeadModel
from simulators.vehicle_on_plate import VehicleOnPlate
from simulators.vehicle_sim import SimulatedVehicle, default_axle, default_quarter_car

log = logging.getLogger(__name__)

ExciterKind = Literal["modbus", "can"]
LaserTransport = Literal["tcp", "pty", "mixed"]

VEHICLE_PRESETS = {"quarter-car": default_quarter_car, "axle": default_axle}
"""Vehicles `shockbench sim-devices --vehicle-preset` offers."""

HEAD_MODELS: dict[str, HeadModel] = {head.name: head for head in (ZX_LD40, ZX_LD100)}
"""Simulated heads by catalogue name (the names a bench configuration may give)."""

DEFAULT_TICK_PERIOD_S = 0.01
BENCH_STEP_S = 0.001
"""Integration step of the vehicle on a served bench: twice VehicleOnPlate's default (positions a few
micrometres off it during a 20 Hz sweep) for about half the CPU, so that the simulation keeps up with real
time on a loaded machine (one that falls behind makes every read wait for it) and a manual-clock sweep runs
about as fast as real time."""
START_TIMEOUT_S = 10.0
CLOSE_STEP_TIMEOUT_S = 3.0
"""Longest wait for the Modbus server's close, then for the loop's cancelled tasks, when the bench closes."""
SIMULATED_BUFFER_LENGTH = 1000
"""Samples a simulated streaming amplifier keeps (1 s at 1 kHz). A real amplifier samples in hardware
whatever the host does; a simulated one samples only when its process gets the CPU, so it is given the
longest buffer a bench configuration allows, for the moments a loaded machine starves the simulator."""


def head_for_channel(channel: str) -> HeadModel:
    """The head a simulated bench puts on a channel: ZX-LD100 (+-40 mm) on the body, which moves most,
    ZX-LD40 (+-10 mm, finer resolution) on wheels and plates (within +-10 mm for a 4 mm sweep)."""
    return ZX_LD100 if channel.startswith("x_s") else ZX_LD40


def vehicle_preset(name: str) -> SimulatedVehicle:
    try:
        return VEHICLE_PRESETS[name]()
    except KeyError:
        raise ValueError(
            f"unknown vehicle preset {name!r}; expected one of {list(VEHICLE_PRESETS)}"
        ) from None


class SimulatedBench:
    """Every simulated device of a bench, started together; `config` says where each one is. Exists so that
    sim-devices, `sweep --simulated`, `serve --simulated` and the tests start the same bench one way.

    vehicle: what stands on the plate (default: the default quarter car).
    exciter: "modbus" (Modbus TCP on 127.0.0.1) or "can" (python-can bus `can_interface`/`can_channel`,
        by default a 'virtual' channel of its own).
    lasers: amplifier transports: "tcp" (socket://127.0.0.1:PORT), "pty" (/dev/pts/N) or "mixed"
        (alternately). One server, hence one port, per amplifier; node numbers 1, 2, ... in channel order.
    seed: seeds the laser noise (one independent stream per laser); noise_sigma_m overrides the heads'
        noise (0 for exact readings).
    step_s: the vehicle's integration step (default BENCH_STEP_S).
    laser_sample_period_s: the amplifiers sample on their own clock at this period into a buffer with a
        sample counter (drivers.compowayf.amplifier.streaming_measured_config); None: they hold only the
        value at the moment of a read (sampled on read, as a polled amplifier).
    """

    def __init__(
        self,
        vehicle: SimulatedVehicle | None = None,
        *,
        realtime: bool = False,
        exciter: ExciterKind = "modbus",
        lasers: LaserTransport = "tcp",
        seed: int = 0,
        noise_sigma_m: float | None = None,
        name: str = "simulated bench",
        envelope: EnvelopeLimits | None = None,
        can_interface: str = "virtual",
        can_channel: str | None = None,
        tick_period_s: float = DEFAULT_TICK_PERIOD_S,
        step_s: float | None = None,
        laser_sample_period_s: float | None = 0.001,
    ) -> None:
        if exciter not in ("modbus", "can"):
            raise ValueError(f"exciter must be 'modbus' or 'can', got {exciter!r}")
        if lasers not in ("tcp", "pty", "mixed"):
            raise ValueError(f"lasers must be 'tcp', 'pty' or 'mixed', got {lasers!r}")
        self.vehicle = vehicle or default_quarter_car()
        self.realtime = realtime
        self.clock = SimulatedClock(follow_wall_clock=realtime)
        self.physics = VehicleOnPlate(self.vehicle, self.clock, step_s=step_s or BENCH_STEP_S)
        self.exciter_kind: ExciterKind = exciter
        self.laser_transport: LaserTransport = lasers
        self.seed = seed
        self.noise_sigma_m = noise_sigma_m
        self.name = name
        self.envelope = envelope
        self.can_interface = can_interface
        self.can_channel = can_channel or f"shockbench-sim-{uuid.uuid4().hex[:12]}"
        self.tick_period_s = tick_period_s
        self.laser_sample_period_s = laser_sample_period_s
        self.amplifiers: dict[str, SimulatedAmplifier] = {}
        """Simulated amplifier per channel."""
        self.laser_lines: dict[str, AmplifierLine] = {}
        """The server carrying each channel's amplifier (inject_fault / clear_faults there)."""
        self.modbus: SimulatedModbusExciter | None = None
        self.can: SimulatedCanExciter | None = None
        self._config: BenchConfig | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._loop_thread: threading.Thread | None = None
        self._ticker: Future[None] | None = None
        self._servers: list[TcpAmplifierServer | PtyAmplifierServer] = []

    # ---- lifecycle ----------------------------------------------------------------------------------

    def start(self) -> BenchConfig:
        """Start every device and return the bench configuration naming them. On failure, whatever was
        started is closed again."""
        if self._config is not None:
            return self._config
        try:
            self._start_loop()
            lasers = self._start_lasers()
            exciter = self._start_exciter()
            self._config = BenchConfig(
                self.name, self.vehicle.known.model, exciter, tuple(lasers), self.envelope
            )
            if self.realtime:
                self._ticker = self._submit(self._tick_forever())
        except BaseException:
            self.close()
            raise
        return self._config

    def close(self) -> None:
        """Stop every device (idempotent)."""
        if self._ticker is not None:
            self._ticker.cancel()
            self._ticker = None
        if self._loop is not None:
            with contextlib.suppress(Exception):
                self._submit(self._close_in_loop()).result(START_TIMEOUT_S)
        self.modbus = None
        if self.can is not None:
            self.can.close()
            self.can = None
        for server in self._servers:
            server.stop()
        self._servers.clear()
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._loop.stop)
            assert self._loop_thread is not None
            self._loop_thread.join(START_TIMEOUT_S)
            if self._loop_thread.is_alive():
                # a callback that never returns holds the loop: it cannot be closed, and its daemon thread
                # ends with the process; every server on it was stopped above
                log.warning("simulated bench: its event loop did not stop within %.0f s", START_TIMEOUT_S)
            else:
                self._loop.close()
            self._loop = self._loop_thread = None
        self._config = None

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def config(self) -> BenchConfig:
        if self._config is None:
            raise RuntimeError("simulated bench not started")
        return self._config

    @property
    def exciter(self) -> SimulatedExciter:
        """The simulated exciter behind whichever protocol (inject_fault, watchdog state...)."""
        sim = self.modbus or self.can
        if sim is None:
            raise RuntimeError("simulated bench not started")
        return sim.exciter

    # ---- time ---------------------------------------------------------------------------------------

    def tick(self) -> None:
        """The drive's cyclic checks and due CAN heartbeats at the current time; integrates the vehicle
        up to now."""
        if self.modbus is not None:
            self.modbus.tick()
        if self.can is not None:
            self.can.tick()
        self.physics.plate_status()

    def advance(self, dt_s: float) -> None:
        """Manual clock only: move time by dt_s, tick, and let every amplifier take a sample (so buffered
        amplifiers hold one sample per advance)."""
        self.clock.advance(dt_s)
        self.tick()
        for line in self.laser_lines.values():
            line.sample_all()

    async def _tick_forever(self) -> None:
        failing = False
        while True:
            try:
                self.tick()
                failing = False
            except Exception:  # keep serving; say so once per run of failures
                if not failing:
                    log.exception("simulated bench tick failed")
                failing = True
            await asyncio.sleep(self.tick_period_s)

    # ---- assembly -----------------------------------------------------------------------------------

    async def _close_in_loop(self) -> None:
        """Close the Modbus server, then end every task left on the loop (ticker, connections)."""
        if self.modbus is not None:
            # pymodbus's close can wait on a connection it is still trying to repeat; the tasks are
            # cancelled below in any case
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.modbus.close(), CLOSE_STEP_TIMEOUT_S)
        tasks = [task for task in asyncio.all_tasks() if task is not asyncio.current_task()]
        for task in tasks:
            task.cancel()
        if tasks:
            await asyncio.wait(tasks, timeout=CLOSE_STEP_TIMEOUT_S)

    def _start_loop(self) -> None:
        self._loop = asyncio.new_event_loop()
        self._loop_thread = threading.Thread(
            target=self._loop.run_forever, name="simulated-bench loop", daemon=True
        )
        self._loop_thread.start()

    def _submit(self, coroutine: Coroutine[Any, Any, Any]) -> Future[Any]:
        assert self._loop is not None
        return asyncio.run_coroutine_threadsafe(coroutine, self._loop)

    def _start_lasers(self) -> list[LaserConfig]:
        channels = self.physics.channels
        seeds = np.random.SeedSequence(self.seed).generate_state(len(channels))
        lasers = []
        for index, channel in enumerate(channels):
            head = head_for_channel(channel)
            amplifier = SimulatedAmplifier.for_channel(
                self.physics,
                channel,
                head,
                config=self._amplifier_config(),
                seed=int(seeds[index]),
                noise_sigma_m=self.noise_sigma_m,
                origin_s=self.physics.time_origin_s,  # samples on the integration grid: exact states
            )
            node = index + 1
            use_pty = self.laser_transport == "pty" or (self.laser_transport == "mixed" and index % 2 == 1)
            server = (
                PtyAmplifierServer({node: amplifier}) if use_pty else TcpAmplifierServer({node: amplifier})
            )
            self._servers.append(server)
            server.start()
            self.amplifiers[channel] = amplifier
            self.laser_lines[channel] = server
            lasers.append(
                LaserConfig(
                    f"laser-{channel}",
                    server.device_url(node),
                    channel,
                    head.name,
                    sign=amplifier.head.sign,
                    zero_m=amplifier.head.static_offset_m,
                    sample_period_s=self.laser_sample_period_s,
                    buffer_length=amplifier.config.measured.buffer_length,
                )
            )
        return lasers

    def _amplifier_config(self) -> AmplifierConfig:
        if self.laser_sample_period_s is None:
            return AmplifierConfig()
        return AmplifierConfig(
            measured=streaming_measured_config(self.laser_sample_period_s, SIMULATED_BUFFER_LENGTH)
        )

    def _start_exciter(self) -> ExciterConfig:
        if self.exciter_kind == "modbus":
            self.modbus = self._submit(self._start_modbus()).result(START_TIMEOUT_S)
            return ExciterConfig("plate-exciter", self.modbus.url)
        self.can = SimulatedCanExciter(self.physics, channel=self.can_channel, interface=self.can_interface)
        self.can.start()
        self.can.tick()  # the first heartbeat, at once
        return ExciterConfig("plate-exciter", f"can://{self.can_interface}/{self.can_channel}")

    async def _start_modbus(self) -> SimulatedModbusExciter:
        sim = SimulatedModbusExciter(self.physics)
        await sim.start()
        return sim
