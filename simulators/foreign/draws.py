"""Random draws of the foreign world, by class, from a namespace's SeedSequence entropy (a DEV namespace for
designing, a HELD-OUT one frozen in benchmarks/heldout/manifest.json).

A draw is a random vehicle (the independent world's vehicle draws: a car, van or motorcycle corner, or a car
axle in a fifth of the draws), a random test (12 s sweep 0-20 Hz ±4 mm; 500 Hz or 1 kHz; white, AR(1) or
1/f-like noise of 2-10 µm RMS per channel, one kind per draw; 1 µm resolution) and the effect(s) of its class
with a size drawn log-uniformly over a range that runs from undetectable to obvious.

Classes: "clean"; one effect (SINGLE_EFFECTS); "pair" (two of PAIRABLE, not two frictions nor two filters);
"outside" (one of OUTSIDE_EFFECTS, which no catalogue family of the model doctor describes).

Each effect's truth carries its parameters and a scalar size (SIZE_UNITS):
- force effects (friction, bump stops, damper lag, unrecorded force): the RMS of the effect's force over the
  RMS of the suspension's dynamic force K_s·ζ + f_d(ζ') in the same recording (largest over the corners),
  measured on the simulated recording (a bump stop never touched has size 0);
- sensor filters: the equivalent delay in ms (τ of a lag, the group delay of a moving average);
- gain and stated rates: the relative error |factor − 1|;
- asymmetric axle: the largest relative left/right difference of unsprung mass, spring rate, static load.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from simulators.foreign.effects import (
    BumpStop,
    DamperLag,
    LuGreFriction,
    StribeckFriction,
    UnrecordedForce,
)
from simulators.foreign.physics import ForeignVehicle
from simulators.foreign.sensors import Channel, ChannelNoise, FirstOrderLag, MovingAverage
from simulators.foreign.world import ForeignRecording, ForeignSettings, StatedErrors, channel_names, simulate
from simulators.independent.cases import random_vehicle
from simulators.independent.excitation import Chirp
from simulators.independent.vehicles import GRAVITY_M_S2
from simulators.independent.world import AXLE_NAMES, QUARTER_CAR_NAMES

SINGLE_EFFECTS = (
    "stribeck_friction",
    "hysteretic_friction",
    "bump_stop",
    "sensor_lag",
    "sensor_average",
    "sensor_gain",
    "spring_rate",
    "tyre_rate",
    "asymmetric_axle",
)
OUTSIDE_EFFECTS = ("damper_lag", "unrecorded_force")
CLASSES = ("clean", *SINGLE_EFFECTS, "pair", "outside")
CLASS_KEYS = {label: number for number, label in enumerate(CLASSES)}
"""A class's number in the draw's SeedSequence spawn key: frozen (a new class takes a new number)."""
PAIRABLE = SINGLE_EFFECTS[:-1]
EXCLUSIVE = (
    frozenset({"stribeck_friction", "hysteretic_friction"}),
    frozenset({"sensor_lag", "sensor_average"}),
)
FORCE_SHARE = "RMS effect force / RMS suspension dynamic force"
SIZE_UNITS = {
    "stribeck_friction": FORCE_SHARE,
    "hysteretic_friction": FORCE_SHARE,
    "bump_stop": FORCE_SHARE,
    "damper_lag": FORCE_SHARE,
    "unrecorded_force": FORCE_SHARE,
    "sensor_lag": "equivalent delay (ms)",
    "sensor_average": "equivalent delay (ms)",
    "sensor_gain": "|gain - 1|",
    "spring_rate": "|stated/true - 1|",
    "tyre_rate": "|stated/true - 1|",
    "asymmetric_axle": "largest |right/left - 1| of unsprung mass, spring rate, static load",
}
FORCE_KEYS = {
    "stribeck_friction": "friction",
    "hysteretic_friction": "friction",
    "bump_stop": "bump",
    "damper_lag": "lag_excess",
    "unrecorded_force": "unrecorded",
}
"""Which of ForeignRecording.effect_forces_N measures a force effect's size."""
DEV_ENTROPY = 0x5EED_F0E1_6000_0000_0000_0000_0000_0001
"""The DEV namespace (design on it freely: draw indices 0-9999). The held-out entropy is not in the code:
it is in benchmarks/heldout/manifest.json."""
SWEEP_S = 12.0
AXLE_SHARE = 0.2


