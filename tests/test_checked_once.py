"""Parse once at the edge, check once (issue 16): where the product may check a sweep against the safety
envelope, and where the acquisition layer may read a vehicle file, found on the source with ast.

* The safety envelope judges a sweep in two places only: daq/sweep/plan.py, at the edge (a clear message
  naming the setting before anything is stored or moves), and the exciter driver, as the safety net
  (drivers/exciter/interface.py, at configure and again at start). A third call site is a check written
  twice.
* The sweep (daq/) never reads a vehicle file: the request carries it as read at the edge
  (daq.formats.vehicle_file.VehicleFile). Only the vehicle file's own module parses one.

tests/service/test_api_sweeps.py counts the parses of one sweep through the service at run time (one).
Each scan is also run on a snippet that breaks it, so a scanner that stopped seeing calls fails here too.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("estimator", "drivers", "daq", "simulators", "service")

ENVELOPE_CHECKERS = frozenset({"daq/sweep/plan.py", "drivers/exciter/interface.py"})
VEHICLE_READERS = frozenset({"parse_vehicle", "parse_vehicle_file", "load_vehicle_file", "read_vehicle"})


def product_modules() -> dict[str, ast.Module]:
    return {
        path.relative_to(ROOT).as_posix(): ast.parse(path.read_text(encoding="utf-8"))
        for package in PACKAGES
        for path in sorted((ROOT / package).rglob("*.py"))
    }


def envelope_checks(tree: ast.Module) -> list[int]:
    """Lines of `<...envelope...>.check(...)` calls: `config.safety_envelope().check(s)`,
    `self.envelope.check(s)`, `envelope.check(s)`."""
    lines = []
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "check"
            and "envelope" in ast.unparse(node.func.value).lower()
        ):
            lines.append(node.lineno)
    return lines


def vehicle_reads(tree: ast.Module) -> list[int]:
    """Lines of calls to a vehicle file reader, by name or as an attribute (vehicle_file.parse_vehicle)."""
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if name in VEHICLE_READERS:
                lines.append(node.lineno)
    return lines


def test_the_envelope_is_checked_at_the_edge_and_in_the_driver_only() -> None:
    found = {path: lines for path, tree in product_modules().items() if (lines := envelope_checks(tree))}
    assert set(found) == ENVELOPE_CHECKERS, found
    assert len(found["daq/sweep/plan.py"]) == 1, found


def test_the_sweep_never_reads_a_vehicle_file_again() -> None:
    acquisition = {
        path: tree
        for path, tree in product_modules().items()
        if path.startswith("daq/") and path != "daq/formats/vehicle_file.py"
    }
    found = {path: lines for path, tree in acquisition.items() if (lines := vehicle_reads(tree))}
    assert found == {}


def test_the_scans_see_what_they_forbid() -> None:
    snippet = ast.parse(
        "def run(config, request, path):\n"
        "    config.safety_envelope().check(request.sweep)\n"
        "    vehicle = read_vehicle(path)\n"
        "    return vehicle_file.parse_vehicle_file(text)\n"
    )
    assert envelope_checks(snippet) == [2]
    assert vehicle_reads(snippet) == [3, 4]
