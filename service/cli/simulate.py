"""`shockbench simulate`: write a simulated recording of a sweep (the physics simulator on a vehicle file),
and `shockbench demo` (its parser is registered with identify). The one CLI module that uses the offline
physics simulator."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from estimator.sweep import SweepSettings
from estimator.vehicle import TyreModel
from service.cli.errors import CliError
from service.cli.options import add_option

if TYPE_CHECKING:
    from simulators.vehicle_sim import SimulatedVehicle, SimulationSettings

DAMPER_CHOICES = "valve (embedded valve-model damper), paper-tanh (the paper's Table 3), or a CSV table path"


def damper_from_option(value: str):
    """--damper: 'valve', 'valve-weak', 'paper-tanh', or a velocity_m_s,force_N CSV file."""
    from simulators.dampers import PAPER_TANH_MAXWELL, load_table, valve_damper

    if value == "valve":
        return valve_damper()
    if value == "valve-weak":
        return valve_damper(
            bleed_Ns_per_m=3000.0,
            blowoff_extension_N=300.0,
            blowoff_compression_N=180.0,
            high_speed_extension_Ns_per_m=1200.0,
            high_speed_compression_Ns_per_m=600.0,
        )
    if value == "paper-tanh":
        return PAPER_TANH_MAXWELL
    path = Path(value)
    if not path.is_file():
        raise CliError(f"--damper {value!r}: not {DAMPER_CHOICES}")
    try:
        return load_table(path)
    except (KeyError, ValueError) as exc:
        raise CliError(f"--damper {value}: not a velocity_m_s,force_N table ({exc})") from None


def add_simulation_options(p: argparse.ArgumentParser) -> None:
    """The simulation's options; the unit-bearing ones spelled as `sweep` spells them, their spellings before
    that still accepted (service.cli.options)."""
    add_option(
        p,
        "--duration-s",
        formerly="--seconds",
        type=float,
        default=20.0,
        help="sweep duration, s (default 20)",
    )
    add_option(
        p,
        "--settle-s",
        formerly="--settle",
        type=float,
        default=1.0,
        help="recorded after the sweep, s (default 1)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed of the sensor noise (default 0)")
    p.add_argument(
        "--noise-m", type=float, default=5e-6, help="sensor noise standard deviation, m (default 5e-6)"
    )
    p.add_argument("--resolution-m", type=float, default=1e-6, help="sensor resolution, m (default 1e-6)")
    add_option(
        p,
        "--amplitude-mm",
        formerly="--amplitude-m",
        factor=1e3,
        unit="mm",
        type=float,
        default=4.0,
        help="plate amplitude, 0-peak, mm (default 4)",
    )
    p.add_argument("--stop-hz", type=float, default=20.0, help="sweep end frequency, Hz (default 20)")
    p.add_argument("--damper", default="valve", help=f"the damper: {DAMPER_CHOICES} (default valve)")
    p.add_argument("--damper-right", default="valve-weak", help="axle: the right damper (default valve-weak)")
    p.add_argument(
        "--sprung-fraction", type=float, default=0.89, help="true sprung share of mass_kg (default 0.89)"
    )
    add_option(
        p,
        "--tyre-damping-ns-per-m",
        formerly="--tyre-damping",
        type=float,
        default=1500.0,
        help="true tyre damping C_d, N·s/m (default 1500)",
    )
    p.add_argument(
        "--tyre",
        choices=[t.value for t in TyreModel],
        default="maxwell",
        help="true tyre model (default maxwell)",
    )
    add_option(
        p,
        "--roll-inertia-kg-m2",
        formerly="--roll-inertia",
        type=float,
        default=280.0,
        help="axle: true roll inertia, kg·m² (default 280)",
    )


SIMULATION_KEYS = ("spring_stiffness_N_per_m", "tyre_stiffness_N_per_m", "tyre_viscoelastic_coefficient")
"""Vehicle-file keys that are optional for identify but the simulator's truth."""


