"""The model doctor (issue 6): find where the identified model and the measurement disagree, name the
missing effect from a catalog, add it, re-identify and show the gap shrink; say "unexplained" when a clear
disagreement remains that no candidate explains.

- catalog.py: the candidate effects, each a model extension the estimator can fit, with its signature;
- columns.py: the signals effects are made of and how a force enters the equations of motion;
- model.py: a model with effects added (ModelStructure) and its identification (fit);
- simulation.py: output error of many fitted models in one Runge-Kutta run;
- residuals.py: locating a disagreement (sweep bands, velocity and deflection bins, spectra, whiteness);
- evidence.py: what a candidate explains, in numbers and in words;
- expected.py: the gap and residual a model without missing effects reaches (parametric bootstrap);
- diagnose.py: the loop; result.py: what it returns and its JSON.


Must not import daq, drivers, service or simulators (the estimator's layer rule), and does no I/O."""

from estimator.doctor.diagnose import DiagnoseOptions, DiagnoseProgress, diagnose
from estimator.doctor.result import DiagnosisResult

__all__ = ["DiagnoseOptions", "DiagnoseProgress", "DiagnosisResult", "diagnose"]
