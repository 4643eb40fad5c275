"""The bench configuration file as a document: its tables ([bench], [bench.envelope], [exciter],
[[lasers]]) as pydantic models over the declarations of daq.bench_config.models, read into a BenchConfig
(`read_document`), and its JSON Schema (`bench_config_schema`, what `shockbench config schema` prints)."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, Strict, ValidationError, create_model

from daq.bench_config.errors import BenchConfigError, from_validation
from daq.bench_config.models import BenchConfig, BenchModel, BenchName, ExciterConfig, LaserConfig
from drivers.exciter.envelope import DEFAULT_HARD_LIMITS, EnvelopeLimits, SafetyEnvelope
from drivers.exciter.errors import ExciterConfigError

ENVELOPE_HELP = {
    "max_amplitude_m": "zero-to-peak plate amplitude (m)",
    "max_frequency_Hz": "any frequency of the sweep (Hz)",
    "max_duration_s": "the sweep's duration (s)",
}
"""What each limit of drivers.exciter.envelope.EnvelopeLimits bounds, for the schema's help text."""


def _limit_alone(name: str) -> AfterValidator:
    """One limit checked alone against the hard limits, so that its error names its key."""

    def check(value: float) -> float:
        try:
            SafetyEnvelope(EnvelopeLimits(**{name: value}))
        except ExciterConfigError as exc:
            raise BenchConfigError(str(exc)) from None
        return value

    return AfterValidator(check)


EnvelopeTable: type[BaseModel] = create_model(  # type: ignore[call-overload]
    "EnvelopeTable",
    __config__=ConfigDict(extra="forbid"),
    __doc__="[bench.envelope], optional: lowers the sweeps allowed; never above the installation's hard "
    "limits (only the duration may be raised, up to the hard limit).",
    **{
        f.name: (
            Annotated[float, Strict(), _limit_alone(f.name)],
            Field(
                f.default,
                description=ENVELOPE_HELP.get(f.name, f.name),
                json_schema_extra={"exclusiveMinimum": 0, "maximum": getattr(DEFAULT_HARD_LIMITS, f.name)},
            ),
        )
        for f in fields(EnvelopeLimits)
    },
)
"""[bench.envelope]: the fields, defaults and hard limits of EnvelopeLimits, each optional."""


class BenchTable(BaseModel):
    """[bench]: the bench's name and model, and its safety envelope."""

    model_config = ConfigDict(extra="forbid")

    name: BenchName
    model: BenchModel
    envelope: EnvelopeTable | None = None  # type: ignore[valid-type]


class BenchDocument(BaseModel):
    """A shockbench bench configuration (TOML): which devices make up a bench, where they are, what each
    laser measures."""

    model_config = ConfigDict(extra="forbid", title="shockbench bench configuration")

    bench: BenchTable
    exciter: ExciterConfig = Field(description="the plate drive")
    lasers: list[LaserConfig] = Field(description="one table per laser sensor (amplifier + head)")

    def config(self) -> BenchConfig:
        envelope = self.bench.envelope
        return BenchConfig(
            self.bench.name,
            self.bench.model,
            self.exciter,
            tuple(self.lasers),
            EnvelopeLimits(**envelope.model_dump()) if envelope is not None else None,
        )


KNOWN_KEYS: dict[str, tuple[str, ...]] = {
    "bench": tuple(BenchTable.model_fields),
    "envelope": tuple(EnvelopeTable.model_fields),
    "exciter": tuple(f.name for f in fields(ExciterConfig)),
    "lasers": tuple(f.name for f in fields(LaserConfig)),
}
"""The keys of each table, named when a key is unknown."""


def read_document(document: dict[str, Any], base_dir: Path) -> BenchConfig:
    """The bench a parsed TOML document states (BenchConfigError with the key of the first problem);
    relative files it names are taken from `base_dir`."""
    try:
        parsed = BenchDocument.model_validate(document, context={"base_dir": base_dir})
    except ValidationError as exc:
        raise from_validation(exc, KNOWN_KEYS, located=True) from None
    return parsed.config()


def bench_config_schema() -> dict[str, Any]:
    """The JSON Schema of a bench configuration file (for editors: TOML language servers such as Taplo and
    Even Better TOML read it)."""
    schema = BenchDocument.model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}
