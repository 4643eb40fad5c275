"""A lost laser reply does not cost the sweep (issue 30, item 8): one reply the amplifier never sends is a
marked gap in the recording, not an abort, while OMRON's wait after no reply still holds; a line that stays
dead still ends in a controlled stop, within the stated time, with a reason naming the cause.

The lasers are reached in process on the simulated clock (simulators/devices/laser_loopback.py), so reply
timeouts and the 3 s late-reply wait take simulated time, deterministically: no test waits on the wall
clock. The link keeps OMRON's 3 s wait and 2 retries; its reply timeout is 0.1 s (a wait inside a poll holds
the whole simulated bench, see that module). Time to stop is measured as in test_plate_always_stops.py;
`python -m pytest tests/daq/test_lost_laser_reply.py -s` prints the README's rows.
"""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from daq.sources.laser_source import SourceStatistics
from daq.storage.hdf5_recording import FLAG_GAP, StoredRecording, load_recording
from daq.sweep.devices import DriverDevices
from daq.sweep.model import StopKind, SweepOutcome, SweepRequest
from daq.sweep.pacing import DEFAULT_POLL_INTERVAL_S
from daq.sweep.plan import plan_sweep
from daq.sweep.run import DEFAULT_SILENCE_TIMEOUT_S, STEP_S, run_sweep
from daq.sweep.silence import NO_ERROR
from drivers.compowayf.transport import OMRON_WORST_CASE_RESPONSE_S, CompowayFPort
from drivers.compowayf.urls import parse_device_url
from estimator.sweep import SweepSettings
from service.simulated_bench import SIMULATED_BUFFER_LENGTH, SimulatedBench
from simulators.devices.laser_amplifier import AmplifierLine, FaultKind
from simulators.devices.laser_loopback import LoopbackLine
from simulators.plate import CONTROLLED_STOP_RAMP_S
from tests.daq.test_plate_always_stops import FAULT_AT_S, WatchedPacing, at_fault_time

SWEEP = SweepSettings(duration_s=8.0)
"""Long enough that the plate still sweeps when a dead line is detected (about 4 s after the fault)."""
TIMEOUT_S = 0.1
LINK_OPTIONS = f"&timeout_s={TIMEOUT_S}"
"""OMRON's 3 s late-reply wait and 2 retries stay the defaults."""
FAULTY = "x_t"
"""The wheel's laser: its reply is lost, its cable pulled."""
PERIOD_S = 0.001
RING_S = SIMULATED_BUFFER_LENGTH * PERIOD_S
"""What a simulated streaming amplifier holds: 1 s."""
DEAD_LINE_LIMIT_S = DEFAULT_SILENCE_TIMEOUT_S + OMRON_WORST_CASE_RESPONSE_S + TIMEOUT_S
"""daq/sweep/silence.py's limit for a laser whose line lost a reply: 3.6 s here (4.0 s at 0.5 s timeout)."""
DEAD_LINE_STOP_S = DEAD_LINE_LIMIT_S + STEP_S + TIMEOUT_S + CONTROLLED_STOP_RAMP_S + DEFAULT_POLL_INTERVAL_S
"""Stated time from a pulled cable to the plate at rest (4.27 s): the limit counted from the last sample
(polled at most one step before the pull), one orchestration cycle, one reply timeout inside a poll, the
controlled-stop ramp and one poll step of measurement."""


@dataclass
class CommandLog:
    """Every command a line received: (simulated time, node, answered?)."""

    entries: list[tuple[float, int, bool]] = dataclasses.field(default_factory=list)

    def watch(self, line: AmplifierLine, now_s: Callable[[], float]) -> None:
        reply_to = line.reply_to

        def logged(frame: bytes) -> tuple[bytes | None, bool]:
            reply, drop = reply_to(frame)
            self.entries.append((now_s(), int(frame[1:3]), reply is not None))
            return reply, drop

        line.reply_to = logged  # type: ignore[method-assign]


