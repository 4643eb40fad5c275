"""A vehicle's history: `GET /vehicles/{vehicle_id}/results`, every test of that vehicle on every lane
(newest first) with its curves, lane figures and verdict, and how its damping has changed since the first
test (service.api.history builds it; the command line's `shockbench history` prints the same)."""

from __future__ import annotations

import asyncio
from typing import Annotated

from fastapi import APIRouter, Path, Request

from service.api.auth import Viewer
from service.api.errors import ApiError, responses
from service.api.history import VehicleHistoryOut, vehicle_history
from service.api.sweep_launch import VEHICLE_ID_MAX_LENGTH, VEHICLE_ID_PATTERN

router = APIRouter(tags=["vehicles"])

VehicleId = Annotated[
    str,
    Path(
        min_length=1,
        max_length=VEHICLE_ID_MAX_LENGTH,
        pattern=VEHICLE_ID_PATTERN,
        description="VIN or registration, as recorded with the tests (case does not matter)",
    ),
]


@router.get(
    "/vehicles/{vehicle_id}/results",
    response_model=VehicleHistoryOut,
    operation_id="get_vehicle_results",
    responses=responses(401, 403, 404, 422),
)
async def vehicle_results(request: Request, vehicle_id: VehicleId, _principal: Viewer) -> VehicleHistoryOut:
    """Every test of the vehicle on every lane, newest first: lane, date, tyre pressure, operator, status,
    and its newest succeeded identification's curves, lane figures and verdict; plus the trend of the
    damping force at reference velocities since the first test. 404 when no test names the vehicle.
    A lane with a central database lists its own tests from its local store and the other lanes' from the
    central database (`other_lanes_missing` when that does not answer)."""
    services = request.app.state.services
    sync = services.sync
    central = sync.central if sync is not None and sync.status().reachable is not False else None
    history = await asyncio.to_thread(
        vehicle_history, services.database, vehicle_id, central, services.settings.lane
    )
    if sync is not None and central is None:  # known away: not waited for
        history.other_lanes_missing = True
    if not history.tests:
        raise ApiError(404, f"no test of vehicle {vehicle_id!r}")
    return history
