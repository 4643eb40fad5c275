"""Solvers for the identification objective: exact (convex) and differential evolution.

Must not import daq, drivers, service or simulators (the estimator's layer rule)."""
