"""The OpenAPI schema states what the server does: short operation ids, the upload bodies as one flat
multipart object with binary files, the bounds of every number a request carries, typed answers (jobs
told apart by `kind`, their options and results, sweep settings, the bench), Location on every 201, the
media type and binary body of every download, the event stream's events and their data, 405's Allow.

The typed result models are checked against real results: reading the stored JSON of an identification
(quarter car and axle) and of a diagnosis into them and back gives the same keys and values, so typing the
API changed nothing a client receives."""

from __future__ import annotations

from collections.abc import Iterator
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from live_server import SimulatedInputs
from pydantic import BaseModel

from estimator.doctor.result import CandidateScore, DiagnosisResult, DiagnosisStep
from estimator.identify import IdentifyOptions, identify
from estimator.sweep import SweepSettings
from estimator.validation import ValidationResult
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.api.results import DiagnoseResult, IdentifyResult, ValidateResult
from service.jobs.context import finite_json
from service.jobs.identify_job import IdentifyJobOptions
from simulators.vehicle_sim import SimulationSettings, default_axle, simulate

OPERATION_IDS = {
    "get_status", "submit_identify", "submit_diagnose", "list_jobs",
    "submit_validate", "get_job", "cancel_job", "job_events",
    "get_job_plot_png", "get_job_plot_svg", "get_job_file", "get_bench", "list_devices", "emergency_stop",
    "start_sweep", "list_sweeps", "get_sweep", "abort_sweep", "get_sweep_recording_csv",
    "submit_sweep_identify", "schedule_test", "list_scheduled_tests", "get_scheduled_test",
    "cancel_scheduled_test", "whoami", "bench_live", "get_sweep_recording_h5",
    "submit_sweep_diagnose", "get_vehicle_results", "get_sweep_report_pdf", "get_sweep_report_html",
}  # fmt: skip
DOWNLOADS = {
    ("/api/v1/jobs/{job_id}/plot.png", "image/png"),
    ("/api/v1/jobs/{job_id}/plot.svg", "image/svg+xml"),
    ("/api/v1/sweeps/{sweep_id}/recording.csv", "text/csv"),
    ("/api/v1/sweeps/{sweep_id}/recording.h5", "application/octet-stream"),
    ("/api/v1/jobs/{job_id}/files/{name}", "text/markdown"),
    ("/api/v1/jobs/{job_id}/files/{name}", "image/png"),
    ("/api/v1/sweeps/{sweep_id}/report.pdf", "application/pdf"),
    ("/api/v1/sweeps/{sweep_id}/report.html", "text/html"),
}


@cache
def document() -> dict[str, Any]:
    keys = KeyRing({"admin-key-0123456789abc": Role.ADMIN})
    return create_app(ServiceSettings(data_dir=Path("unused"), keys=keys)).openapi()


def operations() -> Iterator[tuple[str, str, dict[str, Any]]]:
    for path, methods in document()["paths"].items():
        for method, operation in methods.items():
            yield path, method, operation


def resolve(schema: dict[str, Any]) -> dict[str, Any]:
    while "$ref" in schema:
        schema = document()["components"]["schemas"][schema["$ref"].rsplit("/", 1)[1]]
    return schema


def walk(schema: dict[str, Any], seen: set[str] | None = None) -> Iterator[tuple[str, dict[str, Any]]]:
    """Every (component name or '', subschema) reachable from `schema`, each component once."""
    seen = set() if seen is None else seen
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[1]
        if name not in seen:
            seen.add(name)
            yield name, resolve(schema)
            yield from walk(resolve(schema), seen)
        return
    yield "", schema
    children = [*schema.get("properties", {}).values(), *schema.get("prefixItems", [])]
    for key in ("anyOf", "oneOf", "allOf"):
        children += schema.get(key, [])
    for key in ("items", "additionalProperties"):
        if isinstance(schema.get(key), dict):
            children.append(schema[key])
    for child in children:
        yield from walk(child, seen)


def test_operation_ids_are_short_names() -> None:
    assert {operation["operationId"] for _, _, operation in operations()} == OPERATION_IDS


