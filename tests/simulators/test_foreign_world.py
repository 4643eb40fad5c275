"""The foreign world (simulators/foreign, issue 29 item 4): its physics is sane on its own, its effect laws
have the shapes they claim, its sensors do what the amplifier does, and its held-out draws are frozen:
regenerated here, they must reproduce the hashes of benchmarks/heldout/manifest.json (a world changed to suit
an estimator fails this test; re-freezing is in benchmarks/heldout/README.md).
Random cases come from fixed seeds; sweeps are short.
"""

from __future__ import annotations

import ast
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from daq.formats.recording_csv import read_recording_csv
from simulators.foreign.draws import CLASSES, DEV_ENTROPY, SIZE_UNITS, draw, realise
from simulators.foreign.effects import BumpStop, LuGreFriction, StribeckFriction
from simulators.foreign.manifest import MANIFEST, PROBE_SETTLE_S, PROBE_SWEEP_S, load_manifest
from simulators.foreign.physics import CORNER_STATES, ForeignVehicle, Physics
from simulators.foreign.sensors import Channel, ChannelNoise, FirstOrderLag, MovingAverage
from simulators.foreign.world import ForeignSettings, channels_sha256, measured_sha256, simulate
from simulators.independent.excitation import Chirp
from simulators.independent.files import write_recording
from simulators.independent.vehicles import GRAVITY_M_S2

PACKAGE = Path(__file__).resolve().parents[2] / "simulators" / "foreign"
QUIET = ChannelNoise("white", 0.0)
SHORT = ForeignSettings(chirp=Chirp(duration_s=1.0), settle_s=0.1)


def _short(label: str, index: int) -> ForeignVehicle:
    return draw(DEV_ENTROPY, label, index, sweep_s=1.0, settle_s=0.1).vehicle


