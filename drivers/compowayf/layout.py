"""Where an amplifier keeps its measured value and how to read it: area, type, address, count unit, the
out-of-range markers, and the layout of an amplifier that buffers samples behind a sample counter.

Sources (OMRON's CompoWay/F command references; the ZX-L amplifier's own map could not be read):

* ZS series (Z231) and ZFV-C (Z243) smart sensors read a measurement result with service 0201 (parameter
  area read): parameter type C000h + data number, read start address = unit number << 8 | channel number,
  one element (8001h), 8 hex characters, in nm. The measurement result is unit 30h, data 20h, so the ZS-LDC
  channel 0 value is type C020, address 3000 (Z231 section 3, "Measurement Result Obtaining Command":
  "02 01 C020 3002 8001" -> "... 04CC5520" = 80 500 000 nm). These are the defaults here.
* The ZX-SF11 interface unit (the ZX-L's link to RS-232C) offers the same services (0101, 0201, 0202,
  0503, 0601, 0801, 3005; OMRON AST1-01X055 "ZX-SF11 CompoWay/F message communication command
  specifications"), but its unit/data number table was not available. ASSUMPTION: the ZX-L measured value
  sits where the ZS series keeps it. Check it against the ZX-SF11 table and set `value_area`,
  `value_type`, `value_address`, `value_unit` in BENCH.toml (daq/bench_config/) where it differs.
* Abnormal measured values are "7FFFFFFXh" ("X" varies with the case; ZFV-C Z243 section 2): every count
  from 7FFFFFF0 to 7FFFFFFF means out of range. For word (4 hex character) areas the same top sixteen
  values 7FF0..7FFF are taken to be markers (an assumption, no OMRON text says so).
* The streaming layout (sample counter and a ring of samples) is the simulator's own: no ZX manual at hand
  describes a buffered read over CompoWay/F.

`AmplifierConfig` (the value layout plus the operation codes) is the whole address map of one amplifier; the
driver reads by it and the simulated amplifier serves by it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum, StrEnum

from drivers.compowayf.service_data import parameter_element_width, variable_element_width


class MeasuredArea(StrEnum):
    """Which CompoWay/F area holds the measured value: variable area (read with 0101) or parameter area
    (read with 0201)."""

    VARIABLE = "variable"
    PARAMETER = "parameter"


class CountUnit(Enum):
    """Length of one count of the measured value, in metres."""

    NANOMETRE = 1e-9
    TENTH_MICROMETRE = 1e-7
    MICROMETRE = 1e-6

    @property
    def metres(self) -> float:
        return float(self.value)


COUNT_UNIT_NAMES: dict[str, CountUnit] = {
    "nm": CountUnit.NANOMETRE,
    "0.1um": CountUnit.TENTH_MICROMETRE,
    "um": CountUnit.MICROMETRE,
}
"""The names a bench configuration uses for the count units."""

ZS_MEASUREMENT_RESULT_TYPE = 0xC020
"""Parameter type of the ZS/ZFV measurement result: C000h + data number 20h."""
ZS_MEASUREMENT_RESULT_UNIT = 0x30
"""Unit number of the ZS/ZFV measurement result (TASK1)."""

MARKER_SPAN = 16
"""Out-of-range markers: the top MARKER_SPAN values of the element's positive range (7FFFFFF0..7FFFFFFF)."""


def zs_result_address(channel: int = 0) -> int:
    """Read start address of the ZS measurement result of `channel`: unit number << 8 | channel."""
    if not 0 <= channel <= 0xFF:
        raise ValueError(f"channel must be 0..255, got {channel}")
    return ZS_MEASUREMENT_RESULT_UNIT << 8 | channel


