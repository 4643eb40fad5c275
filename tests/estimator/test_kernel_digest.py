"""The compiled kernel's version (estimator.simulation_kernel.source_digest): the extension built ahead of
time holds the kernel modules' code and the values of the constants they import from other modules, frozen
at its build. A stale extension would run silently, so the digest must change with either."""

from __future__ import annotations

import ast
import importlib.util

import pytest

import estimator.simulation_kernel as simulation_kernel


def imports_of_ours(module: str) -> dict[str, set[str]]:
    """{module: names} of the `from estimator.… import …` statements in the module's source."""
    spec = importlib.util.find_spec(module)
    assert spec is not None and spec.loader is not None
    tree = ast.parse(spec.loader.get_source(module))
    found: dict[str, set[str]] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("estimator"):
            found.setdefault(node.module, set()).update(alias.name for alias in node.names)
    return found


def test_every_constant_a_compiled_module_imports_is_in_the_digest() -> None:
    """The numba modules' imports (estimator.simulation_kernel itself runs in Python at every call)."""
    compiled = [m for m in simulation_kernel.KERNEL_MODULES if m != simulation_kernel.__name__]
    assert compiled
    for module in compiled:
        for source, names in imports_of_ours(module).items():
            if source in simulation_kernel.KERNEL_MODULES:
                continue  # its source is in the digest
            listed = set(simulation_kernel.IMPORTED_CONSTANTS.get(source, ()))
            assert names <= listed, f"{module} imports {sorted(names - listed)} from {source} unlisted"


@pytest.mark.parametrize(
    ("module", "name", "value"),
    [
        ("estimator.friction", "COULOMB_SMOOTHING_M_S", 0.02),
        ("estimator.digital_filters", "FLUSH_BELOW_PEAK", 2.0**-90),
        ("estimator.dynamics", "HINGES", 3),
    ],
)
def test_the_digest_changes_with_an_imported_constant(monkeypatch, module: str, name: str, value) -> None:
    before = simulation_kernel.source_digest()
    monkeypatch.setattr(importlib.import_module(module), name, value)
    assert simulation_kernel.source_digest() != before
