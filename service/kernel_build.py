"""Build the output-error simulation kernel ahead of time: numba's pycc compiles
estimator/simulation_kernel_numba.py's `integrate` (and estimator/filter_kernel_numba.py's recursive filters)
into the Python extension
`estimator/_simulation_kernel_aot_<digest>` that estimator.simulation_kernel loads when its digest matches the
present source (see that module). `shockbench demo` runs this once; so can an install script:

    .venv/bin/python -m service.kernel_build

Why here and not in estimator/: building writes files, and the estimator does no file I/O
(tests/estimator/test_layering.py). Without a C compiler (pycc links with the system's) the build fails and
numba's just-in-time kernel is compiled into its on-disk cache instead, so the first identify still does not
pay the compile.
"""

from __future__ import annotations

import importlib
import os
import tempfile
import warnings
from pathlib import Path

from estimator import simulation_kernel

KERNEL_FOLDER = Path(simulation_kernel.__file__).resolve().parent


def build_extension(module_name: str, output_dir: Path) -> Path:
    """Compile the kernels into the extension `module_name` (exporting `integrate` and the filters'
    `recursion` and `zero_phase`) in output_dir; returns the extension's path."""
    from estimator.filter_kernel_numba import (
        RECURSION_SIGNATURE,
        ZERO_PHASE_SIGNATURE,
        recursion,
        zero_phase,
    )
    from estimator.simulation_kernel_numba import INTEGRATE_SIGNATURE, integrate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pycc is pending deprecation in numba; no replacement exists yet
        from numba.pycc import CC

        compiler = CC(module_name)
        compiler.output_dir = str(output_dir)
        compiler.verbose = False
        compiler.export("integrate", INTEGRATE_SIGNATURE)(integrate.py_func)
        compiler.export("recursion", RECURSION_SIGNATURE)(recursion.py_func)
        compiler.export("zero_phase", ZERO_PHASE_SIGNATURE)(zero_phase.py_func)
        compiler.compile()
    built = [path for path in output_dir.iterdir() if path.name.startswith(module_name + ".")]
    if not built:
        raise RuntimeError(f"numba pycc wrote no extension {module_name} into {output_dir}")
    return built[0]


def compile_ahead() -> str:
    """Build the extension for the present kernel source beside it, unless it exists (returns "extension");
    where it cannot be built (no C compiler, a read-only folder), compile numba's just-in-time kernel into
    its on-disk cache instead (returns "numba (...)" with the reason). Extensions of older sources are
    removed. Safe to run in parallel: each build is renamed into place."""
    if simulation_kernel.kernel_in_use() == "extension":
        return "extension"
    name = simulation_kernel.extension_name()
    try:
        with tempfile.TemporaryDirectory(prefix="shockbench_kernel_", dir=KERNEL_FOLDER) as scratch:
            built = build_extension(name, Path(scratch))
            os.replace(built, KERNEL_FOLDER / built.name)
    except Exception as exc:  # any failure to build leaves the just-in-time kernel in use
        simulation_kernel.warm()
        return f"numba (the extension was not built: {exc})"
    for stale in KERNEL_FOLDER.glob(simulation_kernel.EXTENSION_PREFIX + "*"):
        if not stale.name.startswith(name + "."):
            stale.unlink(missing_ok=True)
    importlib.invalidate_caches()
    simulation_kernel.forget_loaded_kernel()
    simulation_kernel.warm()
    return simulation_kernel.kernel_in_use()


if __name__ == "__main__":
    print(f"output-error simulation kernel: {compile_ahead()}")
