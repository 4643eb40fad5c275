"""Sweep orchestration: zero the sensors at rest, run the plate's sweep, record it, stop safely.
Must not import service or simulators (daq's layer rule, tests/test_dependency_rules.py)."""