@dataclass(frozen=True)
class EffectTruth:
    """A hidden effect: its physical name (SIZE_UNITS' keys), its parameters and its size."""

    effect: str
    parameters: dict[str, Any]
    size: float | None = None
    """None until the recording is simulated, for the force effects."""

    def to_json(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "parameters": self.parameters,
            "size": self.size,
            "size_unit": SIZE_UNITS[self.effect],
        }


@dataclass(frozen=True)
class Draw:
    """One draw: its id ("<namespace>/<class>/<index>"), class, the true vehicle and its force effects, the
    laser channels, the test, what the vehicle file gets wrong, the effects' truth, the noise's seed."""

    draw_id: str
    label: str
    vehicle: ForeignVehicle
    channels: dict[str, Channel]
    settings: ForeignSettings
    stated_errors: StatedErrors
    effects: tuple[EffectTruth, ...]
    noise_seed: np.random.SeedSequence = field(repr=False)


@dataclass
class _Builder:
    """A draw under construction: what each effect changes."""

    vehicle: ForeignVehicle
    channels: dict[str, Channel]
    stated: StatedErrors = field(default_factory=StatedErrors)
    effects: list[EffectTruth] = field(default_factory=list)


def _log_uniform(rng: np.random.Generator, low: float, high: float) -> float:
    return float(math.exp(rng.uniform(math.log(low), math.log(high))))


def _signed_factor(rng: np.random.Generator, low: float, high: float) -> float:
    error = _log_uniform(rng, low, high)
    return 1.0 + error if rng.random() < 0.5 else 1.0 - error


def _reference_force_N(builder: _Builder) -> float:
    damper = builder.vehicle.base.corners[0].damper
    return 0.5 * (abs(damper.force(0.1)) + abs(damper.force(-0.1)))


def _friction(effect: str, b: _Builder, rng: np.random.Generator) -> None:
    reference = _reference_force_N(b)
    sliding = reference * _log_uniform(rng, 0.01, 0.4)
    viscous = rng.uniform(0.0, 0.1) * reference / 0.1
    forces = b.vehicle.forces
    if effect == "stribeck_friction":
        law = StribeckFriction(
            sliding,
            sliding * rng.uniform(1.2, 2.5),
            _log_uniform(rng, 0.003, 0.03),
            rng.uniform(1.0, 2.0),
            viscous,
            smoothing_m_s=0.00075,
        )
        b.vehicle = replace(b.vehicle, forces=replace(forces, stribeck=law))
        parameters = {
            "law": "stribeck",
            "sliding_N": law.sliding_N,
            "static_N": law.static_N,
            "stribeck_velocity_m_s": law.stribeck_velocity_m_s,
            "shape_exponent": law.shape_exponent,
            "viscous_Ns_per_m": law.viscous_Ns_per_m,
            "sign_smoothing_m_s": law.smoothing_m_s,
        }
    else:
        sigma0 = sliding / _log_uniform(rng, 1e-4, 5e-4)
        if rng.random() < 0.5:
            lugre = LuGreFriction(sliding, sliding, 0.01, sigma0)
        else:
            unsprung = b.vehicle.base.corners[0].unsprung_mass_kg
            lugre = LuGreFriction(
                sliding,
                sliding * rng.uniform(1.2, 2.5),
                _log_uniform(rng, 0.003, 0.03),
                sigma0,
                rng.uniform(0.0, 0.5) * math.sqrt(sigma0 * unsprung),
                viscous,
            )
        b.vehicle = replace(b.vehicle, forces=replace(forces, lugre=lugre))
        parameters = {
            "law": lugre.kind,
            "sliding_N": lugre.sliding_N,
            "static_N": lugre.static_N,
            "stribeck_velocity_m_s": lugre.stribeck_velocity_m_s,
            "bristle_stiffness_N_per_m": sigma0,
            "presliding_m": lugre.presliding_m,
            "bristle_damping_Ns_per_m": lugre.bristle_damping_Ns_per_m,
            "viscous_Ns_per_m": lugre.viscous_Ns_per_m,
        }
    b.effects.append(EffectTruth(effect, parameters))