@dataclass(frozen=True)
class MeasuredValueConfig:
    """Where and how an amplifier exposes its measured value.

    area / area_type / address: the area, its type code (parameter type, 4 hex digits, e.g. C020 for the
        ZS measurement result; or variable type, 2 hex digits, e.g. C0) and the first element's address.
        Defaults: the ZS-series measurement result (parameter area C020, address 3000), see the module
        docstring for the sources and the assumption.
    buffer_length: polled amplifiers: how many consecutive elements from `address` hold samples, newest
        first (1 = only the current value; a read of more than 25 is split into several requests, between
        which such a buffer may shift). Streaming amplifiers: the slots of the sample ring, whose
        addresses do not move, so split reads stay consistent.
    count_unit: metres per count (signed 32-bit counts for double-word areas); OMRON's ZS/ZFV send nm.
    sample_period_s: the amplifier's own sampling period when it samples on its own clock and buffers
        (None: it holds only the value at the moment of the read, which the host then timestamps).
    counter_address: with sample_period_s, the address of a sample counter (samples taken since the
        amplifier started, modulo 2**31) directly before the ring (address - 1). Sample number n (as the
        counter counts it) sits in slot n % buffer_length at address + slot until sample n +
        buffer_length overwrites it; the newest sample is number counter - 1. The counter is the device
        clock (time = counter * sample_period_s) and tells how many samples are new since the last read.
    """

    area: MeasuredArea = MeasuredArea.PARAMETER
    area_type: int = ZS_MEASUREMENT_RESULT_TYPE
    address: int = ZS_MEASUREMENT_RESULT_UNIT << 8
    buffer_length: int = 1
    count_unit: CountUnit = CountUnit.NANOMETRE
    sample_period_s: float | None = None
    counter_address: int | None = None

    def __post_init__(self) -> None:
        if self.buffer_length < 1:
            raise ValueError(f"buffer_length must be >= 1, got {self.buffer_length}")
        if self.sample_period_s is not None and not (
            math.isfinite(self.sample_period_s) and self.sample_period_s > 0
        ):
            raise ValueError(f"sample_period_s must be positive, got {self.sample_period_s}")
        if self.counter_address is not None:
            if self.sample_period_s is None:
                raise ValueError("a sample counter needs the sample_period_s it counts")
            if self.counter_address != self.address - 1:
                raise ValueError(
                    f"the sample counter must sit directly before the sample ring (address "
                    f"0x{self.address - 1:04X}), got 0x{self.counter_address:04X}"
                )
        type_max = 0xFF if self.area is MeasuredArea.VARIABLE else 0xFFFF
        if not 0 <= self.area_type <= type_max:
            raise ValueError(f"area_type 0x{self.area_type:X} does not fit a {self.area} area")
        if not 0 <= self.address <= 0xFFFF or self.address + self.buffer_length - 1 > 0xFFFF:
            raise ValueError(f"addresses 0x{self.address:X} + {self.buffer_length} do not fit 0000..FFFF")

    @property
    def element_width(self) -> int:
        """Hex characters per element in the reply."""
        if self.area is MeasuredArea.VARIABLE:
            return variable_element_width(self.area_type)
        return parameter_element_width(self.area_type)

    @property
    def out_of_range_marker(self) -> int:
        """The marker the simulator sends: the largest positive element (7FFFFFFF)."""
        return (1 << (4 * self.element_width - 1)) - 1

    def is_out_of_range(self, counts: int) -> bool:
        """True for any of OMRON's 7FFFFFFx markers (the top MARKER_SPAN positive values)."""
        return counts > self.out_of_range_marker - MARKER_SPAN

    def counts_to_m(self, counts: int) -> float:
        """Metres for a count value; NaN for an out-of-range marker."""
        return math.nan if self.is_out_of_range(counts) else counts * self.count_unit.metres

    def m_to_counts(self, value_m: float) -> int:
        return round(value_m / self.count_unit.metres)

    @property
    def is_streaming(self) -> bool:
        """True when the amplifier samples on its own clock and exposes a sample counter."""
        return self.counter_address is not None

    def slot_of(self, sample_number: int) -> int:
        """Streaming: the ring slot of sample `sample_number` (as the counter counts, modulo 2**31)."""
        return (sample_number % COUNTER_MODULUS) % self.buffer_length


COUNTER_MODULUS = 2**31
"""The sample counter wraps here (a non-negative signed double word)."""

STREAM_BUFFER_LENGTH = 256
"""Samples a streaming amplifier keeps by default: 256 ms at 1 kHz, so a host may pause that long between
reads without losing a sample."""


def streaming_measured_config(
    sample_period_s: float = 0.001,
    buffer_length: int = STREAM_BUFFER_LENGTH,
    *,
    area: MeasuredArea = MeasuredArea.VARIABLE,
    area_type: int = 0xC0,
    counter_address: int = 0x0000,
    count_unit: CountUnit = CountUnit.NANOMETRE,
) -> MeasuredValueConfig:
    """The layout of an amplifier that samples on its own clock: the sample counter at `counter_address`
    (default variable area C0, address 0000), the ring of `buffer_length` samples right after it. An
    assumed layout (no ZX-L manual describes one); the simulated amplifier serves exactly this."""
    return MeasuredValueConfig(
        area=area,
        area_type=area_type,
        address=counter_address + 1,
        buffer_length=buffer_length,
        count_unit=count_unit,
        sample_period_s=sample_period_s,
        counter_address=counter_address,
    )


@dataclass(frozen=True)
class OperationCodes:
    """Command code + related information of the operation commands (3005) the driver sends.

    The defaults are placeholders (OMRON assigns codes per amplifier generation); the simulator honours
    whatever is configured here.
    """

    zero_reset: tuple[int, int] = (0x01, 0x00)
    zero_reset_cancel: tuple[int, int] = (0x01, 0x01)


@dataclass(frozen=True)
class AmplifierConfig:
    """Everything that describes one amplifier on the line besides its node number."""

    measured: MeasuredValueConfig = field(default_factory=MeasuredValueConfig)
    operations: OperationCodes = field(default_factory=OperationCodes)
