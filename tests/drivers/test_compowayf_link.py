"""The CompoWay/F link and the ZX-L driver against a scripted line on a simulated clock (PyMeasure style: the
line holds the exact command bytes expected and the reply bytes to give, and at the end every command and
every reply byte must have been consumed).

Frames: OMRON publishes one complete frame with its BCC (E5CN, 3G3JV, KM-N3 manuals, "BCC calculation
example": STX "0" "0" "0" "0" "0" "0" "5" "0" "3" ETX, BCC 35h, a 0503 read to node 00); `frame` below is
checked against it. OMRON's ZS-series command reference publishes the command and response text of a
measurement result read ("02 01 C020 3002 8001" -> "02 01 C020 3002 8001 04CC5520", 80.5 mm); the frames
around that text, and all other frames here, are constructed from the documented frame format (STX, node
number, sub-address "00", SID "0", FINS-mini command text, ETX, BCC = XOR of node number through ETX) by
`frame`, which is independent of drivers.compowayf.codec.

Timing: the scripted line has its own clock (simulated seconds) which the port uses for its deadlines: a
reply scheduled `delay_s` after its command arrives at that simulated time; a read with nothing due moves the
clock on by one read slice. No test waits on the wall clock.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import pytest

from drivers.compowayf import errors
from drivers.compowayf.amplifier import AmplifierConfig, MeasuredArea, MeasuredValueConfig, ZxlAmplifier
from drivers.compowayf.layout import streaming_measured_config, zs_result_address
from drivers.compowayf.transport import OMRON_WORST_CASE_RESPONSE_S, CompowayFPort, LinkSettings
from drivers.compowayf.urls import parse_device_url

STX, ETX = b"\x02", b"\x03"


def frame(text: str) -> bytes:
    """STX, text, ETX, BCC (XOR of every byte after STX through ETX), as OMRON's manuals define it."""
    body = text.encode("ascii") + ETX
    check = 0
    for byte in body:
        check ^= byte
    return STX + body + bytes([check])


def command(node: str, mrc_src: str, data: str = "") -> bytes:
    return frame(node + "00" + "0" + mrc_src + data)


def reply(node: str, mrc_src: str, data: str = "", response_code: str = "0000") -> bytes:
    return frame(node + "00" + "00" + mrc_src + response_code + data)


# ZS measurement result of channel 2 (OMRON's published example text, node 01): parameter type C020,
# address 3002 (unit 30h, CH 2), one element (8001); the reply repeats those and carries 04CC5520 nm.
ZS_READ = command("01", "0201", "C020" + "3002" + "8001")
ZS_REPLY_80_5_MM = reply("01", "0201", "C020" + "3002" + "8001" + "04CC5520")
ZS_REPLY_MARKER = reply("01", "0201", "C020" + "3002" + "8001" + "7FFFFFF5")
ZS_LAYOUT = MeasuredValueConfig(address=zs_result_address(2))

# The same read on variable area C0 (a layout a bench may configure): one and two elements.
READ_ONE = command("01", "0101", "C0" + "0000" + "00" + "0001")
READ_TWO = command("01", "0101", "C0" + "0000" + "00" + "0002")
REPLY_1000 = reply("01", "0101", "000003E8")
REPLY_2000 = reply("01", "0101", "000007D0")
REPLY_TWO = reply("01", "0101", "000007D0" + "FFFFF830")
VARIABLE_C0 = MeasuredValueConfig(area=MeasuredArea.VARIABLE, area_type=0xC0, address=0x0000)

MODEL = command("01", "0503")
MODEL_REPLY_217 = reply("01", "0503", "ZX-LDA11-N" + "00D9")  # 217-byte buffer, as OMRON's 900-TC reports
MODEL_REPLY_40 = reply("01", "0503", "ZX-LDA11-N" + "0028")  # 40-byte buffer, OMRON's E5CN example
FRAME_TOO_LONG = frame("01" + "00" + "18")  # short error form: node, sub-address, end code 18


@dataclass
class Exchange:
    """One scripted exchange: the command expected, the reply bytes and when they arrive after it."""

    command: bytes
    reply: bytes = b""
    delay_s: float = 0.0


