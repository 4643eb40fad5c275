"""A vehicle's history as typed models: every test of the vehicle (newest first) with its newest succeeded
identification's curves, lane figures and verdict, and the trend of its damping at reference velocities.

What `GET /api/v1/vehicles/{vehicle_id}/results` answers and `shockbench history VEHICLE_ID --json` prints:
both call `vehicle_history`. The tests come from the store (service.store.history); the trend is
estimator.trend's, computed on the tests that have an identification, oldest first.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from pydantic import BaseModel, Field
from sqlalchemy.exc import SQLAlchemyError

from estimator.trend import REFERENCE_VELOCITIES_M_S, Curve, damping_trend
from service.api.results import AxleInspectionOut, InspectionOut, ModelCurveOut, VerdictOut
from service.store.database import Database
from service.store.history import VehicleTest, vehicle_tests
from service.store.models import SweepStatus

CURVE_KEYS = ("corner", "velocity_m_s", "force_N")


class VehicleTestOut(BaseModel):
    """One test of the vehicle: the sweep, what the operator recorded, and its newest identification."""

    sweep_id: int
    lane: str = Field(description="the lane whose bench ran it")
    date: datetime = Field(description="when the test was requested (UTC)")
    status: SweepStatus = Field(description="the sweep's status: complete, failed, aborted ...")
    vehicle_id: str | None = Field(None, description="the vehicle id as recorded with this test")
    tyre_pressure_bar: float | None = Field(None, description="tyre pressure measured (bar)")
    operator_name: str | None = Field(None, description="who ran the test")
    identification_job_id: int | None = Field(
        None, description="the newest succeeded identification of the sweep; null when none"
    )
    curves: list[ModelCurveOut] = Field(
        default_factory=list, description="the identified damper curves (empty without identification)"
    )
    inspection: InspectionOut | AxleInspectionOut | None = Field(
        None, description="the lane figures (quarter car: the corner's; axle: left, right, imbalance)"
    )
    verdict: VerdictOut | None = Field(None, description="the verdict stored with the identification")
    result_hash: str | None = Field(
        None,
        description="the identification's content hash, chained to its lane's previous result (sha256, "
        "hex; `shockbench verify` checks it)",
    )


class TrendTestOut(BaseModel):
    """One test's damping at the reference velocities, for one corner."""

    sweep_id: int
    date: datetime
    force_N: list[float | None] = Field(
        description="damper force at each reference velocity (N); null outside the curve's range"
    )
    change_percent: list[float | None] = Field(
        description="change since the first test reaching that velocity (%); null where not comparable"
    )


class CornerTrendOut(BaseModel):
    corner: str = Field(description="single (quarter car), or left / right (axle)")
    tests: list[TrendTestOut] = Field(description="the tests with a curve for this corner, oldest first")


class TrendOut(BaseModel):
    """How the damping has changed since the first test (estimator.trend)."""

    reference_velocities_m_s: list[float] = Field(description="damper velocities compared (m/s)")
    corners: list[CornerTrendOut]


class VehicleHistoryOut(BaseModel):
    vehicle_id: str = Field(description="as asked (tests match it without regard to case)")
    tests: list[VehicleTestOut] = Field(description="every test of the vehicle, all lanes, newest first")
    trend: TrendOut
    other_lanes_missing: bool = Field(
        False,
        description="true: this lane keeps a local store and its central database did not answer, so "
        "only this lane's tests are listed",
    )


def _curves(result: dict[str, Any]) -> list[ModelCurveOut]:
    return [
        ModelCurveOut.model_validate({key: curve[key] for key in CURVE_KEYS})
        for curve in result.get("curves") or []
    ]


def vehicle_test_out(test: VehicleTest) -> VehicleTestOut:
    sweep, job = test.sweep, test.identification
    result = (job.result or {}) if job is not None else {}
    inspection = result.get("inspection")
    return VehicleTestOut(
        sweep_id=sweep.id,
        lane=sweep.lane,
        date=sweep.created_at,
        status=sweep.status,
        vehicle_id=sweep.settings.get("vehicle_id"),
        tyre_pressure_bar=sweep.settings.get("tyre_pressure_bar"),
        operator_name=sweep.settings.get("operator_name"),
        identification_job_id=job.id if job is not None else None,
        curves=_curves(result),
        inspection=inspection if isinstance(inspection, dict) else None,  # type: ignore[arg-type]
        verdict=result.get("verdict"),
        result_hash=test.result_hash,
    )


def trend_out(tests: list[VehicleTestOut]) -> TrendOut:
    """The trend over the tests that have curves, oldest first (`tests` as listed: newest first)."""
    dated = [t for t in reversed(tests) if t.curves]
    per_test: list[dict[str, Curve]] = [
        {c.corner: (c.velocity_m_s, c.force_N) for c in t.curves} for t in dated
    ]
    corners = [
        CornerTrendOut(
            corner=trend.corner,
            tests=[
                TrendTestOut(
                    sweep_id=dated[point.test].sweep_id,
                    date=dated[point.test].date,
                    force_N=list(point.force_N),
                    change_percent=list(point.change_percent),
                )
                for point in trend.points
            ],
        )
        for trend in damping_trend(per_test)
    ]
    return TrendOut(reference_velocities_m_s=list(REFERENCE_VELOCITIES_M_S), corners=corners)


def vehicle_history(
    database: Database, vehicle_id: str, central: Database | None = None, lane: str = ""
) -> VehicleHistoryOut:
    """Every test of `vehicle_id` in the database, and the trend. Blocking (database): call it in a
    thread from async code.

    With `central` (a lane that keeps a local store, service.store.sync): `lane`'s tests from the local
    store (their ids are the lane's, current even before they are synced) and every other lane's from the
    central database (its ids), merged newest first; when the central database does not answer, the
    lane's own, saying so (`other_lanes_missing`)."""
    if central is None:
        found = vehicle_tests(database, vehicle_id)
        missing = False
    else:
        found = vehicle_tests(database, vehicle_id, lane=lane)
        try:
            found += vehicle_tests(central, vehicle_id, other_than=lane)
            missing = False
        except SQLAlchemyError:
            missing = True
        found.sort(key=lambda test: test.sweep.created_at, reverse=True)  # stable: the lane's first on a tie
    tests = [vehicle_test_out(t) for t in found]
    return VehicleHistoryOut(
        vehicle_id=vehicle_id, tests=tests, trend=trend_out(tests), other_lanes_missing=missing
    )
