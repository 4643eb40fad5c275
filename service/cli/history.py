"""`shockbench history VEHICLE_ID`: every test of a vehicle in the service's database (all lanes, newest
first) with its lane figures and verdict, and how its damping has changed since the first test. `--json`
prints what `GET /api/v1/vehicles/{id}/results` answers (service.api.history builds both).

Stored text (an operator's name, a lane) is printed with its control characters and bidirectional
overrides escaped (service.free_text): the API refuses them now, but an older database may hold some, and
printed raw they would reach the terminal as escape sequences."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from service.cli.db import add_database_arguments, open_database
from service.cli.errors import CliError
from service.free_text import escaped, json_escaped

if TYPE_CHECKING:
    from service.api.history import TrendOut, VehicleHistoryOut, VehicleTestOut


def _number(value: float | None, digits: int = 0, unit: str = "") -> str:
    return "-" if value is None else f"{value:.{digits}f}{unit}"


def _figures(test: VehicleTestOut) -> str:
    """The lane figures in a few characters: EUSAMA and least phase shift (an axle: per side)."""
    from service.api.results import AxleInspectionOut

    inspection = test.inspection
    if inspection is None:
        return "-"
    if isinstance(inspection, AxleInspectionOut):
        sides = (("L", inspection.left), ("R", inspection.right))
        return " ".join(
            f"{name} {_number(s.eusama_percent, 0, '%')} {_number(s.phase_shift_min_deg, 0, '°')}"
            for name, s in sides
        )
    return f"{_number(inspection.eusama_percent, 0, '%')} {_number(inspection.phase_shift_min_deg, 0, '°')}"


def tests_table(history: VehicleHistoryOut) -> list[str]:
    lines = [
        f"vehicle {escaped(history.vehicle_id)}: {len(history.tests)} test(s), all lanes, newest first",
        f"{'sweep':>6}  {'lane':<12} {'date (UTC)':<16} {'status':<9} {'tyre bar':>8}  {'operator':<16} "
        f"{'job':>6}  {'verdict':<7} EUSAMA, least phase",
    ]
    for t in history.tests:
        lines.append(
            f"{t.sweep_id:>6}  {escaped(t.lane) or '-':<12.12} {t.date:%Y-%m-%d %H:%M} {t.status.value:<9} "
            f"{_number(t.tyre_pressure_bar, 2):>8}  {escaped(t.operator_name or '-'):<16.16} "
            f"{t.identification_job_id if t.identification_job_id is not None else '-':>6}  "
            f"{t.verdict.outcome if t.verdict is not None else '-':<7} {_figures(t)}"
        )
    return lines


def trend_table(trend: TrendOut) -> list[str]:
    velocities = trend.reference_velocities_m_s
    lines = ["damper force (N) at reference velocities, change since the first test in brackets"]
    for corner in trend.corners:
        lines.append(f"corner {escaped(corner.corner)}:")
        lines.append(f"{'sweep':>6}  {'date':<10} " + " ".join(f"{f'{v:+.1f} m/s':>16}" for v in velocities))
        for t in corner.tests:
            cells = [
                "-" if f is None else f"{f:.0f} ({_number(c, 1, '%') if c is not None else '-'})"
                for f, c in zip(t.force_N, t.change_percent, strict=True)
            ]
            lines.append(f"{t.sweep_id:>6}  {t.date:%Y-%m-%d} " + " ".join(f"{cell:>16}" for cell in cells))
    if not trend.corners:
        lines.append("(no identified test yet)")
    return lines


def run_history(args: argparse.Namespace) -> int:
    from service.api.history import vehicle_history

    database = open_database(args.database, args.data)
    try:
        history = vehicle_history(database, args.vehicle_id)
    finally:
        database.dispose()
    if not history.tests:
        raise CliError(f"no test of vehicle {args.vehicle_id!r} in database {database.safe_url}")
    if args.json:
        print(json_escaped(history.model_dump_json(indent=2)))
    else:
        print("\n".join([*tests_table(history), "", *trend_table(history.trend)]))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "history",
        help="a vehicle's tests and damping trend, from the database",
        description="Every test of the vehicle in the service's database (all lanes, newest first) with "
        "its lane figures and verdict, and the damper force at reference velocities with its change "
        "since the first test.",
    )
    p.add_argument("vehicle_id", metavar="VEHICLE_ID", help="VIN or registration (case does not matter)")
    add_database_arguments(p)
    p.add_argument("--json", action="store_true", help="print what GET /vehicles/{id}/results answers")
    p.set_defaults(handler=run_history)