@dataclass
class ScriptedLine:
    """A pyserial stand-in with a simulated clock (see the module docstring). echo: the line sends every
    command back at once, before any reply, as an RS-485 adapter that hears itself."""

    script: list[Exchange]
    echo: bool = False
    poll_s: float = 0.02
    now_s: float = 0.0
    timeout: float | None = 0.0
    closed: bool = False
    flushed: bytes = b""
    _due: list[tuple[float, bytes]] = field(default_factory=list)

    def clock(self) -> float:
        return self.now_s

    @property
    def in_waiting(self) -> int:
        return sum(len(chunk) for due_s, chunk in self._due if due_s <= self.now_s)

    def _take_due(self) -> bytes:
        ready = [chunk for due_s, chunk in self._due if due_s <= self.now_s]
        self._due = [(due_s, chunk) for due_s, chunk in self._due if due_s > self.now_s]
        return b"".join(ready)

    def reset_input_buffer(self) -> None:
        self.flushed += self._take_due()

    def write(self, data: bytes) -> int:
        assert self.script, f"unexpected command {data!r}"
        exchange = self.script.pop(0)
        assert data == exchange.command, f"command {data!r}, expected {exchange.command!r}"
        if self.echo:
            self._due.append((self.now_s, data))
        if exchange.reply:
            self._due.append((self.now_s + exchange.delay_s, exchange.reply))
        return len(data)

    def read(self, size: int = 1) -> bytes:
        chunk = self._take_due()
        if not chunk:
            self.now_s += self.poll_s  # waiting for bytes takes time
        return chunk

    def close(self) -> None:
        self.closed = True

    def assert_consumed(self) -> None:
        assert not self.script, f"{len(self.script)} scripted exchange(s) never happened"
        assert not self._due, f"reply bytes never read: {self._due!r}"
        assert not self.flushed, f"reply bytes flushed unread: {self.flushed!r}"


@pytest.fixture
def lines() -> Iterator[list[ScriptedLine]]:
    """Collects the scripted lines a test creates and checks each was consumed completely."""
    made: list[ScriptedLine] = []
    yield made
    for line in made:
        line.assert_consumed()


def _amplifier(
    lines: list[ScriptedLine],
    script: list[Exchange],
    measured: MeasuredValueConfig = ZS_LAYOUT,
    *,
    echo: bool = False,
    link: LinkSettings | None = None,
) -> tuple[ZxlAmplifier, ScriptedLine]:
    line = ScriptedLine(script, echo=echo)
    lines.append(line)
    port = CompowayFPort(
        "loop://",
        link=link or LinkSettings(timeout_s=0.5, retries=2, echo=echo),
        opener=lambda: line,
        clock=line.clock,
    )
    return ZxlAmplifier(port, 1, AmplifierConfig(measured=measured)), line


# --- frames and defaults ----------------------------------------------------------------------------------


def test_frame_helper_reproduces_omrons_published_bcc_example() -> None:
    assert frame("000000503") == b"\x02" + b"000000503" + b"\x03" + b"\x35"


def test_default_layout_reads_the_zs_measurement_result_in_nm(lines: list[ScriptedLine]) -> None:
    amplifier, _ = _amplifier(lines, [Exchange(ZS_READ, ZS_REPLY_80_5_MM)])
    assert amplifier.read_position_m() == pytest.approx(0.0805)


def test_omrons_worst_case_reply_time_is_the_default_late_reply_wait() -> None:
    assert OMRON_WORST_CASE_RESPONSE_S == 3.0 and LinkSettings().late_reply_s == 3.0
    url = parse_device_url("socket://127.0.0.1:9?node=1&timeout_s=3&late_reply_s=0&echo=1")
    assert (url.timeout_s, url.late_reply_s, url.echo) == (3.0, 0.0, True)
    with pytest.raises(errors.DeviceUrlError, match="echo"):
        parse_device_url("socket://127.0.0.1:9?node=1&echo=maybe")


# --- C1: resync on STX ------------------------------------------------------------------------------------


def test_a_null_byte_before_stx_is_skipped(lines: list[ScriptedLine]) -> None:
    amplifier, _ = _amplifier(lines, [Exchange(ZS_READ, b"\x00" + ZS_REPLY_80_5_MM)] * 2)
    assert amplifier.read_position_m() == pytest.approx(0.0805)
    assert amplifier.read_position_m() == pytest.approx(0.0805)  # before every reply: every read still works
    assert amplifier.port.counters.skipped_bytes == 2 and amplifier.port.counters.retries == 0


