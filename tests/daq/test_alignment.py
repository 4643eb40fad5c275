"""Resampling onto the grid: cubic accuracy, gaps kept as gaps, never filled."""

from __future__ import annotations

import numpy as np
import pytest

from daq.alignment import ChannelAligner

AMPLITUDE_M = 0.004
FREQUENCY_HZ = 20.0


def sine(t: np.ndarray) -> np.ndarray:
    return AMPLITUDE_M * np.sin(2 * np.pi * FREQUENCY_HZ * t)


@pytest.mark.parametrize("offset_fraction", [0.1, 0.37, 0.5, 0.9])
def test_cubic_interpolation_of_a_1khz_source_is_within_a_tenth_of_a_micrometre(
    offset_fraction: float,
) -> None:
    period = 1e-3
    samples_t = np.arange(0, 0.5, period) + offset_fraction * period
    aligner = ChannelAligner(1.5 * period)
    aligner.add(samples_t, sine(samples_t))
    grid = np.arange(0.01, 0.49, period)
    values = aligner.values_at(grid)
    assert np.all(np.isfinite(values))
    error = np.max(np.abs(values - sine(grid)))
    linear_error = np.max(np.abs(np.interp(grid, samples_t, sine(samples_t)) - sine(grid)))
    assert error < 1e-7
    assert linear_error > 20 * error  # what cubic buys over linear at this offset


def test_a_missing_sample_is_a_gap_exactly_where_it_is_missing() -> None:
    period = 1e-3
    t = np.arange(0, 0.1, period) + 0.3e-3
    keep = np.ones(t.size, bool)
    keep[50] = False  # the sample at 50.3 ms never came
    aligner = ChannelAligner(1.5 * period)
    aligner.add(t[keep], sine(t[keep]))
    grid = np.arange(0.002, 0.098, period)
    values = aligner.values_at(grid)
    gap = np.isnan(values)
    # grid points between 49.3 ms and 51.3 ms have no pair of neighbours closer than one period
    assert list(np.round(grid[gap] * 1e3).astype(int)) == [50, 51]
    beside = (grid > 0.0475) & (grid < 0.0535)  # linear there: one outer neighbour lies beyond the gap
    assert np.max(np.abs(values[~gap & ~beside] - sine(grid[~gap & ~beside]))) < 1e-7
    assert np.max(np.abs(values[~gap & beside] - sine(grid[~gap & beside]))) < 5e-6


def test_an_out_of_range_sample_is_a_gap_and_not_interpolated_over() -> None:
    period = 1e-3
    t = np.arange(0, 0.05, period)
    v = sine(t)
    v[20] = np.nan
    aligner = ChannelAligner(1.5 * period)
    aligner.add(t, v)
    grid = t[5:45] + 0.5e-3
    values = aligner.values_at(grid)
    assert np.isnan(values[grid.searchsorted(0.0195)])
    assert np.isnan(values[grid.searchsorted(0.0205)])
    assert np.isfinite(values).sum() == grid.size - 2


def test_irregular_polled_samples_interpolate_and_a_long_silence_is_a_gap() -> None:
    rng = np.random.default_rng(3)
    intervals = rng.uniform(2e-3, 4e-3, 200)  # a polled source at ~330 Hz with jitter
    t = np.cumsum(intervals)
    t = t[(t < 0.3) | (t > 0.32)]  # 20 ms without an answer
    aligner = ChannelAligner(2.5 * 3e-3)
    aligner.add(t, sine(t))
    grid = np.arange(0.01, 0.5, 1e-3)
    values = aligner.values_at(grid)
    gap = np.isnan(values)
    assert np.all((grid[gap] > 0.29) & (grid[gap] < 0.33))
    assert gap.sum() >= 15
    assert np.max(np.abs(values[~gap] - sine(grid[~gap]))) < 0.02 * AMPLITUDE_M


def test_samples_out_of_order_are_dropped_and_counted() -> None:
    aligner = ChannelAligner(1.5e-3)
    aligner.add(np.array([0.0, 0.001, 0.002]), np.zeros(3))
    aligner.add(np.array([0.0015, 0.003, 0.0025, 0.004]), np.ones(4))
    assert aligner.out_of_order == 2
    assert aligner.newest_s == pytest.approx(0.004)


def test_no_value_before_the_first_or_after_the_newest_sample() -> None:
    aligner = ChannelAligner(1.5e-3)
    t = np.arange(0.01, 0.02, 1e-3)
    aligner.add(t, sine(t))
    values = aligner.values_at(np.array([0.005, 0.015, 0.025]))
    assert np.isnan(values[0]) and np.isfinite(values[1]) and np.isnan(values[2])