def test_upload_bodies_are_one_flat_multipart_object_with_binary_files() -> None:
    for path, options_fields, other, media in (
        ("/api/v1/jobs", IdentifyJobOptions.model_fields, "vehicle", "application/toml"),
        ("/api/v1/diagnoses", None, "vehicle", "application/toml"),
        ("/api/v1/validations", None, "model", "application/json"),
    ):
        body = document()["paths"][path]["post"]["requestBody"]["content"]["multipart/form-data"]
        schema = resolve(body["schema"])
        assert "allOf" not in schema and schema["additionalProperties"] is False
        assert schema["required"] == ["recording", other]
        files = schema["properties"]
        assert (
            files["recording"]["format"] == "binary" and files["recording"]["contentMediaType"] == "text/csv"
        )
        assert files[other]["format"] == "binary"
        assert files[other]["contentMediaType"] == media
        assert body["encoding"]["recording"]["contentType"] == "text/csv"
        assert body["encoding"][other]["contentType"] == media
        if options_fields is not None:
            assert set(options_fields) <= set(files)
            points = files["points"]  # nullable in the model, but a form field is sent or left out
            assert points["type"] == "integer" and points["minimum"] >= 3 and points["maximum"] == 60


def test_every_number_a_request_carries_has_its_bounds() -> None:
    unbounded = []
    for path, method, operation in operations():
        inputs = [p["schema"] for p in operation.get("parameters", [])]
        for media in operation.get("requestBody", {}).get("content", {}).values():
            inputs.append(media["schema"])
        for schema in inputs:
            for _, sub in walk(schema):
                if sub.get("type") in ("integer", "number"):
                    low = "minimum" in sub or "exclusiveMinimum" in sub
                    high = "maximum" in sub or "exclusiveMaximum" in sub
                    if not (low and high):
                        unbounded.append((method, path, sub.get("title")))
    assert unbounded == []


def test_answers_are_typed_and_jobs_told_apart_by_kind() -> None:
    schemas = document()["components"]["schemas"]
    untyped = []
    for path, method, operation in operations():
        for status, response in operation["responses"].items():
            media = response.get("content", {}).get("application/json")
            if media is None:
                continue
            for name, sub in walk(media["schema"]):
                if sub.get("type") == "object" and "properties" not in sub:
                    values = sub.get("additionalProperties")
                    if not isinstance(values, dict) or not values:  # dict[str, X] with X typed is fine
                        untyped.append((method, path, status, name))
                if sub.get("type") is None and not any(
                    k in sub for k in ("$ref", "anyOf", "oneOf", "allOf", "enum", "const", "properties")
                ):
                    untyped.append((method, path, status, name or str(sub)))  # fmt: skip
    assert untyped == []
    job = document()["paths"]["/api/v1/jobs/{job_id}"]["get"]["responses"]["200"]["content"]
    union = job["application/json"]["schema"]
    assert union["discriminator"]["propertyName"] == "kind"
    assert set(union["discriminator"]["mapping"]) == {"identify", "diagnose", "validate"}
    options = resolve(schemas["IdentifyJobOut"]["properties"]["options"])
    assert set(options["properties"]) == set(IdentifyJobOptions.model_fields)
    assert schemas["SweepOut"]["properties"]["settings"] == {
        "$ref": "#/components/schemas/SweepSettingsOut",
        "description": "the sweep settings and settle_s as submitted",
    }
    bench = schemas["StatusOut"]["properties"]["bench"]["anyOf"]
    assert {"$ref": "#/components/schemas/BenchOut"} in bench


def test_every_201_declares_location_and_every_download_its_media_type() -> None:
    created = 0
    for path, method, operation in operations():
        if "201" in operation["responses"]:
            location = operation["responses"]["201"]["headers"]["Location"]
            assert location["required"] is True and location["schema"]["type"] == "string", (method, path)
            created += 1
    assert created == 7  # jobs, diagnoses, validations, sweeps, sweep jobs, sweep diagnoses, schedules
    for path, media_type in DOWNLOADS:
        content = document()["paths"][path]["get"]["responses"]["200"]["content"]
        assert content[media_type]["schema"] == {"type": "string", "format": "binary"}


