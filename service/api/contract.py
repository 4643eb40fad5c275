"""What the OpenAPI schema states beyond the pydantic models, so that it is a contract clients can be
generated from (openapi-python-client, tests/service/test_api_contract_client.py) and tested against
(schemathesis, tests/service/test_api_schema.py):

- the upload bodies of POST /jobs, /diagnoses and /validations as one flat multipart object: the files
  `recording` (CSV) and `vehicle` (TOML; a validation: `model`, JSON) as `type: string, format: binary`
  beside the options (`upload_model`);
- `Location` on every 201 (`created`), the media type and binary body of every download (`download`);
- the job event stream's event names and the schema of each event's data (`event_stream`, and the
  payload models added to the components by `contract_openapi`);
- the `Allow` header of a 405 (a method the path does not take), as a reusable response.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import FastAPI, UploadFile
from fastapi.openapi.utils import get_openapi
from pydantic import BaseModel, ConfigDict, Field, WithJsonSchema, create_model

from service.api.errors import ErrorBody, responses
from service.api.schemas import (
    JOB_EVENTS,
    ClosingEvent,
    LiveClosingEvent,
    LiveSamplesEvent,
    LiveStateEvent,
    ProgressEvent,
)
from service.jobs.kinds import JobKindSpec

REF = "#/components/schemas/{model}"

RECORDING_DESCRIPTION = (
    "recording CSV, UTF-8: a header t,x_s,x_t,x_r (quarter car) or the axle columns, one row per sample "
    "at a uniform rate, optional '# key: value' metadata lines (see README, Interchange formats)"
)

CsvFile = Annotated[
    UploadFile, WithJsonSchema({"type": "string", "format": "binary", "contentMediaType": "text/csv"})
]
"""An uploaded CSV file (multipart part with a file name)."""


def upload_encoding(spec: JobKindSpec) -> dict[str, dict[str, str]]:
    """The multipart encoding of a kind's upload: the media type of each file part."""
    return {
        "recording": {"contentType": "text/csv"},
        spec.companion.field: {"contentType": spec.companion.media_type},
    }


def upload_model(spec: JobKindSpec) -> type[BaseModel]:
    """The multipart body of a kind's submit endpoint: `recording` and the kind's other file (`vehicle`, or
    `model`) beside the kind's options, one flat object. Unknown fields are refused (422 naming the field),
    hence additionalProperties false."""
    name = "".join(part.capitalize() for part in spec.name.split("_")) + "Upload"
    companion = spec.companion
    other_file = Annotated[
        UploadFile,
        WithJsonSchema({"type": "string", "format": "binary", "contentMediaType": companion.media_type}),
    ]
    model: type[BaseModel] = create_model(
        name,
        __base__=spec.options_model,
        __doc__=f"{spec.summary}: the recording, its {companion.field} file and the options.",
        recording=(CsvFile, Field(description=RECORDING_DESCRIPTION)),
        **{companion.field: (other_file, Field(description=companion.description))},  # type: ignore[call-overload]
    )
    model.model_config = ConfigDict(model.model_config, json_schema_extra=_multipart_form_schema)
    model.model_rebuild(force=True)
    return model


def _multipart_form_schema(schema: dict[str, Any]) -> None:
    """A form field is sent or left out; it cannot be null (the text "null" is refused like any other
    word). So an option that may be null in the model (points: null = the default) is stated without its
    null; and the form takes no field beyond its properties."""
    schema["additionalProperties"] = False
    for name, field in schema.get("properties", {}).items():
        variants = field.get("anyOf")
        if variants and {"type": "null"} in variants:
            others = [v for v in variants if v != {"type": "null"}]
            rest = {k: v for k, v in field.items() if k not in ("anyOf", "default")}
            single = len(others) == 1
            schema["properties"][name] = {**others[0], **rest} if single else {"anyOf": others, **rest}


def created(what: str) -> dict[int | str, dict[str, Any]]:
    """The 201 of a route that creates something: its Location header."""
    return {
        201: {
            "description": f"created: the {what}; Location is its URL",
            "headers": {
                "Location": {
                    "description": f"the new {what}'s URL (path under this server)",
                    "required": True,
                    "schema": {"type": "string", "format": "uri-reference"},
                }
            },
        }
    }


BINARY = {"type": "string", "format": "binary"}


def download(media_type: str, description: str) -> dict[int | str, dict[str, Any]]:
    """The 200 of a download: its media type and a binary body (bytes for a generated client)."""
    return {200: {"description": description, "content": {media_type: {"schema": dict(BINARY)}}}}