def simulated_vehicle_from_args(args: argparse.Namespace) -> SimulatedVehicle:
    from daq.formats.vehicle_file import read_vehicle
    from simulators.vehicle_sim import SimulatedVehicle

    known = read_vehicle(args.vehicle)
    missing = [key for key in SIMULATION_KEYS if getattr(known, key) is None]
    if missing:  # identify finds them from a recording; a simulation needs them as its truth
        raise CliError(f"{args.vehicle}: the simulator needs '{missing[0]}' (identify can do without it)")
    if not 0.3 < args.sprung_fraction < 1.0:
        raise CliError("--sprung-fraction must lie between 0.3 and 1")
    dampers = (damper_from_option(args.damper),)
    if known.is_axle:
        dampers = (*dampers, damper_from_option(args.damper_right))
    return SimulatedVehicle(
        known=known,
        sprung_mass_kg=args.sprung_fraction * known.mass_kg,
        dampers=dampers,
        tyre_damping_Ns_per_m=args.tyre_damping_ns_per_m,
        tyre_model=TyreModel(args.tyre),
        roll_inertia_kg_m2=args.roll_inertia_kg_m2,
    )


def settings_from_args(args: argparse.Namespace) -> SimulationSettings:
    from simulators.vehicle_sim import SensorModel, SimulationSettings

    if args.duration_s <= 0 or args.duration_s > 600:
        raise CliError("--duration-s must lie in (0, 600]")
    sweep = SweepSettings(
        start_Hz=0.0, stop_Hz=args.stop_hz, amplitude_m=args.amplitude_mm * 1e-3, duration_s=args.duration_s
    )
    return SimulationSettings(
        sweep=sweep,
        settle_s=args.settle_s,
        seed=args.seed,
        sensor=SensorModel(noise_m=args.noise_m, resolution_m=args.resolution_m),
    )


def run_simulate(args: argparse.Namespace) -> int:
    from daq.formats.recording_csv import write_recording_csv
    from simulators.vehicle_sim import simulate

    vehicle = simulated_vehicle_from_args(args)
    result = simulate(vehicle, settings_from_args(args))
    result.recording.metadata |= {
        "vehicle": str(args.vehicle),
        "sweep": f"0-{args.stop_hz} Hz, {args.amplitude_mm:g} mm, {args.duration_s:g} s",
        "damper": args.damper,
    }
    write_recording_csv(args.out, result.recording)
    n = result.recording.time_s.size
    print(
        f"wrote {args.out}: {n} samples at {result.recording.sample_time_s * 1e3:g} ms "
        f"({', '.join(result.recording.channels)})"
    )
    return 0


def run_demo(args: argparse.Namespace) -> int:
    """The main job on the embedded default bench: simulate a sweep, identify, print, plot."""
    import numpy as np

    from daq.formats.recording_csv import write_recording_csv
    from daq.formats.vehicle_file import write_vehicle
    from estimator.identify import identify
    from service.cli.identify import summary
    from service.kernel_build import compile_ahead
    from service.plots import save_curve_plot
    from simulators.vehicle_sim import SimulationSettings, default_quarter_car, simulate, true_damper

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    # once per machine and kernel version (10-30 s): later identify and diagnose runs load it in milliseconds
    print(f"output-error simulation kernel: {compile_ahead()}")
    vehicle = default_quarter_car()
    print(
        f"simulating a {20:g} s sweep 0-20 Hz ±4 mm on the default quarter car "
        f"(valve-model damper, Maxwell tyre, 5 µm sensor noise, seed {args.seed}) ..."
    )
    sim = simulate(vehicle, SimulationSettings(seed=args.seed))
    write_recording_csv(out / "demo_recording.csv", sim.recording)
    write_vehicle(out / "demo_vehicle.toml", vehicle.known)
    result = identify(sim.recording, vehicle.known)
    print(summary(result))
    truth = true_damper(vehicle.dampers[0])
    curve = result.curves[0].curve
    dense = np.linspace(curve.velocity_m_s[0], curve.velocity_m_s[-1], 400)
    error = curve.force(dense) - truth.force(dense)
    peak = float(np.max(np.abs(truth.force(dense))))
    print(
        f"\nagainst the simulator's truth: curve RMS error "
        f"{100 * np.sqrt(np.mean(error**2)) / peak:.2f}% of peak "
        f"force, sprung mass error {100 * (result.model.sprung_mass_kg / vehicle.sprung_mass_kg - 1):+.2f}%"
    )
    plot = save_curve_plot(result, out / "demo_curve.png", truth={"single": truth})
    print(f"wrote {out / 'demo_recording.csv'}, {out / 'demo_vehicle.toml'} and the plot {plot}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="simulate a sweep on the bench and write a recording CSV",
        description="Simulate a sine sweep with the physics simulator and write a recording.",
    )
    p.add_argument("--vehicle", required=True, help="vehicle file (TOML)")
    p.add_argument("--out", required=True, help="recording CSV to write")
    add_simulation_options(p)
    p.set_defaults(handler=run_simulate)
