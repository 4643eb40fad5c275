"""What the service tests read from a diagnosis of the plate-offset recording (tests/service/conftest.py)."""

from __future__ import annotations

from typing import Any


def tyre_deflection_zero_error_m(step: dict[str, Any]) -> float:
    """The zero error of the tyre deflection x_t − x_r that a sensor_offset step stands for: an offset of the
    plate (x_r) and the opposite one of the wheel (x_t) enter the equations alike (only x_t − x_r does),
    so the doctor may name either."""
    assert step["effect"] in ("sensor_offset(x_r)", "sensor_offset(x_t)"), step["effect"]
    offset = float(step["parameters"]["offset_m"])
    return -offset if step["parameters"]["channel"] == "x_r" else offset
