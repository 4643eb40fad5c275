"""Can a recording carry its sweep? The achieved rate of the slowest sensor against the sweep's top frequency.

The recorder puts every channel on the 1 ms grid, whatever rate its sensor achieved: a polled amplifier on
a slow serial line may deliver far fewer than 1000 samples/s, and the grid values between its samples are
interpolated (cubic, daq/alignment.py). How wrong that is depends on the samples per period of the fastest
motion, the sweep's top frequency f: cubic interpolation of a sine with N samples per period errs by about
0.023 (2 pi / N)^4 of its amplitude, i.e. 6% at N = 5 and 0.4% at N = 10. Hence, with r the slowest
channel's achieved rate (Hz, the recording's `rate_Hz.<channel>` metadata):

* r < REFUSE_SAMPLES_PER_PERIOD * f: refused (InsufficientBandwidthError): the curve would be an artefact
  of the interpolation, and below 2 f the sweep's top aliases outright;
* r < WARN_SAMPLES_PER_PERIOD * f: identified, with a warning naming the channel and its rate.

The sample grid itself is judged by the same rule: a channel cannot have been sampled faster than its grid,
so the grid rate 1/Δt stands for every channel without rate metadata (simulated recordings, CSVs from
elsewhere, decimated files). A recording on a 20 Hz grid cannot carry a 0-20 Hz sweep, whatever it claims.
The sweep's top frequency comes from `sweep_stop_Hz`/`sweep_start_Hz` metadata, else DEFAULT_TOP_HZ (the
bench's standard 0-20 Hz sweep): a CSV without metadata needs a grid of at least 100 Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from estimator.errors import UserError
from estimator.recording import Recording

REFUSE_SAMPLES_PER_PERIOD = 5.0
WARN_SAMPLES_PER_PERIOD = 10.0
DEFAULT_TOP_HZ = 20.0
RATE_PREFIX = "rate_Hz."


class InsufficientBandwidthError(UserError, ValueError):
    """A sensor's achieved rate cannot carry the sweep; the message names the channel, its rate and the
    sweep's top frequency."""


@dataclass(frozen=True)
class BandwidthCheck:
    slowest_channel: str
    slowest_rate_Hz: float
    sweep_top_Hz: float
    warnings: tuple[str, ...]


def _number(metadata: dict[str, str], key: str) -> float | None:
    try:
        value = float(metadata[key])
    except (KeyError, ValueError):
        return None
    return value if math.isfinite(value) else None


def check_bandwidth(recording: Recording) -> BandwidthCheck:
    """Refuse (InsufficientBandwidthError) or warn when the slowest sensor cannot carry the sweep."""
    metadata = recording.metadata
    tops = [v for v in (_number(metadata, "sweep_stop_Hz"), _number(metadata, "sweep_start_Hz")) if v]
    top_Hz = max(tops) if tops else DEFAULT_TOP_HZ
    rates = {
        key[len(RATE_PREFIX) :]: rate
        for key in metadata
        if key.startswith(RATE_PREFIX) and (rate := _number(metadata, key)) is not None
    }
    grid_Hz = 1.0 / recording.sample_time_s
    rates = {channel: min(rates.get(channel, grid_Hz), grid_Hz) for channel in sorted(recording.channels)}
    channel = min(rates, key=rates.__getitem__)
    rate = rates[channel]
    per_period = rate / top_Hz if top_Hz > 0 else math.inf
    what = f"channel {channel} was sampled at" if rate < grid_Hz else "the recording's sample grid is"
    if per_period < REFUSE_SAMPLES_PER_PERIOD:
        raise InsufficientBandwidthError(
            f"{what} {rate:.1f} Hz, {per_period:.1f} samples per period of the "
            f"sweep's {top_Hz:g} Hz top; at least {REFUSE_SAMPLES_PER_PERIOD * top_Hz:.0f} Hz is needed "
            "(a faster line, fewer amplifiers per line, or a streaming amplifier)"
        )
    warnings: tuple[str, ...] = ()
    if per_period < WARN_SAMPLES_PER_PERIOD:
        warnings = (
            f"channel {channel} was sampled at only {rate:.1f} Hz ({per_period:.1f} samples per period at "
            f"{top_Hz:g} Hz): interpolation errors near the sweep's top reach a few percent",
        )
    return BandwidthCheck(channel, rate, top_Hz, warnings)
