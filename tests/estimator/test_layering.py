"""estimator/ does no I/O and imports nothing of ours outside estimator/ (the architecture's one-way rule)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OURS = {"daq", "drivers", "service", "simulators", "estimator"}
ALLOWED_THIRD_PARTY = {"numpy", "scipy", "numba"}  # numba: the compiled simulation (issue 15)


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_estimator_imports_only_itself_numpy_scipy_numba_and_the_standard_library() -> None:
    import sys

    stdlib = set(sys.stdlib_module_names)
    for path in (ROOT / "estimator").rglob("*.py"):
        for name in _imports(path):
            assert name == "estimator" or name in ALLOWED_THIRD_PARTY or name in stdlib, (
                f"{path}: imports {name}"
            )
            assert name not in OURS - {"estimator"}, f"{path} imports {name}"


def test_estimator_does_no_file_or_network_io() -> None:
    forbidden = {"open(", "socket", "requests", "urllib", "Path("}
    for path in (ROOT / "estimator").rglob("*.py"):
        text = path.read_text()
        for word in forbidden:
            assert word not in text, f"{path} uses {word}"
