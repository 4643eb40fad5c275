"""CompoWay/F codec at byte level: frames written out by hand from the frame rules, BCC worked out by hand in
the comments ('0' = 0x30, '1' = 0x31, ..., ETX = 0x03; a character appearing an even number of times
cancels out of the XOR), plus property tests over random input."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.compowayf import errors
from drivers.compowayf.codec import (
    CommandFrame,
    ResponseFrame,
    Service,
    bcc,
    build_command,
    build_end_code_response,
    build_response,
    check_response,
    parse_command,
    parse_response,
    split_frame,
    split_reply,
)
from drivers.compowayf.service_data import (
    ControllerAttributes,
    StatusReport,
    decode_int,
    decode_parameter_area_request,
    decode_values,
    decode_variable_area_read,
    encode_int,
    encode_operation_command,
    encode_parameter_area_read,
    encode_parameter_area_write,
    encode_variable_area_read,
    max_elements_per_read,
)

# Variable area read, node 01, type C0, address 0000, bit 00, 1 element.
# After STX: "01" "00" "0" "0101" "C0" "0000" "00" "0001" ETX
# '0' x16 (even) -> 0, '1' x4 (even) -> 0, 'C' 0x43, ETX 0x03: 0x43 ^ 0x03 = 0x40
READ_ONE_CMD = (
    b"\x02" + b"01" + b"00" + b"0" + b"0101" + b"C0" + b"0000" + b"00" + b"0001" + b"\x03" + b"\x40"
)

# Its reply: node 01, sub 00, end 00, MRC/SRC 0101, response 0000, value FFFFFC18 (-1000 counts).
# '0' x11 -> 0x30, 'F' x5 -> 0x46, '1' x4 -> 0, 'C' 0x43, '8' 0x38, ETX 0x03:
# 0x30^0x46 = 0x76, ^0x43 = 0x35, ^0x38 = 0x0D, ^0x03 = 0x0E
READ_ONE_REPLY = b"\x02" + b"01" + b"00" + b"00" + b"0101" + b"0000" + b"FFFFFC18" + b"\x03" + b"\x0e"

# Echo-back to node 02 with test data "AB": "02" "00" "0" "0801" "AB" ETX
# '0' x6 -> 0; 0x32 ('2') ^ 0x38 ('8') = 0x0A, ^0x31 ('1') = 0x3B, ^0x41 ('A') = 0x7A, ^0x42 ('B') = 0x38,
# ^0x03 = 0x3B
ECHO_CMD = b"\x02" + b"02" + b"00" + b"0" + b"0801" + b"AB" + b"\x03" + b"\x3b"

# Its reply "02" "00" "00" "0801" "0000" "AB": same characters plus five more '0' -> '0' x11 -> 0x30;
# 0x30 ^ 0x3B = 0x0B
ECHO_REPLY = b"\x02" + b"02" + b"00" + b"00" + b"0801" + b"0000" + b"AB" + b"\x03" + b"\x0b"

# Operation command node 01, code 01 info 00: "01" "00" "0" "3005" "0100" ETX
# '0' x9 -> 0x30, '1' x2 -> 0, '3' 0x33, '5' 0x35: 0x30^0x33 = 0x03, ^0x35 = 0x36, ^0x03 = 0x35
OPERATION_CMD = b"\x02" + b"01" + b"00" + b"0" + b"3005" + b"0100" + b"\x03" + b"\x35"

# Model read node 05: "05" "00" "0" "0503" ETX: '0' x6 -> 0, '5' x2 -> 0, '3' 0x33, ^0x03 = 0x30
MODEL_CMD = b"\x02" + b"05" + b"00" + b"0" + b"0503" + b"\x03" + b"\x30"

# Parameter area read node 01, type C000, address 0000, 2 elements (count with top bit: 8002):
# "01" "00" "0" "0201" "C000" "0000" "8002" ETX: '0' x15 -> 0x30, '1' x2, '2' x2 -> 0, 'C' 0x43, '8' 0x38:
# 0x30^0x43 = 0x73, ^0x38 = 0x4B, ^0x03 = 0x48
PARAM_READ_CMD = b"\x02" + b"01" + b"00" + b"0" + b"0201" + b"C000" + b"0000" + b"8002" + b"\x03" + b"\x48"

# Short error reply: node 01, sub 00, end code 13: "01" "00" "13" ETX
# '0' x3 -> 0x30, '1' x2 -> 0, '3' 0x33: 0x30^0x33 = 0x03, ^0x03 = 0x00
SHORT_13_REPLY = b"\x02" + b"01" + b"00" + b"13" + b"\x03" + b"\x00"

# End code 0F carrying MRC/SRC 0101 and response code 1101: "01" "00" "0F" "0101" "1101" ETX
# '0' x7 -> 0x30, '1' x6 -> 0, 'F' 0x46: 0x30^0x46 = 0x76, ^0x03 = 0x75
COMMAND_ERROR_REPLY = b"\x02" + b"01" + b"00" + b"0F" + b"0101" + b"1101" + b"\x03" + b"\x75"


def test_bcc_is_xor_after_stx_through_etx() -> None:
    assert bcc(READ_ONE_CMD[1:-1]) == 0x40
    assert bcc(b"") == 0
    assert bcc(b"\x03") == 0x03


@pytest.mark.parametrize(
    ("frame", "node", "service", "data"),
    [
        (READ_ONE_CMD, 1, "0101", encode_variable_area_read(0xC0, 0x0000, 1)),
        (ECHO_CMD, 2, "0801", "AB"),
        (OPERATION_CMD, 1, "3005", encode_operation_command(0x01, 0x00)),
        (MODEL_CMD, 5, "0503", ""),
        (PARAM_READ_CMD, 1, "0201", encode_parameter_area_read(0xC000, 0x0000, 2)),
    ],
)
def test_commands_built_byte_for_byte(frame: bytes, node: int, service: str, data: str) -> None:
    assert build_command(node, service, data) == frame
    assert parse_command(frame) == CommandFrame(node, service, data)


def test_read_reply_parsed_and_decoded() -> None:
    response = parse_response(READ_ONE_REPLY)
    assert response == ResponseFrame(1, "00", "0101", "0000", "FFFFFC18")
    check_response(response, 1, Service.VARIABLE_AREA_READ)
    assert decode_values(response.data, 8, 1) == [-1000]
    assert build_response(1, "0101", "0000", "FFFFFC18") == READ_ONE_REPLY


def test_echo_reply_round_trip() -> None:
    assert build_response(2, "0801", data="AB") == ECHO_REPLY
    assert parse_response(ECHO_REPLY).data == "AB"


def test_short_end_code_reply() -> None:
    response = parse_response(SHORT_13_REPLY)
    assert response == ResponseFrame(1, "13")
    assert build_end_code_response(1, "13") == SHORT_13_REPLY
    with pytest.raises(errors.BccEndCodeError, match="end code 13"):
        check_response(response, 1, "0101")


def test_command_error_end_code_with_response_code_raises_the_response_code_error() -> None:
    response = parse_response(COMMAND_ERROR_REPLY)
    assert (response.end_code, response.service, response.response_code) == ("0F", "0101", "1101")
    with pytest.raises(errors.AreaTypeError):
        check_response(response, 1, "0101")
    with pytest.raises(errors.CommandEndCodeError):
        check_response(ResponseFrame(1, "0F"), 1, "0101")


@pytest.mark.parametrize(("code", "cls"), sorted(errors.END_CODE_ERRORS.items()))
def test_every_end_code_maps_to_its_exception(code: str, cls: type[errors.EndCodeError]) -> None:
    response = parse_response(build_end_code_response(7, code))
    with pytest.raises(cls) as info:
        check_response(response, 7, "0101")
    assert info.value.end_code == code and f"end code {code}" in str(info.value)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(("code", "cls"), sorted(errors.RESPONSE_CODE_ERRORS.items()))
def test_every_response_code_maps_to_its_exception(code: str, cls: type[errors.ResponseCodeError]) -> None:
    response = parse_response(build_response(3, "0101", code))
    with pytest.raises(cls) as info:
        check_response(response, 3, "0101")
    assert info.value.response_code == code and "\n" not in str(info.value)


def test_required_codes_are_all_mapped() -> None:
    assert set(errors.END_CODE_ERRORS) == {"0F", "10", "11", "12", "13", "14", "16", "18"}
    required = {"1001", "1002", "1003", "1100", "1101", "1103", "1104", "2203", "2204", "2205"}
    assert required <= set(errors.RESPONSE_CODE_ERRORS)
    with pytest.raises(errors.EndCodeError):  # unlisted codes still raise, as the base class
        check_response(ResponseFrame(1, "7E"), 1, "0101")
    with pytest.raises(errors.ResponseCodeError):
        check_response(ResponseFrame(1, "00", "0101", "9999"), 1, "0101")


def test_reply_for_another_node_or_service_is_unexpected() -> None:
    with pytest.raises(errors.UnexpectedResponseError, match="node 01"):
        check_response(parse_response(READ_ONE_REPLY), 2, "0101")
    with pytest.raises(errors.UnexpectedResponseError, match="service 0101"):
        check_response(parse_response(READ_ONE_REPLY), 1, "0201")


@pytest.mark.parametrize(
    ("frame", "error"),
    [
        (b"", errors.IncompleteResponseError),
        (READ_ONE_REPLY[:-2], errors.IncompleteResponseError),  # no ETX
        (READ_ONE_REPLY[:-1], errors.IncompleteResponseError),  # ETX but no BCC
        (b"\x55" + READ_ONE_REPLY, errors.MalformedFrameError),  # junk before STX
        (READ_ONE_REPLY + b"\x00", errors.MalformedFrameError),  # junk after BCC
        (READ_ONE_REPLY[:-1] + b"\x0f", errors.BccMismatchError),
        (b"\x02" + b"0A0000" + b"\x03" + bytes([bcc(b"0A0000\x03")]), errors.MalformedFrameError),  # node
        (b"\x02" + b"0100" + b"\x03" + bytes([bcc(b"0100\x03")]), errors.MalformedFrameError),  # no end code
        (b"\x02" + b"010000" + b"\x03" + bytes([bcc(b"010000\x03")]), errors.MalformedFrameError),  # no MRC
        (b"\x02" + b"01\x0100" + b"\x03" + bytes([bcc(b"01\x0100\x03")]), errors.MalformedFrameError),
    ],
)
def test_bad_replies_raise_typed_errors(frame: bytes, error: type[errors.CompowayFError]) -> None:
    with pytest.raises(error):
        parse_response(frame)


def test_bcc_mismatch_message_names_both_values() -> None:
    with pytest.raises(errors.BccMismatchError, match="computed 0x0E, frame carries 0x0F"):
        parse_response(READ_ONE_REPLY[:-1] + b"\x0f")


@pytest.mark.parametrize(
    ("frame", "error"),
    [
        (READ_ONE_CMD[:-1] + b"\x41", errors.BccEndCodeError),
        (build_command(1, "0101", "C0000000", sub_address="01"), errors.SubAddressEndCodeError),
        (build_command(1, "0101", "C0 00000"), errors.FormatEndCodeError),  # non-hex data
        (b"\x02" + b"01000" + b"01" + b"\x03" + bytes([bcc(b"0100001\x03")]), errors.FormatEndCodeError),
        (build_command(1, "0801", "X" * 300), errors.FrameLengthEndCodeError),
        (b"\x02" + b"xx000" + b"\x03" + b"\x00", errors.BccMismatchError),  # unreadable node: silence
        (READ_ONE_CMD[:-2], errors.IncompleteResponseError),
    ],
)
def test_command_parse_errors_are_the_end_codes_a_device_answers(
    frame: bytes, error: type[errors.CompowayFError]
) -> None:
    with pytest.raises(error):
        parse_command(frame, max_frame_bytes=256)


def test_split_frame_on_a_stream() -> None:
    stream = READ_ONE_REPLY + ECHO_REPLY[:5]
    frame, rest = split_frame(stream)
    assert frame == READ_ONE_REPLY and rest == ECHO_REPLY[:5]
    assert split_frame(rest) == (None, rest)
    assert split_frame(READ_ONE_REPLY[:-1]) == (None, READ_ONE_REPLY[:-1])  # ETX without BCC yet
    assert split_frame(b"\xff\xfe" + ECHO_REPLY, skip_to_stx=True) == (ECHO_REPLY, b"")
    assert split_frame(b"noise", skip_to_stx=True) == (None, b"")
    # A BCC byte equal to ETX or STX does not confuse the split (text is printable ASCII).
    assert split_frame(SHORT_13_REPLY + READ_ONE_REPLY)[0] == SHORT_13_REPLY


def test_split_reply_resynchronises_on_stx() -> None:
    assert split_reply(b"\x00" + READ_ONE_REPLY) == (READ_ONE_REPLY, b"", 1)  # RS-485 turn-around byte
    broken = b"\x02" + b"0100"  # a frame cut short: reception starts again at the next STX
    assert split_reply(b"\xff" + broken + ECHO_REPLY + b"\x02") == (ECHO_REPLY, b"\x02", 1 + len(broken))
    assert split_reply(b"\x00\x00" + ECHO_REPLY[:5]) == (None, ECHO_REPLY[:5], 2)  # noise dropped early
    garbled = b"\xff#GARBAGE#\x03\x5a"  # ETX + BCC but no STX: returned for the parser to reject
    assert split_reply(garbled) == (garbled, b"", 0)
    with pytest.raises(errors.MalformedFrameError, match="STX"):
        parse_response(garbled)
    assert split_reply(SHORT_13_REPLY + READ_ONE_REPLY)[:2] == (SHORT_13_REPLY, READ_ONE_REPLY)


def test_controller_attributes_are_model_and_buffer_size() -> None:
    assert ControllerAttributes("E5CN-Q2", 0x28).encode() == "E5CN-Q2   0028"  # padded to 10, then 4 hex
    assert ControllerAttributes.decode("ZX-LDA11-N00D9") == ControllerAttributes("ZX-LDA11-N", 217)
    for bad in ("ZX-LDA11-N", "ZX-LDA11-N00D", "ZX-LDA11-N00G9"):
        with pytest.raises(errors.MalformedFrameError):
            ControllerAttributes.decode(bad)


def test_elements_per_read_are_omrons_limit_or_what_the_buffer_holds() -> None:
    assert (max_elements_per_read(8, None), max_elements_per_read(4, None)) == (25, 50)
    assert max_elements_per_read(8, 217) == 25  # 17 bytes of frame + 200 characters
    assert max_elements_per_read(8, 217, echoed_chars=12) == 23  # a parameter read repeats its request
    assert max_elements_per_read(8, 40) == 2 and max_elements_per_read(8, 20) == 0
    assert max_elements_per_read(8, 4096) == 25  # a large buffer does not lift OMRON's limit


def test_integer_encodings_are_twos_complement() -> None:
    assert encode_int(-1000, 8) == "FFFFFC18"
    assert encode_int(0x7FFFFFFF, 8) == "7FFFFFFF"
    assert encode_int(-1, 4) == "FFFF"
    assert decode_int("FFFFFC18") == -1000 and decode_int("000003E8") == 1000 and decode_int("8000") == -32768
    assert decode_values("000003E8FFFFFC18", 8, 2) == [1000, -1000]
    with pytest.raises(ValueError):
        encode_int(1 << 32, 8)
    with pytest.raises(errors.MalformedFrameError):
        decode_values("000003E8", 8, 2)
    with pytest.raises(errors.MalformedFrameError):
        decode_int("00G0")


def test_service_data_encodings() -> None:
    assert encode_variable_area_read(0xC0, 0x0010, 4) == "C00010" + "00" + "0004"
    request = decode_variable_area_read("C0001000" + "0004")
    assert (request.area_type, request.start_address, request.bit_position, request.count) == (
        0xC0,
        0x10,
        0,
        4,
    )
    assert encode_parameter_area_write(0xC000, 1, [5, -1]) == "C000" + "0001" + "8002" + "00000005FFFFFFFF"
    written = decode_parameter_area_request("C00000018002" + "00000005FFFFFFFF")
    assert (written.count, written.values) == (2, (5, -1))
    assert StatusReport.decode("0102") == StatusReport(1, 2) and StatusReport(1, 2).encode() == "0102"
    with pytest.raises(errors.MalformedFrameError):
        StatusReport.decode("01")
    with pytest.raises(ValueError):
        build_command(100, "0101")
    with pytest.raises(ValueError):
        build_command(1, "0801", "\x03")


_NODES = st.integers(0, 99)
_HEX4 = st.text("0123456789ABCDEF", min_size=4, max_size=4)
_PRINTABLE = st.text(st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=60)
_HEX_DATA = st.text("0123456789ABCDEF", max_size=60)


@given(node=_NODES, service=_HEX4, data=_HEX_DATA)
def test_command_round_trip(node: int, service: str, data: str) -> None:
    assert parse_command(build_command(node, service, data)) == CommandFrame(node, service, data)


@given(node=_NODES, data=_PRINTABLE)
def test_echo_command_round_trip_with_any_printable_data(node: int, data: str) -> None:
    assert parse_command(build_command(node, "0801", data)).data == data


@given(node=_NODES, service=_HEX4, response_code=_HEX4, data=_PRINTABLE)
def test_response_round_trip(node: int, service: str, response_code: str, data: str) -> None:
    frame = build_response(node, service, response_code, data)
    assert parse_response(frame) == ResponseFrame(node, "00", service, response_code, data)
    assert split_frame(frame + b"\x02") == (frame, b"\x02")


@given(value=st.integers(-(1 << 31), (1 << 31) - 1))
def test_int32_round_trip(value: int) -> None:
    assert decode_int(encode_int(value, 8)) == value


@given(raw=st.binary(max_size=80))
def test_parsers_raise_only_typed_errors_on_random_bytes(raw: bytes) -> None:
    frame, rest, skipped = split_reply(raw)  # never raises; keeps or drops, never invents bytes
    assert skipped + len(frame or b"") + len(rest) == len(raw)
    for parse in (parse_response, parse_command):
        with contextlib.suppress(errors.CompowayFError):
            parse(raw)
    frame, rest = split_frame(raw)
    assert (frame or b"") + rest == raw


@given(body=st.binary(max_size=40))
def test_parsers_raise_only_typed_errors_on_random_framed_bytes(body: bytes) -> None:
    body = body.replace(b"\x03", b"")
    frame = b"\x02" + body + b"\x03" + bytes([bcc(body + b"\x03")])
    for parse in (parse_response, parse_command):
        with contextlib.suppress(errors.CompowayFError):
            parse(frame)
