"""Random lab rigs and their runs, from fixed seeds.

The ranges are those of real desktop quarter-car rigs (educational active-suspension rigs and their
published parameter sets: a body of a few kilograms on a coil spring of a few hundred N/m, a wheel carriage
of about a kilogram on a stiffer "tyre" spring):

| quantity | range |
|---|---|
| sprung mass | 1.5-4 kg |
| unsprung mass | 0.5-1.5 kg |
| suspension spring | 500-1500 N/m (the data sheet: ×0.2-0.6 or ×1.4-1.8) |
| tyre spring | 1500-5000 N/m (the data sheet: ×0.2-0.6 or ×1.4-1.8, drawn apart from the spring's) |
| tyre pad loss | 2-10 N·s/m, relaxation 2-10 ms |
| damper | 3-15 N·s/m, guide friction 0.1-0.5 N sliding, breakaway ×1.2-2, Stribeck speed 2-10 mm/s |
| voice coil | skyhook 0-10 N·s/m, lag 1-4 ms, cogging 0.05-0.3 N over a 4-12 mm pitch |
| coil command | reference 0.1-0.5 N RMS over 0.3-8 Hz, its own realisation per run |
| cable drag | 0.05-0.3 N, pre-sliding over 0.2-1 mm |
| bearings (frame) | body and wheel 0.02-0.2 N sliding, breakaway ×1-1.8 |
| lasers | 2-10 µm RMS, white or AR(1) with ρ 0.3-0.9 (half each), 1 µm resolution, 500 Hz |

The coil's share is set to the measured rig's class (issue 29: rates left free, a least-squares fit came
to about 35% of the response RMS on held-out runs): on dev rigs 0-9, mass-only `identify` on run A
validated on run B gives a median of 34% (16-59%). A first version with skyhook 0-15 N·s/m and a 0.2-1 N
reference gave 42% there.

Runs of every rig: A, a 0-20 Hz chirp of ±1.5-4 mm; B, a random road (band 0.5 Hz to 12-20 Hz, amplitude
falling as 1/f, 0.7-1.5 mm RMS); C, up to six bumps and step pairs of 1-4 mm. Each lasts `run_s` plus
1 s of settling.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simulators.independent.excitation import Chirp
from simulators.independent.sensors import SensorNoise
from simulators.lab_rig.rig import Actuator, CableDrag, Friction, LabRig
from simulators.lab_rig.signals import Multisine, Steps
from simulators.lab_rig.world import SAMPLE_TIME_S, LabRun, RunSpec, simulate_run

SETTLE_S = 1.0
WRONG_BELOW = (0.2, 0.6)
WRONG_ABOVE = (1.4, 1.8)
"""The data sheet's rate over the true one: 40-80% off, below or above."""
REFERENCE_BAND_HZ = (0.3, 8.0)


@dataclass(frozen=True)
class RigDraw:
    """One rig and its runs (A: chirp, B: random road, C: bumps), the lasers' noise and sampling."""

    seed: int
    rig: LabRig
    runs: tuple[RunSpec, ...]
    noise: SensorNoise
    sample_time_s: float = SAMPLE_TIME_S

    def run(self, name: str) -> RunSpec:
        for spec in self.runs:
            if spec.name == name:
                return spec
        raise KeyError(f"rig {self.seed} has no run {name!r} (runs: {', '.join(s.name for s in self.runs)})")

    def simulate(self, name: str, unrecorded: bool = True) -> LabRun:
        return simulate_run(self.rig, self.run(name), self.noise, self.sample_time_s, unrecorded)

    def describe(self) -> str:
        r = self.rig
        return (
            f"rig {self.seed}: {r.sprung_mass_kg:.2f} + {r.unsprung_mass_kg:.2f} kg, spring "
            f"{r.spring_N_per_m:.0f} N/m (stated ×{r.stated_spring_factor:.2f}), "
            f"tyre {r.tyre_N_per_m:.0f} N/m (stated ×{r.stated_tyre_factor:.2f}), "
            f"damper {r.damper_Ns_per_m:.1f} N·s/m + "
            f"{r.damper_friction.sliding_N:.2f} N, skyhook {r.actuator.skyhook_Ns_per_m:.1f} N·s/m, noise "
            f"{self.noise.rms_m * 1e6:.1f} µm (ρ {self.noise.lag1_correlation:.2f})"
        )


