"""`shockbench --help` stays light (issue 15: it took 2.5-3.5 s and 158 MB importing scipy.signal,
scipy.stats and matplotlib through the doctor): the command modules import the estimator, the acquisition
and device stacks, numpy and the plots inside the command that needs them. Its wall time is measured in
benchmarks/bench_kernel.py, not here.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pytest

HEAVY = (
    "numpy",
    "scipy",
    "matplotlib",
    "numba",
    "estimator.doctor",
    "estimator.identify",
    "h5py",
    "can",
    "pymodbus",
    "fastapi",
    "sqlalchemy",
    "dask",
    "distributed",
)

PROGRAM = """
import json, sys
from service.cli.main import main
try:
    main({argv!r})
except SystemExit:
    pass
print(json.dumps(sorted(sys.modules)))
"""


def _modules_after(argv: list[str]) -> set[str]:
    done = subprocess.run(
        [sys.executable, "-c", PROGRAM.format(argv=argv)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    return set(json.loads(done.stdout.strip().splitlines()[-1]))


@pytest.mark.parametrize(
    "argv", [["--help"], ["identify", "--help"], ["diagnose", "--help"], ["reanalyse", "--help"]]
)
def test_help_imports_no_heavy_module(argv: list[str]) -> None:
    modules = _modules_after(argv)
    registered = {"service.cli.identify", "service.cli.diagnose", "service.cli.reanalyse"}
    assert (registered <= modules) if argv == ["--help"] else (f"service.cli.{argv[0]}" in modules)
    heavy = sorted(m for m in modules if any(m == h or m.startswith(h + ".") for h in HEAVY))
    assert heavy == [], f"shockbench {' '.join(argv)} imports {heavy[:10]}"


def test_the_command_table_names_every_parser() -> None:
    """main.COMMAND_MODULES (which module to import for a command) is what the modules register, in order."""
    from service.cli import main

    parser = main.build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    assert list(commands) == list(main.COMMAND_MODULES)
    for command, module in main.COMMAND_MODULES.items():
        alone = main.build_parser(command)
        sub = next(a for a in alone._actions if isinstance(a, argparse._SubParsersAction))
        assert set(sub.choices) == {c for c, m in main.COMMAND_MODULES.items() if m == module}


def test_a_command_registers_only_its_own_module() -> None:
    modules = _modules_after(["identify", "--help"])
    assert "service.cli.identify" in modules
    others = sorted(
        m
        for m in modules
        if m.startswith("service.cli.")
        and m.split(".")[2] in {"serve", "reanalyse", "diagnose", "db", "sweep"}
    )
    assert others == []


def test_a_command_still_imports_what_it_needs() -> None:
    """The check above can fail: running a command (fit-tanh on a missing file) does import the estimator."""
    modules = _modules_after(["fit-tanh", "/nonexistent/points.csv"])
    assert "numpy" in modules and "estimator.tanh_fit" in modules


def test_the_names_the_parsers_use_equal_the_libraries() -> None:
    """The few choices and defaults the CLI names itself (to stay light) are the libraries' own."""
    from daq.probe import DEFAULT_TIMEOUT_S
    from daq.sweep.model import SweepRequest
    from estimator.identify import Solver
    from service.cli import devices, identify, sweep
    from service.simulated_bench import VEHICLE_PRESETS

    assert tuple(solver.value for solver in Solver) == identify.SOLVERS
    assert tuple(VEHICLE_PRESETS) == devices.VEHICLE_PRESET_NAMES
    assert devices.PROBE_TIMEOUT_S == DEFAULT_TIMEOUT_S
    request = SweepRequest()
    assert [o.default() for o in sweep.TIMING_OPTIONS] == [request.settle_s, request.rest_s]


def _simulated_sweep(folder: Path) -> tuple[Path, Path]:
    """A 4 s quarter-car sweep (`shockbench simulate`) and its vehicle file, with the kernel's extension
    built (as `shockbench demo` builds it), so that a command's imports are those of a lane's machine."""
    from service.kernel_build import compile_ahead

    assert compile_ahead() == "extension"
    vehicle = folder / "car.toml"
    vehicle.write_text(
        '[vehicle]\nmodel = "quarter-car"\nmass_kg = 300.0\nspring_stiffness_N_per_m = 20000.0\n'
        "tyre_stiffness_N_per_m = 200000.0\ntyre_viscoelastic_coefficient = 0.97\n"
    )
    recording = folder / "sweep.csv"
    _modules_after(["simulate", "--vehicle", str(vehicle), "--out", str(recording), "--duration-s", "4"])
    return recording, vehicle


def test_identify_with_stated_theta_imports_no_scipy_optimize_nor_linalg(tmp_path) -> None:
    """A whole `shockbench identify` spent about a quarter of its time importing scipy.optimize (issue 15,
    item 1): the tanh fit refines without it and the ϑ search imports it only when ϑ is searched. Then a
    fifth importing scipy.linalg for the recursive filters' banded solve: with the kernel's extension built
    (as `shockbench demo` builds it) the filters' recursion runs in the extension instead."""
    recording, vehicle = _simulated_sweep(tmp_path)
    modules = _modules_after(["identify", str(recording), "--vehicle", str(vehicle), "--json"])
    assert "estimator.tanh_fit" in modules and "estimator.identify" in modules  # it did identify
    for package in ("scipy.optimize", "scipy.linalg"):
        imported = sorted(m for m in modules if m == package or m.startswith(package + "."))
        assert imported == [], f"identify imports {imported[:5]}"


def test_diagnose_imports_no_scipy(tmp_path) -> None:
    """A 12 s `shockbench diagnose` spent about a fifth of its run importing scipy (issue 15, item 2): the
    doctor's noise fit, its delayed channel's spline shift and its whiteness tail run in numpy instead
    (estimator.doctor.expected, .spline_shift, .residuals)."""
    recording, vehicle = _simulated_sweep(tmp_path)
    modules = _modules_after(["diagnose", str(recording), "--vehicle", str(vehicle), "--json"])
    assert "estimator.doctor.diagnose" in modules  # it did diagnose
    imported = sorted(m for m in modules if m == "scipy" or m.startswith("scipy."))
    assert imported == [], f"diagnose imports {imported[:5]}"
