"""Must show (issue 6, the model doctor), on simulated sweeps in which an effect is hidden:

- an effect of the catalog, chosen at random at a random but physically plausible size (the test tells
  diagnose nothing but the recording, the vehicle file and the starting tyre model): diagnose names exactly
  that effect and the gap at least halves; the hit rate over the seeds is printed in the test summary;
- nothing hidden: it names nothing;
- an effect outside the catalog (a sensor's gain error, an engine resonating on its mounts): it says
  "unexplained" and names nothing.

The vehicles are the random quarter cars and axles of cases.py (real SUV damper table, 5 µm laser noise),
on 8 s sweeps 0-20 Hz (the doctor runs every candidate, so the sweeps are shorter than identify's tests').
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, replace
from functools import cache

import numpy as np
import pytest
from cases import random_axle, random_quarter_car

from estimator.doctor.catalog import CATALOG, EffectName
from estimator.doctor.diagnose import DiagnoseOptions, DiagnosisResult, diagnose
from estimator.doctor.residuals import effective_samples, ljung_box, sweep_frequency_Hz
from estimator.sweep import SweepSettings
from estimator.vehicle import TyreModel, VehicleParameters
from simulators.vehicle_sim import (
    SimulatedVehicle,
    SimulationResult,
    SimulationSettings,
    simulate,
    with_effects,
)

SWEEP_S = 8.0
CATALOG_NAMES = [
    name.value for name in EffectName if name not in (EffectName.SPRING_STIFFNESS, EffectName.TYRE_STIFFNESS)
]
"""The effects drawn here; a wrong stated stiffness is drawn in test_doctor_effects.py."""
HIDDEN_SEEDS = range(12)
"""The first eight draws cover the catalog once in a random order, the rest are drawn at random."""
ORDER_SEED = 6
CLEAN_SEEDS = range(100, 103)
"""One per starting tyre model: spring, Kelvin-Voigt, Maxwell."""
OUTSIDE_SEEDS = range(200, 204)
HIT_RATE_REQUIRED = 0.8
MIN_AIRBORNE_FRACTION = 0.005
TYRES = (TyreModel.SPRING, TyreModel.KELVIN_VOIGT, TyreModel.MAXWELL)


@dataclass(frozen=True)
class DoctorCase:
    """A simulated vehicle with something hidden; `known` is the vehicle file and `tyre` the starting tyre
    model diagnose is given, `hidden` what the test expects (a catalog name, "outside" or None)."""

    name: str
    hidden: str | None
    vehicle: SimulatedVehicle
    known: VehicleParameters
    tyre: TyreModel
    truth: dict[str, float]
    """The hidden effect's size by the name diagnose reports it under."""


def _base(rng: np.random.Generator, seed: int, axle: bool, tyres: tuple[TyreModel, ...]) -> tuple:
    """A random vehicle of cases.py with a random tyre; the starting model gets the same tyre model."""
    vehicle = random_axle(seed) if axle else random_quarter_car(seed)
    tyre = tyres[int(rng.integers(len(tyres)))]
    dashpot, maxwell = rng.uniform(150.0, 400.0), rng.uniform(800.0, 2000.0)
    return vehicle, tyre, dashpot, maxwell


def _with_tyre(
    vehicle: SimulatedVehicle, tyre: TyreModel, dashpot: float, maxwell: float
) -> SimulatedVehicle:
    damping = {TyreModel.SPRING: 0.0, TyreModel.KELVIN_VOIGT: dashpot, TyreModel.MAXWELL: maxwell}[tyre]
    return replace(vehicle, tyre_model=tyre, tyre_damping_Ns_per_m=damping)