def test_garbage_and_a_broken_frame_before_stx_are_skipped(lines: list[ScriptedLine]) -> None:
    noise = b"\xff\x7e\x00" + STX + b"0100"  # noise, then a frame cut short by a new STX
    amplifier, _ = _amplifier(lines, [Exchange(ZS_READ, noise + ZS_REPLY_80_5_MM)])
    assert amplifier.read_position_m() == pytest.approx(0.0805)
    assert amplifier.port.counters.skipped_bytes == len(noise) and amplifier.port.counters.retries == 0


# --- C2: late replies -------------------------------------------------------------------------------------


def test_a_late_reply_is_waited_out_and_not_taken_as_the_next_answer(lines: list[ScriptedLine]) -> None:
    link = LinkSettings(timeout_s=0.5, retries=0)
    script = [Exchange(READ_ONE, REPLY_1000, delay_s=1.2), Exchange(READ_ONE, REPLY_2000)]
    amplifier, line = _amplifier(lines, script, VARIABLE_C0, link=link)
    with pytest.raises(errors.ResponseTimeoutError, match=r"no reply within 0\.5 s"):
        amplifier.read_counts(1)
    assert amplifier.read_counts(1) == [2000]  # its own reply, not the 1000 that came late
    counters = amplifier.port.counters
    assert (counters.late_reply_waits, counters.discarded_frames) == (1, 1)
    assert 1.2 <= line.now_s < 1.3  # the wait ended when the late reply came, not at 3 s


def test_after_a_timeout_the_next_request_waits_omrons_three_seconds(lines: list[ScriptedLine]) -> None:
    link = LinkSettings(timeout_s=0.5, retries=1)
    script = [Exchange(READ_ONE), Exchange(READ_ONE, REPLY_1000)]
    amplifier, line = _amplifier(lines, script, VARIABLE_C0, link=link)
    assert amplifier.read_counts(1) == [1000]  # the retry
    assert line.now_s >= OMRON_WORST_CASE_RESPONSE_S  # sent only once the first could no longer answer


def test_a_reply_that_does_not_match_the_request_is_discarded(lines: list[ScriptedLine]) -> None:
    link = LinkSettings(timeout_s=0.5, retries=0, late_reply_s=0.0)  # no wait: matching alone must do it
    script = [
        Exchange(READ_ONE, REPLY_1000, delay_s=0.6),  # answered after its timeout ...
        Exchange(READ_TWO, REPLY_TWO, delay_s=0.2),  # ... so it arrives during the next request
        Exchange(MODEL, REPLY_1000, delay_s=0.0),  # a reply to another service before the right one
    ]
    script[2].reply += MODEL_REPLY_217
    amplifier, _ = _amplifier(lines, script, VARIABLE_C0, link=link)
    with pytest.raises(errors.ResponseTimeoutError):
        amplifier.read_counts(1)
    assert amplifier.read_variable_area(0xC0, 0x0000, 2) == [2000, -2000]  # the one-element reply dropped
    assert amplifier.read_model() == "ZX-LDA11-N"
    assert amplifier.port.counters.discarded_frames == 2


def test_a_parameter_read_reply_must_repeat_its_own_request(lines: list[ScriptedLine]) -> None:
    other = reply("01", "0201", "C020" + "3000" + "8001" + "00000001")  # channel 0's value, not channel 2's
    amplifier, _ = _amplifier(lines, [Exchange(ZS_READ, other + ZS_REPLY_80_5_MM)])
    assert amplifier.read_position_m() == pytest.approx(0.0805)
    assert amplifier.port.counters.discarded_frames == 1


# --- C3: controller attributes ----------------------------------------------------------------------------


def test_0503_is_model_and_buffer_size(lines: list[ScriptedLine]) -> None:
    amplifier, _ = _amplifier(lines, [Exchange(MODEL, MODEL_REPLY_217)])
    attributes = amplifier.read_attributes()
    assert (attributes.model, attributes.buffer_size_bytes) == ("ZX-LDA11-N", 217)
    assert amplifier.buffer_size_bytes == 217


def test_0503_without_a_buffer_size_is_malformed(lines: list[ScriptedLine]) -> None:
    link = LinkSettings(timeout_s=0.5, retries=0)
    amplifier, _ = _amplifier(lines, [Exchange(MODEL, reply("01", "0503", "ZX-LDA11-N"))], link=link)
    with pytest.raises(errors.MalformedFrameError, match="buffer size"):
        amplifier.read_model()


