"""Benchmark (issue 15, item 2): `shockbench diagnose --json` as a whole process against scipy's
differential_evolution with the seed's settings (also a whole process), side by side in one run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_doctor_speed.py [--repeats 3]

Recordings (written once per run, read back by every process with the project's readers):

- "12 s, 1 kHz, independent": the motorcycle corner of benchmarks/bench_identify_process.py (the paper's
  bench figures, a real dyno-log damper, 5 µm noise, simulated by the independent world), the recording the
  scipy DE row runs on;
- "12 s, 1 kHz, project simulator": `shockbench simulate` of a quarter car (11 s sweep plus 1 s settling,
  default valve damper, Maxwell tyre, 5 µm noise);
- "30 s, 500 Hz, independent": the same motorcycle, a 29 s sweep plus 1 s settling sampled at 2 ms.

"scipy DE" is bench_identify_process.py's child process (its --scipy-de mode, run as it is, not copied):
it reads the 12 s independent recording, builds the paper's objective and runs
scipy.optimize.differential_evolution with rand1bin, F 1, CR 0.3, NP 70, 3000 generations, in each of
scipy's updating modes asked (--updating, default both): "deferred" (the population evaluated as one
vectorised batch, the faster reading of the seed's DE) and "immediate" (scipy's default). The rounds
alternate the processes, so the machine's load falls on all alike; the
figures are medians of wall time, which includes the interpreter's start and every import (and the
largest peak RSS, GNU time's, of each command). Targets: the
12 s diagnoses at least TARGET_RATIO times faster than the DE, the 30 s one under TARGET_LONG_S.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_identify_process
from bench_identify_process import SHOCKBENCH, measured_process, write_motorcycle_recording

REPO = Path(__file__).resolve().parents[1]
TARGET_RATIO = 8.0
TARGET_LONG_S = 4.0
QUARTER_CAR = """[vehicle]
model = "quarter-car"
mass_kg = 420.0
spring_stiffness_N_per_m = 26000
tyre_stiffness_N_per_m = 210000
tyre_viscoelastic_coefficient = 0.97
"""


@dataclass(frozen=True)
class Case:
    name: str
    recording: Path
    vehicle: Path


def write_long_motorcycle_recording(folder: Path) -> tuple[Path, Path]:
    """The motorcycle corner of write_motorcycle_recording, 30 s sampled at 500 Hz."""
    from simulators.independent.dampers import DYNO_LOGS, dyno_table
    from simulators.independent.excitation import Chirp
    from simulators.independent.files import write_recording
    from simulators.independent.sensors import SensorNoise
    from simulators.independent.vehicles import Corner, Vehicle
    from simulators.independent.world import WorldSettings, simulate

    corner = Corner(dyno_table(DYNO_LOGS[0]).scaled(1.8), 14.0, 14_040.0, 101_018.0, 1500.0, 0.0323)
    vehicle = Vehicle("motorcycle", 95.3, (corner,))
    settings = WorldSettings(
        chirp=Chirp(duration_s=29.0), settle_s=1.0, noise=SensorNoise(5e-6), seed=0, sample_time_s=0.002
    )
    csv_path, toml_path = folder / "motorcycle_500Hz.csv", folder / "motorcycle_500Hz.toml"
    write_recording(simulate(vehicle, settings), csv_path, toml_path)
    return csv_path, toml_path


def write_project_recording(folder: Path) -> tuple[Path, Path]:
    """A 12 s quarter-car recording from the project's simulator (`shockbench simulate`)."""
    toml_path, csv_path = folder / "quarter_car.toml", folder / "quarter_car.csv"
    toml_path.write_text(QUARTER_CAR)
    command = [str(SHOCKBENCH), "simulate", "--vehicle", str(toml_path), "--out", str(csv_path)]
    subprocess.run(
        [*command, "--duration-s", "11", "--settle-s", "1"], check=True, capture_output=True, cwd=REPO
    )
    return csv_path, toml_path


def diagnose_command(case: Case) -> list[str]:
    return [str(SHOCKBENCH), "diagnose", str(case.recording), "--vehicle", str(case.vehicle), "--json"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="rounds (default 3; the figures are medians)")
    parser.add_argument("--generations", type=int, default=3000, help="DE generations (default 3000)")
    parser.add_argument(
        "--updating", default="deferred,immediate", help="scipy DE updating modes, comma-separated"
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_doctor_speed_") as name:
        folder = Path(name)
        cases = [
            Case("diagnose 12 s, 1 kHz, independent", *write_motorcycle_recording(folder)),
            Case("diagnose 12 s, 1 kHz, project simulator", *write_project_recording(folder)),
            Case("diagnose 30 s, 500 Hz, independent", *write_long_motorcycle_recording(folder)),
        ]
        commands = {case.name: diagnose_command(case) for case in cases}
        modes = args.updating.split(",")
        de_names = [f"scipy DE ({mode}), 12 s independent" for mode in modes]
        for mode, de_name in zip(modes, de_names, strict=True):
            commands[de_name] = [
                sys.executable, bench_identify_process.__file__, "--scipy-de", str(cases[0].recording),
                str(cases[0].vehicle), "--mode", mode, "--generations", str(args.generations),
            ]  # fmt: skip
        times: dict[str, list[float]] = {name: [] for name in commands}
        cpu: dict[str, list[float]] = {name: [] for name in commands}
        peaks: dict[str, list[float]] = {name: [] for name in commands}
        verdicts: dict[str, str] = {}
        for round_index in range(args.repeats):
            for name, command in commands.items():
                seconds, peak_MiB, cpu_s, out = measured_process(command)
                times[name].append(seconds)
                cpu[name].append(cpu_s)
                peaks[name].append(peak_MiB)
                if name not in de_names:
                    verdicts[name] = json.loads(out)["conclusion"]
                print(f"round {round_index + 1} {name}: {seconds:.2f} s", file=sys.stderr)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    de_medians = {name: statistics.median(times[name]) for name in de_names}
    for name, values in times.items():
        median = statistics.median(values)
        ratios = "".join(
            f"; {mode} DE / diagnose {de_medians[de] / median:.1f}x"
            for mode, de in zip(modes, de_names, strict=True)
            if name not in de_names
        )
        runs = ", ".join(f"{v:.2f}" for v in values)
        cpu_s = statistics.median(cpu[name])
        print(
            f"{name}: median {median:.2f} s ({runs}){ratios}; CPU {cpu_s:.2f} s (the process and its "
            f"children: the doctor forks its fits); peak RSS {max(peaks[name]):.0f} MiB"
        )
    for name, verdict in verdicts.items():
        print(f"{name}: {verdict[:120]}")
    print(f"targets: 12 s >= {TARGET_RATIO:.0f}x faster than the DE, 30 s at 500 Hz under {TARGET_LONG_S} s")


if __name__ == "__main__":
    main()