def draw_hidden(seed: int, effect: str | None = None) -> DoctorCase:
    """The catalog effect of draw `seed` (or the one named), at a random plausible size, on a random
    vehicle whose starting model lacks it."""
    rng = np.random.default_rng(seed)
    if effect is None:
        order = np.random.default_rng(ORDER_SEED).permutation(CATALOG_NAMES)
        effect = str(order[seed]) if seed < len(order) else str(rng.choice(CATALOG_NAMES))
    lacking = {
        "tyre_damping": (TyreModel.SPRING, TyreModel.MAXWELL),
        "tyre_viscoelastic": (TyreModel.SPRING, TyreModel.KELVIN_VOIGT),
    }.get(effect, TYRES)
    vehicle, tyre, dashpot, maxwell = _base(rng, 1000 + seed, effect == "anti_roll_bar", lacking)
    vehicle = _with_tyre(vehicle, tyre, dashpot, maxwell)
    known = vehicle.known
    truth: dict[str, float] = {}
    if (
        effect == "tyre_damping"
    ):  # a dashpot the starting tyre lacks: Kelvin-Voigt, or beside a Maxwell element
        if tyre is TyreModel.SPRING:
            vehicle = _with_tyre(vehicle, TyreModel.KELVIN_VOIGT, dashpot, maxwell)
        else:
            vehicle = with_effects(vehicle, tyre_dashpot_Ns_per_m=dashpot)
        truth, size = {"tyre_dashpot_Ns_per_m": dashpot}, f"dashpot {dashpot:.0f} N·s/m"
    elif effect == "tyre_viscoelastic":  # a Maxwell element the starting tyre lacks
        vehicle = _with_tyre(vehicle, TyreModel.MAXWELL, dashpot, maxwell)
        if tyre is TyreModel.KELVIN_VOIGT:
            vehicle = with_effects(vehicle, tyre_dashpot_Ns_per_m=dashpot)
        truth, size = {"tyre_damping_Ns_per_m": maxwell}, f"Maxwell element C_d {maxwell:.0f} N·s/m"
    elif effect == "coulomb_friction":  # strut and seal friction
        force = rng.uniform(120.0, 300.0)
        vehicle = with_effects(vehicle, coulomb_friction_N=force)
        truth, size = {"coulomb_friction_N": force}, f"{force:.0f} N"
    elif effect == "progressive_spring":  # resting on a helper spring / bump stop
        k3 = rng.uniform(1e8, 2.5e8)
        vehicle = with_effects(vehicle, cubic_spring_N_per_m3=k3)
        truth, size = {"cubic_spring_N_per_m3": k3}, f"k3 {k3:.3g} N/m³"
    elif effect == "tyre_liftoff":  # a worn-out damper lets the wheel hop off the plate
        scale = rng.uniform(0.06, 0.12)
        damper = vehicle.dampers[0]
        vehicle = with_effects(
            replace(vehicle, dampers=(replace(damper, force_N=damper.force_N * scale),)), tyre_liftoff=True
        )
        size = f"damper worn to {100 * scale:.0f}%"
    elif effect == "anti_roll_bar":  # an axle whose vehicle file forgets the bar
        known = replace(known, anti_roll_bar_stiffness_N_per_m=0.0)
        truth = {"anti_roll_bar_stiffness_N_per_m": vehicle.known.anti_roll_bar_stiffness_N_per_m}
        size = f"bar {truth['anti_roll_bar_stiffness_N_per_m']:.0f} N/m"
    elif effect == "channel_delay":  # a laser amplifier with a slower response setting
        channel, delay = str(rng.choice(["x_s", "x_t", "x_r"])), rng.uniform(0.002, 0.005)
        vehicle = with_effects(vehicle, channel_delay_s={channel: delay})
        truth, size = {"delay_s": delay}, f"{channel} lags {1e3 * delay:.2f} ms"
    elif effect == "sensor_offset":  # a laser zeroed with the wrong load (a body channel's offset is
        # unobservable: the damper curve absorbs it, see the catalog)
        channel = str(rng.choice(["x_t", "x_r"]))
        offset = rng.uniform(0.0002, 0.001) * rng.choice([-1.0, 1.0])
        vehicle = with_effects(vehicle, sensor_offset_m={channel: offset})
        truth, size = {"offset_m": offset}, f"{channel} off by {1e3 * offset:+.2f} mm"
    else:
        raise ValueError(effect)
    return DoctorCase(
        f"seed {seed}: {effect}, {size}, start {tyre.value}", effect, vehicle, known, tyre, truth
    )


