"""The architecture's one-way rules, checked on the import graph of the whole product (README, "Where things
live": dependencies point one way).

The graph is read from the source with ast: every `import` and `from ... import` anywhere in a module
(module level, inside functions, under TYPE_CHECKING), relative imports resolved, `from package import
module` counted as an import of the module. Importing `a.b.c` also runs the package modules `a` and `a.b`,
so the rule on what simulators may load follows package __init__ files too.

Rules (bottom to top):

* estimator imports nothing of ours outside estimator/ (tests/estimator/test_layering.py also checks that
  it imports only numpy, scipy, numba and the standard library, and does no I/O);
* drivers import only drivers and estimator;
* daq imports only daq, drivers and estimator (never simulators or service);
* simulators import only simulators, estimator, and the drivers' codecs and address maps
  (SIMULATOR_VISIBLE_DRIVER_MODULES), and what those load stays within that set;
* service may import every layer below it, but simulators only from two modules: exactly one module,
  service/simulated_bench.py, imports the simulated devices (starts a simulated bench), and
  service/cli/simulate.py alone uses the offline vehicle simulation (`shockbench simulate`, `demo`);
* nothing below service imports service.

Every rule is also run on a small synthetic tree that breaks it, so a checker that stopped seeing imports
would fail here too.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("estimator", "drivers", "daq", "simulators", "service")

ALLOWED_LAYERS: dict[str, frozenset[str]] = {
    "estimator": frozenset({"estimator"}),
    "drivers": frozenset({"drivers", "estimator"}),
    "daq": frozenset({"daq", "drivers", "estimator"}),
    "simulators": frozenset({"simulators", "estimator", "drivers"}),  # drivers: the modules below only
    "service": frozenset({"service", "daq", "drivers", "estimator", "simulators"}),
}
"""Which top-level packages each package may import (service's use of simulators is narrowed below)."""

SIMULATOR_VISIBLE_DRIVER_MODULES = frozenset(
    {
        "drivers",  # package modules that import nothing
        "drivers.compowayf",
        "drivers.exciter",
        "drivers.compowayf.codec",  # CompoWay/F frames
        "drivers.compowayf.service_data",  # what the frames carry (the codec's service data)
        "drivers.compowayf.layout",  # the amplifier's address map (AmplifierConfig)
        "drivers.compowayf.errors",  # the codec's errors
        "drivers.exciter.codes",  # command, state, fault and law codes; ExciterStatus
        "drivers.exciter.register_map",  # the Modbus address map
        "drivers.exciter.can_frames",  # the CAN frame set (DBC)
        "drivers.exciter.cia402_objects",  # the CiA 402 object dictionary
        "drivers.exciter.errors",  # the codecs' errors
    }
)
"""The drivers' codecs and address maps: what a simulated device shares with the driver so that both speak
the same bytes. No driver class, transport or safety logic."""

SIMULATED_BENCH_MODULE = "service.simulated_bench"
"""The one service module that starts simulated devices (for sim-devices, sweep/serve --simulated)."""
OFFLINE_SIMULATION_MODULE = "service.cli.simulate"
"""The one service module that runs the offline vehicle simulation (simulate, demo)."""
OFFLINE_SIMULATION = frozenset({"simulators.vehicle_sim", "simulators.dampers"})
"""What the offline simulation module may import from simulators: a recording in memory, no device."""


@dataclass(frozen=True)
class Import:
    importer: str
    imported: str
    line: int

    def __str__(self) -> str:
        return f"{self.importer} imports {self.imported} (line {self.line})"


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def product_modules(root: Path) -> dict[str, Path]:
    """Every module of the product packages under root, by dotted name."""
    modules = {}
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            modules[module_name(root, path)] = path
    return modules


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> list[Import]:
    """The modules of ours that `name` imports, wherever in the file the import statement is."""
    found = []
    is_package = path.name == "__init__.py"
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [Import(name, alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            for alias in node.names:
                submodule = f"{module}.{alias.name}"
                found.append(Import(name, submodule if submodule in modules else module, node.lineno))
    return [item for item in found if item.imported.split(".")[0] in PACKAGES]


def import_graph(root: Path) -> list[Import]:
    modules = product_modules(root)
    return [item for name, path in modules.items() for item in imports_of(name, path, modules)]


def with_packages(module: str) -> list[str]:
    """The modules that importing `module` runs: its parent packages, then itself."""
    parts = module.split(".")
    return [".".join(parts[: index + 1]) for index in range(len(parts))]


def layer_violations(graph: list[Import]) -> list[str]:
    """Imports of a package its layer may not see."""
    return [
        str(item)
        for item in graph
        if item.imported.split(".")[0] not in ALLOWED_LAYERS[item.importer.split(".")[0]]
    ]


def simulator_driver_violations(graph: list[Import]) -> list[str]:
    """Driver modules a simulator loads, directly or through what it imports, beyond the codecs and maps."""
    edges: dict[str, list[Import]] = {}
    for item in graph:
        edges.setdefault(item.importer, []).append(item)
    problems = []
    for item in graph:
        if not item.importer.startswith("simulators") or not item.imported.startswith("drivers"):
            continue
        seen: set[str] = set()
        pending = with_packages(item.imported)
        while pending:
            module = pending.pop()
            if module in seen:
                continue
            seen.add(module)
            if module not in SIMULATOR_VISIBLE_DRIVER_MODULES:
                problems.append(f"{item}, which loads {module}")
                continue
            for nested in edges.get(module, []):
                if nested.imported.startswith("drivers"):
                    pending += with_packages(nested.imported)
    return problems


def service_simulator_violations(graph: list[Import]) -> list[str]:
    """Service modules that use simulators other than the simulated bench and the offline simulation."""
    problems = []
    starts_devices = set()
    for item in graph:
        if not item.importer.startswith("service") or not item.imported.startswith("simulators"):
            continue
        if item.importer == SIMULATED_BENCH_MODULE:
            starts_devices.add(item.importer)
        elif item.importer == OFFLINE_SIMULATION_MODULE:
            if item.imported not in OFFLINE_SIMULATION:
                problems.append(f"{item}: the offline simulation may import {sorted(OFFLINE_SIMULATION)}")
        else:
            problems.append(f"{item}: only {SIMULATED_BENCH_MODULE} may start a simulated bench")
    if starts_devices != {SIMULATED_BENCH_MODULE}:
        problems.append(f"no service module imports the simulated devices; expected {SIMULATED_BENCH_MODULE}")
    return problems


def all_violations(root: Path) -> list[str]:
    graph = import_graph(root)
    return layer_violations(graph) + simulator_driver_violations(graph) + service_simulator_violations(graph)


# ---- the product -----------------------------------------------------------------------------------------


def test_the_graph_sees_the_imports_it_is_checked_on() -> None:
    """A graph that lost its edges would pass every rule: it has the imports the layers are built from."""
    edges = {(item.importer, item.imported) for item in import_graph(ROOT)}
    assert ("daq.sweep.model", "estimator.sweep") in edges
    assert ("simulators.devices.can_exciter", "drivers.exciter.can_frames") in edges  # from-package form
    assert ("service.simulated_bench", "simulators.devices.laser_amplifier") in edges
    assert ("service.cli.simulate", "simulators.vehicle_sim") in edges  # inside a function


def test_every_package_imports_only_the_layers_below_it() -> None:
    assert layer_violations(import_graph(ROOT)) == []


def test_simulators_load_only_the_drivers_codecs_and_address_maps() -> None:
    assert simulator_driver_violations(import_graph(ROOT)) == []


def test_exactly_one_service_module_starts_a_simulated_bench() -> None:
    assert service_simulator_violations(import_graph(ROOT)) == []


def test_every_allowed_driver_module_exists() -> None:
    """A renamed codec module must be renamed here too, not silently dropped from the allowed set."""
    modules = product_modules(ROOT)
    assert sorted(SIMULATOR_VISIBLE_DRIVER_MODULES - set(modules)) == []
    assert SIMULATED_BENCH_MODULE in modules and OFFLINE_SIMULATION_MODULE in modules
    assert set(modules) >= OFFLINE_SIMULATION


# ---- the checker on trees that break each rule -----------------------------------------------------------


def write_tree(root: Path, files: dict[str, str]) -> Path:
    """A minimal product tree: one module per package that imports nothing, plus `files`."""
    base = {
        "estimator/__init__.py": "",
        "estimator/sweep.py": "",
        "drivers/__init__.py": "",
        "drivers/exciter/__init__.py": "",
        "drivers/exciter/codes.py": "from estimator.sweep import x\n",
        "drivers/exciter/interface.py": "from drivers.exciter.codes import y\n",
        "daq/__init__.py": "",
        "daq/run.py": "from drivers.exciter.interface import z\n",
        "simulators/__init__.py": "",
        "simulators/devices/__init__.py": "",
        "simulators/devices/drive.py": "from drivers.exciter import codes\n",
        "simulators/vehicle_sim.py": "from estimator.sweep import x\n",
        "service/__init__.py": "",
        "service/cli/__init__.py": "",
        "service/cli/simulate.py": "def run():\n    from simulators.vehicle_sim import simulate\n",
        "service/simulated_bench.py": "from simulators.devices.drive import d\nfrom daq.run import r\n",
    }
    for name, text in (base | files).items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def test_a_tree_that_keeps_the_rules_passes(tmp_path: Path) -> None:
    assert all_violations(write_tree(tmp_path, {})) == []


@pytest.mark.parametrize(
    ("files", "expected"),
    [
        ({"estimator/fit.py": "import daq.run\n"}, "estimator.fit imports daq.run"),
        ({"drivers/exciter/modbus.py": "from daq import run\n"}, "drivers.exciter.modbus imports daq.run"),
        (
            {"daq/pacing.py": "def f():\n    from simulators.devices.drive import d\n"},
            "daq.pacing imports simulators.devices.drive",
        ),
        (
            {"daq/api.py": "from ..service import simulated_bench\n"},
            "daq.api imports service.simulated_bench",
        ),
        (
            {"simulators/devices/bench.py": "from daq.run import BenchConfig\n"},
            "simulators.devices.bench imports daq.run",
        ),
        (
            {"simulators/plate.py": "from drivers.exciter.interface import Status\n"},
            "simulators.plate imports drivers.exciter.interface (line 1), which loads",
        ),
        (
            # a codec module that loads driver internals: the simulator importing it loads them too
            {"drivers/exciter/codes.py": "from drivers.exciter.interface import y\n"},
            "which loads drivers.exciter.interface",
        ),
        (
            {"drivers/exciter/__init__.py": "from drivers.exciter.interface import PlateExciter\n"},
            "which loads drivers.exciter.interface",
        ),
        (
            {"service/bench_control.py": "from simulators.devices.drive import d\n"},
            "service.bench_control imports simulators.devices.drive (line 1): only service.simulated_bench",
        ),
        (
            {"service/cli/identify.py": "from simulators.vehicle_sim import simulate\n"},
            "service.cli.identify imports simulators.vehicle_sim (line 1): only service.simulated_bench",
        ),
        (
            {"service/cli/simulate.py": "from simulators.devices.drive import d\n"},
            "service.cli.simulate imports simulators.devices.drive (line 1): the offline simulation",
        ),
        (
            {"service/simulated_bench.py": "from daq.run import r\n"},
            "no service module imports the simulated",
        ),
    ],
)
def test_a_tree_that_breaks_a_rule_is_caught(tmp_path: Path, files: dict[str, str], expected: str) -> None:
    problems = all_violations(write_tree(tmp_path, files))
    assert any(expected in problem for problem in problems), problems