def _bump_stop(b: _Builder, rng: np.random.Generator) -> None:
    spring = b.vehicle.base.corners[0].spring_N_per_m
    choice = rng.random()
    sides = (
        ("compression",) if choice < 0.5 else ("rebound",) if choice < 0.75 else ("compression", "rebound")
    )
    stops = []
    for side in sides:
        power = rng.random() < 0.5
        stops.append(
            BumpStop(
                side,
                _log_uniform(rng, 5e-4, 6e-3),
                spring * _log_uniform(rng, 0.5, 20.0),
                _log_uniform(rng, 1e-3, 5e-3),
                "power" if power else "exponential",
                rng.uniform(1.5, 3.0) if power else 1.0,
            )
        )
    b.vehicle = replace(b.vehicle, forces=replace(b.vehicle.forces, bump_stops=tuple(stops)))
    parameters = {
        "stops": [
            {
                "side": s.side,
                "clearance_m": s.clearance_m,
                "stiffness_N_per_m": s.stiffness_N_per_m,
                "length_m": s.length_m,
                "law": s.law,
                "exponent": s.exponent,
            }
            for s in stops
        ]
    }
    b.effects.append(EffectTruth("bump_stop", parameters))


def _sensor(effect: str, b: _Builder, rng: np.random.Generator) -> None:
    names = channel_names(b.vehicle)
    name = str(rng.choice(names))
    channel = b.channels[name]
    if effect == "sensor_lag":
        lag = FirstOrderLag(_log_uniform(rng, 1e-4, 1e-2))
        b.channels[name] = replace(channel, filter=lag)
        parameters: dict[str, Any] = {
            "channel": name,
            "filter": "first_order",
            "time_constant_s": lag.time_constant_s,
        }
        size = 1e3 * lag.equivalent_delay_s
    elif effect == "sensor_average":
        average = MovingAverage(int(2 ** rng.integers(1, 8)))
        b.channels[name] = replace(channel, filter=average)
        parameters = {
            "channel": name,
            "filter": "moving_average",
            "count": average.count,
            "period_s": average.period_s,
        }
        size = 1e3 * average.equivalent_delay_s
    else:
        gain = _signed_factor(rng, 0.003, 0.15)
        b.channels[name] = replace(channel, gain=gain)
        parameters, size = {"channel": name, "gain": gain}, abs(gain - 1.0)
    b.effects.append(EffectTruth(effect, parameters, size))


def _stated(effect: str, b: _Builder, rng: np.random.Generator) -> None:
    factor = _signed_factor(rng, 0.01, 0.6)
    corner = b.vehicle.base.corners[0]
    if effect == "spring_rate":
        b.stated = replace(b.stated, spring_factor=factor)
        true = corner.spring_N_per_m
    else:
        b.stated = replace(b.stated, tyre_factor=factor)
        true = corner.tyre_N_per_m
    b.effects.append(
        EffectTruth(
            effect,
            {"true_N_per_m": true, "stated_N_per_m": true * factor, "factor": factor},
            abs(factor - 1.0),
        )
    )


