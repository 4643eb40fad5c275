"""The science core: bench models, the objective of the paper, solvers, curve fitting, inspection figures.

Pure numpy/scipy (numba for the compiled kernels). Must not import daq/, drivers/, service/ or simulators/,
and does no I/O (tests/estimator/test_layering.py).

The public surface: `identify` (damper curves, masses and inspection figures from a recording),
`diagnose` (the model doctor: which missing effect explains the gap) and `validate` (an identified model on
another recording), with their options and result types and the inputs they take:

    from estimator import Recording, VehicleParameters, identify
    result = identify(recording, vehicle)

They are loaded on first use (module __getattr__): `import estimator` alone imports neither numpy nor the
doctor, so that light callers (the CLI's help, estimator.errors) stay light
(tests/service/test_cli_lazy_imports.py).

`estimator.identify` is both the function and the module that defines it (`from estimator.identify import
IdentifyOptions` keeps working). The import system binds a submodule to its package's attribute once it
is imported, which would make `from estimator import identify` the module; this package's module type
keeps the attribute the function (_Package).
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from estimator.doctor.diagnose import DiagnoseOptions, diagnose
    from estimator.doctor.result import DiagnosisResult
    from estimator.identify import IdentificationResult, IdentifyOptions, identify
    from estimator.output_error import IdentifiedModel
    from estimator.recording import Recording
    from estimator.validation import ValidationResult, validate
    from estimator.vehicle import VehicleParameters

_PUBLIC: dict[str, str] = {
    "identify": "estimator.identify",
    "IdentifyOptions": "estimator.identify",
    "IdentificationResult": "estimator.identify",
    "diagnose": "estimator.doctor.diagnose",
    "DiagnoseOptions": "estimator.doctor.diagnose",
    "DiagnosisResult": "estimator.doctor.result",
    "validate": "estimator.validation",
    "ValidationResult": "estimator.validation",
    "IdentifiedModel": "estimator.output_error",
    "Recording": "estimator.recording",
    "VehicleParameters": "estimator.vehicle",
}
"""Public name -> the module that defines it."""

__all__ = [
    "DiagnoseOptions",
    "DiagnosisResult",
    "IdentificationResult",
    "IdentifiedModel",
    "IdentifyOptions",
    "Recording",
    "ValidationResult",
    "VehicleParameters",
    "diagnose",
    "identify",
    "validate",
]


def __getattr__(name: str) -> Any:
    """A public name, imported from its module on first use (then kept as this package's attribute)."""
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'estimator' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


class _Package(types.ModuleType):
    """The estimator package's module type: its `identify` attribute is always the function. The import
    system's binding of the submodule estimator.identify is ignored here (the module stays importable by
    its full name, from sys.modules); any other value is refused."""

    @property
    def identify(self) -> Any:
        return importlib.import_module("estimator.identify").identify

    @identify.setter
    def identify(self, value: Any) -> None:
        if not isinstance(value, types.ModuleType) or value.__name__ != "estimator.identify":
            raise AttributeError("estimator.identify is the function estimator.identify.identify")


sys.modules[__name__].__class__ = _Package
