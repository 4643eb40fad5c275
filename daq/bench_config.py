"""The bench configuration file: which devices make up a bench, where they are, what each one measures.

One TOML file per bench, read with `load_bench_config` and written with `write_bench_config` (which is what
`shockbench sim-devices` does for the simulated bench it serves). Example, for a quarter car:

    [bench]
    name = "bench 1"
    model = "quarter-car"                # or "axle"

    [bench.envelope]                     # optional: lowers the sweeps allowed; never above the hard limits
    max_amplitude_m = 0.004              # zero-to-peak plate amplitude
    max_frequency_Hz = 20.0

    [exciter]                            # the plate drive
    name = "plate"
    url = "modbus-tcp://192.168.0.20:502?unit=1"
    register_map = "drive-registers.toml"  # optional (Modbus): relative to this file

    [[lasers]]                           # one table per laser sensor (amplifier + head)
    name = "body"
    url = "serial:///dev/ttyUSB0?baudrate=38400&node=1"
    channel = "x_s"
    head = "ZX-LD100"
    sign = 1                             # optional, default 1
    zero_m = 0.0                         # optional, default 0.0
    sample_period_s = 0.001              # optional: the amplifier samples on its own clock (see below)
    buffer_length = 256                  # optional, with sample_period_s

    [[lasers]]
    name = "wheel"
    url = "serial:///dev/ttyUSB0?baudrate=38400&node=2"   # same RS-485 line, next node
    channel = "x_t"
    head = "ZX-LD40"
    value_area = "parameter"             # optional: where the measured value lives (see below)
    value_type = 0xC020
    value_address = 0x3000
    value_unit = "nm"

Keys:

[bench] name: free text. model: "quarter-car" (channels x_s, x_t, x_r: sprung mass, wheel, plate) or "axle"
    (the same per side: x_s_l, x_s_r, x_t_l, x_t_r, x_r_l, x_r_r).
[bench.envelope] max_amplitude_m, max_frequency_Hz, max_duration_s: the bench's safety envelope
    (drivers.exciter.envelope); each may be left out (default 4 mm, 25 Hz, 300 s); none may exceed the
    installation's hard limits (by default 4 mm, 25 Hz and 3600 s: only the duration may be raised).
[exciter] name, url: the plate drive, by a drivers.exciter.urls URL: modbus-tcp://HOST:PORT?unit=N,
    modbus-rtu:///dev/ttyUSB1?baudrate=19200&unit=1, can://INTERFACE/CHANNEL (python-can, e.g.
    can://socketcan/can0, can://virtual/vcan0; base_id=0x680 moves the frame set), or
    canopen://INTERFACE/CHANNEL?node=N for a CiA 402 drive (host_node=127, watchdog_timeout=0.5,
    transition_timeout=0.5 ...).
    register_map (Modbus only, optional): the drive's
    register map file (format: drivers/exciter/default_register_map.toml), relative to this file;
    checked when the configuration is loaded.
[[lasers]] name: unique among all devices. url: a drivers.compowayf.urls device URL that names the node:
    serial:///dev/ttyUSB0?baudrate=38400&node=1, socket://127.0.0.1:9000?node=2 (a serial-to-Ethernet
    converter), or a plain device path /dev/ttyUSB0?node=1; timeout_s= (reply timeout, default 0.5 s;
    OMRON documents replies up to 3 s), late_reply_s= (after a request went unanswered, drain the line
    until this long after it before the next, default 3 s), retries= and echo=1 (the RS-485 adapter echoes
    the host's frames: each is read back and discarded) may be added.
    channel: which bench channel the laser measures (each channel at most once; not every channel needs a
    laser). head: "ZX-LD40" (40 +- 10 mm) or "ZX-LD100" (100 +- 40 mm). sign: +1 when the head looks down
    on its target (an upward move reads positive), -1 when it looks up. zero_m: what the amplifier reads
    with the channel at its static position. The channel displacement is sign * (reading_m - zero_m)
    (`LaserConfig.to_channel_m`). sample_period_s: give it when the amplifier samples on its own clock
    into a buffer with a sample counter (drivers.compowayf.amplifier.streaming_measured_config): samples
    then carry device timestamps and none is missed between reads. Leave it out for an amplifier that only
    holds its present value: it is polled as fast as the line allows and stamped with host time, and the
    recording states the rate achieved. buffer_length: the samples such an amplifier keeps (default 256).
    value_area ("parameter": read with 0201, or "variable": 0101), value_type (parameter type, e.g. 0xC020
    = C000h + data number; or variable type, e.g. 0xC0), value_address (read start address; for the
    parameter area unit number << 8 | channel) and value_unit ("nm", "0.1um", "um"): where the amplifier
    keeps its measured value (drivers.compowayf.layout). Polled defaults: the ZS-series measurement
    result, parameter area C020 address 3000, nm (OMRON ZS/ZFV CompoWay/F references; that the ZX-L
    follows it is an assumption, its own table was not available). Streaming defaults: the sample
    counter at variable area C0 address 0000 with the sample ring after it (the simulator's layout).

Errors are `BenchConfigError` (a ValueError) with one line naming the file, the line where it is known
(TOML syntax errors and keys are located; a missing key points at its table) and the table and key, e.g.

    bench.toml:14: [[lasers]] #2 channel: channel 'x_s' is already measured by laser 'body'
"""