def _wrong_factor(rng: np.random.Generator) -> float:
    return float(rng.uniform(*(WRONG_ABOVE if rng.random() < 0.5 else WRONG_BELOW)))


def _friction(
    rng: np.random.Generator, sliding_N: tuple[float, float], breakaway: tuple[float, float]
) -> Friction:
    sliding = float(rng.uniform(*sliding_N))
    return Friction(sliding, sliding * float(rng.uniform(*breakaway)), float(rng.uniform(0.002, 0.01)))


def draw_lab_rig(rng: np.random.Generator) -> LabRig:
    """A rig over the ranges of the module docstring."""
    cable_level = float(rng.uniform(0.05, 0.3))
    return LabRig(
        sprung_mass_kg=float(rng.uniform(1.5, 4.0)),
        unsprung_mass_kg=float(rng.uniform(0.5, 1.5)),
        spring_N_per_m=float(rng.uniform(500.0, 1500.0)),
        tyre_N_per_m=float(rng.uniform(1500.0, 5000.0)),
        tyre_loss_Ns_per_m=float(rng.uniform(2.0, 10.0)),
        tyre_loss_relaxation_s=float(rng.uniform(0.002, 0.01)),
        damper_Ns_per_m=float(rng.uniform(3.0, 15.0)),
        damper_friction=_friction(rng, (0.1, 0.5), (1.2, 2.0)),
        actuator=Actuator(
            skyhook_Ns_per_m=float(rng.uniform(0.0, 10.0)),
            lag_s=float(rng.uniform(0.001, 0.004)),
            cogging_N=float(rng.uniform(0.05, 0.3)),
            cogging_pitch_m=float(rng.uniform(0.004, 0.012)),
        ),
        cable=CableDrag(cable_level, cable_level / float(rng.uniform(2e-4, 1e-3))),
        body_bearing=_friction(rng, (0.02, 0.2), (1.0, 1.8)),
        wheel_bearing=_friction(rng, (0.02, 0.2), (1.0, 1.8)),
        stated_spring_factor=_wrong_factor(rng),
        stated_tyre_factor=_wrong_factor(rng),
    )


def draw_rig(seed: int, run_s: float = 16.0) -> RigDraw:
    """Rig `seed` with its three runs, each `run_s` of input and SETTLE_S of settling."""
    rng = np.random.default_rng([29, 5, seed])  # issue 29, item 5
    rig = draw_lab_rig(rng)
    coloured = rng.random() < 0.5
    noise = SensorNoise(
        float(rng.uniform(2e-6, 10e-6)), float(rng.uniform(0.3, 0.9)) if coloured else 0.0, 1e-6
    )
    reference_rms_N = float(rng.uniform(0.1, 0.5))
    fade_s = min(0.5, run_s / 8.0)

    def reference() -> Multisine:
        return Multisine.random(rng, REFERENCE_BAND_HZ, reference_rms_N, run_s, fade_s=fade_s)

    amplitude_m = float(rng.uniform(0.0015, 0.004))
    chirp = Chirp(0.0, 20.0, amplitude_m, run_s, min(0.3, run_s / 8.0))
    top_Hz = float(rng.uniform(12.0, 20.0))
    road_rms_m = float(rng.uniform(0.0007, 0.0015))
    road = Multisine.random(rng, (0.5, top_Hz), road_rms_m, run_s, components=80, slope=1.0, fade_s=fade_s)
    bumps = Steps.random(rng, run_s, (0.001, 0.004))
    seeds = [int(s) for s in rng.integers(0, 2**31, size=3)]
    total_s = run_s + SETTLE_S
    runs = (
        RunSpec(
            "A",
            chirp,
            reference(),
            total_s,
            seeds[0],
            f"chirp 0-20 Hz ±{amplitude_m * 1e3:.1f} mm over {run_s:g} s",
            {"sweep_start_Hz": "0", "sweep_stop_Hz": "20"},
        ),
        RunSpec(
            "B",
            road,
            reference(),
            total_s,
            seeds[1],
            f"random road 0.5-{top_Hz:.0f} Hz {road_rms_m * 1e3:.2f} mm RMS over {run_s:g} s",
        ),
        RunSpec(
            "C", bumps, reference(), total_s, seeds[2], f"{len(bumps.start_s) // 2} bumps and steps of 1-4 mm"
        ),
    )
    return RigDraw(seed, rig, runs, noise)
