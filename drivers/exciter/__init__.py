"""Plate exciter drivers: one interface; Modbus, CAN (own frame set) and CiA 402 (CANopen) back ends.
Must not import daq, service or simulators (drivers import only drivers and estimator,
tests/test_dependency_rules.py)."""
