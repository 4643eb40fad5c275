"""Shared test fixtures: simulated recordings (made once per session) and the hit-rate report."""

from __future__ import annotations

from collections import defaultdict

import pytest

# One BLAS thread, as every `shockbench` process has it: importing the CLI package sets it before numpy is
# first imported (service/cli/__init__.py says why); tests that run a service worker or simulated devices
# beside the estimator would otherwise oversubscribe the 2 cores.
import service.cli  # noqa: F401

HIT_RATES: dict[str, list[tuple[str, bool]]] = defaultdict(list)


def report_case(experiment: str, case: str, hit: bool) -> None:
    """Record one randomly drawn case of an accuracy experiment; the summary prints the hit rate."""
    HIT_RATES[experiment].append((case, hit))


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    if not HIT_RATES:
        return
    terminalreporter.section("accuracy experiments (random cases, fixed seeds)")
    for experiment, cases in HIT_RATES.items():
        hits = sum(hit for _, hit in cases)
        terminalreporter.write_line(f"{experiment}: {hits}/{len(cases)} hit")
        for case, hit in cases:
            terminalreporter.write_line(f"    {'hit ' if hit else 'MISS'} {case}")


@pytest.fixture
def hit_rate():
    """report(experiment, case, hit): record a random case of an accuracy experiment for the summary."""
    return report_case
