"""The `model` of diagnose --json carries the effects identify's form has no key for, and validate simulates
them (estimator.doctor.result.model_json -> estimator.model_io -> estimator.validation).

A car corner with strut friction and a lagging wheel laser (recording A, seed 1) is fitted with the
doctor's families of those effects (low_speed_friction, sensor_dynamics of x_t with a first-order
lag); the model goes through its JSON form and is validated on another sweep of
the same car (recording B, seed 2). With its effects the model explains B to a small share of its motion;
the same JSON without them (what the model would be if validate dropped them) leaves a clearly larger gap;
and on A itself validate's gap agrees with the doctor's own output error of the fitted model."""

from __future__ import annotations

import json
import threading
import warnings
from dataclasses import fields, replace

import numpy as np
import pytest

from estimator.damper import CurveBatch, PiecewiseLinearCurve
from estimator.doctor.catalog import FRICTION_UNKNOWNS, EffectInstance, EffectName
from estimator.doctor.fitting import fit
from estimator.doctor.model import FitSettings, Reference, starting_structure
from estimator.doctor.result import model_json
from estimator.doctor.simulation import (
    RUNAWAY_GAP_RATIO,
    BatchOutputError,
    _corner,
    diverged,
    simulate_models,
    substeps,
)
from estimator.model_io import ModelFormatError, model_from_json
from estimator.output_error import IdentifiedModel
from estimator.runge_kutta_steps import MAX_SUBSTEPS
from estimator.sweep import SweepSettings
from estimator.validation import refined_on, validate
from estimator.vehicle import TyreModel
from simulators.vehicle_sim import SimulationSettings, default_quarter_car, simulate, with_effects

FRICTION_N = 120.0
DELAY_S = 0.003
SAME_CAR_MAX_RATIO = 0.05
"""gap_ratio of the model with its effects on another sweep of the same car."""


@pytest.fixture(scope="module")
def fitted():
    car = with_effects(default_quarter_car(), coulomb_friction_N=FRICTION_N, channel_delay_s={"x_t": DELAY_S})
    a = simulate(car, SimulationSettings(sweep=SweepSettings(duration_s=8.0), seed=1)).recording
    b = simulate(car, SimulationSettings(sweep=SweepSettings(duration_s=10.0), seed=2)).recording
    structure = (
        starting_structure(TyreModel.MAXWELL)
        .with_effect(EffectInstance(EffectName.LOW_SPEED_FRICTION, None, "5 mm/s"))
        .with_effect(EffectInstance(EffectName.SENSOR_DYNAMICS, "x_t", "lag"))
    )
    model = fit(Reference.of(a, car.known, FitSettings(points=30)), structure)
    return model, a, b


def test_the_model_form_carries_the_effects_and_validate_simulates_them(fitted) -> None:
    model, a, b = fitted
    data = json.loads(json.dumps({"model": model_json(model)}))  # as diagnose --json prints it
    form = data["model"]
    assert form["tyre_model"] == "maxwell" and len(form["curves"]) == 1
    effects = form["effects"]
    friction = {"coulomb_friction_N", "stribeck_peak_N", "stribeck_velocity_m_s"}
    sensor = {"channel_delay_s", "sensor_lag_s"}
    assert "coulomb_friction_N" in effects and set(effects) <= friction | sensor and set(effects) & sensor
    assert effects["coulomb_friction_N"] == pytest.approx(FRICTION_N, rel=0.3)
    # a pure delay, fitted as a delay plus a lag: it reads as late at low frequency (D + τ)
    late = effects.get("channel_delay_s", {}).get("x_t", 0.0) + effects.get("sensor_lag_s", {}).get(
        "x_t", 0.0
    )
    assert late == pytest.approx(DELAY_S, rel=0.3)

    with_effects_result = validate(model_from_json(data), b)
    assert set(with_effects_result.effects) == set(effects)
    stripped = validate(model_from_json({**form, "effects": {}}), b)
    print(
        f"gap_ratio on B with the effects {with_effects_result.gap_ratio:.4f}, "
        f"without {stripped.gap_ratio:.4f}"
    )
    assert with_effects_result.gap_ratio < SAME_CAR_MAX_RATIO
    assert stripped.gap_ratio > 2 * with_effects_result.gap_ratio
    assert stripped.effects == ()

    # on A, validate's gap is the doctor's own output error of the fitted model: both start from the
    # same initial state (signals.initial_state) and extend the curve alike (damper.dissipative_table);
    # with the low-passed first sample and a linear extension it was up to 1.8x off either way
    doctor_gap = float(simulate_models([model], a).gap_m()[0])
    assert validate(model_from_json(form), a).gap_m == pytest.approx(doctor_gap, rel=1e-3)