def test_a_small_buffer_size_caps_every_read(lines: list[ScriptedLine]) -> None:
    # 40 bytes hold 17 bytes of frame and (40 - 17) // 8 = 2 double words: 5 elements take 3 requests.
    script = [
        Exchange(MODEL, MODEL_REPLY_40),
        Exchange(READ_TWO, REPLY_TWO),
        Exchange(command("01", "0101", "C0" + "0002" + "00" + "0002"), REPLY_TWO),
        Exchange(command("01", "0101", "C0" + "0004" + "00" + "0001"), REPLY_1000),
    ]
    amplifier, _ = _amplifier(lines, script, VARIABLE_C0)
    amplifier.read_model()
    assert amplifier.read_variable_area(0xC0, 0x0000, 5) == [2000, -2000, 2000, -2000, 1000]


# --- C5: at most 25 double words per read ------------------------------------------------------------------


def _ring_script(counter: int, length: int) -> tuple[list[Exchange], list[int]]:
    """The exchanges of read_stream(length) on a ring of `length` slots whose counter reads `counter`: the
    counter, the ring from the oldest sample's slot in requests of at most 25 (19 hex), the counter again.
    Slot s holds the value s + 1 (so a value names its slot)."""
    script = [
        Exchange(command("01", "0101", "C0" + "0000" + "00" + "0001"), reply("01", "0101", f"{counter:08X}"))
    ]
    first = counter % length
    runs = [(first, length - first), (0, first)] if first else [(0, length)]
    for start, n in runs:
        for done in range(0, n, 25):
            chunk = min(25, n - done)
            slot = start + done
            values = "".join(f"{s + 1:08X}" for s in range(slot, slot + chunk))
            request = "C0" + f"{slot + 1:04X}" + "00" + f"{chunk:04X}"
            script.append(Exchange(command("01", "0101", request), reply("01", "0101", values)))
    script.append(script[0])  # every slot was read: the counter is checked again
    newest_first = [(counter - 1 - k) % length + 1 for k in range(length)]
    return script, newest_first


def test_a_1000_sample_ring_is_read_in_requests_of_25(lines: list[ScriptedLine]) -> None:
    script, expected = _ring_script(counter=1500, length=1000)
    assert len(script) == 2 + 40  # counter, 40 x 25 double words, counter
    amplifier, _ = _amplifier(lines, script, streaming_measured_config(0.001, 1000))
    read = amplifier.read_stream(1000)
    assert read.counter == 1500 and read.counts == expected


def test_samples_overwritten_during_a_read_are_dropped(lines: list[ScriptedLine]) -> None:
    script, expected = _ring_script(counter=60, length=50)
    script[-1] = Exchange(script[-1].command, reply("01", "0101", f"{63:08X}"))  # 3 taken meanwhile
    amplifier, _ = _amplifier(lines, script, streaming_measured_config(0.001, 50))
    read = amplifier.read_stream(50)
    assert read.counts == expected[:47]  # the 3 oldest slots may hold newer samples: not returned


def test_a_stream_read_since_a_counter_reads_only_the_new_samples(lines: list[ScriptedLine]) -> None:
    script = [
        Exchange(command("01", "0101", "C0" + "0000" + "00" + "0001"), reply("01", "0101", f"{258:08X}")),
        # samples 255, 256, 257 sit in slots 255, 0, 1 of a 256-slot ring (addresses 0100, 0001, 0002)
        Exchange(command("01", "0101", "C0" + "0100" + "00" + "0001"), reply("01", "0101", "00000001")),
        Exchange(
            command("01", "0101", "C0" + "0001" + "00" + "0002"), reply("01", "0101", "00000002" + "00000003")
        ),
    ]
    amplifier, _ = _amplifier(lines, script, streaming_measured_config(0.001, 256))
    read = amplifier.read_stream(256, since=255)
    assert read.counter == 258 and read.counts == [3, 2, 1]


# --- C4: out-of-range markers, minor findings -----------------------------------------------------------


def test_7ffffff5_is_out_of_range(lines: list[ScriptedLine]) -> None:
    amplifier, _ = _amplifier(lines, [Exchange(ZS_READ, ZS_REPLY_MARKER)])
    with pytest.raises(errors.MeasurementOutOfRangeError, match="7FFFFFF5"):
        amplifier.read_position_m()
    config = ZS_LAYOUT
    assert [config.is_out_of_range(c) for c in (0x7FFFFFEF, 0x7FFFFFF0, 0x7FFFFFFF, -0x80000000)] == [
        False,
        True,
        True,
        False,
    ]


