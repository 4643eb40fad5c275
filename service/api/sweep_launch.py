"""Starting a sweep on the bench, shared by `POST /sweeps` and the inspection-line scheduler: the request
(`SweepIn`), its checks before anything moves (InputError naming the field), and the launch (stored, then
run in the bench's thread, its end stored by that thread).

A sweep's recording is `sweeps/<id>.h5` in the data directory, its vehicle file `sweeps/<id>.vehicle.toml`
beside it.

Bench logic, not HTTP: it raises domain errors (InputError, BenchBusyError, the envelope's and the sweep's
own UserErrors); service.api.errors maps them to statuses.
"""

from __future__ import annotations

import logging
import secrets
from collections.abc import Callable
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, create_model

from daq.sweep.model import StopKind, SweepError, SweepOutcome, SweepRequest
from daq.sweep.plan import SweepPlan
from daq.sweep.timing import SweepTiming
from estimator.sweep import SETTING_NAMES, SweepSettings
from service.api.intake import parse_vehicle_field
from service.api.schemas import FreeText
from service.bench_control import BenchBusyError, BenchController, SweepDone
from service.declarations import pydantic_field, pydantic_fields
from service.jobs.bounds import check_vehicle_bounds
from service.jobs.context import InputError
from service.store.models import SweepStatus
from service.store.sweeps import SweepRecord, SweepStore

log = logging.getLogger("shockbench.api")

SETTINGS_FIELDS = SETTING_NAMES
"""The plate's settings (estimator.sweep.SweepSettings), each declared there once with its bounds."""

PlateSettingsIn: type[BaseModel] = create_model(
    "PlateSettingsIn",
    __config__=ConfigDict(extra="forbid"),
    **pydantic_fields(SweepSettings, SETTINGS_FIELDS),
)
"""The plate's settings as a request takes them: SweepSettings' declarations (estimator.sweep)."""


class SweepSettingsIn(PlateSettingsIn):  # type: ignore[valid-type,misc]
    """The plate's settings and the settling time (as a sweep and a scheduled test take them)."""

    settle_s: float = pydantic_field(SweepTiming, "settle_s")

    def sweep_settings(self) -> SweepSettings:
        try:
            return SweepSettings(**{name: getattr(self, name) for name in SETTINGS_FIELDS})
        except ValueError as exc:
            field = next((name for name in SETTINGS_FIELDS if name in str(exc)), None)
            raise InputError(field, str(exc)) from None

    def as_submitted(self) -> dict[str, object]:
        """The settings as stored with the sweep (JSON)."""
        return self.model_dump(mode="json", include={*SETTINGS_FIELDS, "settle_s"})


VEHICLE_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9 .\-]*$"
"""A vehicle id (VIN or registration): letters, digits, spaces, dots and dashes, 1-40 characters."""
VEHICLE_ID_MAX_LENGTH = 40

TEST_FIELDS = ("vehicle_id", "tyre_pressure_bar", "operator_name")
"""What the operator records about the test, stored with the sweep's settings (not used by the sweep)."""


class SweepIn(SweepSettingsIn):
    """A sweep to run: the plate's settings, the settling time, the vehicle on the bench, and what the
    operator records about the test (vehicle id, tyre pressure, their name)."""

    vehicle_toml: str = Field(
        min_length=1, max_length=1_000_000, description="the vehicle file (TOML, one [vehicle] table)"
    )
    vehicle_id: str | None = Field(
        None,
        min_length=1,
        max_length=VEHICLE_ID_MAX_LENGTH,
        pattern=VEHICLE_ID_PATTERN,
        description="the vehicle's VIN or registration: letters, digits, spaces, dots and dashes",
    )
    tyre_pressure_bar: float | None = Field(None, ge=0.5, le=10, description="tyre pressure measured (bar)")
    operator_name: FreeText | None = Field(
        None, min_length=1, max_length=80, description="who ran the test (free text, for the record)"
    )

    def as_submitted(self) -> dict[str, object]:
        """The settings and the test's record as stored with the sweep (JSON); unset test fields left out."""
        test = self.model_dump(mode="json", include=set(TEST_FIELDS), exclude_none=True)
        return super().as_submitted() | test