@pytest.mark.parametrize(
    ("effects", "message"),
    [
        ({"engine_mount": 1.0}, "unknown effect 'effects.engine_mount'"),
        ({"coulomb_friction_N": "a lot"}, "'effects.coulomb_friction_N' must be a finite number"),
        ({"channel_delay_s": {"x_q": 0.001}}, "names channel 'x_q'"),
        ({"channel_delay_s": {"x_t": -0.001}}, "must be >= 0"),
        ({"tyre_liftoff": 1}, "'effects.tyre_liftoff' must be true or false"),
        ({"coulomb_friction_N": 50.0, "presliding_m": -1e-4}, "'effects.presliding_m' must be >= 0"),
        ({"guide_body_friction_N": "some"}, "'effects.guide_body_friction_N' must be a finite number"),
        ([], "'effects' must be an object"),
    ],
)
def test_bad_effects_are_one_line_errors(fitted, effects, message: str) -> None:
    form = {**model_json(fitted[0]), "effects": effects}
    with pytest.raises(ModelFormatError) as error:
        model_from_json(form)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_a_diagnosis_without_a_final_model_is_one_line() -> None:
    with pytest.raises(ModelFormatError, match="'model' must be an object"):
        model_from_json({"gap_before_m": 1e-5, "model": None})


def test_no_effects_simulates_as_identify_s_model(fitted) -> None:
    """Without effects the model simulates exactly as identify's IdentifiedModel of the same values."""
    form = model_json(fitted[0])
    b = fitted[2]
    rebuilt = model_from_json({k: v for k, v in form.items() if k != "effects"})
    plain = IdentifiedModel(**{f.name: getattr(rebuilt, f.name) for f in fields(IdentifiedModel)})
    gap = validate(rebuilt, b).gap_m
    assert np.isfinite(gap) and gap == validate(plain, b).gap_m


