"""Interchange file formats: the recording CSV and the vehicle TOML (documented in README.md)."""
