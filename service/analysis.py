"""One recording's identification or diagnosis as `shockbench identify` and `shockbench diagnose` run it:
the service's submit checks (bad input is a one-line UserError), then the estimator. The commands print
the result's `to_json()`; `shockbench reanalyse` (service.reanalyse) stores it for each recording of an
archive, so a re-analysis gives exactly what the commands give.

Imported inside the commands (it loads the estimator: `shockbench --help` stays light).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from estimator.identify import IdentificationResult, IdentifyOptions, identify
from estimator.recording import Recording
from estimator.vehicle import VehicleParameters
from service.jobs.bounds import check_physical_bounds, check_recording_fits

if TYPE_CHECKING:
    from estimator.doctor.diagnose import DiagnoseOptions, DiagnoseProgress
    from estimator.doctor.result import DiagnosisResult
    from estimator.solvers.differential_evolution import DEProgress


def identify_recording(
    recording: Recording,
    vehicle: VehicleParameters,
    options: IdentifyOptions,
    progress: Callable[[DEProgress], object] | None = None,
) -> IdentificationResult:
    """Identify after the identification job's checks: the recording's channels fit the vehicle file's
    model, and vehicle and recording lie within physical bounds (InputError, one line, otherwise)."""
    check_recording_fits(recording, vehicle)
    check_physical_bounds(recording, vehicle)
    return identify(recording, vehicle, options, progress=progress)


def diagnose_recording(
    recording: Recording,
    vehicle: VehicleParameters,
    options: DiagnoseOptions,
    progress: Callable[[DiagnoseProgress], None] | None = None,
) -> DiagnosisResult:
    """The model doctor after the diagnosis job's check that the recording's channels fit the vehicle
    file's model (InputError, one line, otherwise)."""
    from estimator.doctor.diagnose import diagnose  # scipy.signal and the catalog: only when diagnosing

    check_recording_fits(recording, vehicle)
    return diagnose(recording, vehicle, options, progress=progress)
