"""From a device's clock to the host's: where a device-stamped sample lies on the host's monotonic time.

A streaming amplifier stamps its samples with its own sample counter (device time = counter x period, from
an origin only the device knows). Each read gives one pair: the device time of the newest sample and the
host time the reply arrived. The sample was taken before the read, so

    host_received - device_newest = offset + (wait from sampling to the read) + transport latency >= offset.

The lower envelope of these differences therefore approaches the clock offset (plus the smallest one-way
latency, which is alike for every source on the same kind of link). `DeviceClockMapping` keeps that minimum
over the reads made while the vehicle stands at rest before a sweep (zeroing) and is then frozen, so the
samples of a sweep are mapped with one offset and never jump against each other. Sources of one bench are
then aligned to within their difference in minimum latency (sub-millisecond on loopback TCP; measure it
on a real line).

Not modelled: drift between the device's clock and the host's. A 50 ppm quartz drifts 1.5 ms over a 30 s
sweep; if real amplifiers show that, fit the slope of the envelope as well.
"""

from __future__ import annotations

import math


class DeviceClockMapping:
    """host time (s) = device time (s) + offset_s, the offset being the lower envelope of the read pairs."""

    def __init__(self) -> None:
        self._offset_s = math.inf
        self.pairs = 0
        self.frozen = False

    def observe(self, device_newest_s: float, host_received_s: float) -> None:
        """Book one read: the device time of its newest sample and the host time the reply came in
        (ignored once frozen)."""
        if not self.frozen:
            self._offset_s = min(self._offset_s, host_received_s - device_newest_s)
            self.pairs += 1

    def freeze(self) -> None:
        """Keep the present offset from now on (RuntimeError if no read was observed)."""
        _ = self.offset_s
        self.frozen = True

    @property
    def calibrated(self) -> bool:
        return self.pairs > 0

    @property
    def offset_s(self) -> float:
        if not self.calibrated:
            raise RuntimeError("no read observed yet: the device clock cannot be mapped")
        return self._offset_s

    def to_host_s(self, device_s: float) -> float:
        return device_s + self.offset_s
