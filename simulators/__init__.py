"""Test worlds: simulated devices that speak the real protocols on real transports (simulators.devices), a
vehicle on the plate, the offline vehicle simulation (simulators.vehicle_sim), and independent worlds that
share no code with the estimator (simulators.independent, .foreign, .lab_rig).

Must not import daq or service, and of drivers only the codecs and address maps a device shares with
its driver (tests/test_dependency_rules.py): a simulator that used the driver's logic could not catch
the driver's mistakes."""