from __future__ import annotations

import math
import os
import re
import time
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, TypeVar
from urllib.parse import urlsplit

from daq.formats.atomic import atomic_write
from drivers.compowayf.amplifier import STREAM_BUFFER_LENGTH, AmplifierConfig, streaming_measured_config
from drivers.compowayf.errors import DeviceUrlError
from drivers.compowayf.layout import COUNT_UNIT_NAMES, MeasuredArea, MeasuredValueConfig
from drivers.compowayf.urls import parse_device_url
from drivers.exciter.envelope import DEFAULT_HARD_LIMITS, EnvelopeLimits, SafetyEnvelope
from drivers.exciter.errors import ExciterConfigError
from drivers.exciter.interface import DEFAULT_KEEPALIVE_INTERVAL_S, PlateExciter
from drivers.exciter.register_map import RegisterMap
from drivers.exciter.urls import CanTarget, Cia402Target, open_exciter, parse_exciter_url
from estimator.errors import UserError
from estimator.recording import AXLE_CHANNELS, QUARTER_CAR_CHANNELS
from estimator.vehicle import ModelKind

LASER_HEADS = ("ZX-LD40", "ZX-LD100")
"""Head models a laser may name (catalogue data in simulators/devices/sensor_heads.py)."""

LASER_URL_SCHEMES = ("serial", "socket", "rfc2217", "loop")
MAX_BUFFER_LENGTH = 1000
"""Longest sample buffer a streaming amplifier may declare (read in requests of at most 25 double words)."""
VALUE_AREAS = ("parameter", "variable")
"""Schemes a laser URL may use (besides a plain device path); all but serial are pyserial URL handlers."""

CHANNELS: dict[ModelKind, tuple[str, ...]] = {
    ModelKind.QUARTER_CAR: QUARTER_CAR_CHANNELS,
    ModelKind.AXLE: AXLE_CHANNELS,
}


class BenchConfigError(UserError, ValueError):
    """A bench configuration that cannot be used. `key` is where the problem is, as a path into the TOML
    document (("lasers", 1, "channel") is the channel of the second [[lasers]] table), when known."""

    def __init__(self, message: str, key: tuple[str | int, ...] = ()) -> None:
        super().__init__(message)
        self.message = message
        self.key = key

    @property
    def field(self) -> str | None:  # type: ignore[override]
        """The key as a dotted path ("lasers.1.channel"), the field to blame."""
        return ".".join(str(part) for part in self.key) or None


