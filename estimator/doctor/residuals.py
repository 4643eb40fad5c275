"""Locate a disagreement: which channel, part of the sweep, range of suspension velocity, deflection and tyre
deflection, and whether what is left is white. Two residuals: the output error (m, per channel: the model
simulated from the measured plate, estimator.doctor.simulation) and the equation error (N, per equation at the
fitted samples). A time maps to a band of the sweep by the plate's instantaneous frequency."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.autocorrelation import ljung_box
from estimator.binned_rms import Profile, band_rms, binned_rms
from estimator.digital_filters import welch_density
from estimator.doctor.model import FittedModel
from estimator.doctor.simulation import RUNAWAY_GAP_RATIO, diverged
from estimator.signals import sweep_frequency_Hz

TIME_WINDOW_S = 0.5
WHITENESS_LEVEL = 0.01


@dataclass
class Localisation:
    """Where a fitted model disagrees with the measurement."""

    gap_m: float
    channel_rms_m: dict[str, float]
    equation_rms_N: dict[str, float]
    output_bands: Profile
    equation_bands: Profile
    by_variable: list[Profile]
    whiteness: dict[str, float]
    """Channel -> Ljung-Box p-value of the output-error residual (white above WHITENESS_LEVEL)."""
    spectra: dict[str, tuple[np.ndarray, np.ndarray]]
    """Channel -> (frequency Hz, one-sided power density m²/Hz) of the output-error residual."""
    worst_time_s: tuple[float, float]
    """The window of TIME_WINDOW_S where the output error (all channels) is largest."""

    def worst_channel(self) -> str:
        return max(self.channel_rms_m, key=lambda c: self.channel_rms_m[c])

    @property
    def white(self) -> list[str]:
        return [c for c, p in self.whiteness.items() if p > WHITENESS_LEVEL]

    def describe(self) -> str:
        """One sentence: channel, time and band of the sweep, equation and suspension velocity, whiteness."""
        if not np.isfinite(self.gap_m):
            return "the model diverges when driven by the measured plate"
        channel = self.worst_channel()
        if channel not in self.output_bands.values:  # its simulation ran away (simulation.diverged)
            band = f"where the model runs away from its motion (over {RUNAWAY_GAP_RATIO:g}× its RMS)"
        else:
            band = "in the {:g}-{:g} Hz part of the sweep".format(*self.output_bands.worst(channel))
        equation = max(self.equation_rms_N, key=lambda e: self.equation_rms_N[e])
        elo, ehi = self.equation_bands.worst(equation)
        vlo, vhi = self.by_variable[0].worst(equation)
        start, stop = self.worst_time_s
        return (
            f"gap {self.gap_m * 1e6:.1f} µm; largest on {channel} "
            f"({self.channel_rms_m[channel] * 1e6:.1f} µm RMS), at {start:.1f}-{stop:.1f} s, "
            f"{band}; largest equation residual: {equation} "
            f"({self.equation_rms_N[equation]:.1f} N RMS, {elo:g}-{ehi:g} Hz, most at suspension velocities "
            f"{vlo:+.3f}..{vhi:+.3f} m/s); output error "
            + ("white on " + ", ".join(self.white) if self.white else "not white on any channel")
        )


def locate(model: FittedModel, output_residual: dict[str, np.ndarray], gap_m: float) -> Localisation:
    """Residual analysis of one fitted model; output_residual: its output error per channel (m). A diverged
    simulation's residuals overflow to inf when squared, which is what it should say (without warnings)."""
    with np.errstate(over="ignore", invalid="ignore"):
        signals, index, filters = model.signals, model.system.sample_index, model.system.filters
        dt, measured = signals.sample_time_s, signals.recording.channels
        frequency = sweep_frequency_Hz(measured["x_r_l" if model.vehicle.is_axle else "x_r"], dt)
        finite = {c: r for c, r in output_residual.items() if not diverged(r, measured[c])}
        equations = dict(zip(signals.equations, model.residuals(), strict=True))
        corner = signals.corners[0]  # the left one of an axle
        variables = (
            ("suspension velocity", "m/s", corner.velocity_m_s),
            ("suspension deflection", "m", corner.deflection_m),
            ("tyre deflection", "m", corner.tyre_deflection_smooth_m),
        )
        worst_time = (float("nan"), float("nan"))
        if finite:
            power = np.mean([r**2 for r in finite.values()], axis=0)
            window = max(1, round(TIME_WINDOW_S / dt))
            start = int(np.argmax(np.convolve(power, np.ones(window) / window, mode="valid"))) * dt
            worst_time = (start, start + window * dt)
        return Localisation(
            gap_m=gap_m,
            channel_rms_m={c: float(np.sqrt(np.mean(r**2))) for c, r in output_residual.items()},
            equation_rms_N={e: float(np.sqrt(np.mean(r**2))) for e, r in equations.items()},
            output_bands=band_rms(finite, frequency, filters.excitation_top_Hz),
            equation_bands=band_rms(equations, frequency[index], filters.excitation_top_Hz),
            by_variable=[binned_rms(x[index], equations, label, unit) for label, unit, x in variables],
            whiteness={c: ljung_box(r, dt, filters.equation_cutoff_Hz) for c, r in finite.items()},
            spectra={
                c: welch_density(r - np.mean(r), 1.0 / dt, min(r.size, 2048)) for c, r in finite.items()
            },
            worst_time_s=worst_time,
        )
