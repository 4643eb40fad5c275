"""OMRON CompoWay/F: frame codec (codec), typed errors (errors), the serial/socket link with retries
(transport), device URLs (urls), read-rate bookkeeping (rate) and the ZX-L laser amplifier driver
(amplifier)."""

from drivers.compowayf.amplifier import (
    AmplifierConfig,
    CountUnit,
    MeasuredArea,
    MeasuredValueConfig,
    OperationCodes,
    ZxlAmplifier,
)
from drivers.compowayf.rate import ReadRate
from drivers.compowayf.transport import CompowayFPort, LinkSettings
from drivers.compowayf.urls import DeviceUrl, SerialSettings, parse_device_url

__all__ = [
    "AmplifierConfig",
    "CompowayFPort",
    "CountUnit",
    "DeviceUrl",
    "LinkSettings",
    "MeasuredArea",
    "MeasuredValueConfig",
    "OperationCodes",
    "ReadRate",
    "SerialSettings",
    "ZxlAmplifier",
    "parse_device_url",
]
