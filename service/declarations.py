"""The API's pydantic fields derived from the estimator's declared settings (estimator.declared): each
setting's type, default, bounds and description come from its one declaration, so the OpenAPI schema says
what the dataclass says. The CLI's arguments come from the same declarations (service.cli.declared)."""

from __future__ import annotations

from typing import Any

from pydantic import Field
from pydantic.fields import FieldInfo

from estimator.declared import DeclaredField, declared


def field_info(declared_field: DeclaredField) -> FieldInfo:
    """pydantic's Field for one declared field: its default, bounds and description."""
    d = declared_field.declared
    return Field(declared_field.default, description=d.description(), **d.bounds())  # type: ignore[no-any-return]


def pydantic_field(cls: type, name: str) -> Any:
    """The Field of the declared field `name` of `cls`, for a model's class body:
    `generations: int = pydantic_field(DESettings, "generations")`."""
    return field_info(declared(cls, (name,))[0])


def pydantic_fields(
    cls: type, names: tuple[str, ...] | None = None, *, types: dict[str, Any] | None = None
) -> dict[str, Any]:
    """create_model's field definitions for the declared fields of `cls` (`names` only, when given):
    name -> (type, Field(default, bounds, description)). `types` replaces a field's type where the API
    is narrower (a seed may be None in code, not in a request)."""
    return {d.name: ((types or {}).get(d.name, d.type), field_info(d)) for d in declared(cls, names)}


def echo_fields(cls: type, names: tuple[str, ...] | None = None) -> dict[str, Any]:
    """The same fields as the API echoes what was submitted: without bounds (bounds tightened since must
    not make an older record unreadable), each null when a record does not hold it."""
    return {
        d.name: (d.type | None, Field(None, description=d.declared.description()))
        for d in declared(cls, names)
    }