@dataclass(frozen=True)
class LaserConfig:
    """One laser displacement sensor: amplifier URL (with its node), channel, head, mounting."""

    name: str
    url: str
    channel: str
    head: str
    sign: int = 1
    zero_m: float = 0.0
    sample_period_s: float | None = None
    buffer_length: int = STREAM_BUFFER_LENGTH
    value_area: str | None = None
    value_type: int | None = None
    value_address: int | None = None
    value_unit: str = "nm"

    def __post_init__(self) -> None:
        _check_name(self.name)
        self._check_value_location()
        if self.sample_period_s is not None:
            if not (math.isfinite(self.sample_period_s) and 0 < self.sample_period_s <= 1.0):
                raise BenchConfigError(
                    f"sample_period_s must be in (0, 1] s, got {self.sample_period_s!r}", ("sample_period_s",)
                )
            object.__setattr__(self, "sample_period_s", float(self.sample_period_s))
        if type(self.buffer_length) is not int or not 1 <= self.buffer_length <= MAX_BUFFER_LENGTH:
            raise BenchConfigError(
                f"buffer_length must be an integer 1..{MAX_BUFFER_LENGTH}, got {self.buffer_length!r}",
                ("buffer_length",),
            )
        if self.head not in LASER_HEADS:
            raise BenchConfigError(
                f"unknown head {self.head!r}; expected one of {list(LASER_HEADS)}", ("head",)
            )
        if type(self.sign) is not int or self.sign not in (1, -1):
            raise BenchConfigError(f"sign must be 1 or -1, got {self.sign!r}", ("sign",))
        if not math.isfinite(self.zero_m):
            raise BenchConfigError(f"zero_m must be finite, got {self.zero_m!r}", ("zero_m",))
        object.__setattr__(self, "zero_m", float(self.zero_m))
        self.device()  # the URL must parse and name a node

    def device(self) -> tuple[str, int]:
        """(pyserial URL, node): what identifies the amplifier; two lasers may not share it."""
        scheme = urlsplit(self.url).scheme.lower() if "://" in self.url else ""
        if scheme and scheme not in LASER_URL_SCHEMES:
            raise BenchConfigError(
                f"bad laser URL {self.url!r}: unknown scheme {scheme!r} (use {', '.join(LASER_URL_SCHEMES)} "
                "or a device path)",
                ("url",),
            )
        try:
            parsed = parse_device_url(self.url)
        except DeviceUrlError as exc:
            raise BenchConfigError(f"bad laser URL {self.url!r}: {exc}", ("url",)) from None
        if parsed.node is None:
            raise BenchConfigError(f"laser URL {self.url!r} names no node: add ?node=N", ("url",))
        return parsed.pyserial_url, parsed.node

    def _check_value_location(self) -> None:
        if self.value_area is not None and self.value_area not in VALUE_AREAS:
            raise BenchConfigError(
                f"value_area must be one of {list(VALUE_AREAS)}, got {self.value_area!r}", ("value_area",)
            )
        if self.value_unit not in COUNT_UNIT_NAMES:
            raise BenchConfigError(
                f"value_unit must be one of {list(COUNT_UNIT_NAMES)}, got {self.value_unit!r}",
                ("value_unit",),
            )
        for key in ("value_type", "value_address"):
            value = getattr(self, key)
            if value is not None and (type(value) is not int or not 0 <= value <= 0xFFFF):
                raise BenchConfigError(f"{key} must be an integer 0..0xFFFF, got {value!r}", (key,))
        try:
            self.amplifier_config()
        except ValueError as exc:
            raise BenchConfigError(f"measured value location: {exc}", ("value_type",)) from None

    def amplifier_config(self) -> AmplifierConfig:
        """How the driver reads this amplifier: where its value lives (value_* keys over the defaults), and
        the streaming layout when it samples on its own clock."""
        unit = COUNT_UNIT_NAMES[self.value_unit]
        if self.sample_period_s is None:
            defaults = MeasuredValueConfig()
            area = MeasuredArea(self.value_area) if self.value_area else defaults.area
            type_default = defaults.area_type if area is defaults.area else 0xC0
            measured = MeasuredValueConfig(
                area=area,
                area_type=type_default if self.value_type is None else self.value_type,
                address=defaults.address if self.value_address is None else self.value_address,
                count_unit=unit,
            )
            return AmplifierConfig(measured=measured)
        area = MeasuredArea(self.value_area or MeasuredArea.VARIABLE)
        type_default = 0xC0 if area is MeasuredArea.VARIABLE else 0xC000
        measured = streaming_measured_config(
            self.sample_period_s,
            self.buffer_length,
            area=area,
            area_type=type_default if self.value_type is None else self.value_type,
            counter_address=0 if self.value_address is None else self.value_address,
            count_unit=unit,
        )
        return AmplifierConfig(measured=measured)

    def to_channel_m(self, reading_m: float) -> float:
        """Channel displacement (upward positive, from the static position) for an amplifier reading."""
        return self.sign * (reading_m - self.zero_m)


