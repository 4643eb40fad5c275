"""Interchange file formats: the recording CSV and the vehicle TOML (documented in README.md).

Must not import service, simulators or drivers: the formats are read by the estimator's users and by
the service alike, without a device stack."""
