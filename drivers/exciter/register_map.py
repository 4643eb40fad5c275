"""The Modbus register map of a plate drive, read from a TOML file into dataclasses, and the register codec.

A map names every register the driver uses, in two tables: `[holding.<name>]` (written by the host) and
`[input.<name>]` (reported by the drive). Each register has an address (0-based PDU address), a type
(u16, s16: one register; u32, s32: a register pair) and a fixed-point scale (physical = raw * scale), and
may override the map-wide `word_order` of register pairs ("big": high word at the lower address;
"little": low word first). Unknown or missing keys, unknown or missing registers and overlapping
addresses are `RegisterMapError`s naming the culprit. See default_register_map.toml.

The simulated drive (simulators/devices/modbus_exciter.py) uses the same map and codec.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from drivers.exciter.errors import ExciterConfigError, ExciterEncodingError

DEFAULT_REGISTER_MAP_PATH = Path(__file__).with_name("default_register_map.toml")

HOLDING_REGISTERS = (
    "command",
    "keepalive",
    "sweep_start_Hz",
    "sweep_stop_Hz",
    "sweep_amplitude_m",
    "sweep_duration_s",
    "sweep_law",
)
"""Registers written by the host."""

INPUT_REGISTERS = ("state", "fault_code", "frequency_Hz", "position_m")
"""Registers reported by the drive (read together as one block)."""

CODE_REGISTERS = frozenset({"command", "keepalive", "sweep_law", "state", "fault_code"})
"""Registers that carry codes or counters: their scale must be 1."""

_TOP_LEVEL_KEYS = frozenset({"word_order", "holding", "input"})
_REQUIRED_REGISTER_KEYS = ("address", "type", "scale")
_OPTIONAL_REGISTER_KEYS = frozenset({"word_order", "description"})


class RegisterMapError(ExciterConfigError):
    """The register map file is malformed; the message names the key, register or address at fault."""


class WordOrder(StrEnum):
    """Order of the two 16-bit words of a 32-bit value."""

    BIG = "big"  # high word first (at the lower address)
    LITTLE = "little"  # low word first


class RegisterType(StrEnum):
    U16 = "u16"
    S16 = "s16"
    U32 = "u32"
    S32 = "s32"

    @property
    def words(self) -> int:
        return 2 if self in (RegisterType.U32, RegisterType.S32) else 1

    @property
    def signed(self) -> bool:
        return self in (RegisterType.S16, RegisterType.S32)

    @property
    def raw_range(self) -> tuple[int, int]:
        bits = 16 * self.words
        return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if self.signed else (0, (1 << bits) - 1)


@dataclass(frozen=True)
class RegisterSpec:
    """One named register (or register pair) and how its words map to a physical value."""

    name: str
    address: int
    type: RegisterType
    scale: float
    word_order: WordOrder = WordOrder.BIG
    description: str = ""

    @property
    def words(self) -> int:
        return self.type.words

    def encode(self, value: float) -> list[int]:
        """Physical value -> register words (in wire order). Out of range -> ExciterEncodingError."""
        if not math.isfinite(value):
            raise ExciterEncodingError(f"register {self.name}: value {value!r} is not finite")
        raw = round(value / self.scale)
        low, high = self.type.raw_range
        if not low <= raw <= high:
            raise ExciterEncodingError(
                f"register {self.name}: {value!r} (raw {raw}) does not fit {self.type.value} "
                f"with scale {self.scale!r} (raw range {low}..{high})"
            )
        unsigned = raw & ((1 << (16 * self.words)) - 1)
        if self.words == 1:
            return [unsigned]
        high_word, low_word = unsigned >> 16, unsigned & 0xFFFF
        return [high_word, low_word] if self.word_order is WordOrder.BIG else [low_word, high_word]

    def decode(self, words: Sequence[int]) -> float:
        """Register words (in wire order) -> physical value."""
        if len(words) != self.words:
            raise ValueError(f"register {self.name} needs {self.words} word(s), got {len(words)}")
        if self.words == 1:
            unsigned = words[0] & 0xFFFF
        else:
            first, second = words[0] & 0xFFFF, words[1] & 0xFFFF
            high_word, low_word = (first, second) if self.word_order is WordOrder.BIG else (second, first)
            unsigned = (high_word << 16) | low_word
        bits = 16 * self.words
        raw = unsigned - (1 << bits) if self.type.signed and unsigned >> (bits - 1) else unsigned
        return raw * self.scale


@dataclass(frozen=True)
class RegisterMap:
    """All registers of the drive, by name. Build with `load`, `from_toml` or `default`."""

    holding: Mapping[str, RegisterSpec]
    input: Mapping[str, RegisterSpec]
    word_order: WordOrder = WordOrder.BIG

    @classmethod
    def default(cls) -> RegisterMap:
        """The documented default map shipped with the driver."""
        return cls.load(DEFAULT_REGISTER_MAP_PATH)

    @classmethod
    def load(cls, path: str | Path) -> RegisterMap:
        path = Path(path)
        return cls.from_toml(path.read_text(encoding="utf-8"), source=str(path))

    @classmethod
    def from_toml(cls, text: str, source: str = "<register map>") -> RegisterMap:
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise RegisterMapError(f"{source}: not valid TOML: {exc}") from exc
        return cls.from_dict(data, source)

    @classmethod
    def from_dict(cls, data: Mapping[str, object], source: str = "<register map>") -> RegisterMap:
        _reject_unknown(data, _TOP_LEVEL_KEYS, source, "top level")
        word_order = _word_order(data.get("word_order", WordOrder.BIG.value), source, "word_order")
        holding = _parse_table(data, "holding", HOLDING_REGISTERS, word_order, source)
        inputs = _parse_table(data, "input", INPUT_REGISTERS, word_order, source)
        return cls(holding=holding, input=inputs, word_order=word_order)

    def encode_holding(self, values: Mapping[str, float]) -> dict[int, int]:
        """Named physical values -> {address: word} of the holding registers. Encodes everything before
        returning, so a value that does not fit raises before anything could be written."""
        words: dict[int, int] = {}
        for name, value in values.items():
            spec = self.holding[name]
            for offset, word in enumerate(spec.encode(value)):
                words[spec.address + offset] = word
        return words

    def input_block(self) -> tuple[int, int]:
        """(first address, count) of the smallest block covering every input register."""
        return _block(self.input.values())

    def decode_inputs(self, start: int, words: Sequence[int]) -> dict[str, float]:
        """Input register block read from `start` -> named physical values."""
        return {
            name: spec.decode(words[spec.address - start : spec.address - start + spec.words])
            for name, spec in self.input.items()
        }


def contiguous_runs(words: Mapping[int, int]) -> list[tuple[int, list[int]]]:
    """{address: word} -> [(first address, [words...])] with one entry per run of consecutive addresses,
    so each run can go out as one write."""
    runs: list[tuple[int, list[int]]] = []
    for address in sorted(words):
        if runs and runs[-1][0] + len(runs[-1][1]) == address:
            runs[-1][1].append(words[address])
        else:
            runs.append((address, [words[address]]))
    return runs


def _block(specs: Iterable[RegisterSpec]) -> tuple[int, int]:
    specs = list(specs)
    first = min(s.address for s in specs)
    last = max(s.address + s.words for s in specs)
    return first, last - first


def _reject_unknown(table: Mapping[str, object], allowed: Iterable[str], source: str, where: str) -> None:
    for key in table:
        if key not in allowed:
            raise RegisterMapError(f"{source}: unknown key {key!r} in {where} (allowed: {sorted(allowed)})")


def _word_order(value: object, source: str, where: str) -> WordOrder:
    try:
        return WordOrder(value)
    except ValueError:
        raise RegisterMapError(f"{source}: {where} must be 'big' or 'little', got {value!r}") from None


def _parse_table(
    data: Mapping[str, object], table: str, names: tuple[str, ...], word_order: WordOrder, source: str
) -> dict[str, RegisterSpec]:
    raw = data.get(table)
    if not isinstance(raw, dict):
        raise RegisterMapError(f"{source}: missing table [{table}]")
    _reject_unknown(raw, names, source, f"[{table}] (unknown register)")
    specs: dict[str, RegisterSpec] = {}
    for name in names:
        if name not in raw:
            raise RegisterMapError(f"{source}: missing register [{table}.{name}]")
        specs[name] = _parse_register(raw[name], name, f"[{table}.{name}]", word_order, source)
    _check_overlaps(specs.values(), table, source)
    return specs


def _parse_register(entry: object, name: str, where: str, word_order: WordOrder, source: str) -> RegisterSpec:
    if not isinstance(entry, dict):
        raise RegisterMapError(f"{source}: {where} must be a table")
    _reject_unknown(entry, {*_REQUIRED_REGISTER_KEYS, *_OPTIONAL_REGISTER_KEYS}, source, where)
    for key in _REQUIRED_REGISTER_KEYS:
        if key not in entry:
            raise RegisterMapError(f"{source}: missing key {key!r} in {where}")
    address, type_name, scale = entry["address"], entry["type"], entry["scale"]
    if not isinstance(address, int) or isinstance(address, bool) or not 0 <= address <= 0xFFFF:
        raise RegisterMapError(f"{source}: {where} address must be an integer 0..65535, got {address!r}")
    try:
        reg_type = RegisterType(type_name)
    except ValueError:
        allowed = [t.value for t in RegisterType]
        raise RegisterMapError(
            f"{source}: {where} type must be one of {allowed}, got {type_name!r}"
        ) from None
    scale_ok = isinstance(scale, int | float) and not isinstance(scale, bool) and math.isfinite(scale)
    if not (scale_ok and scale > 0):
        raise RegisterMapError(f"{source}: {where} scale must be a number > 0, got {scale!r}")
    if name in CODE_REGISTERS and scale != 1:
        raise RegisterMapError(f"{source}: {where} carries a code: its scale must be 1, got {scale!r}")
    if address + reg_type.words - 1 > 0xFFFF:
        raise RegisterMapError(f"{source}: {where} register pair runs past address 65535")
    description = entry.get("description", "")
    if not isinstance(description, str):
        raise RegisterMapError(f"{source}: {where} description must be a string")
    order = _word_order(entry.get("word_order", word_order.value), source, f"{where} word_order")
    return RegisterSpec(name, address, reg_type, float(scale), order, description)


def _check_overlaps(specs: Iterable[RegisterSpec], table: str, source: str) -> None:
    owner: dict[int, str] = {}
    for spec in specs:
        for address in range(spec.address, spec.address + spec.words):
            if address in owner:
                raise RegisterMapError(
                    f"{source}: [{table}] address {address} used by both {owner[address]!r} and {spec.name!r}"
                )
            owner[address] = spec.name
