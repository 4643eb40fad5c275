"""OMRON CompoWay/F: frame codec (codec), typed errors (errors), the serial/socket link with resync, reply
matching, late-reply waits and retries (transport), device URLs (urls), where an amplifier keeps its
measured value (layout), read-rate bookkeeping (rate) and the ZX-L laser amplifier driver (amplifier)."""

from drivers.compowayf.amplifier import (
    AmplifierConfig,
    CountUnit,
    MeasuredArea,
    MeasuredValueConfig,
    OperationCodes,
    StreamRead,
    ZxlAmplifier,
)
from drivers.compowayf.codec import ControllerAttributes
from drivers.compowayf.layout import streaming_measured_config, zs_result_address
from drivers.compowayf.rate import ReadRate
from drivers.compowayf.transport import OMRON_WORST_CASE_RESPONSE_S, CompowayFPort, LinkSettings
from drivers.compowayf.urls import DeviceUrl, SerialSettings, parse_device_url

__all__ = [
    "OMRON_WORST_CASE_RESPONSE_S",
    "AmplifierConfig",
    "CompowayFPort",
    "ControllerAttributes",
    "CountUnit",
    "DeviceUrl",
    "LinkSettings",
    "MeasuredArea",
    "MeasuredValueConfig",
    "OperationCodes",
    "ReadRate",
    "SerialSettings",
    "StreamRead",
    "ZxlAmplifier",
    "parse_device_url",
    "streaming_measured_config",
    "zs_result_address",
]
