"""The model doctor (issue 29): find where the identified model and the measurement disagree, name the
missing effect family by a statistical test, add it, and show the gap shrink; say "unexplained", and where,
when the final model leaves more than its own noise would (a goodness-of-fit test).

- catalog.py: the effect families, each a shape with a bounded number of unknowns;
- columns.py: the signals families are made of and how a force enters the equations of motion;
- model.py: a model with families added (ModelStructure) and the equations it is fitted on;
- fitting.py: its identification (fit), channel parameters by bounded Gauss-Newton steps;
- screening.py: a candidate moved by one linearised step from the current model, and its Wald test;
- criteria.py: the tests (equations, free simulation, selection, goodness of fit), one object each;
- simulation.py: output error of many fitted models in one Runge-Kutta run;
- noise.py, expected.py: the recording's own noise and the synthetic recordings of a model;
- residuals.py: locating a disagreement (sweep bands, velocity and deflection bins, spectra);
- parameters.py: what a fitted family reports, and when its values are physically impossible;
- diagnose.py: the procedure, top to bottom; result.py: what it returns and its JSON.

Must not import daq, drivers, service or simulators (the estimator's layer rule), and does no I/O."""

from estimator.doctor.diagnose import DiagnoseOptions, DiagnoseProgress, diagnose
from estimator.doctor.result import DiagnosisResult

__all__ = ["DiagnoseOptions", "DiagnoseProgress", "DiagnosisResult", "diagnose"]