SECOND_EFFECTS = ("coulomb_friction", "progressive_spring", "channel_delay", "sensor_offset")
PAIR_SEEDS = range(20, 22)


def draw_pair(seed: int) -> DoctorCase:
    """Two different effects hidden at once: the first of any kind that combines (not lift-off, not the
    axle's bar), the second a suspension or sensor effect, each at a random plausible size."""
    rng = np.random.default_rng(seed)
    first = str(rng.choice(["tyre_damping", "tyre_viscoelastic", *SECOND_EFFECTS]))
    second = str(rng.choice([e for e in SECOND_EFFECTS if e != first]))
    case = draw_hidden(seed, first)
    other_case = draw_hidden(seed + 1, second)
    other = other_case.vehicle.effects
    extra = {
        "coulomb_friction": {"coulomb_friction_N": other.coulomb_friction_N},
        "progressive_spring": {"cubic_spring_N_per_m3": other.cubic_spring_N_per_m3},
        "channel_delay": {"channel_delay_s": other.channel_delay_s},
        "sensor_offset": {"sensor_offset_m": other.sensor_offset_m},
    }[second]
    name = f"{case.name} + {second}, {other_case.name.split(', ')[1]}"
    return replace(case, name=name, hidden=f"{first}+{second}", vehicle=with_effects(case.vehicle, **extra))


def draw_clean(seed: int) -> DoctorCase:
    rng = np.random.default_rng(seed)
    vehicle, _, dashpot, maxwell = _base(rng, 1000 + seed, False, TYRES)
    vehicle = _with_tyre(vehicle, TYRES[seed % 3], dashpot, maxwell)
    return DoctorCase(
        f"seed {seed}: nothing hidden, {vehicle.tyre_model.value} tyre",
        None,
        vehicle,
        vehicle.known,
        vehicle.tyre_model,
        {},
    )


def draw_outside(seed: int) -> DoctorCase:
    """An effect the catalog does not have: a laser's gain error (4-8%) or an engine of 20-35 kg resonating
    at 9-13 Hz on its mounts."""
    rng = np.random.default_rng(seed)
    vehicle, tyre, dashpot, maxwell = _base(rng, 1000 + seed, False, TYRES)
    vehicle = _with_tyre(vehicle, tyre, dashpot, maxwell)
    if seed % 2 == 0:
        channel, gain = str(rng.choice(["x_s", "x_t", "x_r"])), rng.uniform(1.04, 1.08)
        vehicle, what = with_effects(vehicle, sensor_gain={channel: gain}), f"{channel} reads {gain:.3f}x"
    else:
        mass, frequency = rng.uniform(20.0, 35.0), rng.uniform(9.0, 13.0)
        vehicle = with_effects(
            vehicle, body_mode_mass_kg=mass, body_mode_frequency_Hz=frequency, body_mode_damping_ratio=0.1
        )
        what = f"{mass:.0f} kg engine on mounts at {frequency:.1f} Hz"
    return DoctorCase(
        f"seed {seed}: outside the catalog, {what}, start {tyre.value}",
        "outside",
        vehicle,
        vehicle.known,
        tyre,
        {},
    )


def _simulate(vehicle: SimulatedVehicle, seed: int) -> SimulationResult:
    settings = SimulationSettings(sweep=SweepSettings(duration_s=SWEEP_S), seed=seed, substeps=2)
    return simulate(vehicle, settings)


def airborne_fraction(case: DoctorCase, result: SimulationResult) -> float:
    load = case.known.static_wheel_load_N
    forces = np.concatenate(list(result.truth_contact_force_N.values()))
    return float(np.mean(forces <= -load * (1.0 - 1e-9)))


@cache
def hidden(seed: int, effect: str | None = None) -> tuple[DoctorCase, SimulationResult]:
    case = draw_hidden(seed, effect)
    result = _simulate(case.vehicle, seed)
    if case.hidden == "tyre_liftoff":
        for _ in range(3):  # wear the damper further until the wheel does leave the plate
            if airborne_fraction(case, result) >= MIN_AIRBORNE_FRACTION:
                break
            damper = case.vehicle.dampers[0]
            vehicle = replace(case.vehicle, dampers=(replace(damper, force_N=damper.force_N * 0.7),))
            case = replace(case, vehicle=vehicle, name=case.name + ", worn further")
            result = _simulate(vehicle, seed)
    return case, result