@dataclass(frozen=True)
class ExciterConfig:
    """The plate drive: a drivers.exciter.urls URL and, for Modbus, the register map file (None: the
    default map)."""

    name: str
    url: str
    register_map: str | None = None

    def __post_init__(self) -> None:
        _check_name(self.name)
        try:
            parse_exciter_url(self.url)
        except ExciterConfigError as exc:
            raise BenchConfigError(f"bad exciter URL: {exc}", ("url",)) from None
        if self.register_map is not None:
            if self.kind != "modbus":
                raise BenchConfigError("a register map applies to a Modbus exciter only", ("register_map",))
            self.load_register_map()

    def load_register_map(self) -> RegisterMap | None:
        """The register map the file names (None: none named, the driver's default)."""
        if self.register_map is None:
            return None
        try:
            return RegisterMap.load(self.register_map)
        except OSError as exc:
            raise BenchConfigError(
                f"register map {self.register_map}: {exc.strerror or exc}", ("register_map",)
            ) from None
        except ExciterConfigError as exc:
            raise BenchConfigError(str(exc).splitlines()[0], ("register_map",)) from None

    async def open(
        self,
        *,
        envelope: SafetyEnvelope | None = None,
        keepalive_interval_s: float | None = DEFAULT_KEEPALIVE_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> PlateExciter:
        """Open this drive (drivers.exciter.urls.open_exciter) with its register map."""
        return await open_exciter(
            self.url,
            envelope=envelope,
            register_map=self.load_register_map(),
            keepalive_interval_s=keepalive_interval_s,
            clock=clock,
        )

    @property
    def kind(self) -> str:
        """'can', 'canopen' or 'modbus'."""
        target = parse_exciter_url(self.url)
        if isinstance(target, Cia402Target):
            return "canopen"
        return "can" if isinstance(target, CanTarget) else "modbus"


@dataclass(frozen=True)
class BenchConfig:
    """A whole bench as its TOML file states it: every device by URL and which channel each laser measures.
    The one description of a bench that acquisition, probing and the service read, real or simulated.
    envelope None: the hard limits (drivers.exciter.envelope.DEFAULT_HARD_LIMITS)."""

    name: str
    model: ModelKind
    exciter: ExciterConfig
    lasers: tuple[LaserConfig, ...]
    envelope: EnvelopeLimits | None = None

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "model", ModelKind(self.model))
        except ValueError:
            expected = [m.value for m in ModelKind]
            raise BenchConfigError(
                f"unknown model {self.model!r}; expected one of {expected}", ("bench", "model")
            ) from None
        object.__setattr__(self, "lasers", tuple(self.lasers))
        if not self.lasers:
            raise BenchConfigError("a bench needs at least one [[lasers]] table", ("lasers",))
        names: dict[str, str] = {self.exciter.name: "the exciter"}
        channels: dict[str, str] = {}
        devices: dict[tuple[str, int], str] = {}
        for index, laser in enumerate(self.lasers):
            if laser.name in names:
                raise BenchConfigError(
                    f"name {laser.name!r} is already used by {names[laser.name]}", ("lasers", index, "name")
                )
            names[laser.name] = f"laser {laser.name!r}"
            if laser.channel not in self.channels:
                raise BenchConfigError(
                    f"unknown channel {laser.channel!r} for a {self.model} bench; expected one of "
                    f"{list(self.channels)}",
                    ("lasers", index, "channel"),
                )
            if laser.channel in channels:
                raise BenchConfigError(
                    f"channel {laser.channel!r} is already measured by {channels[laser.channel]}",
                    ("lasers", index, "channel"),
                )
            channels[laser.channel] = f"laser {laser.name!r}"
            device = laser.device()
            if device in devices:
                raise BenchConfigError(
                    f"node {device[1]} on {device[0]} is already used by {devices[device]}",
                    ("lasers", index, "url"),
                )
            devices[device] = f"laser {laser.name!r}"
        self.safety_envelope()

    @property
    def channels(self) -> tuple[str, ...]:
        """Every channel of this bench model."""
        return CHANNELS[self.model]

    def laser_for(self, channel: str) -> LaserConfig | None:
        return next((laser for laser in self.lasers if laser.channel == channel), None)

    def safety_envelope(self, hard_limits: EnvelopeLimits = DEFAULT_HARD_LIMITS) -> SafetyEnvelope:
        """The bench envelope checked against `hard_limits` (BenchConfigError naming the limit if above)."""
        try:
            return SafetyEnvelope(self.envelope, hard_limits)
        except ExciterConfigError as exc:
            key = next((f.name for f in fields(EnvelopeLimits) if f.name in str(exc)), None)
            where = ("bench", "envelope", key) if key else ("bench", "envelope")
            raise BenchConfigError(str(exc), where) from None