def test_imports_nothing_from_the_product_but_simulators() -> None:
    for path in PACKAGE.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            names += [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            for name in names:
                assert name.split(".")[0] not in {"estimator", "drivers", "daq", "service"}, (
                    f"{path.name}: {name}"
                )


@pytest.mark.parametrize("label", ["asymmetric_axle", "hysteretic_friction", "bump_stop", "outside", "pair"])
def test_at_rest_it_is_in_equilibrium_and_internal_forces_balance(label: str) -> None:
    rng = np.random.default_rng(29)
    for index in range(4):
        vehicle = _short(label, index)
        still = Chirp(amplitude_m=0.0, duration_s=1.0)
        physics = Physics(vehicle, (still.motion, still.motion))
        if vehicle.forces.unrecorded is None:
            assert np.max(np.abs(physics(0.5, [0.0] * physics.state_size))) < 1e-10
        # any state: suspension, friction, bump stop, damper lag, bar and unrecorded forces are internal, so
        # the masses' accelerations sum to the contact forces minus the weight
        state = list(rng.normal(0.0, 1e-3, physics.state_size))
        rates = physics(0.7, state)
        base = vehicle.base
        accelerations = [rates[1]] + [
            rates[physics.body_states + i * CORNER_STATES + 1] for i in range(len(base.corners))
        ]
        masses = [base.sprung_mass_kg] + [c.unsprung_mass_kg for c in base.corners]
        contact = sum(f.contact_N for f in physics.corner_forces(0.7, state))
        momentum_rate = sum(m * a for m, a in zip(masses, accelerations, strict=True))
        assert momentum_rate == pytest.approx(contact - base.total_mass_kg * GRAVITY_M_S2, abs=1e-6)


def test_stribeck_peaks_above_the_sliding_level_and_dissipates() -> None:
    rng = np.random.default_rng(1)
    for _ in range(20):
        sliding = rng.uniform(5.0, 300.0)
        law = StribeckFriction(
            sliding, sliding * rng.uniform(1.2, 2.5), rng.uniform(0.003, 0.03), rng.uniform(1, 2)
        )
        velocity = np.linspace(-1.0, 1.0, 20001)
        resistance = np.array([law.resistance(float(v)) for v in velocity])
        assert np.all(resistance * velocity >= 0.0)  # it always resists
        assert resistance.max() > 1.1 * sliding  # a breakaway peak above the sliding level
        assert resistance.max() <= law.static_N + 1e-9
        far = law.resistance(20 * law.stribeck_velocity_m_s)
        assert far == pytest.approx(sliding, rel=1e-3)  # decays to the sliding level


@pytest.mark.parametrize("kind", ["dahl", "lugre"])
def test_hysteretic_friction_traces_a_loop_that_dissipates(kind: str) -> None:
    law = (
        LuGreFriction(100.0, 100.0, 0.01, 100.0 / 2e-4)
        if kind == "dahl"
        else LuGreFriction(100.0, 180.0, 0.01, 100.0 / 2e-4, 300.0, 50.0)
    )
    assert law.kind == kind
    omega, amplitude = 2 * math.pi * 2.0, 0.002

    def rate(t: float, y: list[float]) -> list[float]:
        return [law.state_rate(y[0], amplitude * omega * math.cos(omega * t))]

    t = np.linspace(0.0, 1.0, 20001)
    z = solve_ivp(rate, (0.0, 1.0), [0.0], method="LSODA", t_eval=t, rtol=1e-8, atol=1e-12).y[0]
    velocity = amplitude * omega * np.cos(omega * t)
    force = np.array([law.resistance(float(a), float(v)) for a, v in zip(z, velocity, strict=True)])
    last = t >= 0.5  # the last cycle, after the first loading
    work = np.trapezoid(force[last] * velocity[last], t[last])
    assert work > 0.0  # the loop's area: energy taken out per cycle
    assert np.max(np.abs(z)) <= 1.0001 * law.static_N / law.bristle_stiffness_N_per_m
    displacement = amplitude * np.sin(omega * t)
    up = last & (velocity > 0) & (np.abs(displacement) < 1e-4)
    down = last & (velocity < 0) & (np.abs(displacement) < 1e-4)
    assert force[up].mean() - force[down].mean() > 100.0  # two branches at the same displacement


def test_a_bump_stop_pushes_nothing_inside_its_clearance_and_stiffens_beyond() -> None:
    rng = np.random.default_rng(2)
    for law in ("exponential", "power"):
        for side in ("compression", "rebound"):
            stop = BumpStop(
                side, rng.uniform(5e-4, 6e-3), rng.uniform(1e4, 5e5), rng.uniform(1e-3, 5e-3), law, 2.2
            )
            inside = rng.uniform(-stop.clearance_m, stop.clearance_m, 200)
            assert all(stop.force(float(x)) == 0.0 for x in inside)
            sign = -1.0 if side == "compression" else 1.0
            travel = stop.clearance_m + np.linspace(1e-5, 5e-3, 200)
            force = np.array([stop.force(float(sign * x)) for x in travel])
            assert np.all(-sign * force > 0.0)  # it pushes back towards the static position
            assert np.all(np.diff(np.abs(force)) > 0) and np.all(np.diff(np.abs(force), 2) > 0)  # stiffening


def test_the_moving_average_averages_the_amplifier_samples_exactly() -> None:
    vehicle = _short("clean", 1)
    average = MovingAverage(16)
    channels = {"x_r": Channel(average, 1.0, QUIET, 0.0)}
    world = simulate(vehicle, channels, SHORT, 0).world
    chirp = SHORT.chirp
    for k in (137, 512, 900):
        t = world.time_s[k]
        last = math.floor(t / average.period_s + 1e-9)
        ticks = [(last - i) * average.period_s for i in range(16)]
        expected = np.mean([chirp.motion(x)[0] for x in ticks])
        assert world.measured["x_r"][k] == pytest.approx(expected, abs=1e-15)


def test_the_first_order_lag_has_the_lag_s_gain_and_phase() -> None:
    tau, frequency, step = 0.004, 15.0, 1e-4
    t = np.arange(0.0, 1.0, step)
    lagged = FirstOrderLag(tau).apply(np.sin(2 * math.pi * frequency * t), step)
    wt = 2 * math.pi * frequency * tau
    expected = np.sin(2 * math.pi * frequency * t - math.atan(wt)) / math.sqrt(1 + wt * wt)
    # exact for an input linear between the points: a sine's curvature costs (ω·step)²/8 of its amplitude
    np.testing.assert_allclose(
        lagged[t > 0.1], expected[t > 0.1], atol=(2 * math.pi * frequency * step) ** 2 / 8
    )


def test_gain_scales_the_reading_and_500_hz_is_read_back_on_its_grid(tmp_path: Path) -> None:
    vehicle = _short("clean", 0)
    settings = replace(SHORT, sample_time_s=0.002)
    channels = {"x_t" if not vehicle.is_axle else "x_t_l": Channel(None, 1.12, QUIET, 0.0)}
    world = simulate(vehicle, channels, settings, 0).world
    name = next(iter(channels))
    np.testing.assert_allclose(world.measured[name], 1.12 * world.true[name], rtol=1e-12, atol=1e-15)
    plain = simulate(vehicle, {}, settings, 0).world
    write_recording(plain, tmp_path / "r.csv", tmp_path / "v.toml")
    recording = read_recording_csv(tmp_path / "r.csv")
    assert recording.sample_time_s == pytest.approx(0.002)
    assert recording.time_s.size == round(1.1 / 0.002) + 1
    assert channels_sha256(recording.sample_time_s, recording.channels) == measured_sha256(plain)


@pytest.mark.parametrize("kind", ["white", "ar1", "pink"])
def test_noise_has_the_drawn_rms_and_colour(kind: str) -> None:
    rho = 0.7 if kind == "ar1" else 0.0
    noise = ChannelNoise(kind, 6e-6, rho).draw(2**17, 0.001, np.random.default_rng(3))  # type: ignore[arg-type]
    assert float(np.sqrt(np.mean(noise**2))) == pytest.approx(6e-6, rel=0.02)
    lag1 = float(np.corrcoef(noise[:-1], noise[1:])[0, 1])
    if kind != "pink":
        assert lag1 == pytest.approx(rho, abs=0.02)
        return
    spectrum = np.abs(np.fft.rfft(noise)) ** 2
    frequency = np.fft.rfftfreq(noise.size, 0.001)
    band = (frequency > 1.0) & (frequency < 200.0)
    slope = np.polyfit(np.log(frequency[band]), np.log(spectrum[band]), 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.1)


def test_draws_are_reproducible_and_carry_their_truth() -> None:
    for label in CLASSES:
        first, again = draw(DEV_ENTROPY, label, 3), draw(DEV_ENTROPY, label, 3)
        assert first.effects == again.effects and _key(first.vehicle) == _key(again.vehicle)
        expected = {"clean": 0, "pair": 2}.get(label, 1)
        assert len(first.effects) == expected
        assert all(e.effect in SIZE_UNITS for e in first.effects)
        assert first.vehicle.is_axle or label != "asymmetric_axle"
    assert _key(draw(DEV_ENTROPY, "clean", 0).vehicle) != _key(draw(DEV_ENTROPY + 1, "clean", 0).vehicle)


def _key(vehicle: ForeignVehicle) -> tuple[float, ...]:
    corners = vehicle.base.corners
    return (vehicle.base.sprung_mass_kg, vehicle.com_offset_m, *(c.spring_N_per_m for c in corners))


def test_a_force_effect_s_size_is_measured_on_its_recording() -> None:
    _, truth = realise(draw(DEV_ENTROPY, "stribeck_friction", 0, sweep_s=1.0, settle_s=0.1))
    (effect,) = truth["effects"]
    assert 0.0 < effect["size"] < 5.0 and effect["size_unit"] == SIZE_UNITS["stribeck_friction"]
    assert truth["true_vs_stated"]["spring_N_per_m"][0] == pytest.approx(
        truth["stated"]["spring_stiffness_N_per_m"], rel=1e-4
    )


@pytest.mark.parametrize(
    "frozen",
    [MANIFEST, *(MANIFEST.with_name(f"manifest-{n}.json") for n in (2, 3, 4, 5, 6, 7, 8))],
    ids=lambda p: p.name,
)
def test_the_held_out_draws_reproduce_their_frozen_hashes(frozen: Path) -> None:
    manifest = load_manifest(frozen)
    entropy = int(manifest["entropy"], 16)
    versions = f"frozen with numpy {manifest['frozen']['numpy']}, scipy {manifest['frozen']['scipy']}"
    probes = manifest["probes"]
    assert (probes["sweep_s"], probes["settle_s"]) == (PROBE_SWEEP_S, PROBE_SETTLE_S)
    for label in CLASSES:
        recording, _ = realise(
            draw(entropy, label, probes["index"], "heldout", PROBE_SWEEP_S, PROBE_SETTLE_S)
        )
        assert measured_sha256(recording.world) == probes["sha256"][label], (
            f"probe {label} changed ({versions})"
        )
    cheapest = min(manifest["draws"], key=lambda i: manifest["draws"][i]["solver_evaluations"])
    _, label, index = cheapest.split("/")
    recording, _ = realise(draw(entropy, label, int(index), "heldout"))
    assert measured_sha256(recording.world) == manifest["draws"][cheapest]["sha256"], (
        f"{cheapest} ({versions})"
    )
    assert sum(len(ids) for ids in manifest["classes"].values()) == len(manifest["draws"])
