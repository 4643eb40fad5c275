"""A bench as its configuration states it: the plate drive (ExciterConfig), the laser sensors
(LaserConfig) and the bench (BenchConfig). Each is a pydantic dataclass, declared once with every key's
type, bounds, unit and help text: the TOML reader (daq.bench_config.document), the JSON Schema
(`shockbench config schema`) and code that builds a bench (the simulated bench, tests) all go through these
declarations. Built in code, a bad value raises BenchConfigError naming the field."""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable
from dataclasses import fields
from typing import Annotated, Any, TypeVar
from urllib.parse import urlsplit

from pydantic import (
    AfterValidator,
    BeforeValidator,
    ConfigDict,
    Field,
    GetCoreSchemaHandler,
    GetJsonSchemaHandler,
    Strict,
    ValidationError,
    ValidationInfo,
)
from pydantic import field_validator as pydantic_field_validator
from pydantic.dataclasses import dataclass
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import CoreSchema, core_schema

from daq.bench_config.errors import BenchConfigError, from_validation
from drivers.compowayf.amplifier import STREAM_BUFFER_LENGTH, AmplifierConfig, streaming_measured_config
from drivers.compowayf.errors import DeviceUrlError
from drivers.compowayf.layout import COUNT_UNIT_NAMES, MeasuredArea, MeasuredValueConfig
from drivers.compowayf.urls import parse_device_url
from drivers.exciter.envelope import DEFAULT_HARD_LIMITS, EnvelopeLimits, SafetyEnvelope
from drivers.exciter.errors import ExciterConfigError
from drivers.exciter.interface import DEFAULT_KEEPALIVE_INTERVAL_S, PlateExciter
from drivers.exciter.register_map import RegisterMap
from drivers.exciter.urls import CanTarget, Cia402Target, open_exciter, parse_exciter_url
from estimator.recording import AXLE_CHANNELS, QUARTER_CAR_CHANNELS
from estimator.vehicle import ModelKind

LASER_HEADS = ("ZX-LD40", "ZX-LD100")
"""Head models a laser may name (catalogue data in simulators/devices/sensor_heads.py)."""
LASER_URL_SCHEMES = ("serial", "socket", "rfc2217", "loop")
"""Schemes a laser URL may use (besides a plain device path); all but serial are pyserial URL handlers."""
MAX_BUFFER_LENGTH = 1000
"""Longest sample buffer a streaming amplifier may declare (read in requests of at most 25 double words)."""
VALUE_AREAS = ("parameter", "variable")
"""Where an amplifier keeps its measured value: the parameter area (read with 0201) or the variable
area (0101)."""

CHANNELS: dict[ModelKind, tuple[str, ...]] = {
    ModelKind.QUARTER_CAR: QUARTER_CAR_CHANNELS,
    ModelKind.AXLE: AXLE_CHANNELS,
}
ALL_CHANNELS = tuple(dict.fromkeys(QUARTER_CAR_CHANNELS + AXLE_CHANNELS))

CONFIG = ConfigDict(extra="forbid")
T = TypeVar("T")