def test_end_code_18_is_raised_at_once_not_retried(lines: list[ScriptedLine]) -> None:
    amplifier, _ = _amplifier(lines, [Exchange(ZS_READ, FRAME_TOO_LONG)])  # retries=2, one exchange only
    with pytest.raises(errors.FrameLengthEndCodeError, match="end code 18"):
        amplifier.read_position_m()
    assert amplifier.port.counters.retries == 0


def test_an_echoing_adapter_with_echo_suppression(lines: list[ScriptedLine]) -> None:
    amplifier, _ = _amplifier(lines, [Exchange(ZS_READ, ZS_REPLY_80_5_MM)] * 2, echo=True)
    assert amplifier.read_position_m() == pytest.approx(0.0805)
    assert amplifier.read_position_m() == pytest.approx(0.0805)
    assert amplifier.port.counters.discarded_frames == 0 and amplifier.port.counters.retries == 0


def test_echo_suppression_on_a_line_that_does_not_echo_is_a_clear_error(lines: list[ScriptedLine]) -> None:
    link = LinkSettings(timeout_s=0.5, retries=0, echo=True)
    amplifier, line = _amplifier(lines, [Exchange(ZS_READ, ZS_REPLY_80_5_MM)], link=link)
    with pytest.raises(errors.MissingEchoError, match="does this adapter echo"):
        amplifier.read_position_m()
    line.script.append(Exchange(ZS_READ, ZS_REPLY_80_5_MM))  # the next request drains the unechoed reply
    line.echo = True
    assert amplifier.read_position_m() == pytest.approx(0.0805)


# --- a port that does not wait itself (the acquisition) -------------------------------------------------


def test_a_port_that_does_not_wait_sends_nothing_until_omrons_wait_is_over(lines: list[ScriptedLine]) -> None:
    link = LinkSettings(timeout_s=0.5, retries=2)
    amplifier, line = _amplifier(lines, [Exchange(READ_ONE)], VARIABLE_C0, link=link)
    port = amplifier.port
    port.waits_for_late_replies = False
    with pytest.raises(errors.ResponseTimeoutError, match=r"no reply within 0\.5 s"):
        amplifier.read_counts(1)  # not retried: the retry would have to wait
    assert (port.counters.retries, port.counters.unanswered) == (0, 1)
    assert port.last_failure == "ResponseTimeoutError: node 01 on loop://: no reply within 0.5 s"
    assert port.quiet_s() == pytest.approx(OMRON_WORST_CASE_RESPONSE_S - 0.5, abs=0.05)
    with pytest.raises(errors.LineQuietError, match="nothing sent"):
        amplifier.read_counts(1)  # the script holds no exchange for it: nothing may reach the line
    line.now_s = OMRON_WORST_CASE_RESPONSE_S  # the late reply can no longer come
    assert port.quiet_s() == 0.0
    line.script.append(Exchange(READ_ONE, REPLY_1000))
    assert amplifier.read_counts(1) == [1000]


def test_a_late_reply_ends_the_quiet_early_and_is_not_taken_for_the_next(lines: list[ScriptedLine]) -> None:
    link = LinkSettings(timeout_s=0.5, retries=0)
    script = [Exchange(READ_ONE, REPLY_1000, delay_s=1.2), Exchange(READ_ONE, REPLY_2000)]
    amplifier, line = _amplifier(lines, script, VARIABLE_C0, link=link)
    port = amplifier.port
    port.waits_for_late_replies = False
    with pytest.raises(errors.ResponseTimeoutError):
        amplifier.read_counts(1)
    line.now_s = 1.1
    assert port.quiet_s() > 0  # the late reply has not come yet
    line.now_s = 1.25
    assert port.quiet_s() == 0.0  # it came: taken off the line and discarded, the wait is over
    assert port.counters.discarded_frames == 1
    assert amplifier.read_counts(1) == [2000]  # its own reply, not the late 1000


def test_a_retried_failure_is_kept_as_the_lines_last_failure(lines: list[ScriptedLine]) -> None:
    bcc_end_code = frame("01" + "00" + "13")  # short error form: the amplifier got a wrong BCC
    script = [Exchange(READ_ONE, bcc_end_code), Exchange(READ_ONE, REPLY_1000)]
    amplifier, _ = _amplifier(lines, script, VARIABLE_C0)
    assert amplifier.read_counts(1) == [1000]  # the retry succeeded ...
    assert amplifier.port.last_failure.startswith("BccEndCodeError: node 01: end code 13")  # ... and why
