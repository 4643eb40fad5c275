"""The model doctor (issue 29); its procedure, top to bottom, is estimator.doctor.diagnose's docstring.

- catalog.py: the effect families, each a shape with a bounded number of unknowns, and their columns;
- model.py: a model with families added (ModelStructure) and the equations it is fitted on;
- fitting.py: its identification (fit), channel parameters by bounded Gauss-Newton steps, and a candidate
  moved by one linearised step from the current model with its Wald test (one_step);
- criteria.py: the tests (equations, free simulation, selection, goodness of fit), one object each;
- simulation.py: output error of many fitted models in one Runge-Kutta run;
- expected.py: the bootstrap: a model's plausible truth, the recording's own noise, synthetic recordings;
- residuals.py: locating a disagreement (sweep bands, velocity and deflection bins, spectra);
- parameters.py: what a fitted family reports, and when its values are physically impossible;
- diagnose.py: the procedure; result.py: what it returns and its JSON.

Must not import daq, drivers, service or simulators (the estimator's layer rule), and does no I/O."""

from estimator.doctor.diagnose import DiagnoseOptions, DiagnoseProgress, diagnose
from estimator.doctor.result import DiagnosisResult

__all__ = ["DiagnoseOptions", "DiagnoseProgress", "DiagnosisResult", "diagnose"]
