"""The force shapes of estimator.dynamics.CornerPhysics beyond identify's model, and their model form:

- spring hinges: a hinge with knot c and rate k adds nothing while the deflection has not passed c (on c's
  side) and exactly k·(ζ − c) beyond it; several hinges add; fewer than HINGES are padded; a population
  carries its own per column;
- Stribeck friction: the low-speed friction rises to Coulomb + peak just above the smoothing band and
  falls back to the Coulomb level at speeds far above the Stribeck velocity, with the Coulomb friction's
  own smoothed sign; the Runge-Kutta steps follow the friction law's steepest slope, and a simulation at
  those steps equals one at finer steps;
- estimator.model_io: `spring_hinges`, the Stribeck pair and the sensor effects go through the model's
  JSON form and back onto the corner and the channel corrections; bad values are one-line errors.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from estimator.damper import PiecewiseLinearCurve
from estimator.dynamics import HINGES, CornerPhysics, QuarterCarPhysics
from estimator.friction import COULOMB_SMOOTHING_M_S, coulomb_sign, friction_peak_N, friction_slope_Ns_per_m
from estimator.model_io import ModelFormatError, SpringHinge, model_from_json
from estimator.runge_kutta_steps import model_substeps, sample_substeps
from estimator.simulation_kernel import integrate_compiled

SPRING_N_PER_M = 20e3
NO_DAMPER = PiecewiseLinearCurve(np.array([-1.0, 1.0]), np.array([0.0, 0.0]))
"""A damper of no force: the suspension force is then the spring's and the effects' alone."""


def _corner(**effects: object) -> CornerPhysics:
    return CornerPhysics(
        damper=NO_DAMPER, spring_stiffness_N_per_m=SPRING_N_PER_M, tyre_stiffness_N_per_m=2e5, **effects
    )


def _extra_N(corner: CornerPhysics, deflection_m: np.ndarray, velocity_m_s: np.ndarray) -> np.ndarray:
    """The suspension force less the linear spring's."""
    return corner.suspension_force_N(deflection_m, velocity_m_s) - SPRING_N_PER_M * deflection_m


def test_a_stop_adds_nothing_inside_its_clearance_and_its_rate_beyond() -> None:
    """A hinge at knot c > 0 (a rebound stop c beyond the static length; ζ > 0 is extension)."""
    clearance_m, rate_N_per_m = 0.012, 150e3
    corner = _corner(spring_hinge_knots_m=np.array([clearance_m]), spring_hinge_rates_N_per_m=[rate_N_per_m])
    inside = np.linspace(-0.05, clearance_m, 1001)  # the knot itself included
    assert np.all(corner.spring_hinge_force_N(inside) == 0.0)
    assert np.all(_extra_N(corner, inside, np.zeros_like(inside)) == 0.0)
    beyond = clearance_m + np.array([1e-9, 1e-4, 0.003, 0.04])
    np.testing.assert_allclose(corner.spring_hinge_force_N(beyond), rate_N_per_m * (beyond - clearance_m))
    np.testing.assert_allclose(
        _extra_N(corner, beyond, np.zeros(4)), rate_N_per_m * (beyond - clearance_m), rtol=1e-9, atol=1e-9
    )


def test_a_negative_knot_acts_below_it_and_a_knot_at_zero_above_zero() -> None:
    """A negative knot −c is a bump stop: it acts once the suspension is compressed by more than c."""
    bump = _corner(spring_hinge_knots_m=[-0.02], spring_hinge_rates_N_per_m=[80e3])
    deflection = np.array([-0.05, -0.021, -0.02, -0.01, 0.0, 0.03])
    np.testing.assert_array_equal(
        bump.spring_hinge_force_N(deflection), [80e3 * (-0.05 + 0.02), 80e3 * (-0.021 + 0.02), 0, 0, 0, 0]
    )
    at_zero = _corner(spring_hinge_knots_m=[0.0], spring_hinge_rates_N_per_m=[5e3])
    np.testing.assert_array_equal(at_zero.spring_hinge_force_N(deflection), [0, 0, 0, 0, 0, 5e3 * 0.03])


