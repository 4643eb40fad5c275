"""How long a sweep reads the sensors beside the plate's own sweep, declared once (estimator.declared): the
request's checks (daq.sweep.model.SweepRequest), the API's field and the CLI's options come from here.

Standard library only, so that `shockbench --help` does not import the acquisition stack."""

from __future__ import annotations

from dataclasses import dataclass

from estimator.declared import setting

TIMING_NAMES = ("settle_s", "rest_s")


@dataclass(frozen=True)
class SweepTiming:
    """settle_s: recorded after the sweep ends; rest_s: read at rest beforehand, to zero the channels and map
    the amplifiers' clocks (at least 0.1 s: fewer readings cannot zero a channel)."""

    settle_s: float = setting(2.0, "recorded after the sweep", unit="s", ge=0, le=600)
    rest_s: float = setting(1.0, "read at rest before the sweep (zeroing)", unit="s", ge=0.1, le=600)
