"""Solvers for the identification objective: exact (convex) and differential evolution."""