def _asymmetry(b: _Builder, rng: np.random.Generator) -> None:
    magnitude = _log_uniform(rng, 0.01, 0.4)
    ratios = [1.0 + magnitude * rng.uniform(0.3, 1.0) * float(rng.choice([-1.0, 1.0])) for _ in range(3)]
    unsprung, spring, load = ratios
    left, right = b.vehicle.base.corners
    right = replace(
        right, unsprung_mass_kg=left.unsprung_mass_kg * unsprung, spring_N_per_m=left.spring_N_per_m * spring
    )
    offset = b.vehicle.base.track_m * (1.0 / load - 1.0) / (2.0 * (1.0 / load + 1.0))  # P_r/P_l = load
    b.vehicle = replace(b.vehicle, base=replace(b.vehicle.base, corners=(left, right)), com_offset_m=offset)
    parameters = {
        "unsprung_ratio": unsprung,
        "spring_ratio": spring,
        "static_load_ratio": load,
        "com_offset_m": offset,
    }
    b.effects.append(EffectTruth("asymmetric_axle", parameters, float(max(abs(r - 1.0) for r in ratios))))


def _outside(effect: str, b: _Builder, rng: np.random.Generator) -> None:
    if effect == "damper_lag":
        tau = _log_uniform(rng, 2e-4, 1e-2)
        damper = b.vehicle.base.corners[0].damper
        slope = (damper.force(0.1) - damper.force(-0.1)) / 0.2
        lag = (
            DamperLag("first_order", tau)
            if rng.random() < 0.5
            else DamperLag("series_stiffness", 0.0, slope / tau)
        )
        parameters = {
            "kind": lag.kind,
            "time_constant_s": tau,
            "series_stiffness_N_per_m": lag.series_stiffness_N_per_m,
        }
        b.vehicle = replace(b.vehicle, forces=replace(b.vehicle.forces, damper_lag=lag))
    else:
        corner_weight = b.vehicle.base.sprung_mass_kg / len(b.vehicle.base.corners) * GRAVITY_M_S2
        rms = corner_weight * _log_uniform(rng, 0.003, 0.1)
        count = 5
        force = UnrecordedForce(
            tuple([rms * math.sqrt(2.0 / count)] * count),
            tuple(_log_uniform(rng, 0.3, 15.0) for _ in range(count)),
            tuple(rng.uniform(0.0, 2.0 * math.pi) for _ in range(count)),
        )
        parameters = {
            "rms_N": force.rms_N,
            "frequencies_Hz": list(force.frequencies_Hz),
            "amplitudes_N": list(force.amplitudes_N),
            "phases_rad": list(force.phases_rad),
        }
        b.vehicle = replace(b.vehicle, forces=replace(b.vehicle.forces, unrecorded=force))
    b.effects.append(EffectTruth(effect, parameters))


def _add(effect: str, b: _Builder, rng: np.random.Generator) -> None:
    if effect in ("stribeck_friction", "hysteretic_friction"):
        _friction(effect, b, rng)
    elif effect == "bump_stop":
        _bump_stop(b, rng)
    elif effect in ("sensor_lag", "sensor_average", "sensor_gain"):
        _sensor(effect, b, rng)
    elif effect in ("spring_rate", "tyre_rate"):
        _stated(effect, b, rng)
    elif effect == "asymmetric_axle":
        _asymmetry(b, rng)
    elif effect in OUTSIDE_EFFECTS:
        _outside(effect, b, rng)
    else:
        raise ValueError(f"unknown effect {effect!r}")