def test_the_live_stream_lists_its_events_and_their_data() -> None:
    response = document()["paths"]["/api/v1/bench/live"]["get"]["responses"]["200"]
    variants = response["content"]["text/event-stream"]["itemSchema"]["oneOf"]
    events = {v["properties"]["event"]["const"]: v["properties"]["data"] for v in variants}
    assert set(events) == {"state", "samples", "closing"}
    schemas = document()["components"]["schemas"]
    assert resolve(events["samples"]["contentSchema"]) is schemas["LiveSamplesEvent"]
    assert set(schemas["LiveSamplesEvent"]["properties"]) >= {"sweep_id", "t_s", "channels"}
    assert resolve(events["state"]["contentSchema"]) is schemas["LiveStateEvent"]


def test_the_event_stream_lists_its_events_and_their_data() -> None:
    response = document()["paths"]["/api/v1/jobs/{job_id}/events"]["get"]["responses"]["200"]
    variants = response["content"]["text/event-stream"]["itemSchema"]["oneOf"]
    events = {v["properties"]["event"]["const"]: v["properties"]["data"] for v in variants}
    assert set(events) == {"state", "progress", "succeeded", "failed", "cancelled", "closing"}
    for name, data in events.items():
        assert f"`{name}`" in response["description"]
        assert data["contentMediaType"] == "application/json"
    schemas = document()["components"]["schemas"]
    assert resolve(events["progress"]["contentSchema"]) is schemas["ProgressEvent"]
    assert set(schemas["ProgressEvent"]["properties"]) >= {"job_id", "stage", "generation", "eta_s"}
    assert resolve(events["closing"]["contentSchema"]) is schemas["ClosingEvent"]
    final = events["succeeded"]["contentSchema"]["oneOf"]
    assert {resolve(ref)["title"] for ref in final} == {"IdentifyJobOut", "DiagnoseJobOut", "ValidateJobOut"}


def test_a_405_states_its_allow_header() -> None:
    components = document()["components"]
    answer = components["responses"]["MethodNotAllowed"]
    assert answer["headers"]["Allow"] == {"$ref": "#/components/headers/Allow"}
    assert components["headers"]["Allow"]["schema"] == {"type": "string"}


def same_json(raw: dict[str, Any], typed: BaseModel) -> list[str]:
    """Keys whose value differs, keys the typed model dropped, added (an optional key the model fills
    with null or [] where the stored JSON leaves it out is fine) or passed through without typing."""
    dumped = without_filled_in(typed.model_dump(mode="json"), raw)
    problems = [key for key in raw if key not in dumped or dumped[key] != raw[key]]
    problems += [key for key in dumped if key not in raw]
    return problems + untyped_keys(typed)


def without_filled_in(dumped: Any, raw: Any) -> Any:
    """`dumped` without the optional keys (null or []) that `raw` leaves out, at every level."""
    if isinstance(dumped, dict) and isinstance(raw, dict):
        return {
            key: without_filled_in(value, raw.get(key))
            for key, value in dumped.items()
            if key in raw or value not in (None, [])
        }
    if isinstance(dumped, list) and isinstance(raw, list) and len(dumped) == len(raw):
        return [without_filled_in(d, r) for d, r in zip(dumped, raw, strict=True)]
    return dumped


def untyped_keys(value: Any) -> list[str]:
    """Keys of a result that its model (or a nested one) only passes through."""
    if isinstance(value, BaseModel):
        found = list(value.model_extra or {})
        for name in type(value).model_fields:
            found += untyped_keys(getattr(value, name))
        return found
    if isinstance(value, list | tuple):
        return [key for item in value for key in untyped_keys(item)]
    if isinstance(value, dict):
        return [key for item in value.values() for key in untyped_keys(item)]
    return []


@pytest.mark.parametrize("vehicle_kind", ["quarter-car", "axle"])
def test_identify_results_read_into_the_typed_model_unchanged(
    inputs: SimulatedInputs, vehicle_kind: str
) -> None:
    from daq.formats.recording_csv import read_recording_csv
    from daq.formats.vehicle_file import read_vehicle

    if vehicle_kind == "quarter-car":
        recording, vehicle = read_recording_csv(inputs.recording), read_vehicle(inputs.vehicle)
    else:
        axle = default_axle()
        settings = SimulationSettings(sweep=SweepSettings(duration_s=4.0), seed=2, substeps=2)
        recording, vehicle = simulate(axle, settings).recording, axle.known
    raw = finite_json(identify(recording, vehicle, IdentifyOptions()).to_json())
    assert same_json(raw, IdentifyResult.model_validate(raw)) == []
    assert ("left" in raw["inspection"]) == (vehicle_kind == "axle")


