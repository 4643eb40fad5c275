"""The test's report through the API, on the real server with the simulated bench: a sweep with what the
operator recorded, its identification and the model doctor's diagnosis by the worker, then
`GET /sweeps/{id}/report.pdf` and `.html`: the sheet names the vehicle, operator, lane, bench, date and tyre
pressure, the verdict with its thresholds, the lane figures, the doctor's conclusion and the result's link
in the lane's hash chain, as stored. 404 before an identification succeeded and for an unknown sweep; a
viewer may read it, an anonymous caller not; the sweep's links name both reports.

The first page of the PDF is saved as docs/report-example.png, to be looked at."""

from __future__ import annotations

import base64
import hashlib
import io
import re
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from live_server import ROOT, LiveServer, wait_for_status
from pypdf import PdfReader
from sqlalchemy import select

from daq.formats.vehicle_file import format_vehicle
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from service.store.database import Database
from service.store.models import ResultChainRow
from simulators.vehicle_sim import default_quarter_car

OPERATOR = "operator-key-for-reports-1"
VIEWER = "viewer-key-for-reports-001"
LANE = "lane-7"
TEST = {"vehicle_id": "WVW ZZZ 1JZ 3W386752", "tyre_pressure_bar": 2.2, "operator_name": "A. Tester"}
SWEEP = {"duration_s": 4, "settle_s": 0.5, "vehicle_toml": format_vehicle(default_quarter_car().known)}
EXAMPLE = ROOT / "docs" / "report-example.png"


@pytest.fixture(scope="module")
def settings(tmp_path_factory: pytest.TempPathFactory) -> ServiceSettings:
    keys = KeyRing({OPERATOR: Role.OPERATOR, VIEWER: Role.VIEWER})
    return ServiceSettings(data_dir=tmp_path_factory.mktemp("reports"), keys=keys, simulated=True, lane=LANE)


@pytest.fixture(scope="module")
def server(settings: ServiceSettings) -> Iterator[LiveServer]:
    with LiveServer(create_app(settings)) as s:
        yield s


def finished_job(client: httpx.Client, response: httpx.Response) -> dict[str, Any]:
    assert response.status_code == 201, response.text
    done = wait_for_status(client, response.headers["location"], "succeeded", "failed", timeout_s=300)
    assert done["status"] == "succeeded", done["error"]
    return done


@pytest.fixture(scope="module")
def tested(server: LiveServer) -> dict[str, Any]:
    """A sweep of the vehicle, 404 for its report until identified, then identified and diagnosed."""
    with server.client(OPERATOR) as client:
        started = client.post("/api/v1/sweeps", json={**SWEEP, **TEST})
        assert started.status_code == 201, started.text
        sweep = wait_for_status(client, started.headers["location"], "complete", "failed", "aborted")
        assert sweep["status"] == "complete", sweep["reason"]
        early = client.get(sweep["links"]["report_pdf"])
        identification = finished_job(client, client.post(sweep["links"]["jobs"], json={}))
        diagnosis = finished_job(
            client, client.post(f"{sweep['links']['self']}/diagnoses", json={"max_steps": 1})
        )
    return {"sweep": sweep, "early": early, "identification": identification, "diagnosis": diagnosis}


def flat(text: str) -> str:
    return " ".join(text.split())


def test_the_sweep_links_its_reports_and_they_wait_for_an_identification(
    server: LiveServer, tested: dict[str, Any]
) -> None:
    sweep = tested["sweep"]
    base = f"/api/v1/sweeps/{sweep['id']}"
    assert sweep["links"]["report_pdf"] == f"{base}/report.pdf"
    assert sweep["links"]["report_html"] == f"{base}/report.html"
    early = tested["early"]
    assert early.status_code == 404 and early.json()["error"]["code"] == "not_found"
    assert early.json()["error"]["message"].startswith(
        f"sweep {sweep['id']} has no identification result yet"
    )
    with server.client(VIEWER) as viewer:
        missing = viewer.get("/api/v1/sweeps/999999/report.pdf")
        assert missing.status_code == 404 and missing.json()["error"]["message"] == "no sweep 999999"
        assert viewer.get(f"{base}/report.html").status_code == 200  # a viewer reads it as it reads the sweep
    anonymous = httpx.get(f"{server.url}{base}/report.pdf")
    assert anonymous.status_code == 401


