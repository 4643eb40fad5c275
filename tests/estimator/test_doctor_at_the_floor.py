"""Effects whose gap is mostly the curve's floor (issue 13, item 4): on the independent world a channel delay,
an anti-roll bar the vehicle file omits or a bump stop beside a lift-off can leave most of the gap to what a
complete model leaves too (the damper curve's discretisation), while the equations demand them. The doctor
must name them all the same (_Doctor.at_the_floor, Judging.min_gap_reduction), and not take the bar for a
stiffer spring.

Draws of benchmarks/bench_doctor_independent.py (10 s sweeps, ϑ referred to 1 ms), simulated, written and
read back as `shockbench diagnose` reads them. Hit rates are printed in the test summary; the benchmark runs
the classes over more draws (BENCHMARKS.md).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from independent_recordings import recorded

from estimator.doctor import DiagnoseOptions, DiagnosisResult, diagnose
from simulators.independent.cases import Case

SWEEP_S = 10.0
DELAY_ACCURACY = 0.05
"""The fitted delay must be within this fraction of the hidden one."""
BAR_ACCURACY = 0.1
"""The fitted bar must be within this fraction of the true one (the doctor's curve and the world's valve
damper differ; a complete model identifies stiffnesses a few per cent off)."""


def _diagnosed(label: str, seed: int, max_steps: int) -> tuple[Case, DiagnosisResult]:
    with tempfile.TemporaryDirectory(prefix="doctor-floor-") as name:
        case, _, recording, vehicle = recorded(label, seed, Path(name), SWEEP_S)
    return case, diagnose(recording, vehicle, DiagnoseOptions(max_steps=max_steps))


def _line(case: Case, result: DiagnosisResult) -> str:
    said = ", ".join(result.effects_named) or "nothing"
    return f"{case.description}: named {said}; {result.conclusion}"


def _delay_named_right(case: Case, result: DiagnosisResult) -> bool:
    """Only the delay named, on the lagging channel, within DELAY_ACCURACY, and not "unexplained"."""
    hidden = case.vehicle.effects.channel_delay_s
    step = result.steps[0] if result.steps else None
    return (
        result.effects_named == ["channel_delay"]
        and not result.unexplained
        and step is not None
        and step.parameters["channel"] in hidden
        and abs(float(step.parameters["delay_s"]) / hidden[str(step.parameters["channel"])] - 1.0)
        <= DELAY_ACCURACY
    )


def test_a_channel_delay_at_the_floor_is_named(hit_rate) -> None:
    """Draw channel_delay 1 (car, valve model, 1 ms, x_s lags 3.42 ms): the delay lowers the objective to a
    fifth but the gap by 19% only (220 -> 178 µm, a complete model leaves about 200 µm); it was "unexplained"
    before."""
    case, result = _diagnosed("channel_delay", 1, max_steps=2)
    hit = _delay_named_right(case, result)
    hit_rate("independent world: a channel delay at the floor", _line(case, result), hit)
    assert hit, _line(case, result)
    assert result.residual_ratio <= 1.0


def test_an_omitted_bar_is_named_not_a_stiffer_spring(hit_rate) -> None:
    """Draw anti_roll_bar 6 (car axle, valve dampers, 1 ms, a 12.4 kN/m bar omitted): the bar lowers the
    objective to half and the gap by 22%, to below what a complete model leaves; a spring rate 37% stiffer
    stands in for it less well (objective 0.63, gap -11%) but was the one named."""
    case, result = _diagnosed("anti_roll_bar", 6, max_steps=2)
    step = result.steps[0] if result.steps else None
    truth = case.vehicle.anti_roll_bar_N_per_m
    error = float(step.parameters["anti_roll_bar_stiffness_N_per_m"]) / truth - 1.0 if step else 1.0
    hit = result.effects_named == ["anti_roll_bar"] and not result.unexplained and abs(error) <= BAR_ACCURACY
    hit_rate("independent world: an omitted bar, not a stiffer spring", _line(case, result), hit)
    assert hit, _line(case, result)


def test_a_small_lift_off_is_named_at_the_floor_without_an_unknown(hit_rate) -> None:
    """Draw clean 89 (motorcycle, FSAE s6 table, 2 ms, 10 µm AR(1) noise): the tyre leaves the plate 2.1% of
    the time although nothing was hidden. tyre_liftoff lowers the objective by 9% (all samples and held out)
    and the gap by 20%, to below what a complete model leaves: short of the 10% a candidate must lower the
    objective by to be named at the floor, but the lift-off adds no unknown and so cannot lower it by fitting
    (DiagnoseOptions.unknown_free_objective_reduction). Before, nothing was named."""
    with tempfile.TemporaryDirectory(prefix="doctor-floor-") as name:
        case, world, recording, vehicle = recorded("clean", 89, Path(name), SWEEP_S)
    result = diagnose(recording, vehicle, DiagnoseOptions())
    scores = [c for r in result.rounds for c in r if c.effect == "tyre_liftoff"]
    hit = result.effects_named == ["tyre_liftoff"] and not result.unexplained
    line = f"{_line(case, result)} (airborne {100 * world.airborne_fraction:.1f}%)"
    hit_rate("independent world: a small lift-off at the floor", line, hit)
    assert world.airborne_fraction >= 0.01, line
    assert hit, line
    named = next(c for c in scores if c.verdict.startswith("named"))
    # strong enough without an unknown, not by the rule for candidates with one
    assert 1.0 - DiagnoseOptions().strong_objective_reduction < named.objective_ratio <= 0.96, line
    assert result.gap_after_m < result.gap_before_m, line


def test_a_delay_whose_gap_rises_a_little_at_the_floor_is_named(hit_rate) -> None:
    """Draw channel_delay 145 (motorcycle, valve model, 1 ms, the body laser lags 3.13 ms): the delay is
    found right and lowers the objective to a fifth, leaving the equations as complete as a complete
    model's, but the refitted gap is 5% above the current model's (248.9 -> 261.6 µm, a complete model
    leaves about 215 µm). With the 2% tie of the rounds it ended "unexplained"; at the floor the gap may be
    up to floor_tie_tolerance above the current one's."""
    case, result = _diagnosed("channel_delay", 145, max_steps=2)
    hit = _delay_named_right(case, result)
    hit_rate("independent world: a delay at the floor with its gap a little higher", _line(case, result), hit)
    assert hit, _line(case, result)
    options = DiagnoseOptions()
    assert 1.0 + options.tie_tolerance < result.gap_after_m / result.gap_before_m, _line(case, result)
    assert result.gap_after_m / result.gap_before_m <= 1.0 + options.floor_tie_tolerance, _line(case, result)
