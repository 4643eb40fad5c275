"""The bench service and the command line: the HTTP API (service.api) and its job worker (service.jobs),
the one bench a service owns (service.bench_control), persistence (service.store), the customer report
(service.report), archive re-analysis (service.reanalyse) and the `shockbench` commands (service.cli).
Where each kind of work runs is in service.engines.

The top layer: it may import daq, drivers and estimator, but must not import simulators except from
service.simulated_bench (a simulated bench's devices) and service.cli.simulate (the offline vehicle
simulation) (tests/test_dependency_rules.py)."""