def test_the_pdf_report_states_the_stored_test(
    server: LiveServer, settings: ServiceSettings, tested: dict[str, Any]
) -> None:
    sweep, identification = tested["sweep"], tested["identification"]
    with server.client(VIEWER) as viewer:
        answer = viewer.get(sweep["links"]["report_pdf"])
    assert answer.status_code == 200, answer.text
    assert answer.headers["content-type"] == "application/pdf" and answer.content.startswith(b"%PDF-")
    text = flat("\n".join(page.extract_text() for page in PdfReader(io.BytesIO(answer.content)).pages))

    for label, value in (
        ("vehicle id", TEST["vehicle_id"]),
        ("operator", TEST["operator_name"]),
        ("lane", LANE),
        ("bench", sweep["bench"]),
        ("tyre pressure", "2.2 bar"),
        ("identification job", str(identification["id"])),
    ):
        assert f"{label} {value}" in text, (label, text[:600])
    started = sweep["started_at"][:16].replace("T", " ")  # 2026-11-25T18:04 -> 2026-11-25 18:04
    assert re.search(rf"date {re.escape(started)}:\d\d UTC", text), text[:600]

    result = identification["result"]
    verdict = result["verdict"]
    assert f"Verdict: {verdict['outcome'].upper()}" in text
    assert f"thresholds {verdict['thresholds_version']}" in text
    figures = result["inspection"]
    assert f"wheel {figures['eusama_percent']:.1f} % {figures['phase_shift_min_deg']:.1f}° " in text
    assert f" {figures['damping_ratio']:.2f} " in text
    assert f"sprung mass {result['masses_kg']['sprung']:.1f} kg" in text
    low, high = result["masses_kg_interval"]["sprung"]
    assert f"{low:.1f} – {high:.1f} kg" in text
    assert flat(tested["diagnosis"]["result"]["conclusion"]) in text

    database = Database(settings.resolved_database_url)
    try:
        with database.sessions() as session:
            link = session.scalars(
                select(ResultChainRow).where(ResultChainRow.job_id == identification["id"])
            ).one()
    finally:
        database.dispose()
    assert f"lane {LANE} sequence {link.sequence} job {identification['id']} result hash {link.hash}" in text
    assert "Transmissibility" in text and "The sweep over time" in text  # the recording is still stored


def test_the_html_report_is_self_contained(server: LiveServer, tested: dict[str, Any]) -> None:
    with server.client(VIEWER) as viewer:
        answer = viewer.get(tested["sweep"]["links"]["report_html"])
    assert answer.status_code == 200, answer.text
    assert answer.headers["content-type"] == "text/html; charset=utf-8"
    policy = answer.headers["content-security-policy"]
    assert "default-src 'none'" in policy and "img-src data:" in policy and "script" not in policy
    page = answer.text
    assert TEST["vehicle_id"] in page and TEST["operator_name"] in page and LANE in page
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", page, flags=re.IGNORECASE)
    assert "<script" not in page.lower() and "<link" not in page.lower()
    assert page.count('<img src="data:image/svg+xml;base64,') == 3  # curve, sweep, transmissibility
    (style,) = re.findall(r"<style>(.*?)</style>", page, flags=re.DOTALL)  # the one style the policy allows
    digest = base64.b64encode(hashlib.sha256(style.encode()).digest()).decode()
    assert f"style-src 'sha256-{digest}'" in policy


def test_the_first_page_is_saved_to_be_looked_at(settings: ServiceSettings, tested: dict[str, Any]) -> None:
    """docs/report-example.png: the first page of the PDF report of the test above, as the route makes it."""
    from service.api.app import service_version
    from service.report import build_report
    from service.report.pdf import page_figures
    from service.report.plots import rendering
    from service.report.source import stored_input, stored_test

    database = Database(settings.resolved_database_url)
    try:
        stored = stored_test(database, tested["sweep"]["id"])
    finally:
        database.dispose()
    assert stored is not None and stored.identification is not None and stored.diagnosis is not None
    with rendering():
        first = page_figures(build_report(stored_input(stored, service_version())))[0]
        EXAMPLE.parent.mkdir(exist_ok=True)
        first.savefig(EXAMPLE, format="png", dpi=100, facecolor="white")
    assert EXAMPLE.read_bytes().startswith(b"\x89PNG")
