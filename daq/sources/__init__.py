"""Sources: the drivers feeding the acquisition, each into a ring buffer of its own at its own rate.
Must not import service or simulators (daq's layer rule, tests/test_dependency_rules.py)."""
