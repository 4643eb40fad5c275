"""OMRON CompoWay/F: frame codec (codec), the service data the frames carry (service_data), typed errors
(errors), the serial/socket link with resync, reply matching, late-reply waits and retries (transport),
device URLs (urls), where an amplifier keeps its measured value (layout), read-rate bookkeeping (rate) and
the ZX-L laser amplifier driver (amplifier).

Nothing is imported here: a simulator that imports the codec or the address map (drivers.compowayf.codec,
.service_data, .layout) loads them alone, without the driver and its serial transport; import from the
modules.
Must not import daq, service or simulators (drivers import only drivers and estimator,
tests/test_dependency_rules.py)."""
