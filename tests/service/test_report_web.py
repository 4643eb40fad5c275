"""The operator page's "Report" button in a real headless Chromium, against the service in-process with
the simulated bench: a viewer opens a tested vehicle's result from the history, presses "Report" and the
PDF opens in a new tab (fetched with the key, shown from an object URL); "Report HTML" saves the page. No
browser console error.

(The test browser runs without extensions, so its tab holds the PDF without Chromium's viewer drawing it;
with the viewer, under the page's own Content-Security-Policy, the same tab shows the report's pages.)"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from headless_chromium import chromium_driver, console_errors, find_chromium
from live_server import LiveServer, wait_for_status
from test_web_page import Page

from daq.formats.vehicle_file import format_vehicle
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from simulators.vehicle_sim import default_quarter_car

OPERATOR = "operator-key-for-report-web"
VIEWER = "viewer-key-for-report-web-1"
VEHICLE = "REPORT-WEB-1"


@pytest.fixture(scope="module")
def tested(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[LiveServer, int]]:
    """The service with one identified sweep of VEHICLE; (server, sweep id)."""
    keys = KeyRing({OPERATOR: Role.OPERATOR, VIEWER: Role.VIEWER})
    settings = ServiceSettings(data_dir=tmp_path_factory.mktemp("report-web"), keys=keys, simulated=True)
    body = {"duration_s": 3, "settle_s": 0.5, "vehicle_toml": format_vehicle(default_quarter_car().known)}
    with LiveServer(create_app(settings)) as server:
        with server.client(OPERATOR) as client:
            started = client.post("/api/v1/sweeps", json={**body, "vehicle_id": VEHICLE})
            assert started.status_code == 201, started.text
            sweep = wait_for_status(client, started.headers["location"], "complete", "failed", "aborted")
            job = client.post(sweep["links"]["jobs"], json={})
            assert job.status_code == 201, job.text
            done = wait_for_status(client, job.headers["location"], "succeeded", "failed", timeout_s=300)
            assert done["status"] == "succeeded", done["error"]
        yield server, sweep["id"]


def test_the_report_button_opens_the_pdf_in_a_new_tab(tested: tuple[LiveServer, int], tmp_path: Path) -> None:
    from selenium.common.exceptions import StaleElementReferenceException
    from selenium.webdriver.common.keys import Keys

    server, sweep_id = tested
    downloads = tmp_path / "downloads"
    with chromium_driver(find_chromium(), downloads) as driver:
        page = Page(driver, server.url + "/", downloads)
        page.sign_in(VIEWER)

        def open_from_history() -> bool:
            """Enter on the test's row in the history (False while it is not there, or redrawn)."""
            try:
                rows = [row for row in page.all_testid("history-row") if VEHICLE in row.text]
                if rows:
                    rows[0].send_keys(Keys.ENTER)
                return bool(rows)
            except StaleElementReferenceException:
                return False

        page.wait(open_from_history, "the test opened from the history")
        page.wait(lambda: page.testid("result-curve").find_elements("css selector", "svg"), "its result")

        report = page.testid("open-report")
        assert report.is_enabled() and report.text == "Report"  # a viewer may read the report
        page_tab = driver.current_window_handle
        report.click()
        page.wait(lambda: len(driver.window_handles) == 2, "the report's tab")
        page.wait(
            lambda: page.by_id("download-status").text == "report opened in a new tab", "the tab filled"
        )
        (tab,) = [handle for handle in driver.window_handles if handle != page_tab]
        driver.switch_to.window(tab)
        page.wait(lambda: driver.current_url.startswith(f"blob:{server.url}/"), "the report's object URL")
        assert driver.execute_script("return document.contentType") == "application/pdf"
        driver.switch_to.window(page_tab)

        page.by_id("dl-report-html").click()
        saved = downloads / f"sweep-{sweep_id}-report.html"
        page.wait(saved.is_file, "the HTML report saved")
        assert VEHICLE in saved.read_text(encoding="utf-8")
        assert console_errors(driver) == []