def _check_name(name: str) -> None:
    if not name.strip():
        raise BenchConfigError("name must not be empty", ("name",))


# ---- reading ------------------------------------------------------------------------------------------

_TABLE_KEYS: dict[str, dict[str, tuple[type, ...]]] = {
    "bench": {"name": (str,), "model": (str,), "envelope": (dict,)},
    "envelope": {f.name: (int, float) for f in fields(EnvelopeLimits)},
    "exciter": {"name": (str,), "url": (str,), "register_map": (str,)},
    "lasers": {
        "name": (str,),
        "url": (str,),
        "channel": (str,),
        "head": (str,),
        "sign": (int,),
        "zero_m": (int, float),
        "sample_period_s": (int, float),
        "buffer_length": (int,),
        "value_area": (str,),
        "value_type": (int,),
        "value_address": (int,),
        "value_unit": (str,),
    },
}
_REQUIRED = {
    "bench": ("name", "model"),
    "exciter": ("name", "url"),
    "lasers": ("name", "url", "channel", "head"),
}
_TYPE_NAMES = {
    str: "a string",
    int: "an integer",
    float: "a number",
    dict: "a table",
    list: "an array of tables ([[lasers]])",
}
_TOP_LEVEL = {"bench": "[bench]", "exciter": "[exciter]", "lasers": "[[lasers]]"}
T = TypeVar("T")


def load_bench_config(path: str | os.PathLike[str]) -> BenchConfig:
    """Read and check a bench configuration file (BenchConfigError, or OSError if it cannot be read)."""
    path = Path(path)
    return parse_bench_config(path.read_text(encoding="utf-8"), source=str(path), base_dir=path.parent)


def parse_bench_config(
    text: str, source: str = "<bench config>", base_dir: str | os.PathLike[str] | None = None
) -> BenchConfig:
    """Parse and check the TOML text of a bench configuration; `source` names it in error messages;
    relative file names in it (the exciter's register_map) are taken from `base_dir` (default: the
    current directory)."""
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        at_line = re.search(r"at line (\d+)", str(exc))  # Python < 3.14 has no lineno attribute
        raise BenchConfigError(f"{source}:{at_line.group(1) + ':' if at_line else ''} {exc}") from None
    lines = _KeyLines(text)
    try:
        return _build(document, Path(base_dir) if base_dir is not None else Path.cwd())
    except BenchConfigError as exc:
        line = lines.find(exc.key)
        where = f"{source}:{line}" if line else source
        raise BenchConfigError(f"{where}: {_describe(exc.key)}{exc.message}", exc.key) from None