def plan_request(bench: BenchController, body: SweepIn, operator: str | None = None) -> SweepPlan:
    """The request as one checked plan (a UserError naming the field): the settings, the vehicle file
    (parsed here, once; its bounds), then daq.sweep.plan against the bench (its model, the safety
    envelope, the bandwidth). The driver checks the envelope again as the safety net; nothing else does."""
    settings = body.sweep_settings()
    vehicle = parse_vehicle_field(body.vehicle_toml, "vehicle_toml", "vehicle_toml")
    try:
        check_vehicle_bounds(vehicle.parameters, field="vehicle_toml")
    except InputError as exc:
        raise InputError(exc.field, f"vehicle_toml: {exc}") from None
    request = SweepRequest(settings, vehicle=vehicle, operator=operator or "", settle_s=body.settle_s)
    return bench.plan(request, vehicle_field="vehicle_toml")


def outcome_status(outcome: SweepOutcome) -> SweepStatus:
    if outcome.complete:
        return SweepStatus.COMPLETE
    if outcome.stop is StopKind.CONTROLLED and outcome.reason.startswith("aborted"):
        return SweepStatus.ABORTED
    return SweepStatus.FAILED


def sweep_done(store: SweepStore, on_end: Callable[[], None] | None = None) -> SweepDone:
    """The bench's `done` callback: runs in the sweep's thread, stores how the sweep ended, then calls
    `on_end` (the scheduler's wake-up)."""

    def done(sweep_id: str, outcome: SweepOutcome | None, error: str) -> None:
        try:
            if outcome is None:
                reason = error or "the sweep did not begin"
                store.finish(int(sweep_id), SweepStatus.FAILED, complete=False, reason=reason)
            else:
                store.finish(
                    int(sweep_id),
                    outcome_status(outcome),
                    complete=outcome.complete,
                    reason=outcome.reason or None,
                )
            log.info("sweep %s ended: %s", sweep_id, outcome.summary() if outcome else error)
        except Exception:  # the sweep thread must not die silently; the row stays for the next restart
            log.exception("could not store the end of sweep %s", sweep_id)
        if on_end is not None:
            on_end()

    return done


def launch_sweep(
    bench: BenchController,
    store: SweepStore,
    data_dir: Path,
    body: SweepIn,
    operator: str | None,
    on_end: Callable[[], None] | None = None,
) -> SweepRecord:
    """Check the request (a UserError naming the field; BenchBusyError when busy), store it, start it.
    Blocking: call it in a thread. `operator` is the key id recorded with the sweep."""
    plan = plan_request(bench, body, operator)
    if bench.busy:
        raise BenchBusyError(f"bench {bench.config.name!r} is running a sweep")

    folder = data_dir / "sweeps"
    folder.mkdir(parents=True, exist_ok=True)

    def place(sweep_id: int) -> tuple[Path, Path]:
        recording = folder / f"{sweep_id}.h5"
        if recording.exists():  # a new database over an old data directory: never overwrite
            recording = folder / f"{sweep_id}-{secrets.token_hex(4)}.h5"
        vehicle_file = recording.with_suffix(".vehicle.toml")
        vehicle_file.write_text(body.vehicle_toml, encoding="utf-8")
        return recording, vehicle_file

    record = store.create(bench.config.name, body.as_submitted(), place, operator=operator)
    assert record.recording_path is not None and record.vehicle_file is not None
    plan = plan.vehicle_stored_as(record.vehicle_file)
    try:
        bench.start_sweep(str(record.id), plan, Path(record.recording_path), sweep_done(store, on_end))
    except (BenchBusyError, SweepError) as exc:  # the caller sees the error (409, 422); the row its end
        store.finish(record.id, SweepStatus.FAILED, complete=False, reason=str(exc))
        raise
    store.mark_running(record.id)
    return store.get(record.id) or record
