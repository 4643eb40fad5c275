"""Probe a bench: connect to every device of a bench configuration, read who it is, its status and one
measurement, and report per device instead of stopping at the first failure.

Lasers on the same port (an RS-485 line with several nodes) are probed one after the other on one shared
port; different ports, and the exciter, are probed concurrently, so a dead device costs one timeout, not
one per device. Timeouts are short: `timeout_s` per CompoWay/F attempt with one retry unless the laser's URL
sets timeout_s= / retries=; the exciter keeps its URL's reply timeout and gets an overall deadline.

A device is ok when it answers and can measure: a laser out of its measuring range, or a plate drive in
fault, is reported as a failure (the bench is not ready), with the reason in one line.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Any, Literal

from daq.bench_config import BenchConfig, ExciterConfig, LaserConfig
from drivers.compowayf.amplifier import ZxlAmplifier
from drivers.compowayf.transport import CompowayFPort, LinkSettings
from drivers.compowayf.urls import parse_device_url
from drivers.exciter.urls import CanTarget, parse_exciter_url
from drivers.interfaces import Exciter, LaserAmplifier
from estimator.errors import one_line

DEFAULT_TIMEOUT_S = 0.5
"""Reply timeout of one CompoWay/F attempt while probing (unless the URL says otherwise)."""

PROBE_RETRIES = 1


@dataclass(frozen=True)
class DeviceReport:
    """What probing one device gave: a reading (ok) or a one-line error."""

    name: str
    kind: Literal["laser", "exciter"]
    url: str
    reading: dict[str, Any] | None = None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None

    def to_json(self) -> dict[str, Any]:
        """{"name", "kind", "url", "ok", "reading" or "error"}."""
        out: dict[str, Any] = {"name": self.name, "kind": self.kind, "url": self.url, "ok": self.ok}
        if self.ok:
            out["reading"] = self.reading
        else:
            out["error"] = self.error
        return out


def probe_bench(config: BenchConfig, timeout_s: float = DEFAULT_TIMEOUT_S) -> list[DeviceReport]:
    """Probe every device of `config`; reports in configuration order (exciter first, then lasers)."""
    return asyncio.run(probe_bench_async(config, timeout_s))


async def probe_bench_async(config: BenchConfig, timeout_s: float = DEFAULT_TIMEOUT_S) -> list[DeviceReport]:
    lines: dict[str, list[LaserConfig]] = {}
    for laser in config.lasers:
        lines.setdefault(laser.device()[0], []).append(laser)
    probes = [asyncio.to_thread(_probe_laser_line, line, timeout_s) for line in lines.values()]
    results = await asyncio.gather(probe_exciter(config.exciter, timeout_s), *probes)
    by_name = {report.name: report for group in results[1:] for report in group}
    return [results[0], *(by_name[laser.name] for laser in config.lasers)]


# ---- lasers -------------------------------------------------------------------------------------------


def _probe_laser_line(lasers: list[LaserConfig], timeout_s: float) -> list[DeviceReport]:
    """Lasers sharing one port: open it once, then ask each node in turn."""
    url = parse_device_url(lasers[0].url)
    link = LinkSettings(
        timeout_s=url.timeout_s or timeout_s, retries=PROBE_RETRIES if url.retries is None else url.retries
    )
    try:
        port = CompowayFPort(lasers[0].url, link=link)
    except Exception as exc:  # a probe reports every failure as the device's error
        return [_failed(laser, exc) for laser in lasers]
    with port:
        return [
            probe_laser(laser, ZxlAmplifier(port, laser.device()[1], laser.amplifier_config()))
            for laser in lasers
        ]


def probe_laser(laser: LaserConfig, amplifier: LaserAmplifier) -> DeviceReport:
    """Model, status and one position of the amplifier `laser` names (any drivers.interfaces.LaserAmplifier:
    the ZX-L driver on an open port, or a mock)."""
    try:
        model = amplifier.read_model()
        status = amplifier.read_status()
        position_m = amplifier.read_position_m()
    except Exception as exc:  # a probe reports every failure as the device's error
        return _failed(laser, exc)
    reading = {
        "model": model,
        "operating_status": status.operating_status,
        "related_info": status.related_info,
        "position_m": position_m,
        "channel": laser.channel,
        "channel_position_m": laser.to_channel_m(position_m),
    }
    return DeviceReport(laser.name, "laser", laser.url, reading)


def _failed(laser: LaserConfig, exc: BaseException) -> DeviceReport:
    return DeviceReport(laser.name, "laser", laser.url, error=one_line(exc))


# ---- exciter ------------------------------------------------------------------------------------------


async def probe_exciter(exciter: ExciterConfig, timeout_s: float = DEFAULT_TIMEOUT_S) -> DeviceReport:
    """State, frequency and plate position reported by the drive; no keep-alive, nothing written."""
    target = parse_exciter_url(exciter.url)
    reply_timeout_s = target.reply_timeout_s if isinstance(target, CanTarget) else target.timeout_s
    deadline_s = 2 * reply_timeout_s + timeout_s  # connect + one status request, with some slack

    def failed(message: str) -> DeviceReport:
        return DeviceReport(exciter.name, "exciter", exciter.url, error=message)

    try:
        async with asyncio.timeout(deadline_s):
            drive: Exciter = await exciter.open(keepalive_interval_s=None)  # with its register map, if any
            try:
                status = await drive.status()
            finally:
                await drive.close()
        status.raise_for_fault()
    except TimeoutError as exc:
        return failed(one_line(exc) if str(exc) else f"no answer within {deadline_s:g} s")
    except Exception as exc:  # a probe reports every failure as the device's error
        return failed(one_line(exc))
    reading = {
        "state": str(status.state),
        "fault_code": status.fault_code,
        "frequency_Hz": status.frequency_Hz,
        "position_m": status.position_m,
    }
    return DeviceReport(exciter.name, "exciter", exciter.url, reading)


def all_ok(reports: list[DeviceReport]) -> bool:
    return all(report.ok for report in reports)