@dataclass
class Rig:
    """The bench with its lasers in process: the line behind each pyserial URL and its loopback."""

    bench: SimulatedBench
    lines: dict[str, AmplifierLine]
    loopbacks: dict[str, LoopbackLine]
    urls: dict[str, str]
    """Laser URL per channel."""
    commands: CommandLog
    ports: list[CompowayFPort] = dataclasses.field(default_factory=list)
    """Every port the sweep opened, in order."""

    def line_of(self, channel: str) -> AmplifierLine:
        return self.lines[parse_device_url(self.urls[channel]).pyserial_url]

    def node_of(self, channel: str) -> int:
        node = parse_device_url(self.urls[channel]).node
        assert node is not None
        return node

    def open_port(self, url: str) -> CompowayFPort:
        loopback = self.loopbacks[parse_device_url(url).pyserial_url]
        port = CompowayFPort(url, opener=loopback.open, clock=self.bench.clock.now_s)
        self.ports.append(port)
        return port


def make_rig(bench: SimulatedBench, *, shared: bool) -> Rig:
    """shared: every laser on one RS-485 line (nodes 1, 2, 3); else one line per laser, as the bench has."""
    urls: dict[str, str] = {}
    lines: dict[str, AmplifierLine] = {}
    for laser in bench.config.lasers:
        node = laser.device()[1]
        if shared:
            urls[laser.channel] = f"loop://?node={node}{LINK_OPTIONS}"
            lines.setdefault("loop://", AmplifierLine({})).amplifiers[node] = bench.amplifiers[laser.channel]
        else:
            urls[laser.channel] = laser.url + LINK_OPTIONS
            lines[laser.device()[0]] = bench.laser_lines[laser.channel]
    loopbacks = {url: LoopbackLine(line, bench.clock.now_s, bench.advance) for url, line in lines.items()}
    rig = Rig(bench, lines, loopbacks, urls, CommandLog())
    rig.commands.watch(rig.line_of(FAULTY), bench.clock.now_s)
    return rig


@dataclass
class Result:
    outcome: SweepOutcome
    pacing: WatchedPacing
    stored: StoredRecording
    rig: Rig

    def stats(self, channel: str) -> SourceStatistics:
        return next(s for s in self.outcome.sources if s.channel == channel)

    def gap_rows(self, channel: str) -> np.ndarray:
        return np.flatnonzero(np.isnan(self.stored.channels[channel]))

    @property
    def time_to_stop_s(self) -> float:
        assert self.pacing.stopped_at_s is not None and self.pacing.fault_at_s is not None
        return self.pacing.stopped_at_s - self.pacing.fault_at_s


def sweep_with(tmp_path: Path, fault: Callable[[Rig], None], *, shared: bool = False) -> Result:
    """A sweep on the simulated bench with its lasers in process; `fault` acts 1 s into the sweep."""
    out = tmp_path / "run.h5"
    with SimulatedBench(seed=5) as bench:
        rig = make_rig(bench, shared=shared)
        config = dataclasses.replace(
            bench.config,
            lasers=tuple(dataclasses.replace(la, url=rig.urls[la.channel]) for la in bench.config.lasers),
        )
        pacing = WatchedPacing(bench)
        outcome = asyncio.run(
            run_sweep(
                config,
                plan_sweep(config, SweepRequest(SWEEP)),
                out,
                pacing=pacing,
                progress=at_fault_time(pacing, lambda: fault(rig)),
                devices=DriverDevices(open_port=rig.open_port),
            )
        )
        pacing.run_out()
    assert pacing.fault_at_s is not None, "the fault was never injected"
    return Result(outcome, pacing, load_recording(out), rig)


def lose_one_reply(rig: Rig) -> None:
    rig.line_of(FAULTY).inject_fault(FaultKind.NO_REPLY, count=1, node=rig.node_of(FAULTY))


def runs(rows: np.ndarray) -> int:
    """Number of runs of consecutive row indices."""
    return 0 if rows.size == 0 else 1 + int(np.count_nonzero(np.diff(rows) > 1))


