"""Sweep orchestration: zero the sensors at rest, run the plate's sweep, record it, stop safely."""