def _build(document: dict[str, Any], base_dir: Path) -> BenchConfig:
    for name in document:
        if name not in _TOP_LEVEL:
            expected = ", ".join(_TOP_LEVEL.values())
            raise BenchConfigError(f"unknown table or key {name!r} (expected {expected})", (name,))
    _check_keys(document, {"bench": (dict,), "exciter": (dict,), "lasers": (list,)}, ())
    for name, header in _TOP_LEVEL.items():
        if name not in document:
            raise BenchConfigError(f"missing {header} table")
    bench = _table(document["bench"], "bench", ("bench",))
    envelope = None
    if "envelope" in bench:
        values = _table(bench["envelope"], "envelope", ("bench", "envelope"))
        for name, value in values.items():  # each limit alone, so an error names its key
            limit_key = ("bench", "envelope", name)
            _located(lambda n=name, v=value: SafetyEnvelope(EnvelopeLimits(**{n: v})), limit_key)
        envelope = EnvelopeLimits(**values)
    exciter_table = _table(document["exciter"], "exciter", ("exciter",))
    if "register_map" in exciter_table:
        exciter_table["register_map"] = str(base_dir / exciter_table["register_map"])
    exciter = _located(lambda: ExciterConfig(**exciter_table), ("exciter",))
    lasers_doc = document["lasers"]
    lasers = []
    for index, laser in enumerate(lasers_doc):
        if not isinstance(laser, dict):
            raise BenchConfigError("lasers must be an array of tables ([[lasers]])", ("lasers",))
        key = ("lasers", index)
        values = _table(laser, "lasers", key)
        lasers.append(_located(lambda v=values: LaserConfig(**v), key))
    return BenchConfig(bench["name"], bench["model"], exciter, tuple(lasers), envelope)


def _table(value: Any, kind: str, key: tuple[str | int, ...]) -> dict[str, Any]:
    """The table's entries after checking keys and types; required keys must be present."""
    if not isinstance(value, dict):
        raise BenchConfigError("must be a table", key)
    _check_keys(value, _TABLE_KEYS[kind], key)
    missing = [name for name in _REQUIRED.get(kind, ()) if name not in value]
    if missing:
        raise BenchConfigError(f"missing key {missing[0]!r}", key)
    return dict(value)


def _check_keys(
    table: Mapping[str, Any], known: Mapping[str, tuple[type, ...]], key: tuple[str | int, ...]
) -> None:
    for name, value in table.items():
        if name not in known:
            raise BenchConfigError(f"unknown key {name!r} (expected one of {', '.join(known)})", (*key, name))
        types = known[name]
        if isinstance(value, bool) or not isinstance(value, types):
            raise BenchConfigError(f"must be {_TYPE_NAMES[types[-1]]}, got {value!r}", (*key, name))


def _located(build: Callable[[], T], key: tuple[str | int, ...]) -> T:
    """Run build(); errors raised by a dataclass (which know their field, not their table) get `key`."""
    try:
        return build()
    except BenchConfigError as exc:
        raise BenchConfigError(exc.message, (*key, *exc.key[-1:])) from None
    except ExciterConfigError as exc:
        raise BenchConfigError(str(exc), key) from None


def _describe(key: tuple[str | int, ...]) -> str:
    """'[[lasers]] #2 channel: ' for ("lasers", 1, "channel"); '[bench.envelope] max_amplitude_m: ' ..."""
    if not key or key[0] not in _TOP_LEVEL:
        return ""
    if key[0] == "lasers":
        table = "[[lasers]]" + (f" #{key[1] + 1}" if len(key) > 1 and isinstance(key[1], int) else "")
        rest = key[2:] if len(key) > 1 and isinstance(key[1], int) else key[1:]
    else:
        tables = [str(part) for part in key[:2] if part in ("bench", "exciter", "envelope")]
        table, rest = f"[{'.'.join(tables)}]", key[len(tables) :]
    return f"{table}{' ' + str(rest[0]) if rest else ''}: "