def test_a_diverged_channel_is_told_without_numpy_warnings() -> None:
    """An unstable candidate's simulation leaves residuals near the float range's end (1e200 m): the
    doctor's noise measurement and localisation skip such a channel, and telling it must not print
    numpy's overflow warnings on a user's terminal (clean draw 18 of the independent world did)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert diverged(np.full(1000, 1e200))
        assert diverged(np.array([np.nan, 0.0, 1e-6]))
        assert diverged(np.full(1000, 2.0))  # metres off a bench that moves millimetres
        assert not diverged(np.random.default_rng(0).normal(0.0, 5e-6, 1000))
        # beside its measured readings, a channel off by the runaway ratio of their motion or more
        motion = 2e-3 * np.sin(np.linspace(0.0, 60.0, 1000)) + 0.01  # 1.4 mm RMS about a 10 mm mean
        off = np.full(1000, 1.0)
        assert diverged(off * 1.01 * RUNAWAY_GAP_RATIO * np.std(motion), motion)
        assert not diverged(off * 0.99 * RUNAWAY_GAP_RATIO * np.std(motion), motion)
        assert not diverged(off * 1.01 * RUNAWAY_GAP_RATIO * np.std(motion))


def test_a_curve_stiffer_than_any_damper_is_reported_diverged_not_simulated(fitted) -> None:
    """A smooth truth re-identified with twice the points once had a 2e11 N·s/m segment at the velocities the
    sweep hardly reaches (a fresh independent draw): the Runge-Kutta asked for millions of steps per sample
    and 339 GiB. Such a model is reported as diverged beside a sound one, which simulates as it does alone."""
    model, a, _ = fitted
    curve = model.curves[0]
    force = curve.force_N.copy()
    force[-1] = force[-2] + 1e8  # 10⁸ N across the last interval
    steep = replace(model, curve_override=(PiecewiseLinearCurve(curve.velocity_m_s, force),))
    assert substeps(steep, a.sample_time_s) > MAX_SUBSTEPS
    gaps = simulate_models([model, steep], a).gap_m()
    assert gaps[0] == pytest.approx(float(simulate_models([model], a).gap_m()[0]), rel=1e-12)
    assert np.isinf(gaps[1])


def test_validate_and_the_refinement_report_such_a_curve_diverged_not_simulated(fitted) -> None:
    """The output-error path (validate, and refined_on: the doctor's model handed out refined) has the same
    limit: a degenerate final model (a held-out foreign draw's: a 0.6 kg body under a 3·10⁸ N·s/m segment)
    asked it for 278 775 steps a sample, 27 GiB of plate drive, and the diagnosis died."""
    model, a, _ = fitted
    curve = model.curves[0]
    force = curve.force_N.copy()
    force[-1] = force[-2] + 1e8
    steep = model_from_json(
        model_json(replace(model, curve_override=(PiecewiseLinearCurve(curve.velocity_m_s, force),)))
    )
    assert np.isinf(validate(steep, a).gap_m)
    assert refined_on(steep, a) is None  # every member of the population diverges too: nothing lowers it


def test_a_curve_that_slopes_back_at_its_end_is_extended_flat(fitted) -> None:
    """Beyond its end knots a curve keeps its end slope where that is not negative and stays flat where it
    is (damper.dissipative_table): a fitted curve that slopes back at its last knots (few samples there)
    would otherwise push with the motion beyond them, and its simulation ran away (independent pair 115).
    The doctor and validate simulate it so alike."""
    model, a, _ = fitted
    curve = model.curves[0]
    knots, force = curve.velocity_m_s, curve.force_N.copy()
    force[-1] = force[-2] - 1e5 * (knots[-1] - knots[-2])  # slopes back at -10⁵ N·s/m
    back = PiecewiseLinearCurve(knots, force)
    extended = back.dissipative()
    inside = np.linspace(knots[0], knots[-1], 101)
    np.testing.assert_allclose(extended.force(inside), back.force(inside), rtol=1e-12, atol=1e-9)
    beyond = knots[-1] + np.array([0.01, 0.1, 1.0])
    np.testing.assert_allclose(extended.force(beyond), np.full(3, force[-1]), rtol=1e-12)
    below = knots[0] - np.array([0.01, 0.1])
    np.testing.assert_allclose(extended.force(below), back.force(below), rtol=1e-12)
    # a batch of curves is extended column by column, as each curve is
    batch = CurveBatch(knots, np.column_stack([force, curve.force_N])).dissipative()
    far = np.array([knots[-1] + 1.0, knots[-1] + 1.0])
    np.testing.assert_allclose(
        batch.force(far), [extended.force(far[0]), curve.dissipative().force(far[1])], rtol=1e-12
    )
    # the population the doctor runs is that curve so extended, beside a sound model with wider knots
    sloped = replace(model, curve_override=(back,))
    wider = replace(model, curve_override=(curve.resampled(np.linspace(knots[0], 2 * knots[-1], 40)),))
    damper = _corner([sloped, wider], 0, a.sample_time_s).damper
    assert damper.force(far)[0] == pytest.approx(force[-1], rel=1e-12)
    assert damper.force(far)[1] == pytest.approx(wider.curves[0].force(far[1]), rel=1e-12)
    # bounded: the simulation no longer overflows (its gap, tens of mm off a curve this wrong, then counts
    # as run away by RUNAWAY_GAP_RATIO instead)
    predicted = simulate_models([sloped], a).predicted
    assert all(np.all(np.isfinite(p)) for p in predicted.values())
    # and validate, given the same model in the model form, stays bounded too (it extended linearly and
    # reported this model diverged)
    form = model_json(sloped)
    assert np.isfinite(validate(model_from_json(form), a).gap_m)


def test_a_model_far_more_off_than_the_motion_it_predicts_counts_as_diverged() -> None:
    """BatchOutputError.gap_m: a gap of RUNAWAY_GAP_RATIO times the measured motion's RMS or more is a model
    that ran away (bounded by the curves' flat extension, not by physics), counted as diverged like one
    whose simulation overflowed; below it the gap is kept."""
    rng = np.random.default_rng(0)
    motion_m = 2e-3
    residual = rng.normal(0.0, 1.0, (1000, 3)) * np.array([0.5, 2.9, 3.1]) * motion_m
    batch = BatchOutputError({"x_s": residual}, {"x_s": residual}, np.full(3, motion_m))
    gaps = batch.gap_m()
    ratio = np.sqrt(np.mean(residual**2, axis=0)) / motion_m
    np.testing.assert_array_equal(np.isinf(gaps), ratio >= RUNAWAY_GAP_RATIO)
    assert np.isfinite(gaps[0]) and np.isinf(gaps[2])


def test_validate_simulates_a_spring_curve_and_sensor_shapes_as_the_doctor_does() -> None:
    """validate's gap of a model with spring hinges, a gain error and an averaging sensor (through its
    JSON form) is the doctor's own output error of it: the hinges, the gain and the moving average are
    simulated alike. A car with a progressive spring and a wheel laser reading 3% high, fitted with
    spring_curve and sensor_gain; the body laser's averaging (1 ms late, 4 ms window) is set, not fitted
    (this simulator has no such filter). The doctor compares the prediction with the measurement seen
    through the sensor model's inverse, validate the prediction seen through the sensor model with the
    measurement: they agree to 1e-3 where the sensor model is the recording's (above), and here, where
    the average is not in the recording, to the share of its inverse in what the model leaves (0.2%)."""
    car = with_effects(default_quarter_car(), cubic_spring_N_per_m3=5e7, sensor_gain={"x_t": 1.03})
    recording = simulate(car, SimulationSettings(sweep=SweepSettings(duration_s=8.0), seed=3)).recording
    gain = EffectInstance(EffectName.SENSOR_GAIN, "x_t")
    average = EffectInstance(EffectName.SENSOR_DYNAMICS, "x_s", "average")
    structure = starting_structure(TyreModel.MAXWELL).with_effect(EffectInstance(EffectName.SPRING_CURVE))
    fitted_model = fit(
        Reference.of(recording, car.known, FitSettings(points=30)), structure.with_effect(gain)
    )
    assert fitted_model.channel_value(gain, "gain") == pytest.approx(0.03, rel=0.15)
    values = np.concatenate([fitted_model.channel_values, [0.001, 0.004]])
    model = replace(
        fitted_model, structure=fitted_model.structure.with_effect(average), channel_values=values
    )
    form = json.loads(json.dumps({"model": model_json(model)}))
    effects = form["model"]["effects"]
    assert len(effects["spring_hinges"]) == len(model.knots_m)
    assert effects["sensor_gain_error"] == {"x_t": pytest.approx(0.03, rel=0.15)}
    assert effects["channel_delay_s"] == {"x_s": 0.001} and effects["sensor_average_s"] == {"x_s": 0.004}
    doctor_gap = float(simulate_models([model], recording).gap_m()[0])
    validated = validate(model_from_json(form), recording)
    print(f"doctor {doctor_gap * 1e6:.2f} µm, validate {validated.gap_m * 1e6:.2f} µm")
    assert validated.gap_m == pytest.approx(doctor_gap, rel=1e-2)


def test_validate_simulates_hysteretic_friction_as_the_doctor_does(fitted) -> None:
    """low_speed_friction's hysteretic variant (Dahl's state, estimator.dynamics) goes through the model's
    JSON form as `presliding_m` beside the sliding force, and validate simulates it as the doctor does: on
    recording A its gap is the doctor's own output error of the fitted model (to 1e-3, as above)."""
    _, a, _ = fitted
    hysteretic = EffectInstance(EffectName.LOW_SPEED_FRICTION, None, "presliding 0.2 mm")
    lag = EffectInstance(EffectName.SENSOR_DYNAMICS, "x_t", "lag")  # the fixture's wheel laser is late
    structure = starting_structure(TyreModel.MAXWELL).with_effect(hysteretic).with_effect(lag)
    model = fit(Reference.of(a, fitted[0].vehicle, FitSettings(points=30)), structure)
    assert model.presliding_m == 0.0002 and model.stribeck_velocity_m_s == 0.0
    # this car's friction steps with the velocity, which the curve's low-speed knots take; the Dahl force
    # is set to its size so that the simulations compared carry it
    theta = model.theta.copy()
    theta[model.system.parameter_names.index(FRICTION_UNKNOWNS[0])] = FRICTION_N
    model = replace(model, theta=theta)
    form = json.loads(json.dumps({"model": model_json(model)}))["model"]
    assert form["effects"]["presliding_m"] == 0.0002
    assert form["effects"]["coulomb_friction_N"] == FRICTION_N
    assert "stribeck_peak_N" not in form["effects"]
    doctor_gap = float(simulate_models([model], a).gap_m()[0])
    validated = validate(model_from_json(form), a)
    print(f"doctor {doctor_gap * 1e6:.2f} µm, validate {validated.gap_m * 1e6:.2f} µm")
    assert "presliding_m" in validated.effects
    assert validated.gap_m == pytest.approx(doctor_gap, rel=1e-3)


def test_refining_a_model_on_a_recording_stops_when_cancelled(fitted) -> None:
    """estimator.validation.refined_on (the doctor's model for prediction) honours a diagnosis's cancel:
    a DE stopped early is not handed out as a refined model."""
    model, a, _ = fitted
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(InterruptedError):
        refined_on(model_from_json(model_json(model)), a, cancel)
