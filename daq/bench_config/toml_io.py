"""Reading and writing bench configuration files: TOML text in, a checked BenchConfig out (errors name
the file, the line and the key), and back to TOML."""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import fields
from pathlib import Path

from daq.bench_config.document import read_document
from daq.bench_config.errors import TOP_LEVEL, BenchConfigError, Key
from daq.bench_config.models import BenchConfig, LaserConfig
from daq.formats.atomic import atomic_write


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
    try:
        return read_document(document, Path(base_dir) if base_dir is not None else Path.cwd())
    except BenchConfigError as exc:
        line = KeyLines(text).find(exc.key)
        where = f"{source}:{line}" if line else source
        raise BenchConfigError(f"{where}: {describe(exc.key)}{exc.message}", exc.key) from None


def describe(key: Key) -> str:
    """'[[lasers]] #2 channel: ' for ("lasers", 1, "channel"); '[bench.envelope] max_amplitude_m: ' ..."""
    if not key or key[0] not in TOP_LEVEL:
        return ""
    if key[0] == "lasers":
        table = "[[lasers]]" + (f" #{key[1] + 1}" if len(key) > 1 and isinstance(key[1], int) else "")
        rest = key[2:] if len(key) > 1 and isinstance(key[1], int) else key[1:]
    else:
        tables = [str(part) for part in key[:2] if part in ("bench", "exciter", "envelope")]
        table, rest = f"[{'.'.join(tables)}]", key[len(tables) :]
    return f"{table}{' ' + str(rest[0]) if rest else ''}: "


class KeyLines:
    """Best-effort line numbers of TOML tables and keys (tomllib does not report them): scans for
    [table] / [[array]] headers and `key =` lines outside multi-line strings."""

    _HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\-\s\"']+?)\s*\]\]?\s*(#.*)?$")
    _KEY = re.compile(r"^\s*([A-Za-z0-9_\-]+|\"[^\"]*\"|'[^']*')\s*=")

    def __init__(self, text: str) -> None:
        self._lines: dict[Key, int] = {}
        table: Key = ()
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
                parts: Key = tuple(name.split("."))
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

    def find(self, key: Key) -> int | None:
        """The line of `key`, else of the nearest enclosing table that has one."""
        for end in range(len(key), 0, -1):
            if key[:end] in self._lines:
                return self._lines[key[:end]]
        return None


def dump_bench_config(config: BenchConfig, comment: str = "") -> str:
    """The TOML text of `config` (parse_bench_config gives it back); `comment` lines go on top."""
    out = [f"# {line}".rstrip() for line in comment.splitlines()]
    out += ["# shockbench bench configuration (format: daq/bench_config; `shockbench config schema`)", ""]
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
