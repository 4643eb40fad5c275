"""Packages are used through their public surfaces, and a reader can hold a module in mind (issue 32, items 6
and 7):

* no module imports another package's underscore names (`from estimator.x import _private`, or
  `module._private` on a module imported from another package): a name with an underscore is its
  package's to change; a name another package needs gets a public name in its home module;
* every package's docstring says what the package is for and what it must not import (the words "must
  not import"), not just "X package.";
* no module is over 500 lines;
* estimator/ exports identify, diagnose and validate with their result types, without importing numpy
  or the doctor on `import estimator`.

"Package" is a directory with an __init__.py: daq.storage's modules may share underscore names among
themselves, but not with daq.sweep. Every check is also run on a small synthetic tree that breaks it, so
a checker that stopped seeing its problem would fail here too.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("estimator", "drivers", "daq", "simulators", "service")

MAX_LINES = 500
LINE_LIMIT_EXEMPT = ("estimator/doctor/",)
"""The model doctor's modules (diagnose.py, model.py) are redesigned by issue 29 (issue 19 took them);
they follow the limit when that lands."""


def _package_of(root: Path, path: Path) -> str:
    """The dotted package a module belongs to (a package's __init__ belongs to the package itself)."""
    return ".".join(path.parent.relative_to(root).parts)


def _module_path(root: Path, dotted: str) -> Path | None:
    base = root.joinpath(*dotted.split("."))
    if (base / "__init__.py").is_file():
        return base / "__init__.py"
    return base.with_suffix(".py") if base.with_suffix(".py").is_file() else None


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def underscore_imports(root: Path, packages: tuple[str, ...] = PACKAGES) -> list[str]:
    """`from a.b import _x` and `alias._x` (alias a module of ours) where the module's package differs
    from the importer's, as 'file:line: what'."""
    problems = []
    for top in packages:
        for path in sorted((root / top).rglob("*.py")):
            mine = _package_of(root, path)
            tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
            modules: dict[str, str] = {}  # local name -> dotted module of ours
            for node in ast.walk(tree):
                if isinstance(node, ast.Import):
                    for alias in node.names:
                        if alias.name.split(".")[0] in packages and alias.asname:
                            modules[alias.asname] = alias.name
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    if node.module.split(".")[0] not in packages:
                        continue
                    home = _module_path(root, node.module)
                    for alias in node.names:
                        if _module_path(root, f"{node.module}.{alias.name}") is not None:
                            modules[alias.asname or alias.name] = f"{node.module}.{alias.name}"
                        elif _is_private(alias.name) and home is not None and _package_of(root, home) != mine:
                            problems.append(
                                f"{path.relative_to(root)}:{node.lineno}: imports {node.module}.{alias.name}"
                            )
            for node in ast.walk(tree):
                if (
                    isinstance(node, ast.Attribute)
                    and _is_private(node.attr)
                    and isinstance(node.value, ast.Name)
                    and node.value.id in modules
                ):
                    home = _module_path(root, modules[node.value.id])
                    if home is not None and _package_of(root, home) != mine:
                        where = f"{path.relative_to(root)}:{node.lineno}"
                        problems.append(f"{where}: uses {modules[node.value.id]}.{node.attr}")
    return problems


def docstring_problems(root: Path, packages: tuple[str, ...] = PACKAGES) -> list[str]:
    """Package __init__ files whose docstring is missing, only names the package, or does not say what the
    package must not import."""
    problems = []
    for top in packages:
        for path in sorted((root / top).rglob("__init__.py")):
            where = str(path.relative_to(root))
            doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")))
            if not doc:
                problems.append(f"{where}: no docstring")
            elif len(doc.split()) < 8:
                problems.append(f"{where}: the docstring does not say what the package is for: {doc!r}")
            elif "must not import" not in " ".join(doc.lower().split()):
                problems.append(f"{where}: the docstring does not say what the package must not import")
    return problems


def long_modules(root: Path) -> list[str]:
    """Python files of the repository (not the virtual environment) over MAX_LINES lines."""
    found = []
    for path in sorted(root.rglob("*.py")):
        relative = path.relative_to(root).as_posix()
        if relative.split("/")[0].startswith(".") or ".egg-info/" in relative:
            continue
        lines = len(path.read_text(encoding="utf-8").splitlines())
        if lines > MAX_LINES:
            found.append(f"{relative}: {lines} lines")
    return found


# ---- the product ----------------------------------------------------------------------------------------


def test_no_module_imports_another_packages_underscore_names() -> None:
    assert underscore_imports(ROOT) == []


def test_every_package_docstring_says_what_it_is_for_and_what_it_must_not_import() -> None:
    problems = docstring_problems(ROOT)
    assert problems == []


def test_no_module_is_over_500_lines() -> None:
    exempt = [m for m in long_modules(ROOT) if m.startswith(LINE_LIMIT_EXEMPT)]
    assert all(m.startswith("estimator/doctor/") for m in exempt)
    over = [m for m in long_modules(ROOT) if not m.startswith(LINE_LIMIT_EXEMPT)]
    assert over == []


def test_the_estimator_exports_identify_diagnose_validate_and_their_results() -> None:
    import estimator
    import estimator.identify  # binds nothing over the function (estimator's module type)
    from estimator.doctor.diagnose import diagnose
    from estimator.doctor.result import DiagnosisResult
    from estimator.identify import IdentificationResult, identify
    from estimator.validation import ValidationResult, validate

    assert (estimator.identify, estimator.diagnose, estimator.validate) == (identify, diagnose, validate)
    assert (estimator.IdentificationResult, estimator.DiagnosisResult, estimator.ValidationResult) == (
        IdentificationResult,
        DiagnosisResult,
        ValidationResult,
    )
    assert set(estimator.__all__) <= set(dir(estimator))
    with pytest.raises(AttributeError, match="no attribute 'identfy'"):
        _ = estimator.identfy  # type: ignore[attr-defined]


def test_importing_the_estimator_loads_neither_numpy_nor_the_doctor() -> None:
    program = (
        "import sys, estimator\n"
        "from estimator import identify\n"  # a name is there...
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'numpy' or m.startswith('estimator.')))\n"
    )
    before = subprocess.run(
        [sys.executable, "-c", program.replace("from estimator import identify\n", "")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        check=True,
    )
    assert before.stdout.strip() == "[]"  # ...but loaded only when asked for
    after = subprocess.run(
        [sys.executable, "-c", program], capture_output=True, text=True, cwd=ROOT, timeout=120, check=True
    )
    assert "'estimator.identify'" in after.stdout and "estimator.doctor" not in after.stdout


def test_a_sweep_on_the_hardware_does_not_load_the_mocks() -> None:
    """The product's sweep (daq.sweep.run, its devices and the service's sweep route) reaches the real
    drivers; the in-process mocks (drivers.mock, daq.sweep.mock_devices) are for tests only."""
    program = (
        "import sys, daq.sweep.run, daq.sweep.devices, service.api.app\n"
        "print(sorted(m for m in sys.modules if m in ('drivers.mock', 'daq.sweep.mock_devices')))\n"
    )
    loaded = subprocess.run(
        [sys.executable, "-c", program], capture_output=True, text=True, cwd=ROOT, timeout=120, check=True
    )
    assert loaded.stdout.strip() == "[]"


# ---- the checkers see what they look for ----------------------------------------------------------------


def _tree(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return root


def test_the_underscore_check_sees_both_forms_across_packages_only(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "low/__init__.py": "",
            "low/kernel.py": "def _step(): ...\n",
            "low/user.py": "from low.kernel import _step\n",  # the same package: its own business
            "high/__init__.py": "",
            "high/a.py": "from low.kernel import _step\n",
            "high/b.py": "from low import kernel\nkernel._step()\n",
            "high/c.py": "import low.kernel as k\nk._step()\n",
            "high/d.py": "from low.kernel import __doc__\n",  # dunders are not private
        },
    )
    found = underscore_imports(root, ("low", "high"))
    assert [line.split(":")[0] for line in found] == ["high/a.py", "high/b.py", "high/c.py"]


def test_the_docstring_check_sees_a_bare_and_a_silent_package(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "low/__init__.py": '"""low package."""\n',
            "low/quiet/__init__.py": '"""Kernels for the low layer, compiled ahead of time, one each."""\n',
            "low/none/__init__.py": "",
            "low/good/__init__.py": '"""Kernels for the low layer, compiled.\n\nMust not\nimport high."""\n',
        },
    )
    problems = docstring_problems(root, ("low",))
    assert [p.split(":")[0] for p in problems] == [
        "low/__init__.py",
        "low/none/__init__.py",
        "low/quiet/__init__.py",
    ]


def test_the_line_check_counts_lines(tmp_path: Path) -> None:
    root = _tree(tmp_path, {"a.py": "x = 1\n" * 501, "b.py": "x = 1\n" * 500, ".venv/c.py": "x = 1\n" * 900})
    assert long_modules(root) == ["a.py: 501 lines"]
