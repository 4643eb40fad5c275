"""Simulated amplifier lines reached in process, on the simulated clock: deterministic link timing.

Over a pty or a socket (simulators/devices/laser_amplifier.py) the host's reply timeouts and OMRON's
late-reply wait run on the wall clock while a manual-clock bench stands still, so a lost reply costs the
simulated sweep nothing and cannot be measured. A `LoopbackLine` (the host's port opens it as its pyserial
stand-in and times on the bench's clock) instead hands each command frame straight to an `AmplifierLine`
(its faults included: a NO_REPLY fault with count=1 is one lost reply) and puts the reply, if any, where
the port reads it at once. A read that finds nothing moves the bench on by one read
slice: waiting for a reply takes simulated time, so a timeout takes `timeout_s` of it, deterministically.

`unplug()` pulls the adapter (the port itself fails, as a USB adapter pulled out does: writes raise and
re-opening fails); `plug_in()` puts it back. A cable pulled between the adapter and the amplifiers is a
NO_REPLY fault on every node of the line instead (the adapter stays, nothing answers).

Caveat: a reply timeout happens inside a poll, and a manual-clock bench has one thread, so it holds the whole
bench (the orchestration's keep-alive included), where on a real bench only the line's thread waits. Keep
reply timeouts of simulated runs well under the drive's watchdog (0.5 s): 0.1 s is used in the tests.
"""

from __future__ import annotations

from collections.abc import Callable

import serial

from simulators.devices.laser_amplifier import AmplifierLine

DEFAULT_READ_SLICE_S = 0.01
"""Simulated time one empty read takes (the resolution of a timeout)."""


class LoopbackLine:
    """A pyserial stand-in (drivers.compowayf.transport.SerialLike) carrying one AmplifierLine in process.

    now_s: the bench's clock; advance(dt_s): moves the bench on (SimulatedBench.advance)."""

    def __init__(
        self,
        line: AmplifierLine,
        now_s: Callable[[], float],
        advance: Callable[[float], None],
        read_slice_s: float = DEFAULT_READ_SLICE_S,
    ) -> None:
        if read_slice_s <= 0:
            raise ValueError("read_slice_s must be positive")
        self.line = line
        self.now_s = now_s
        self.advance = advance
        self.read_slice_s = read_slice_s
        self.timeout: float | None = 0.0
        self.plugged = True
        self._pending = b""

    def open(self) -> LoopbackLine:
        """The port opener: this line, unless unplugged."""
        if not self.plugged:
            raise serial.SerialException("loopback adapter unplugged")
        return self

    def unplug(self) -> None:
        self.plugged = False

    def plug_in(self) -> None:
        self.plugged = True

    @property
    def in_waiting(self) -> int:
        return len(self._pending)

    def _check_plugged(self) -> None:
        if not self.plugged:
            raise serial.SerialException("loopback adapter unplugged")

    def write(self, data: bytes) -> int:
        self._check_plugged()
        reply, _drop = self.line.reply_to(data)  # a serial line cannot drop: DROP acts as no reply
        if reply:
            self._pending += reply
        return len(data)

    def read(self, size: int = 1) -> bytes:
        self._check_plugged()
        if not self._pending:
            self.advance(self.read_slice_s)  # waiting for bytes takes (simulated) time
            return b""
        chunk, self._pending = self._pending[:size], self._pending[size:]
        return chunk

    def reset_input_buffer(self) -> None:
        self._pending = b""

    def close(self) -> None:
        self._pending = b""