JOB_STREAM_SUMMARY = (
    "Server-Sent Events, each `id: N`, `event: NAME`, `data: JSON`. The stream opens with `state`, "
    "carries `progress` while the job runs and ends with exactly one of `succeeded`, `failed`, "
    "`cancelled` (or `closing`). A comment line every 15 s keeps it open."
)


def event_stream(
    events: dict[str, tuple[str, str]] = JOB_EVENTS, summary: str = JOB_STREAM_SUMMARY
) -> dict[int | str, dict[str, Any]]:
    """The 200 of an event stream (GET /jobs/{id}/events, GET /bench/live): a text/event-stream. Each
    event is described by `itemSchema` (as OpenAPI 3.2 and FastAPI's own SSE routes state it): one variant
    per event name (`events`: name -> (schema of its data, when it comes)), its `data` JSON text with the
    schema of what it carries (`contentSchema`). No `schema`: a generated client reads the stream as
    text."""
    lines = [f"- `{name}`: {when}; data: {schema} (JSON)" for name, (schema, when) in events.items()]
    description = summary + " Events:\n" + "\n".join(lines)
    variants = [
        {
            "type": "object",
            "description": when,
            "required": ["event", "data"],
            "properties": {
                "event": {"const": name},
                "id": {"type": "string", "description": "1, 2, ... in the order sent"},
                "data": {
                    "type": "string",
                    "contentMediaType": "application/json",
                    "contentSchema": _event_data_schema(schema),
                },
            },
        }
        for name, (schema, when) in events.items()
    ]
    return {
        200: {
            "description": description,
            "content": {"text/event-stream": {"itemSchema": {"oneOf": variants}}},
        }
    }


def stream_errors(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """The error answers of an event stream route (errors.responses), stated as JSON: FastAPI would put
    their model under the route's own media type, and an EventSourceResponse route's is text/event-stream
    while its errors stay JSON (ErrorBody)."""
    return {
        status: {
            "description": answer["description"],
            "content": {"application/json": {"schema": {"$ref": REF.format(model="ErrorBody")}}},
        }
        for status, answer in responses(*statuses).items()
    }


def _event_data_schema(names: str) -> dict[str, Any]:
    refs = [{"$ref": REF.format(model=name.strip())} for name in names.split("|")]
    return refs[0] if len(refs) == 1 else {"oneOf": refs}


EXTRA_COMPONENTS: tuple[type[BaseModel], ...] = (
    ProgressEvent,
    ClosingEvent,
    LiveStateEvent,
    LiveSamplesEvent,
    LiveClosingEvent,
)
"""Models only the event stream's description refers to (no route returns them as JSON)."""


def contract_openapi(app: FastAPI) -> dict[str, Any]:
    """The app's OpenAPI schema (made once, then cached as FastAPI does) with the components that the
    routes alone do not bring: the event payloads, and the 405 answer with its Allow header."""
    if app.openapi_schema:
        return app.openapi_schema
    schema = get_openapi(
        title=app.title,
        version=app.version,
        openapi_version=app.openapi_version,
        summary=app.summary,
        description=app.description,
        routes=app.routes,
        tags=app.openapi_tags,
        servers=app.servers,
    )
    components = schema.setdefault("components", {})
    schemas = components.setdefault("schemas", {})
    for model in EXTRA_COMPONENTS:
        definition = model.model_json_schema(ref_template=REF, mode="serialization")
        for name, nested in definition.pop("$defs", {}).items():
            schemas.setdefault(name, nested)
        schemas[model.__name__] = definition
    for definition in schemas.values():  # a vehicle file sent as JSON text (POST /sweeps, /schedules)
        text = definition.get("properties", {}).get("vehicle_toml")
        if text is not None and text.get("type") == "string":
            text["contentMediaType"] = "application/toml"
    schemas.setdefault("ErrorBody", ErrorBody.model_json_schema(ref_template=REF))
    components.setdefault("headers", {})["Allow"] = {
        "description": "the methods the path takes, e.g. GET, POST",
        "schema": {"type": "string"},
    }
    components.setdefault("responses", {})["MethodNotAllowed"] = {
        "description": "405: the path does not take this method; Allow lists those it takes",
        "headers": {"Allow": {"$ref": "#/components/headers/Allow"}},
        "content": {"application/json": {"schema": {"$ref": REF.format(model="ErrorBody")}}},
    }
    app.openapi_schema = schema
    return schema


def install_contract(app: FastAPI) -> None:
    """Serve `contract_openapi` at the app's openapi_url (and /docs)."""
    app.openapi = lambda: contract_openapi(app)  # type: ignore[method-assign]