def draw(
    entropy: int,
    label: str,
    index: int,
    namespace: str = "dev",
    sweep_s: float = SWEEP_S,
    settle_s: float = 1.0,
) -> Draw:
    """Draw `index` of class `label` in the namespace of `entropy` (its name only labels the draw id). A
    shorter sweep_s or settle_s (a test's probe) changes the test only, not the vehicle or the effects."""
    if label not in CLASS_KEYS:
        raise ValueError(f"unknown class {label!r}; expected one of {', '.join(CLASSES)}")
    if index < 0:
        raise ValueError(f"a draw index is >= 0, got {index}")
    parameters_seed, noise_seed = np.random.SeedSequence(entropy, spawn_key=(CLASS_KEYS[label], index)).spawn(
        2
    )
    rng = np.random.default_rng(parameters_seed)
    axle = label == "asymmetric_axle" or rng.random() < AXLE_SHARE
    base = random_vehicle(rng, axle=axle)
    kind = str(rng.choice(["white", "ar1", "pink"]))
    rho = rng.uniform(0.3, 0.9) if kind == "ar1" else 0.0
    names = AXLE_NAMES if axle else QUARTER_CAR_NAMES
    channels = {n: Channel(noise=ChannelNoise(kind, rng.uniform(2e-6, 10e-6), rho)) for n in names}  # type: ignore[arg-type]
    settings = ForeignSettings(
        chirp=Chirp(0.0, 20.0, 0.004, sweep_s),
        settle_s=settle_s,
        sample_time_s=float(rng.choice([0.001, 0.002])),
    )
    builder = _Builder(ForeignVehicle(base), channels)
    if label == "pair":
        while True:
            first, second = (str(e) for e in rng.choice(PAIRABLE, size=2, replace=False))
            if frozenset({first, second}) not in EXCLUSIVE:
                break
        hidden: tuple[str, ...] = (first, second)
    elif label == "outside":
        hidden = (str(rng.choice(OUTSIDE_EFFECTS)),)
    else:
        hidden = () if label == "clean" else (label,)
    for effect in hidden:
        _add(effect, builder, rng)
    return Draw(
        f"{namespace}/{label}/{index}",
        label,
        builder.vehicle,
        builder.channels,
        settings,
        builder.stated,
        tuple(builder.effects),
        noise_seed,
    )


def realise(d: Draw) -> tuple[ForeignRecording, dict[str, Any]]:
    """Simulate a draw; its truth record with every effect's size filled in."""
    recording = simulate(d.vehicle, d.channels, d.settings, d.noise_seed, d.stated_errors)
    effects = [
        replace(e, size=recording.force_share(FORCE_KEYS[e.effect])) if e.size is None else e
        for e in d.effects
    ]
    return recording, truth_record(replace(d, effects=tuple(effects)), recording)


def truth_record(d: Draw, recording: ForeignRecording) -> dict[str, Any]:
    """What the draw hides and what the vehicle file says, JSON-ready."""
    base = d.vehicle.base
    corners = [
        {
            "damper": c.damper.name,
            "unsprung_mass_kg": c.unsprung_mass_kg,
            "spring_N_per_m": c.spring_N_per_m,
            "tyre_N_per_m": c.tyre_N_per_m,
            "maxwell_damping_Ns_per_m": c.maxwell_damping_Ns_per_m,
            "maxwell_relaxation_s": c.maxwell_relaxation_s,
        }
        for c in base.corners
    ]
    stated = recording.world.stated
    return {
        "id": d.draw_id,
        "class": d.label,
        "effects": [e.to_json() for e in d.effects],
        "vehicle": {
            "kind": base.kind,
            "sprung_mass_kg": base.sprung_mass_kg,
            "corners": corners,
            "roll_inertia_kg_m2": base.roll_inertia_kg_m2,
            "track_m": base.track_m,
            "anti_roll_bar_N_per_m": base.anti_roll_bar_N_per_m,
            "com_offset_m": d.vehicle.com_offset_m,
        },
        "stated": stated,
        "true_vs_stated": {
            "mass_kg": [base.total_mass_kg, stated["mass_kg"]],
            "spring_N_per_m": [base.corners[0].spring_N_per_m, stated["spring_stiffness_N_per_m"]],
            "tyre_N_per_m": [base.corners[0].tyre_N_per_m, stated["tyre_stiffness_N_per_m"]],
        },
        "test": {
            "sample_time_s": d.settings.sample_time_s,
            "sweep_s": d.settings.chirp.duration_s,
            "noise": {
                n: {
                    "kind": c.noise.kind,
                    "rms_m": c.noise.rms_m,
                    "lag1_correlation": c.noise.lag1_correlation,
                }
                for n, c in d.channels.items()
            },
        },
        "airborne_fraction": recording.world.airborne_fraction,
    }
