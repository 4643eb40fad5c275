"""One declaration per parameter set (issue 32, item 1), seen from outside: what the CLI's --help says,
what the OpenAPI schema says and what the bench configuration's reader does agree on every field's name,
default and bounds. The surfaces are read as a user or a client sees them (the help text, the served
schema, a TOML file); nothing here builds them from the declarations.
"""

from __future__ import annotations

import argparse
import copy
import re
import tomllib
from functools import cache
from pathlib import Path
from typing import Any

import pytest

from daq.bench_config import BenchConfigError, bench_config_schema, parse_bench_config
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[1]

SWEEP = {  # API field -> (CLI option, scale from the API's unit to the option's)
    "start_Hz": ("--start-hz", 1.0),
    "stop_Hz": ("--stop-hz", 1.0),
    "amplitude_m": ("--amplitude-mm", 1e3),
    "duration_s": ("--duration-s", 1.0),
    "law": ("--law", 1.0),
    "settle_s": ("--settle-s", 1.0),
}
DE = {"generations": ("--generations", 1.0), "seed": ("--seed", 1.0)}
HELP = re.compile(
    r"\((?:[^;()[<>]*; )?(?:(?P<range>[\[(][^\])]*[\])]|[<>]=? [\d.e+-]+); )?default (?P<default>[^)]+)\)$"
)
"""The end of an option's help: "(unit; range; default D)", unit and range when it has them."""


@cache
def openapi() -> dict[str, Any]:
    keys = KeyRing({"admin-key-0123456789abc": Role.ADMIN})
    return create_app(ServiceSettings(data_dir=Path("unused"), keys=keys)).openapi()


def api_field(model: str, name: str) -> dict[str, Any]:
    return dict(openapi()["components"]["schemas"][model]["properties"][name])


def cli_action(command: str, flag: str) -> argparse.Action:
    parser = build_parser(command)
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return next(a for a in sub.choices[command]._actions if flag in a.option_strings)


def help_says(action: argparse.Action) -> tuple[str | None, str]:
    """(range in words or None, default in words) as the option's help states them."""
    text = re.sub(r" \[env \w+\]$", "", " ".join((action.help or "").split()))  # serve's variable
    found = HELP.search(text)
    assert found, f"{action.option_strings[0]}: the help states no default: {action.help!r}"
    return found.group("range"), found.group("default")


def range_words(field: dict[str, Any], scale: float) -> str:
    """The schema's bounds as the CLI writes them: [low, high] or (low, high]."""

    def number(value: float) -> str:
        scaled = value * scale
        return str(int(scaled)) if float(scaled).is_integer() else f"{scaled:g}"

    low = field.get("minimum", field.get("exclusiveMinimum"))
    high = field.get("maximum", field.get("exclusiveMaximum"))
    left = "[" if "minimum" in field else "("
    right = "]" if "maximum" in field else ")"
    return f"{left}{number(low)}, {number(high)}{right}"


@pytest.mark.parametrize(
    ("models", "command", "fields"),
    [
        (("SweepIn", "ScheduleIn"), "sweep", SWEEP),
        (("IdentifyUpload", "JobOptionsIn", "SweepJobIn"), "identify", DE),
    ],
    ids=["sweep settings", "DE settings"],
)
def test_cli_help_and_openapi_agree(models: tuple[str, ...], command: str, fields: dict[str, Any]) -> None:
    for name, (flag, scale) in fields.items():
        first = api_field(models[0], name)
        for model in models[1:]:  # every request body that takes the field says the same
            assert api_field(model, name) == first, (model, name)
        action = cli_action(command, flag)
        stated_range, stated_default = help_says(action)
        if "$ref" in first:  # an enum (the law): the same choices and default
            enum = openapi()["components"]["schemas"][first["$ref"].rsplit("/", 1)[1]]["enum"]
            assert list(action.choices or ()) == enum and stated_default == first["default"] == action.default
            continue
        assert stated_range == range_words(first, scale), (flag, action.help)
        assert float(stated_default) == pytest.approx(first["default"] * scale) == action.default, flag