class _KeyLines:
    """Best-effort line numbers of TOML tables and keys (tomllib does not report them): scans for
    [table] / [[array]] headers and `key =` lines outside multi-line strings."""

    _HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\-\s\"']+?)\s*\]\]?\s*(#.*)?$")
    _KEY = re.compile(r"^\s*([A-Za-z0-9_\-]+|\"[^\"]*\"|'[^']*')\s*=")

    def __init__(self, text: str) -> None:
        self._lines: dict[tuple[str | int, ...], int] = {}
        table: tuple[str | int, ...] = ()
        counts: dict[str, int] = {}
        in_multiline = False
        for number, line in enumerate(text.splitlines(), start=1):
            quotes = line.count('"""') + line.count("'''")
            if in_multiline:
                in_multiline = quotes % 2 == 0
                continue
            header = self._HEADER.match(line)
            if header:
                name = header.group(2).replace(" ", "").replace('"', "").replace("'", "")
                parts: tuple[str | int, ...] = tuple(name.split("."))
                if header.group(1) == "[[":
                    counts[name] = counts.get(name, -1) + 1
                    parts = (*parts, counts[name])
                elif parts[0] == "lasers" and "lasers" in counts:  # [lasers.x] under the current element
                    parts = ("lasers", counts["lasers"], *parts[1:])
                table = parts
                self._lines.setdefault(table, number)
            elif key := self._KEY.match(line):
                self._lines.setdefault((*table, key.group(1).strip("\"'")), number)
            in_multiline = quotes % 2 == 1

    def find(self, key: tuple[str | int, ...]) -> int | None:
        """The line of `key`, else of the nearest enclosing table that has one."""
        for end in range(len(key), 0, -1):
            if key[:end] in self._lines:
                return self._lines[key[:end]]
        return None


# ---- writing ------------------------------------------------------------------------------------------


def dump_bench_config(config: BenchConfig, comment: str = "") -> str:
    """The TOML text of `config` (parse_bench_config gives it back); `comment` lines go on top."""
    out = [f"# {line}".rstrip() for line in comment.splitlines()]
    out += ["# shockbench bench configuration (format: daq/bench_config.py)", ""]
    out += ["[bench]", _pair("name", config.name), _pair("model", str(config.model))]
    if config.envelope is not None:
        limits = config.envelope
        out += ["", "[bench.envelope]"] + [_pair(f.name, getattr(limits, f.name)) for f in fields(limits)]
    out += ["", "[exciter]", _pair("name", config.exciter.name), _pair("url", config.exciter.url)]
    if config.exciter.register_map is not None:
        out.append(_pair("register_map", config.exciter.register_map))
    for laser in config.lasers:
        out += ["", "[[lasers]]"] + [
            _pair(f.name, getattr(laser, f.name))
            for f in fields(LaserConfig)
            if getattr(laser, f.name) is not None
        ]
    return "\n".join(out) + "\n"


def write_bench_config(config: BenchConfig, path: str | os.PathLike[str], comment: str = "") -> Path:
    """Write `config` to `path` atomically (a reader never sees a half-written file); returns the path."""
    path = Path(path)
    with atomic_write(path) as handle:
        handle.write(dump_bench_config(config, comment))
    return path


def _toml_string(text: str) -> str:
    """A TOML basic string: backslash, quote and control characters escaped, the rest as is."""
    escaped = "".join(
        f"\\u{ord(c):04X}" if ord(c) < 0x20 or ord(c) == 0x7F else "\\" + c if c in '"\\' else c for c in text
    )
    return f'"{escaped}"'


def _pair(key: str, value: object) -> str:
    if isinstance(value, str):
        return f"{key} = {_toml_string(value)}"
    if isinstance(value, float):
        return f"{key} = {value!r}"
    return f"{key} = {value}"


__all__ = [
    "CHANNELS",
    "LASER_HEADS",
    "BenchConfig",
    "BenchConfigError",
    "ExciterConfig",
    "LaserConfig",
    "dump_bench_config",
    "load_bench_config",
    "parse_bench_config",
    "write_bench_config",
]