def the_wait_held(result: Result) -> float:
    """Checks OMRON's rule on the faulty line: after the unanswered command, nothing was sent on the line
    for late_reply_s; returns when the unanswered command was sent."""
    entries = result.rig.commands.entries
    lost = [k for k, (_, _, answered) in enumerate(entries) if not answered]
    assert lost, "no command went unanswered"
    first = lost[0]
    lost_at_s = entries[first][0]
    after = [t for t, _, _ in entries[first + 1 :]]
    assert after, "nothing was sent after the lost reply"
    assert after[0] - lost_at_s >= OMRON_WORST_CASE_RESPONSE_S - 1e-9
    return lost_at_s


def test_one_lost_reply_is_a_marked_gap_in_that_laser_only(tmp_path: Path) -> None:
    result = sweep_with(tmp_path, lose_one_reply)
    outcome = result.outcome
    assert outcome.complete and outcome.reason == "" and outcome.stop is StopKind.END_OF_SWEEP
    the_wait_held(result)
    faulty = result.stats(FAULTY)
    assert faulty.failed_reads == 1 and faulty.line_waits > 0
    assert faulty.last_error.startswith("ResponseTimeoutError: node 02 on socket://")
    assert f"no reply within {TIMEOUT_S:g} s" in faulty.last_error
    # the wait (3 s) outlasts the amplifier's ring (1 s): the samples it could not hold are lost and marked
    gap = result.gap_rows(FAULTY)
    assert runs(gap) == 1
    assert abs(gap.size - faulty.lost_samples) <= 2
    wait_s = OMRON_WORST_CASE_RESPONSE_S
    assert wait_s - RING_S - 0.05 <= faulty.lost_samples * PERIOD_S <= wait_s - RING_S + 0.1
    assert np.all(result.stored.flags[gap] & FLAG_GAP)
    assert outcome.gap_rows == gap.size
    # the other lasers, on lines of their own, keep every sample
    for channel in result.stored.channels:
        if channel != FAULTY:
            stats = result.stats(channel)
            assert result.gap_rows(channel).size == 0
            assert (stats.lost_samples, stats.failed_reads, stats.line_waits) == (0, 0, 0)
            assert stats.last_error == ""


def test_one_lost_reply_on_a_shared_line_costs_its_lasers_the_same_marked_gap(tmp_path: Path) -> None:
    """Three amplifiers on one RS-485 line: the wait after one lost reply holds back every node (nothing may
    be sent on the line), so each loses what its ring could not hold -- a gap, the sweep goes on."""
    result = sweep_with(tmp_path, lose_one_reply, shared=True)
    assert result.outcome.complete and result.outcome.reason == ""
    the_wait_held(result)
    wait_s = OMRON_WORST_CASE_RESPONSE_S
    for channel in result.stored.channels:
        stats = result.stats(channel)
        gap = result.gap_rows(channel)
        assert runs(gap) == 1 and abs(gap.size - stats.lost_samples) <= 2
        assert wait_s - RING_S - 0.05 <= stats.lost_samples * PERIOD_S <= wait_s - RING_S + 0.1
        gap_s = result.stored.time_s[gap]  # within the wait after the lost request (sent at about 1 s)
        assert gap_s[0] >= FAULT_AT_S - STEP_S and gap_s[-1] <= FAULT_AT_S + wait_s + 2 * STEP_S
        assert stats.failed_reads == (1 if channel == FAULTY else 0)
        assert stats.line_waits > 0
    assert "its line waits out a late reply after ResponseTimeoutError" in result.stats("x_s").last_error


def pull_cable(rig: Rig) -> None:
    """The line to the faulty laser's amplifier is cut: no node on it answers any more."""
    rig.line_of(FAULTY).inject_fault(FaultKind.NO_REPLY)