def test_the_cli_refuses_what_the_api_refuses(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Past a bound the CLI answers one line naming the option and the range its help states."""
    from service.cli.main import main

    vehicle = ROOT / "examples" / "vehicles" / "car.toml"
    stop = api_field("SweepIn", "stop_Hz")
    args = ["sweep", "--simulated", "--vehicle", str(vehicle), "--out", str(tmp_path / "r.h5")]
    assert main([*args, "--stop-hz", str(stop["maximum"] + 1)]) == 2
    err = capsys.readouterr().err
    assert err == f"shockbench sweep: error: --stop-hz must lie in {range_words(stop, 1.0)}\n"
    assert not (tmp_path / "r.h5").exists()


# ---- the bench configuration: its JSON Schema and its TOML reader ----------------------------------------

BASE = tomllib.loads((ROOT / "examples" / "benches" / "zx-rs485-modbus-tcp.toml").read_text())
TABLES = {  # schema definition -> where its table is in a document, and its object in a BenchConfig
    "BenchTable": (("bench",), lambda c: c),
    "EnvelopeTable": (("bench", "envelope"), lambda c: c.envelope),
    "ExciterConfig": (("exciter",), lambda c: c.exciter),
    "LaserConfig": (("lasers", 0), lambda c: c.lasers[0]),
}


def dump(document: dict[str, Any]) -> str:
    """A TOML text of `document` (tables and arrays of tables of scalars, as a bench file has)."""

    def scalar(value: Any) -> str:
        return f'"{value}"' if isinstance(value, str) else repr(value)

    lines: list[str] = []
    for name, table in document.items():
        for item in table if isinstance(table, list) else [table]:
            lines.append(f"[[{name}]]" if isinstance(table, list) else f"[{name}]")
            lines += [f"{k} = {scalar(v)}" for k, v in item.items() if not isinstance(v, dict)]
            for sub, values in ((k, v) for k, v in item.items() if isinstance(v, dict)):
                lines.append(f"[{name}.{sub}]")
                lines += [f"{k} = {scalar(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"


def table_of(document: dict[str, Any], path: tuple[str | int, ...]) -> dict[str, Any]:
    node: Any = document
    for part in path:
        node = node.setdefault(part, {}) if isinstance(part, str) else node[part]
    return node  # type: ignore[no-any-return]


def properties() -> list[tuple[str, str, dict[str, Any]]]:
    defs = bench_config_schema()["$defs"]
    return [(table, key, spec) for table in TABLES for key, spec in defs[table]["properties"].items()]


def bounds_of(spec: dict[str, Any]) -> tuple[str, dict[str, float]]:
    """(JSON type, bounds) of a property, nullable or not."""
    plain = next((s for s in spec.get("anyOf", [spec]) if s.get("type") in ("number", "integer")), spec)
    keys = ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum")
    return str(plain.get("type")), {k: plain[k] for k in keys if k in plain}


@pytest.mark.parametrize(
    ("table", "key", "spec"), properties(), ids=lambda v: v if isinstance(v, str) else ""
)
def test_the_bench_schema_and_the_toml_reader_agree(table: str, key: str, spec: dict[str, Any]) -> None:
    path, part = TABLES[table]
    where = ".".join(str(p) for p in path)
    if "default" in spec and spec["default"] is not None:  # left out, the reader uses the schema's default
        document = copy.deepcopy(BASE)
        table_of(document, path).pop(key, None)
        assert getattr(part(parse_bench_config(dump(document))), key) == spec["default"], f"{where}.{key}"
    kind, bounds = bounds_of(spec)
    for bound, value in bounds.items():
        step = 1 if kind == "integer" else max(abs(value) * 1e-3, 1e-9)
        below = bound in ("minimum", "exclusiveMinimum")
        beyond = value - step if below else value + step
        inside = value if bound in ("minimum", "maximum") else (value + step if below else value - step)
        for given, refused in ((beyond, True), (inside, False)):
            document = copy.deepcopy(BASE)
            table_of(document, path)[key] = int(given) if kind == "integer" else float(given)
            try:
                parse_bench_config(dump(document), "bench.toml")
                outcome = None
            except BenchConfigError as exc:
                outcome = exc
            if refused:
                assert outcome is not None and outcome.key[-1] == key, f"{where}.{key} = {given} read"
            else:
                assert outcome is None or outcome.key[-1] != key, f"{where}.{key} = {given}: {outcome}"


def test_the_bench_reader_refuses_a_key_the_schema_lacks_and_names_the_schemas() -> None:
    for table, (path, _part) in TABLES.items():
        document = copy.deepcopy(BASE)
        table_of(document, path)["not_a_key"] = 1
        with pytest.raises(BenchConfigError, match="unknown key 'not_a_key'") as info:
            parse_bench_config(dump(document), "bench.toml")
        expected = ", ".join(bench_config_schema()["$defs"][table]["properties"])
        assert f"(expected one of {expected})" in str(info.value), table


def enum_of(spec: dict[str, Any]) -> list[Any]:
    """The values a property's schema allows by name (its enum, nullable or by $ref), or []."""
    defs = bench_config_schema()["$defs"]
    for option in spec.get("anyOf", [spec]):
        if "$ref" in option:
            option = defs[option["$ref"].rsplit("/", 1)[1]]
        if "enum" in option:
            return list(option["enum"])
    return []


@pytest.mark.parametrize(
    ("table", "key", "spec"),
    # the channel's enum lists every model's channels; which a bench takes depends on its model
    [(t, k, s) for t, k, s in properties() if enum_of(s) and k != "channel"],
    ids=lambda v: v if isinstance(v, str) else "",
)
def test_the_bench_reader_takes_the_schemas_choices_and_no_other(
    table: str, key: str, spec: dict[str, Any]
) -> None:
    path, part = TABLES[table]
    for value in enum_of(spec):
        document = copy.deepcopy(BASE)
        table_of(document, path)[key] = value
        if key == "model":  # an axle needs the axle's channels
            for laser, side in zip(document["lasers"], ("x_s_l", "x_t_l", "x_r_l"), strict=True):
                laser["channel"] = side if value == "axle" else side[:3]
        assert getattr(part(parse_bench_config(dump(document))), key) == value
    document = copy.deepcopy(BASE)
    table_of(document, path)[key] = "not a choice" if isinstance(enum_of(spec)[0], str) else 7
    with pytest.raises(BenchConfigError) as info:
        parse_bench_config(dump(document), "bench.toml")
    assert info.value.key[-1] == key


# ---- the service's limits: serve's options and the settings the service starts with ---------------------


def serve_limit_actions() -> list[argparse.Action]:
    from service.cli.serve import LIMIT_OPTIONS

    return [cli_action("serve", option.flag) for option in LIMIT_OPTIONS]


def test_serve_help_states_the_defaults_the_service_starts_with(tmp_path: Path) -> None:
    """What `serve --help` says each limit defaults to is what ServiceSettings holds when nothing is given
    (sizes in MiB or KiB there, bytes here); the service's other copies of a default agree too."""
    from service.api.stream_limit import DEFAULT_MAX_STREAMS_PER_KEY
    from service.cli.serve import LIMIT_OPTIONS
    from service.store.retention import DEFAULT_RETAIN_DAYS

    settings = ServiceSettings(data_dir=tmp_path, keys=KeyRing({}))
    for option, action in zip(LIMIT_OPTIONS, serve_limit_actions(), strict=True):
        _range, default = help_says(action)
        assert float(default) == pytest.approx(action.default), option.flag
        service_default = getattr(settings, option.field.name)
        assert service_default == pytest.approx(float(default) / option.scale), option.flag
    assert settings.max_streams_per_key == DEFAULT_MAX_STREAMS_PER_KEY
    assert settings.retain_days == DEFAULT_RETAIN_DAYS


def test_serve_refuses_each_limit_just_past_the_range_its_help_states(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from service.cli.serve import main as serve_main

    for action in serve_limit_actions():
        stated, _default = help_says(action)
        assert stated is not None, action.help
        if stated.startswith((">", "<")):  # one bound only: ">= 1", "> 0"
            relation, _, bound = stated.partition(" ")
            past = float(bound) - 1 if relation == ">=" else float(bound)
        else:
            past = float(stated[1:-1].split(",")[1]) * 1.5 + 1  # above the upper bound
        flag = action.option_strings[0]
        given = str(int(past)) if action.type is int else repr(past)
        assert serve_main(["--data", str(tmp_path), flag, given]) == 2, flag
        err = capsys.readouterr().err
        assert err.startswith(f"shockbench serve: error: {flag} must ") and err.count("\n") == 1, err
