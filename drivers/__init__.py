"""Device drivers: one sub-package per device family, protocol codecs kept apart from transports.

drivers.interfaces holds what the acquisition needs of a laser amplifier, its line and a plate exciter
(typing.Protocol); drivers.mock holds in-process mock back ends of them for unit tests.
Must not import daq, service or simulators (tests/test_dependency_rules.py)."""