@cache
def clean_simulation(seed: int) -> SimulationResult:
    return _simulate(draw_clean(seed).vehicle, seed)


@cache
def diagnosed(kind: str, seed: int) -> tuple[DoctorCase, DiagnosisResult]:
    if kind == "hidden":
        case, simulation = hidden(seed)
    elif kind == "pair":
        case = draw_pair(seed)
        simulation = _simulate(case.vehicle, seed)
    elif kind == "clean":
        case, simulation = draw_clean(seed), clean_simulation(seed)
    else:
        case = draw_outside(seed)
        simulation = _simulate(case.vehicle, seed)
    return case, diagnose(simulation.recording, case.known, DiagnoseOptions(tyre=case.tyre))


def _gaps(result: DiagnosisResult) -> str:
    return (
        f"gap {result.gap_before_m * 1e6:.1f} -> {result.gap_after_m * 1e6:.1f} µm "
        f"(expected of a complete model {result.expected_gap_m * 1e6:.1f} µm)"
    )


def _parameter_error(case: DoctorCase, result: DiagnosisResult) -> str:
    if not result.steps:
        return ""
    fitted = result.steps[0].parameters
    errors = [
        f"{name} {fitted[name]:.4g} (true {true:.4g})" for name, true in case.truth.items() if name in fitted
    ]
    return "; fitted " + ", ".join(errors) if errors else ""


def test_the_catalog_has_the_issue_s_stable_names() -> None:
    assert {name.value for name in EffectName} == {
        "spring_stiffness",
        "tyre_stiffness",
        "tyre_damping",
        "tyre_viscoelastic",
        "coulomb_friction",
        "tyre_liftoff",
        "progressive_spring",
        "anti_roll_bar",
        "channel_delay",
        "sensor_offset",
    }
    assert all(CATALOG[name].summary and CATALOG[name].signature for name in EffectName)


def test_the_draws_cover_the_catalog_and_hide_what_they_say() -> None:
    assert {draw_hidden(seed).hidden for seed in HIDDEN_SEEDS} == set(CATALOG_NAMES)
    for seed in HIDDEN_SEEDS:
        case = draw_hidden(seed)
        assert case.known.is_axle == (case.hidden == "anti_roll_bar")
        assert case.known.anti_roll_bar_stiffness_N_per_m == 0.0 or case.hidden != "anti_roll_bar"
        if case.hidden == "tyre_liftoff":
            assert airborne_fraction(*hidden(seed)) >= MIN_AIRBORNE_FRACTION, case.name


def test_names_the_hidden_effect_and_the_gap_at_least_halves(hit_rate) -> None:
    hits = []
    for seed in HIDDEN_SEEDS:
        case, result = diagnosed("hidden", seed)
        named = result.effects_named
        halved = result.gap_after_m <= 0.5 * result.gap_before_m
        hit = named == [case.hidden] and halved
        hits.append(hit)
        hit_rate(
            "hidden catalog effect: named exactly, gap at least halved",
            f"{case.name}: named {named or 'nothing'}, {_gaps(result)}{_parameter_error(case, result)}",
            hit,
        )
    assert np.mean(hits) >= HIT_RATE_REQUIRED, f"{sum(hits)}/{len(hits)} hidden effects found"


def test_two_hidden_effects_are_both_named(hit_rate) -> None:
    for seed in PAIR_SEEDS:
        case, result = diagnosed("pair", seed)
        expected = set(str(case.hidden).split("+"))
        hit = set(result.effects_named) == expected and len(result.effects_named) == 2
        hit_rate(
            "two hidden effects: both named, nothing else",
            f"{case.name}: named {result.effects_named or 'nothing'}, {_gaps(result)}",
            hit,
        )
        assert hit, result.conclusion
        assert result.gap_after_m <= 0.5 * result.gap_before_m
        assert [s.gap_after_m for s in result.steps] == sorted(
            (s.gap_after_m for s in result.steps), reverse=True
        )


