"""service.doctor_words: a named family's fitted shape and the goodness-of-fit verdict in words, from the
JSON form of estimator.doctor.parameters.report; a stored result of the earlier doctor reads as its values."""

from __future__ import annotations

from estimator.doctor import catalog
from service.doctor_words import JOIN, departs_from_linear, family, fit_verdict, shape

SPRING = {
    "rate_at_static_load_N_per_m": 20_000.0,
    "stated_rate_N_per_m": 26_000.0,
    "rate_change_percent": -23.1,
    "extra_rate_beyond_9.0_mm_compression_N_per_m": 60_000.0,
    "extra_rate_beyond_5.1_mm_compression_N_per_m": 1_000.0,
    "extra_rate_beyond_2.4_mm_extension_N_per_m": -800.0,
    "extra_rate_beyond_4.2_mm_extension_N_per_m": 300.0,
}


def test_the_spring_curve_reads_as_its_rate_and_where_it_departs_from_linear() -> None:
    assert departs_from_linear(SPRING) == ["beyond 9.0 mm of compression (+6e+04 N/m)"]
    words = shape("spring_curve", SPRING)
    assert words.startswith("rate at static load 2e+04 N/m (stated 2.6e+04, -23.1%)")
    assert words.endswith("departs from linear beyond 9.0 mm of compression (+6e+04 N/m)")
    linear = {k: (v if "extra" not in k else 0.0) for k, v in SPRING.items()}
    assert shape("spring_curve", linear).endswith("linear over the deflection measured")


def test_the_load_paths_rates_named_together_read_as_each_ones_shape() -> None:
    tyre = {
        "tyre_stiffness_N_per_m": 3300.0,
        "stated_tyre_stiffness_N_per_m": 6200.0,
        "change_percent": -46.8,
    }
    words = shape("spring_curve + tyre_stiffness", SPRING | tyre)
    assert words == f"{shape('spring_curve', SPRING)}; {shape('tyre_stiffness', tyre)}"
    assert words.endswith("tyre rate 3300 N/m (stated 6200, -46.8%)")
    assert JOIN == catalog.JOIN  # the joined label as the doctor writes it


def test_friction_and_sensors_read_as_their_kind_and_constants() -> None:
    friction = {"sliding_friction_N": 80.0, "static_friction_N": 120.0, "stribeck_velocity_m_s": 0.005}
    assert family("low_speed_friction(5 mm/s)") == "low_speed_friction"
    assert shape("low_speed_friction(5 mm/s)", friction) == (
        "force step of 80 N sliding, static peak 120 N (Stribeck velocity 5 mm/s)"
    )
    hysteretic = {**friction, "static_friction_N": 80.0, "stribeck_velocity_m_s": 0.0, "presliding_m": 2e-4}
    assert shape("low_speed_friction(presliding 0.2 mm)", hysteretic) == (
        "hysteretic friction of 80 N sliding, built up over a presliding displacement of 0.2 mm after each "
        "reversal (Dahl)"
    )
    lag = {
        "channel": "x_s",
        "filter": "first-order lag",
        "delay_s": 0.0005,
        "lag_time_constant_s": 0.003,
        "equivalent_delay_s": 0.0035,
    }
    assert shape("sensor_dynamics(x_s, lag)", lag) == (
        "x_s: first-order lag, τ 3 ms after a delay of 0.5 ms (reads 3.5 ms late)"
    )
    assert shape("sensor_gain(x_t)", {"channel": "x_t", "gain_error_percent": -2.5}) == "x_t reads 2.5% low"
    assert shape("sensor_offset(x_r)", {"channel": "x_r", "offset_m": 5e-4}) == "x_r zero off by +500.0 µm"


def test_a_result_of_the_earlier_doctor_reads_as_its_values() -> None:
    assert shape("progressive_spring", {"cubic_spring_N_per_m3": 2e8}) == "cubic_spring_N_per_m3 = 2e+08"
    assert shape("spring_curve", {"spring_stiffness_N_per_m": 3e4}) == "spring_stiffness_N_per_m = 3e+04"
    assert fit_verdict(None, None, True, None) == "unexplained"
    assert fit_verdict(None, None, False, None) == "explained"


def test_the_goodness_of_fit_in_words() -> None:
    assert fit_verdict(0.31, 0.05, False, None) == "p = 0.31: nothing left that the noise does not explain"
    assert (
        fit_verdict(0.0012, 0.05, True, "largest on x_s")
        == "p = 0.0012 < α = 0.05: unexplained; largest on x_s"
    )
