"""Simulated OMRON ZX-L-N laser amplifiers speaking CompoWay/F on a pty or a TCP socket.

Each `SimulatedAmplifier` is one node: a `SimulatedHead` bound to a bench channel, the same
`AmplifierConfig` the driver uses (so both agree on where the measured value lives and how it scales), a
small parameter area and the zero-reset state. A server (`PtyAmplifierServer`, `TcpAmplifierServer`) carries
one or more nodes on one transport, like an RS-485 multi-drop line: every node answers only its own node
number, commands for absent nodes get no reply. One thread per server; frames are parsed and built with
drivers.compowayf.codec, the driver's own codec.

Measured values live where the configuration says (area, type, address; by default the ZS-series
measurement result, parameter area C020 address 3000, see drivers.compowayf.layout). Each read of the
measured area takes a sample at bench.clock.now_s() (unless one was already taken at that simulated time)
and pushes it into a buffer of `buffer_length` samples, newest at the configured address, older ones at the
following addresses. Tests fill the buffer at a chosen rate by advancing the clock and calling `sample()`; a
buffer not yet full repeats its oldest sample.

Streaming amplifiers (a configuration with `sample_period_s` and a sample counter, see
drivers.compowayf.layout.streaming_measured_config) sample on their own clock instead: sample k is taken at
origin + k * sample_period_s, where origin is the bench time at which the amplifier was created, and is
stored in ring slot k % buffer_length after the counter. On every read (and every `sample()`), the samples
due since the last one are taken, at their own instants (the bench keeps a short history of its motion for
this), and the counter says how many have been taken in all. Samples older than the ring are counted but
never measured.

Protocol limits as OMRON documents them: 0503 answers the model and the communications buffer size
(BUFFER_SIZE_BYTES, 217 = 00D9 hex, as the 900-TC controllers report); a command frame longer than the buffer
gets end code 18; a read of more elements than one reply may carry (25 double words, fewer when the buffer
is smaller) gets response code 110B (response too long).

Faults (`inject_fault`, `clear_faults`), switchable at run time, for one node or all, for the next `count`
replies or until cleared: no reply, garbage bytes, bad BCC, a given end code, a given response code,
out-of-range readings, an incomplete reply (no ETX/BCC), a 0x00 byte before the reply's STX (an RS-485 line
turning around) and, on TCP, a dropped connection (on a pty that one behaves as no reply). A line built with
echo=True echoes every byte it receives before answering, as some RS-485 adapters do.

The node, the line and its faults, and the servers live in simulators.devices.amplifier_node,
.amplifier_line and .amplifier_servers; their public names are importable from here.
"""

from __future__ import annotations

from simulators.devices.amplifier_line import GARBAGE_REPLY, AmplifierLine, Fault, FaultKind
from simulators.devices.amplifier_node import (
    BUFFER_SIZE_BYTES,
    DEFAULT_PARAMETERS,
    PARAMETER_READ_ECHO_CHARS,
    SimulatedAmplifier,
)
from simulators.devices.amplifier_servers import PtyAmplifierServer, TcpAmplifierServer

__all__ = [
    "BUFFER_SIZE_BYTES",
    "DEFAULT_PARAMETERS",
    "GARBAGE_REPLY",
    "PARAMETER_READ_ECHO_CHARS",
    "AmplifierLine",
    "Fault",
    "FaultKind",
    "PtyAmplifierServer",
    "SimulatedAmplifier",
    "TcpAmplifierServer",
]