def test_hinges_add_and_a_population_carries_its_own() -> None:
    """Two stops either way plus a softening beyond one (a negative rate): the force is their sum. As a
    population (H, columns), each column has its own; (H,) hinges act in every column alike."""
    knots, rates = np.array([0.01, 0.02, -0.015]), np.array([50e3, -20e3, 70e3])
    corner = _corner(spring_hinge_knots_m=knots, spring_hinge_rates_N_per_m=rates)
    deflection = np.linspace(-0.04, 0.04, 81)
    expected = (
        50e3 * np.maximum(deflection - 0.01, 0)
        - 20e3 * np.maximum(deflection - 0.02, 0)
        + 70e3 * np.minimum(deflection + 0.015, 0)
    )
    np.testing.assert_allclose(corner.spring_hinge_force_N(deflection), expected, rtol=1e-12, atol=1e-9)
    knots_table, rates_table = corner.hinge_table()
    assert knots_table.shape == (HINGES,) and rates_table[3:].tolist() == [0.0] * (HINGES - 3)

    # a population of three: the hinges above, the first alone, none
    per_column = np.column_stack([rates, [50e3, 0.0, 0.0], np.zeros(3)])
    population = _corner(
        spring_hinge_knots_m=np.repeat(knots[:, None], 3, axis=1), spring_hinge_rates_N_per_m=per_column
    )
    states = np.repeat(deflection[:, None], 3, axis=1)  # (deflections, columns)
    force = population.spring_hinge_force_N(states)
    np.testing.assert_allclose(force[:, 0], expected, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(force[:, 1], 50e3 * np.maximum(deflection - 0.01, 0), rtol=1e-12)
    assert np.all(force[:, 2] == 0.0)
    shared = corner.spring_hinge_force_N(states)
    np.testing.assert_allclose(shared, np.repeat(expected[:, None], 3, axis=1), rtol=1e-12, atol=1e-9)


def test_without_hinges_or_stribeck_nothing_is_added() -> None:
    """Absent (the default), all rates zero, or a Stribeck peak without velocity: the force is the plain
    corner's, bit for bit (and no division by a zero velocity)."""
    deflection, velocity = np.linspace(-0.03, 0.03, 61), np.linspace(-0.5, 0.5, 61)
    plain = _corner(coulomb_friction_N=30.0)
    assert plain.spring_hinge_force_N(deflection) == 0.0
    zero_rates = _corner(
        coulomb_friction_N=30.0, spring_hinge_knots_m=[0.01, -0.01], spring_hinge_rates_N_per_m=[0.0, 0.0]
    )
    no_velocity = _corner(coulomb_friction_N=30.0, stribeck_peak_N=50.0, stribeck_velocity_m_s=0.0)
    with np.errstate(all="raise"):
        for other in (zero_rates, no_velocity):
            np.testing.assert_array_equal(
                other.suspension_force_N(deflection, velocity), plain.suspension_force_N(deflection, velocity)
            )


def test_hinges_the_corner_cannot_take_are_refused() -> None:
    with pytest.raises(ValueError, match=f"at most {HINGES}"):
        _corner(spring_hinge_knots_m=np.zeros(HINGES + 1), spring_hinge_rates_N_per_m=np.ones(HINGES + 1))
    with pytest.raises(ValueError, match=r"knots \(2,\) and rates \(1,\)"):
        _corner(spring_hinge_knots_m=[0.01, 0.02], spring_hinge_rates_N_per_m=[1e4])


def test_stribeck_friction_peaks_at_low_speed_and_falls_to_the_coulomb_level() -> None:
    # a Stribeck velocity well above the smoothing band, so that the band does not hide the peak
    coulomb_N, peak_N, stribeck_m_s = 40.0, 60.0, 0.5
    corner = _corner(coulomb_friction_N=coulomb_N, stribeck_peak_N=peak_N, stribeck_velocity_m_s=stribeck_m_s)
    velocity = np.concatenate([np.linspace(0.0, 0.05, 501), np.linspace(0.05, 8.0, 500)])
    friction = _extra_N(corner, np.zeros_like(velocity), velocity)
    # the law, with the Coulomb friction's own smoothed sign
    law = (coulomb_N + peak_N * np.exp(-((velocity / stribeck_m_s) ** 2))) * coulomb_sign(velocity)
    np.testing.assert_allclose(friction, law, rtol=1e-12, atol=1e-12)
    # at 0+ (a few smoothing bands above zero, far below the Stribeck velocity): Coulomb + peak
    just_above = 4 * COULOMB_SMOOTHING_M_S
    assert _extra_N(corner, 0.0, just_above) == pytest.approx(coulomb_N + peak_N, rel=0.005)
    assert np.max(friction) == pytest.approx(coulomb_N + peak_N, rel=0.005)
    # far above the Stribeck velocity: the sliding (Coulomb) level; odd in the velocity
    assert _extra_N(corner, 0.0, 10 * stribeck_m_s) == pytest.approx(coulomb_N, rel=1e-12)
    np.testing.assert_array_equal(_extra_N(corner, 0.0, -velocity), -friction)
    # zero at rest
    assert _extra_N(corner, 0.0, 0.0) == 0.0


FRICTION_LAWS = [
    (200.0, 0.0, 0.0),  # Coulomb alone
    (50.0, 200.0, 0.005),  # a static peak above the sliding level
    (120.0, 80.0, 0.0025),  # a peak narrower than the smoothing band
    (1550.0, -1420.0, 0.02),  # a fitted friction whose peak has the other sign: a smooth rise
    (-300.0, 500.0, 0.04),
]


@pytest.mark.parametrize(("coulomb_N", "peak_N", "stribeck_m_s"), FRICTION_LAWS)
def test_the_friction_slope_is_the_steepest_slope_of_the_corner_s_friction(
    coulomb_N: float, peak_N: float, stribeck_m_s: float
) -> None:
    """friction_slope_Ns_per_m against the corner's own friction force differentiated on a fine grid."""
    stribeck = {"stribeck_peak_N": peak_N, "stribeck_velocity_m_s": stribeck_m_s} if stribeck_m_s else {}
    corner = _corner(coulomb_friction_N=coulomb_N, **stribeck)
    velocity = np.linspace(-0.3, 0.3, 600_001)
    force = _extra_N(corner, np.zeros_like(velocity), velocity)
    steepest = float(np.max(np.abs(np.gradient(force, velocity))))
    assert friction_slope_Ns_per_m(coulomb_N, peak_N, stribeck_m_s) == pytest.approx(steepest, rel=0.01)


@pytest.mark.parametrize(("coulomb_N", "peak_N", "stribeck_m_s"), FRICTION_LAWS)
def test_the_breakaway_force_is_the_largest_force_of_the_corner_s_friction(
    coulomb_N: float, peak_N: float, stribeck_m_s: float
) -> None:
    """friction_peak_N (what the doctor reports as static friction) against the corner's own friction force
    on a fine grid out to 0.3 m/s, where every law here has settled to its sliding level."""
    stribeck = {"stribeck_peak_N": peak_N, "stribeck_velocity_m_s": stribeck_m_s} if stribeck_m_s else {}
    corner = _corner(coulomb_friction_N=coulomb_N, **stribeck)
    velocity = np.linspace(0.0, 0.3, 600_001)
    largest = float(np.max(np.abs(_extra_N(corner, np.zeros_like(velocity), velocity))))
    assert friction_peak_N(coulomb_N, peak_N, stribeck_m_s) == pytest.approx(largest, rel=1e-3)


def test_a_peak_narrower_than_the_sign_s_smoothing_holds_no_breakaway_force() -> None:
    """A wide peak develops fully: 100 N sliding with 80 N more decaying over 0.2 m/s breaks away at about
    180 N. One at the smoothing band never rises above sliding. Lab rig 200223's diagnosis named 2.0 N
    sliding with a 726 N peak over 0.031 mm/s (a Stribeck peak standing for a step sharper than the law's),
    which the report gave as 728 N of static friction on a rig whose damper's is 0.45 N: the law holds
    nothing above its sliding level there."""
    assert friction_peak_N(100.0, 80.0, 0.2) == pytest.approx(180.0, rel=0.01)
    assert friction_peak_N(100.0, 80.0, COULOMB_SMOOTHING_M_S) == pytest.approx(100.0)
    assert friction_peak_N(2.02, 726.2, 3.1e-5) == pytest.approx(2.02)


def test_a_peak_of_the_other_sign_is_not_counted_as_friction() -> None:
    """At zero velocity friction and peak step together: (F_c + peak) / band, whatever their signs; the old
    bound (|F_c| + |peak|) / band was ten times too steep for a fitted +1 550 N with a −1 420 N peak at
    20 mm/s, and the simulation took 48 Runge-Kutta steps a 2 ms sample for it instead of 5."""
    assert friction_slope_Ns_per_m(150.0, 50.0, 0.005) == pytest.approx(
        200.0 / COULOMB_SMOOTHING_M_S, rel=1e-3
    )
    assert friction_slope_Ns_per_m(1550.0, -1420.0, 0.02) < 0.15 * 2970.0 / COULOMB_SMOOTHING_M_S
    # a Stribeck velocity of zero is no Stribeck term (CornerPhysics), so its peak adds nothing
    assert friction_slope_Ns_per_m(100.0, 500.0, 0.0) == friction_slope_Ns_per_m(100.0, 0.0, 0.0)
    # per column: the steepest column counts
    columns = friction_slope_Ns_per_m(
        np.array([100.0, 1550.0]), np.array([0.0, -1420.0]), np.array([0, 0.02])
    )
    assert columns == max(friction_slope_Ns_per_m(100.0), friction_slope_Ns_per_m(1550.0, -1420.0, 0.02))


def test_the_steps_the_friction_slope_gives_simulate_as_finer_steps_do() -> None:
    """A motorcycle-sized corner with that fitted friction at 2 ms, driven by a 0-20 Hz sweep: the response
    at the steps model_substeps gives equals the response at four times as many within 0.1 µm."""
    damper = PiecewiseLinearCurve(np.array([-1.0, 0.0, 1.0]), np.array([-1500.0, 0.0, 1500.0]))
    corner = CornerPhysics(
        damper=damper,
        spring_stiffness_N_per_m=14_000.0,
        tyre_stiffness_N_per_m=101_000.0,
        coulomb_friction_N=1550.0,
        stribeck_peak_N=-1420.0,
        stribeck_velocity_m_s=0.02,
    )
    physics = QuarterCarPhysics(corner, 95.0, 14.0)
    dt = 0.002
    steps = model_substeps(
        [damper],
        95.0,
        14.0,
        1,
        dt,
        coulomb_friction_N=1550.0,
        stribeck_peak_N=-1420.0,
        stribeck_velocity_m_s=0.02,
    )
    assert steps <= 8
    time_s = np.arange(0.0, 6.0, dt)
    phase = 2 * np.pi * (20.0 / 6.0) * time_s**2 / 2  # 0 to 20 Hz in 6 s
    plate, rate = 0.004 * np.sin(phase), 0.004 * np.cos(phase) * 2 * np.pi * (20.0 / 6.0) * time_s

    def response(per_sample: int) -> np.ndarray:
        states = integrate_compiled(
            physics,
            np.zeros(5),
            dt / per_sample,
            sample_substeps(plate, per_sample),
            sample_substeps(rate, per_sample),
        )[::per_sample]
        return np.stack([states[:, 0], states[:, 2]])

    coarse, fine = response(steps), response(4 * steps)
    assert np.all(np.isfinite(coarse))
    assert float(np.max(np.abs(coarse - fine))) < 1e-7


MODEL = {
    "curves": [{"velocity_m_s": [-1.0, 0.0, 1.0], "force_N": [-800.0, 0.0, 1500.0]}],
    "masses_kg": {"sprung": 300.0, "unsprung": 40.0},
    "stiffness_N_per_m": {"spring": SPRING_N_PER_M, "tyre": 2e5},
    "tyre_model": "maxwell",
    "tyre_damping_Ns_per_m": 300.0,
    "tyre_relaxation_time_s": 0.03,
}
EFFECTS = {
    "coulomb_friction_N": 30.0,
    "stribeck_peak_N": 45.0,
    "stribeck_velocity_m_s": 0.01,
    "spring_hinges": [{"knot_m": 0.015, "rate_N_per_m": 1e5}, {"knot_m": -0.02, "rate_N_per_m": 6e4}],
    "channel_delay_s": {"x_t": 0.002},
    "sensor_lag_s": {"x_s": 0.004},
    "sensor_average_s": {"x_s": 0.01, "x_t": 0.0},
    "sensor_gain_error": {"x_t": -0.05},
}


def test_the_model_form_carries_hinges_stribeck_and_sensor_effects_both_ways() -> None:
    model = model_from_json(json.loads(json.dumps({**MODEL, "effects": EFFECTS})))
    effects = model.effects
    assert effects.spring_hinges == (SpringHinge(0.015, 1e5), SpringHinge(-0.02, 6e4))
    assert effects.names == [
        "coulomb_friction_N",
        "stribeck_peak_N",
        "stribeck_velocity_m_s",
        "spring_hinges",
        "channel_delay_s",
        "sensor_lag_s",
        "sensor_average_s",
        "sensor_gain_error",
    ]
    assert effects.to_json() == EFFECTS
    assert model_from_json({**MODEL, "effects": effects.to_json()}).effects == effects

    corner = model.physics().corner  # the forces reach the simulated corner
    np.testing.assert_array_equal(corner.spring_hinge_knots_m, [0.015, -0.02])
    np.testing.assert_array_equal(corner.spring_hinge_rates_N_per_m, [1e5, 6e4])
    assert (corner.stribeck_peak_N, corner.stribeck_velocity_m_s) == (45.0, 0.01)
    assert corner.spring_hinge_force_N(0.025) == pytest.approx(1e5 * 0.01)

    corrections = effects.channel_corrections()  # the channel effects reach the doctor's corrections
    assert corrections.delay_s == {"x_t": 0.002} and corrections.offset_m == {}
    assert corrections.lag_s == {"x_s": 0.004}
    assert corrections.average_s == {"x_s": 0.01, "x_t": 0.0}
    assert corrections.gain_error == {"x_t": -0.05}


def test_without_the_new_effects_the_corner_is_identify_s() -> None:
    plain = model_from_json(MODEL)
    assert plain.effects.names == [] and plain.effects.to_json() == {}
    corner = plain.physics().corner
    assert corner.spring_hinge_knots_m is None and corner.stribeck_peak_N == 0.0


@pytest.mark.parametrize(
    ("effects", "message"),
    [
        ({"stribeck_peak_N": 40.0}, "'effects.stribeck_peak_N' and 'effects.stribeck_velocity_m_s' go"),
        ({"stribeck_velocity_m_s": 0.01}, "go together (both or none)"),
        (
            {"stribeck_peak_N": 40.0, "stribeck_velocity_m_s": 0.0},
            "'effects.stribeck_velocity_m_s' must be > 0",
        ),
        (
            {"stribeck_peak_N": "high", "stribeck_velocity_m_s": 0.01},
            "'effects.stribeck_peak_N' must be a finite",
        ),
        ({"spring_hinges": {"knot_m": 0.01}}, "'effects.spring_hinges' must be a list of at most 4"),
        ({"spring_hinges": [{"knot_m": 0.01, "rate_N_per_m": 1.0}] * 5}, "must be a list of at most 4"),
        ({"spring_hinges": [0.01]}, "'effects.spring_hinges[0]' must be an object"),
        ({"spring_hinges": [{"knot_m": 0.01}]}, "missing key 'effects.spring_hinges[0].rate_N_per_m'"),
        (
            {"spring_hinges": [{"knot_m": 0.01, "rate_N_per_m": 1.0}, {"knot_m": None, "rate_N_per_m": 1.0}]},
            "missing key 'effects.spring_hinges[1].knot_m'",
        ),
        (
            {"spring_hinges": [{"knot_m": float("nan"), "rate_N_per_m": 1.0}]},
            "'effects.spring_hinges[0].knot_m' must be a finite number",
        ),
        (
            {"spring_hinges": [{"knot_m": 0.01, "rate_N_per_m": 1.0, "preload_N": 3.0}]},
            "unknown key 'effects.spring_hinges[0].preload_N'",
        ),
        ({"sensor_lag_s": {"x_s": -0.001}}, "'effects.sensor_lag_s' must be >= 0"),
        ({"sensor_average_s": {"x_t": -0.01}}, "'effects.sensor_average_s' must be >= 0"),
        ({"sensor_gain_error": {"x_t": -1.0}}, "'effects.sensor_gain_error' must be > -1"),
        ({"sensor_gain_error": {"x_q": 0.1}}, "'effects.sensor_gain_error' names channel 'x_q'"),
        ({"sensor_lag_s": [0.001]}, "'effects.sensor_lag_s' must be an object: channel -> value"),
        ({"sensor_average_s": {"x_s": True}}, "'effects.sensor_average_s.x_s' must be a finite number"),
    ],
)
def test_bad_shape_and_sensor_effects_are_one_line_errors(effects: object, message: str) -> None:
    with pytest.raises(ModelFormatError) as error:
        model_from_json({**MODEL, "effects": effects})
    assert message in str(error.value) and "\n" not in str(error.value)