def test_diagnose_results_read_into_the_typed_model_unchanged() -> None:
    step = DiagnosisStep(
        effect="sensor_offset",
        parameters={"channel": "x_r", "offset_m": 0.0005},
        gap_before_m=2e-4,
        gap_after_m=float("inf"),  # a model that diverged: stored as null
        evidence="the plate reads high",
        p_value=1e-9,
        located_after=None,  # type: ignore[arg-type]  # not part of the JSON
        predicted_after={},
    )
    score = CandidateScore(
        effect="sensor_offset(x_r)",
        objective_ratio=0.3,
        gap_m=1e-4,
        gap_ratio=0.5,
        equation_statistic=120.0,
        simulation_statistic=float("inf"),  # stored as null
        unknowns=1,
        equation_p=1e-9,
        simulation_p=0.0,
        p_value=1e-9,
        parameters={"channel": "x_r", "offset_m": 0.0005},
        verdict="named",
    )
    result = DiagnosisResult(
        starting_effects=["tyre_viscoelastic"],
        final_effects=["tyre_viscoelastic", "sensor_offset"],
        gap_before_m=2e-4,
        gap_after_m=float("nan"),
        steps=[step],
        rounds=[[score], []],
        unexplained=True,
        conclusion="the model diverged",
        expected_gap_m=3e-5,
        residual_ratio=1.1,
        p_value=0.001,
        alpha=0.05,
        where="the model diverges when driven by the measured plate",
        noise_floor_m=5e-6,
        located_before=None,  # type: ignore[arg-type]  # not part of the JSON
        measured={},
        predicted_before={},
        time_s=np.zeros(0),
        sweep_frequency_Hz=np.zeros(0),
    )
    raw = finite_json(result.to_json())
    typed = DiagnoseResult.model_validate(raw)
    assert same_json(raw, typed) == []
    assert typed.gap_after_m is None and typed.steps[0].gap_after_m is None
    assert typed.candidates[0][0].simulation_statistic is None and typed.p_value == 0.001
    # the final model (estimator.doctor.result.model_json's form), effects included
    raw["model"] = {
        "curves": [{"corner": "single", "velocity_m_s": [-1.0, 1.0], "force_N": [-900.0, 1500.0]}],
        "masses_kg": {"sprung": 420.0, "unsprung": 45.0},
        "stiffness_N_per_m": {"spring": 26000.0, "tyre": 210000.0, "identified": []},
        "tyre_model": "maxwell",
        "tyre_damping_Ns_per_m": 1100.0,
        "tyre_viscoelastic_coefficient": 0.97,
        "tyre_relaxation_time_s": 0.0323,
        "effects": {
            "coulomb_friction_N": 95.0,
            "stribeck_peak_N": 40.0,
            "stribeck_velocity_m_s": 0.005,
            "spring_hinges": [{"knot_m": -0.03, "rate_N_per_m": 9000.0}],
            "sensor_offset_m": {"x_r": 0.0005},
            "sensor_lag_s": {"x_s": 0.004},
            "sensor_gain_error": {"x_t": 0.03},
        },
    }
    assert same_json(raw, DiagnoseResult.model_validate(raw)) == []


def test_validate_results_read_into_the_typed_model_unchanged() -> None:
    for result in (
        ValidationResult(4e-5, 2.7e-3),
        ValidationResult(float("inf"), 2.7e-3),
        ValidationResult(4e-5, 2.7e-3, ("coulomb_friction_N", "channel_delay_s")),
    ):
        raw = finite_json(result.to_json())
        typed = ValidateResult.model_validate(raw)
        assert same_json(raw, typed) == []
        assert (typed.gap_m is None) == (typed.gap_ratio is None) == typed.gap_diverged