def test_names_nothing_when_nothing_is_hidden(hit_rate) -> None:
    for seed in CLEAN_SEEDS:
        case, result = diagnosed("clean", seed)
        hit = not result.effects_named and not result.unexplained
        hit_rate(
            "nothing hidden: names nothing, nothing unexplained",
            f"{case.name}: named {result.effects_named or 'nothing'}, unexplained {result.unexplained}, "
            f"{_gaps(result)}",
            hit,
        )
        assert result.effects_named == [], case.name
        assert not result.unexplained, result.conclusion


def test_says_unexplained_for_an_effect_outside_the_catalog(hit_rate) -> None:
    for seed in OUTSIDE_SEEDS:
        case, result = diagnosed("outside", seed)
        hit = result.unexplained and not result.effects_named
        hit_rate(
            "effect outside the catalog: unexplained, nothing named",
            f"{case.name}: named {result.effects_named or 'nothing'}, unexplained {result.unexplained}, "
            f"{_gaps(result)}",
            hit,
        )
        assert result.unexplained, result.conclusion
        assert result.effects_named == [], result.conclusion
        assert result.conclusion.startswith("unexplained")


def test_the_steps_carry_evidence_parameters_and_the_json_shape() -> None:
    _, result = diagnosed("hidden", HIDDEN_SEEDS[0])
    out = result.to_json()
    assert {"gap_before_m", "steps", "gap_after_m", "unexplained"} <= set(out)
    assert isinstance(out["unexplained"], bool) and isinstance(out["gap_before_m"], float)
    for step in out["steps"]:
        assert set(step) == {"effect", "gap_before_m", "gap_after_m", "parameters", "evidence"}
        assert step["effect"] in CATALOG_NAMES and step["gap_after_m"] < step["gap_before_m"]
        assert "the residual of the" in step["evidence"] and "gap falls from" in step["evidence"]
    assert out["steps"][-1]["gap_after_m"] == out["gap_after_m"]
    rounds = out["candidates"]
    assert len(rounds) == len(out["steps"]) + 1
    assert all(c["verdict"] for round_ in rounds for c in round_)


def test_progress_is_reported_and_a_diagnosis_can_be_cancelled() -> None:
    case = draw_clean(CLEAN_SEEDS[0])
    recording = clean_simulation(CLEAN_SEEDS[0]).recording
    stages = []
    cancel = threading.Event()

    def progress(p) -> None:
        stages.append(p.stage)
        if len(stages) == 2:
            cancel.set()

    with pytest.raises(InterruptedError):
        diagnose(recording, case.known, DiagnoseOptions(tyre=case.tyre), progress=progress, cancel=cancel)
    assert stages[0] == "identifying the starting model" and len(stages) == 2


def test_a_vehicle_file_of_the_wrong_kind_is_an_error() -> None:
    recording = clean_simulation(CLEAN_SEEDS[0]).recording
    axle = random_axle(1).known
    with pytest.raises(ValueError, match="axle"):
        diagnose(recording, axle)


def test_locate_tools_whiteness_effective_samples_and_sweep_frequency() -> None:
    rng = np.random.default_rng(0)
    noise = rng.normal(size=20_000)
    t = np.arange(20_000) * 0.001
    assert ljung_box(noise, 0.001, 50.0).white
    assert not ljung_box(np.sin(2 * np.pi * 3.0 * t) + 0.1 * noise, 0.001, 50.0).white
    assert 0.8 * noise.size < effective_samples(noise) < 1.2 * noise.size
    smooth = np.convolve(noise, np.ones(50) / 50, mode="same")
    assert effective_samples(smooth) < 0.1 * noise.size
    chirp = 0.004 * np.sin(2 * np.pi * (0.5 * 20.0 / 20.0 * t**2))  # 0 -> 20 Hz in 20 s
    found = sweep_frequency_Hz(chirp, 0.001)
    inside = (t > 2.0) & (t < 18.0)
    assert np.max(np.abs(found[inside] - t[inside])) < 0.5
