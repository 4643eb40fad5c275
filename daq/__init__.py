"""Acquisition: the bench configuration, the laser and exciter sources feeding ring buffers, the sweep that
zeroes the sensors, drives the plate and records, the HDF5 recordings and the interchange formats (CSV
recordings, TOML vehicle files), and the decimated live view.

Must not import service or simulators: daq runs the real bench through drivers and estimator only
(tests/test_dependency_rules.py); a simulated bench is started by service.simulated_bench, above it."""