@dataclasses.dataclass(frozen=True)
class OneOf:
    """Annotated metadata: the value must be one of `choices` (BenchConfigError naming the field), and the
    JSON Schema says so (an enum). `unknown`: word the error "unknown NAME X; expected one of [...]".
    `enforce` False: the schema's enum only (the bench checks the value against more than this field)."""

    name: str
    choices: tuple[object, ...]
    unknown: bool = False
    enforce: bool = True
    words: str = ""
    """The choices in words ("1 or -1"); default the list."""

    def check(self, value: T) -> T:
        if self.enforce and value is not None and value not in self.choices:
            if self.unknown:
                raise BenchConfigError(f"unknown {self.name} {value!r}; expected one of {list(self.choices)}")
            words = self.words or f"one of {list(self.choices)}"
            raise BenchConfigError(f"{self.name} must be {words}, got {value!r}")
        return value

    def __get_pydantic_core_schema__(self, source: Any, handler: GetCoreSchemaHandler) -> CoreSchema:
        return core_schema.no_info_after_validator_function(self.check, handler(source))

    def __get_pydantic_json_schema__(
        self, schema: CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        found = handler(schema)
        found["enum"] = list(self.choices)
        return found


def _non_empty(name: str) -> str:
    if not name.strip():
        raise BenchConfigError("name must not be empty")
    return name


def _finite(value: float) -> float:
    if not math.isfinite(value):
        raise BenchConfigError(f"zero_m must be finite, got {value!r}")
    return value


def _model_kind(value: object) -> ModelKind:
    try:
        return ModelKind(value)
    except ValueError:
        expected = [m.value for m in ModelKind]
        raise BenchConfigError(f"unknown model {value!r}; expected one of {expected}") from None


def _exciter_url(url: str) -> str:
    try:
        parse_exciter_url(url)
    except ExciterConfigError as exc:
        raise BenchConfigError(f"bad exciter URL: {exc}") from None
    return url


Text = Annotated[str, Strict()]
DeviceName = Annotated[Text, AfterValidator(_non_empty), Field(description="unique among all devices")]
BenchName = Annotated[Text, Field(description="the bench's name (free text)")]
BenchModel = Annotated[
    ModelKind,
    BeforeValidator(_model_kind),
    Field(
        description="quarter-car (channels x_s, x_t, x_r: sprung mass, wheel, plate) or axle (the same per "
        "side: x_s_l, x_s_r, x_t_l, x_t_r, x_r_l, x_r_r)"
    ),
]
Word = Annotated[int, Strict(), Field(ge=0, le=0xFFFF)]


def checked(cls: type[T]) -> type[T]:
    """`cls`'s constructor raising BenchConfigError (naming the field) instead of pydantic's
    ValidationError, so that code building a bench hears one located line, as a file's reader does."""
    init: Callable[..., None] = cls.__init__  # type: ignore[misc]

    @functools.wraps(init)
    def checked_init(self: object, *args: object, **kwargs: object) -> None:
        try:
            init(self, *args, **kwargs)
        except ValidationError as exc:
            raise from_validation(exc, {}, located=False) from None

    cls.__init__ = checked_init  # type: ignore[misc]
    return cls


@checked
@dataclass(frozen=True, config=CONFIG)
class LaserConfig:
    """One laser displacement sensor ([[lasers]]): amplifier URL (with its node), channel, head, mounting.
    The channel displacement is sign * (reading_m - zero_m) (`to_channel_m`)."""

    name: DeviceName
    url: Annotated[
        Text,
        Field(
            description="a drivers.compowayf.urls device URL that names the node: "
            "serial:///dev/ttyUSB0?baudrate=38400&node=1, socket://HOST:PORT?node=2 (a serial-to-Ethernet "
            "converter) or a device path /dev/ttyUSB0?node=1; timeout_s= (reply timeout, default 0.5 s), "
            "late_reply_s= (drain the line this long after an unanswered request, default 3 s), retries= "
            "and echo=1 (the RS-485 adapter echoes the host's frames) may be added"
        ),
    ]
    channel: Annotated[
        Text,
        OneOf("channel", ALL_CHANNELS, enforce=False),
        Field(
            description="the bench channel the laser measures (each at most once; not every channel needs "
            "a laser)",
        ),
    ]
    head: Annotated[
        Text,
        OneOf("head", LASER_HEADS, unknown=True),
        Field(description="ZX-LD40 (40 +- 10 mm) or ZX-LD100 (100 +- 40 mm)"),
    ]
    sign: Annotated[
        int,
        Strict(),
        OneOf("sign", (1, -1), words="1 or -1"),
        Field(description="+1 when the head looks down on its target (an upward move reads positive), -1 up"),
    ] = 1
    zero_m: Annotated[
        float,
        Strict(),
        AfterValidator(_finite),
        Field(description="what the amplifier reads with the channel at its static position (m)"),
    ] = 0.0
    sample_period_s: Annotated[
        float | None,
        Strict(),
        Field(
            gt=0,
            le=1.0,
            description="the amplifier samples on its own clock into a buffer with a sample counter, every "
            "this long (s): samples carry device timestamps and none is missed. Leave it out for an "
            "amplifier that holds its present value only: it is polled as fast as the line allows",
        ),
    ] = None
    buffer_length: Annotated[
        int,
        Strict(),
        Field(ge=1, le=MAX_BUFFER_LENGTH, description="the samples a streaming amplifier keeps"),
    ] = STREAM_BUFFER_LENGTH
    value_area: Annotated[
        Text | None,
        OneOf("value_area", VALUE_AREAS),
        Field(
            description="where the amplifier keeps its measured value: parameter (0201) or variable (0101)"
        ),
    ] = None
    value_type: Annotated[
        Word | None,
        Field(description="parameter type (e.g. 0xC020 = C000h + data number) or variable type (e.g. 0xC0)"),
    ] = None
    value_address: Annotated[
        Word | None,
        Field(description="read start address; for the parameter area unit number << 8 | channel"),
    ] = None
    value_unit: Annotated[
        Text,
        OneOf("value_unit", tuple(COUNT_UNIT_NAMES)),
        Field(description="the unit of the measured value's counts"),
    ] = "nm"

    def __post_init__(self) -> None:
        try:
            self.amplifier_config()
        except ValueError as exc:
            raise BenchConfigError(f"measured value location: {exc}", ("value_type",)) from None
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

    def amplifier_config(self) -> AmplifierConfig:
        """How the driver reads this amplifier: where its value lives (value_* keys over the defaults), and
        the streaming layout when it samples on its own clock. Polled defaults: the ZS-series measurement
        result, parameter area C020 address 3000, nm (OMRON ZS/ZFV CompoWay/F references; that the ZX-L
        follows it is an assumption). Streaming defaults: the sample counter at variable area C0 address
        0000 with the sample ring after it (the simulator's layout)."""
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


@checked
@dataclass(frozen=True, config=CONFIG)
class ExciterConfig:
    """The plate drive ([exciter]): a drivers.exciter.urls URL and, for Modbus, the register map file
    (None: the default map)."""

    name: DeviceName
    url: Annotated[
        Text,
        AfterValidator(_exciter_url),
        Field(
            description="modbus-tcp://HOST:PORT?unit=N, modbus-rtu:///dev/ttyUSB1?baudrate=19200&unit=1, "
            "can://INTERFACE/CHANNEL (python-can, e.g. can://socketcan/can0; base_id=0x680 moves the frame "
            "set), or canopen://INTERFACE/CHANNEL?node=N for a CiA 402 drive (host_node=127, "
            "watchdog_timeout=0.5, transition_timeout=0.5 ...)"
        ),
    ]
    register_map: Annotated[
        Text | None,
        Field(
            description="Modbus only: the drive's register map file (format: "
            "drivers/exciter/default_register_map.toml), relative to the configuration file"
        ),
    ] = None

    @pydantic_field_validator("register_map")
    @classmethod
    def _beside_the_file(cls, value: str | None, info: ValidationInfo) -> str | None:
        """A relative register map is taken from the configuration file's folder (context base_dir)."""
        base_dir = (info.context or {}).get("base_dir")
        return str(base_dir / value) if value is not None and base_dir is not None else value

    def __post_init__(self) -> None:
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


@checked
@dataclass(frozen=True, config=CONFIG)
class BenchConfig:
    """A whole bench as its TOML file states it: every device by URL and which channel each laser measures.
    The one description of a bench that acquisition, probing and the service read, real or simulated.
    envelope None: the hard limits (drivers.exciter.envelope.DEFAULT_HARD_LIMITS)."""

    name: BenchName
    model: BenchModel
    exciter: ExciterConfig
    lasers: tuple[LaserConfig, ...]
    envelope: EnvelopeLimits | None = None

    def __post_init__(self) -> None:
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
