"""Bench configuration file: round trip through the writer, and one clear located error for every mistake."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from daq.bench_config import (
    LASER_HEADS,
    BenchConfig,
    BenchConfigError,
    ExciterConfig,
    LaserConfig,
    dump_bench_config,
    load_bench_config,
    parse_bench_config,
    write_bench_config,
)
from drivers.exciter.envelope import EnvelopeLimits
from estimator.vehicle import ModelKind
from service.simulated_bench import HEAD_MODELS

VALID = """\
[bench]
name = "bench 1"
model = "quarter-car"

[bench.envelope]
max_amplitude_m = 0.003
max_frequency_Hz = 20

[exciter]
name = "plate"
url = "modbus-tcp://127.0.0.1:5020?unit=1"

[[lasers]]
name = "body"
url = "serial:///dev/ttyUSB0?baudrate=38400&node=1"
channel = "x_s"
head = "ZX-LD100"

[[lasers]]
name = "wheel"
url = "socket://127.0.0.1:9000?node=2"
channel = "x_t"
head = "ZX-LD40"
sign = -1
zero_m = 0.0015
"""
# line numbers in VALID: 2 name, 3 model, 5 [bench.envelope], 6 max_amplitude_m, 7 max_frequency_Hz,
# 9 [exciter], 10 name, 11 url, 13 [[lasers]] #1, 14 name, 15 url, 16 channel, 17 head,
# 19 [[lasers]] #2, 20 name, 21 url, 22 channel, 23 head, 24 sign, 25 zero_m


def edit(old: str, new: str) -> str:
    """VALID with the last occurrence of `old` replaced by `new`."""
    assert old in VALID, old
    head, _, tail = VALID.rpartition(old)
    return head + new + tail


def laser(name: str, channel: str, url: str, head: str = "ZX-LD40", **extra: object) -> LaserConfig:
    return LaserConfig(name, url, channel, head, **extra)  # type: ignore[arg-type]


# ---- valid files -----------------------------------------------------------------------------------------


def test_valid_file_reads_into_dataclasses() -> None:
    config = parse_bench_config(VALID, "bench.toml")
    assert (config.name, config.model) == ("bench 1", ModelKind.QUARTER_CAR)
    assert config.envelope == EnvelopeLimits(max_amplitude_m=0.003, max_frequency_Hz=20.0)
    assert config.safety_envelope().limits == config.envelope
    assert config.exciter == ExciterConfig("plate", "modbus-tcp://127.0.0.1:5020?unit=1")
    assert config.exciter.kind == "modbus"
    body, wheel = config.lasers
    assert (body.sign, body.zero_m, body.device()) == (1, 0.0, ("/dev/ttyUSB0", 1))
    assert (wheel.sign, wheel.zero_m, wheel.device()) == (-1, 0.0015, ("socket://127.0.0.1:9000", 2))
    assert config.laser_for("x_t") is wheel and config.laser_for("x_r") is None
    assert config.channels == ("x_s", "x_t", "x_r")


def test_laser_reading_to_channel_displacement() -> None:
    below = laser("w", "x_t", "socket://h:1?node=1", sign=-1, zero_m=0.002)
    assert below.to_channel_m(0.0015) == pytest.approx(0.0005)  # target came closer to a head below: up
    above = laser("s", "x_s", "socket://h:1?node=2", zero_m=-0.001)
    assert above.to_channel_m(0.0) == pytest.approx(0.001)


@pytest.mark.parametrize("model", list(ModelKind))
def test_round_trip_through_the_writer(model: ModelKind, tmp_path: Path) -> None:
    names = ("x_s", "x_t", "x_r") if model is ModelKind.QUARTER_CAR else ("x_s_l", "x_t_r", "x_r_r")
    config = BenchConfig(
        'odd "name" \\ with\ttab, é and \x7f',
        model,
        ExciterConfig("drive", "can://virtual/vcan0"),
        tuple(
            laser(
                f"laser {i}",
                ch,
                f"/dev/pts/{i}?node={i + 1}",
                LASER_HEADS[i % 2],
                sign=(-1) ** i,
                zero_m=i * 1e-5,
            )
            for i, ch in enumerate(names)
        ),
        EnvelopeLimits(max_amplitude_m=0.0025, max_frequency_Hz=12.5) if model is ModelKind.AXLE else None,
    )
    assert parse_bench_config(dump_bench_config(config, comment="two\nlines")) == config
    path = write_bench_config(config, tmp_path / "bench.toml")
    assert load_bench_config(path) == config
    assert [p.name for p in tmp_path.iterdir()] == ["bench.toml"]  # no temporary file left behind


def test_head_names_match_the_simulated_catalogue() -> None:
    assert set(LASER_HEADS) == set(HEAD_MODELS)


def test_optional_parts_may_be_left_out() -> None:
    text = VALID.replace("[bench.envelope]\nmax_amplitude_m = 0.003\nmax_frequency_Hz = 20\n", "")
    assert parse_bench_config(text).envelope is None
    only_frequency = parse_bench_config(edit("max_amplitude_m = 0.003\n", ""))
    assert only_frequency.envelope == EnvelopeLimits(max_frequency_Hz=20.0)


# ---- errors ----------------------------------------------------------------------------------------------

ERRORS = [
    # (text, expected message, after "bench.toml")
    (edit('model = "quarter-car"', "model = "), r":3: Invalid value \(at line 3"),  # TOML syntax error
    (VALID + "\n[lazers]\nname = 1\n", r":27: unknown table or key 'lazers'"),
    (
        edit('name = "bench 1"', 'name = "bench 1"\ncolour = "red"'),
        r":3: \[bench\] colour: unknown key 'colour'",
    ),
    (
        edit("max_frequency_Hz = 20", "max_frequency = 20"),
        r":7: \[bench.envelope\] max_frequency: unknown key",
    ),
    (edit('url = "modbus', 'uri = "modbus'), r":11: \[exciter\] uri: unknown key 'uri'"),
    (
        edit("zero_m = 0.0015", "zero = 0.0015"),
        r":25: \[\[lasers\]\] #2 zero: unknown key 'zero' \(expected one",
    ),
    (edit('name = "wheel"\n', ""), r":19: \[\[lasers\]\] #2: missing key 'name'"),
    (edit('head = "ZX-LD100"\n', ""), r":13: \[\[lasers\]\] #1: missing key 'head'"),
    (edit('name = "bench 1"\n', ""), r":1: \[bench\]: missing key 'name'"),
    (
        VALID.replace('[exciter]\nname = "plate"\nurl = "modbus-tcp://127.0.0.1:5020?unit=1"\n', ""),
        r": missing \[exciter\]",
    ),
    (edit("sign = -1", 'sign = "-1"'), r":24: \[\[lasers\]\] #2 sign: must be an integer, got '-1'"),
    (edit("sign = -1", "sign = true"), r":24: \[\[lasers\]\] #2 sign: must be an integer, got True"),
    (edit("sign = -1", "sign = 2"), r":24: \[\[lasers\]\] #2 sign: sign must be 1 or -1, got 2"),
    (edit("zero_m = 0.0015", 'zero_m = "0"'), r":25: \[\[lasers\]\] #2 zero_m: must be a number"),
    (edit("zero_m = 0.0015", "zero_m = nan"), r":25: \[\[lasers\]\] #2 zero_m: zero_m must be finite"),
    (edit('name = "wheel"', "name = 7"), r":20: \[\[lasers\]\] #2 name: must be a string, got 7"),
    (edit('name = "wheel"', 'name = " "'), r":20: \[\[lasers\]\] #2 name: name must not be empty"),
    (edit('model = "quarter-car"', 'model = "truck"'), r":3: \[bench\] model: unknown model 'truck'"),
    (edit('head = "ZX-LD40"', 'head = "ZX-LD400"'), r":23: \[\[lasers\]\] #2 head: unknown head 'ZX-LD400'"),
    (edit("socket://", "sokcet://"), r":21: \[\[lasers\]\] #2 url: bad laser URL .*unknown scheme 'sokcet'"),
    (edit("?node=2", ""), r":21: \[\[lasers\]\] #2 url: laser URL .* names no node"),
    (edit("node=2", "node=two"), r":21: \[\[lasers\]\] #2 url: bad laser URL .*node='two' is not a number"),
    (edit("node=1", "node=1&speed=9"), r":15: \[\[lasers\]\] #1 url: bad laser URL .*unknown option"),
    (edit("modbus-tcp://", "modbus-udp://"), r":11: \[exciter\] url: bad exciter URL: .*unknown scheme"),
    (edit("unit=1", "unit=1&colour=red"), r":11: \[exciter\] url: bad exciter URL: .*unknown parameter"),
    (
        edit('channel = "x_t"', 'channel = "x_s"'),
        r":22: \[\[lasers\]\] #2 channel: channel 'x_s' is already "
        r"measured by laser 'body'",
    ),
    (
        edit('channel = "x_t"', 'channel = "x_s_l"'),
        r":22: \[\[lasers\]\] #2 channel: unknown channel 'x_s_l' for "
        r"a quarter-car bench",
    ),
    (
        edit('name = "wheel"', 'name = "body"'),
        r":20: \[\[lasers\]\] #2 name: name 'body' is already used by laser",
    ),
    (edit('name = "wheel"', 'name = "plate"'), r":20: \[\[lasers\]\] #2 name: .*already used by the exciter"),
    (
        edit("socket://127.0.0.1:9000?node=2", "serial:///dev/ttyUSB0?node=1"),
        r":21: \[\[lasers\]\] #2 url: node 1 on /dev/ttyUSB0 is already used by laser 'body'",
    ),
    (
        edit("max_amplitude_m = 0.003", "max_amplitude_m = 0.01"),
        r":6: \[bench.envelope\] max_amplitude_m: .*above the hard limit max_amplitude_m=0.004",
    ),
    (
        edit("max_frequency_Hz = 20", "max_frequency_Hz = -1"),
        r":7: \[bench.envelope\] max_frequency_Hz: .*> 0",
    ),
    (
        edit("[bench.envelope]\n", "[bench.envelope]\nmin_amplitude_m = 1\n"),
        r":6: \[bench.envelope\] min_amplitude_m",
    ),
    ("lasers = []\n" + VALID.split("[[lasers]]")[0], r":1: \[\[lasers\]\]: a bench needs at least one"),
    (
        VALID.split("[[lasers]]")[0] + '[lasers]\nname = "x"\n',
        r":13: \[\[lasers\]\]: must be an array of tables",
    ),
]


@pytest.mark.parametrize(("text", "expected"), ERRORS, ids=[e[1][:48] for e in ERRORS])
def test_errors_are_one_located_line(text: str, expected: str) -> None:
    with pytest.raises(BenchConfigError) as info:
        parse_bench_config(text, "bench.toml")
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("bench.toml")
    assert re.match(r"bench\.toml" + expected, message), message
    assert isinstance(info.value, ValueError)  # the CLI reports ValueErrors as one line, exit 2


def test_file_errors(tmp_path: Path) -> None:
    with pytest.raises(OSError):
        load_bench_config(tmp_path / "missing.toml")
    (tmp_path / "bench.toml").write_text(edit("sign = -1", "sign = 3"))
    with pytest.raises(
        BenchConfigError, match=re.escape(f"{tmp_path / 'bench.toml'}:24: [[lasers]] #2 sign")
    ):
        load_bench_config(tmp_path / "bench.toml")


def test_dataclasses_check_themselves_without_a_file() -> None:
    exciter = ExciterConfig("plate", "can://virtual/vcan0")
    assert exciter.kind == "can"
    lasers = (laser("a", "x_s", "socket://h:1?node=1"), laser("b", "x_s", "socket://h:2?node=1"))
    with pytest.raises(BenchConfigError, match="channel 'x_s' is already measured") as info:
        BenchConfig("b", ModelKind.QUARTER_CAR, exciter, lasers)
    assert info.value.key == ("lasers", 1, "channel")
    with pytest.raises(BenchConfigError, match="at least one"):
        BenchConfig("b", ModelKind.AXLE, exciter, ())
    with pytest.raises(BenchConfigError, match="above the hard limit"):
        BenchConfig("b", ModelKind.QUARTER_CAR, exciter, lasers[:1], EnvelopeLimits(max_frequency_Hz=30.0))
    with pytest.raises(BenchConfigError, match="bad exciter URL"):
        ExciterConfig("plate", "can://virtual")
    with pytest.raises(BenchConfigError, match="sign must be"):
        laser("a", "x_s", "socket://h:1?node=1", sign=1.0)
