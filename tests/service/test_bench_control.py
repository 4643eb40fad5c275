"""The service's bench owner (service.bench_control.BenchController) on the in-process simulated bench."""

from __future__ import annotations

import threading
from pathlib import Path

from daq.sweep.model import SweepOutcome, SweepRequest
from estimator.sweep import SweepSettings
from service.bench_control import BenchController


def test_the_bench_reads_busy_with_its_sweep_until_the_sweep_end_is_stored(tmp_path: Path) -> None:
    """A client that sees the bench free and then asks for the sweep must find its end stored (a screen
    found the sweep still "running" and showed no result): while `done` stores the end, the state reads
    busy with the sweep's id. The bench itself is free to start the next sweep by then (the scheduler,
    which `done` wakes, starts it)."""
    bench = BenchController(simulated=True)
    seen: list[tuple[bool, str | None, bool, bool]] = []

    def done(sweep_id: str, outcome: SweepOutcome | None, error: str) -> None:
        state = bench.state()
        seen.append((state.busy, state.sweep_id, bench.busy, outcome is not None and outcome.complete))

    try:
        plan = bench.plan(SweepRequest(SweepSettings(duration_s=1.0), settle_s=0.2, rest_s=0.2))
        bench.start_sweep("7", plan, tmp_path / "7.h5", done)
        (thread,) = [t for t in threading.enumerate() if t.name == "sweep 7"]
        thread.join(timeout=120)
        assert not thread.is_alive()
        after = bench.state()
    finally:
        bench.close()
    assert seen == [(True, "7", False, True)]
    assert (after.busy, after.sweep_id) == (False, None)