def test_a_pulled_cable_still_stops_the_plate_in_the_stated_time_naming_the_timeout(tmp_path: Path) -> None:
    result = sweep_with(tmp_path, pull_cable)
    outcome = result.outcome
    print(f"\n| Laser cable pulled (no node answers) | {outcome.stop} | {result.time_to_stop_s:.2f} s |")
    assert not outcome.complete and outcome.stop is StopKind.CONTROLLED
    assert outcome.reason.startswith(f"sensor silence: laser 'laser-{FAULTY}' ({FAULTY})")
    assert "ResponseTimeoutError" in outcome.reason and f"no reply within {TIMEOUT_S:g} s" in outcome.reason
    assert NO_ERROR not in outcome.reason and "\n" not in outcome.reason
    assert f"limit {DEAD_LINE_LIMIT_S:.2f} s" in outcome.reason
    assert result.time_to_stop_s <= DEAD_LINE_STOP_S
    assert result.time_to_stop_s >= DEAD_LINE_LIMIT_S  # one lost reply's allowance was given, no more
    the_wait_held(result)
    assert result.stored.metadata["status"] == "incomplete"


def test_a_pulled_cable_on_a_shared_line_names_the_timeout_for_every_laser(tmp_path: Path) -> None:
    result = sweep_with(tmp_path, pull_cable, shared=True)
    outcome = result.outcome
    assert not outcome.complete and outcome.stop is StopKind.CONTROLLED
    assert outcome.reason.startswith("sensor silence: laser")
    assert "ResponseTimeoutError" in outcome.reason and NO_ERROR not in outcome.reason
    for stats in outcome.sources:
        assert "ResponseTimeoutError" in stats.last_error
    assert result.time_to_stop_s <= DEAD_LINE_STOP_S


def test_an_unplugged_adapter_stops_the_plate_naming_the_port_error(tmp_path: Path) -> None:
    """The port itself fails (a USB adapter pulled out): no request went unanswered, so no late-reply wait
    and the plain silence limit."""

    def unplug(rig: Rig) -> None:
        rig.loopbacks[parse_device_url(rig.urls[FAULTY]).pyserial_url].unplug()

    result = sweep_with(tmp_path, unplug)
    outcome = result.outcome
    print(f"\n| Laser adapter unplugged (port error) | {outcome.stop} | {result.time_to_stop_s:.2f} s |")
    assert not outcome.complete and outcome.stop is StopKind.CONTROLLED
    assert outcome.reason.startswith(f"sensor silence: laser 'laser-{FAULTY}' ({FAULTY})")
    assert "PortLostError" in outcome.reason and "re-open failed" in outcome.reason
    assert f"limit {DEFAULT_SILENCE_TIMEOUT_S:.2f} s" in outcome.reason


@pytest.mark.parametrize(("code", "meaning"), [("0F", "command error"), ("13", "the amplifier received")])
def test_one_reply_with_an_error_end_code_is_named_and_costs_no_sample(
    tmp_path: Path, code: str, meaning: str
) -> None:
    """A reply that came (with an end code) starts no wait: the next poll reads what the failed one
    missed. 13 is retried at once (the retry succeeds), 0F is not (the poll fails)."""

    def spoil_one(rig: Rig) -> None:
        rig.line_of(FAULTY).inject_fault(FaultKind.END_CODE, code, count=1, node=rig.node_of(FAULTY))

    result = sweep_with(tmp_path, spoil_one)
    assert result.outcome.complete and result.outcome.gap_rows == 0
    stats = result.stats(FAULTY)
    assert (stats.lost_samples, stats.line_waits) == (0, 0)
    assert all(answered for _, _, answered in result.rig.commands.entries)
    failure = f"end code {code} ({meaning}"
    if code == "0F":  # refused, not retried: that poll failed, the next one read what it missed
        assert stats.failed_reads == 1 and failure in stats.last_error
    else:  # retried at once and answered: no poll failed, and the line still says what happened
        assert stats.failed_reads == 0 and stats.last_error == ""
        (port,) = [p for p in result.rig.ports if p.pyserial_url in result.rig.urls[FAULTY]]
        assert failure in port.last_failure


def test_a_dead_line_with_an_error_end_code_names_the_end_code(tmp_path: Path) -> None:
    result = sweep_with(tmp_path, lambda rig: rig.line_of(FAULTY).inject_fault(FaultKind.END_CODE, "0F"))
    assert result.outcome.stop is StopKind.CONTROLLED
    assert "CommandEndCodeError: node 02: end code 0F" in result.outcome.reason
    assert f"limit {DEFAULT_SILENCE_TIMEOUT_S:.2f} s" in result.outcome.reason
