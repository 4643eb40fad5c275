"""The operator page (issue 17) in a real headless Chromium against a real `shockbench serve --simulated`
on loopback, keys for a viewer, an operator and an admin: sign in, start a sweep, watch its progress and
the live chart, read the curve, the lane figures and the verdict, open it again from the history, stop
the plate with the emergency-stop button, and what a viewer may not do. Every test fails on a browser
console error. The result view's screenshot is docs/operator-page.png (the README shows it).

The simulated bench runs in simulated time, so a sweep of a few seconds keeps these tests short."""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import headless_chromium
import pytest
from headless_chromium import Chromium, chromium_driver, console_errors, find_chromium, set_viewport
from live_server import ROOT, SERVE_STARTUP_TIMEOUT_S, ServeProcess, serve_process, wait_until

VIEWER = "viewer-key-0123456789"
OPERATOR = "operator-key-0123456789"
ADMIN = "admin-key-0123456789abc"
SCREENSHOT = ROOT / "docs" / "operator-page.png"
VEHICLE_TOML = '[vehicle]\nmodel = "quarter-car"\nmass_kg = 420.0\n'
"""Mass only: what the bench operator knows; the simulated car on the plate carries 420 kg too."""
PLATE_RGB = (124, 196, 255)
"""The live chart's plate colour (service/web/live.js)."""
WAIT_S = 120.0
"""Longest wait for the page: a sweep and its identification on a loaded 2-core machine."""


@pytest.fixture(scope="module")
def chromium() -> Chromium:
    return find_chromium()


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory, chromium: Chromium) -> Iterator[ServeProcess]:
    folder = tmp_path_factory.mktemp("web")
    keys = folder / "keys.toml"
    keys.write_text(f'viewer = ["{VIEWER}"]\noperator = ["{OPERATOR}"]\nadmin = ["{ADMIN}"]\n')
    service = serve_process(
        folder, "serve", "--simulated", "--data", str(folder / "data"), "--keys", str(keys)
    )
    try:
        wait_until(lambda: service.answers(OPERATOR), SERVE_STARTUP_TIMEOUT_S, "service ready", 0.2)
        yield service
    finally:
        service.stop()


class Page:
    """The operator page in a browser: find by data-testid, wait for a condition."""

    def __init__(self, driver: Any, url: str, downloads: Path) -> None:
        self.driver = driver
        self.url = url
        self.downloads = downloads
        self.expected_errors: tuple[str, ...] = ()
        driver.get(url)

    def testid(self, name: str) -> Any:
        from selenium.webdriver.common.by import By

        return self.driver.find_element(By.CSS_SELECTOR, f'[data-testid="{name}"]')

    def all_testid(self, name: str) -> list[Any]:
        from selenium.webdriver.common.by import By

        return self.driver.find_elements(By.CSS_SELECTOR, f'[data-testid="{name}"]')

    def by_id(self, element_id: str) -> Any:
        from selenium.webdriver.common.by import By

        return self.driver.find_element(By.ID, element_id)

    def wait(self, condition: Callable[[], Any], what: str, timeout_s: float = WAIT_S) -> Any:
        from selenium.webdriver.support.ui import WebDriverWait

        return WebDriverWait(self.driver, timeout_s, poll_frequency=0.1).until(
            lambda _driver: condition(), message=what
        )

    def sign_in(self, key: str) -> None:
        """Type the key and press Enter (the keyboard alone signs in)."""
        from selenium.webdriver.common.keys import Keys

        self.testid("login-key").send_keys(key, Keys.ENTER)
        self.wait(lambda: self.testid("bench-status").text.startswith("Bench"), "signed in")

    def fill(self, element_id: str, value: str) -> None:
        field = self.by_id(element_id)
        field.clear()
        field.send_keys(value)

    def start_sweep(self, duration_s: float, vehicle_id: str) -> None:
        """Fill the form (the vehicle pasted as TOML) and press start."""
        self.by_id("vehicle-source-toml").click()
        assert not self.by_id("mass-kg").is_displayed()  # the mass-only form gives way to the file
        self.testid("vehicle-toml").clear()
        self.testid("vehicle-toml").send_keys(VEHICLE_TOML)
        self.fill("vehicle-id", vehicle_id)
        self.fill("tyre-pressure", "2.2")
        self.fill("operator-name", "A. Tester")
        self.fill("duration-s", f"{duration_s:g}")
        self.fill("settle-s", "0.5")
        self.testid("start-sweep").click()

    def phase(self) -> str:
        return str(self.by_id("progress-phase").text)


@pytest.fixture
def page(service: ServeProcess, chromium: Chromium, tmp_path: Path) -> Iterator[Page]:
    with chromium_driver(chromium, tmp_path / "downloads") as driver:
        page = Page(driver, service.url + "/", tmp_path / "downloads")
        yield page
        errors = console_errors(driver, page.expected_errors)
        assert not errors, f"browser console errors: {errors}"


def plate_pixels(page: Page) -> int:
    """How many pixels of the live chart are drawn in the plate's colour."""
    script = """
        const [r, g, b] = arguments[0];
        const canvas = arguments[1];
        const data = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
        let n = 0;
        for (let i = 0; i < data.length; i += 4) {
          const near = (k, v) => Math.abs(data[i + k] - v) < 40;
          if (near(0, r) && near(1, g) && near(2, b)) n++;
        }
        return n;"""
    return int(page.driver.execute_script(script, list(PLATE_RGB), page.testid("live-chart")))


def test_an_operator_runs_a_test_and_reads_curve_figures_and_verdict(
    page: Page, service: ServeProcess
) -> None:
    page.sign_in(OPERATOR)
    assert OPERATOR not in page.driver.current_url
    assert page.driver.execute_script("return sessionStorage.getItem('shockbench.key')") == OPERATOR

    page.start_sweep(duration_s=3, vehicle_id="WVW ZZZ 1JZ 3W386752")
    progress = page.testid("sweep-progress")
    page.wait(
        lambda: "sweeping" in (progress.get_attribute("data-phases") or "").split(), "the progress: sweeping"
    )
    shown = progress.text
    assert re.search(r"\d+\.\d s of \d+\.\d s", shown) and re.search(r"\d+\.\d\d Hz", shown), shown
    chart = page.testid("live-chart")
    page.wait(lambda: int(chart.get_attribute("data-points") or 0) > 0, "samples in the live chart")
    page.wait(lambda: int(chart.get_attribute("data-frames") or 0) >= 3, "the live chart redrawn")
    page.wait(lambda: plate_pixels(page) > 100, "the plate's trace drawn")
    with service.client(VIEWER) as client:
        lane = client.get("/api/v1/status").json()["lane"]
    assert lane and page.testid("bench-lane").text == lane  # the lane this service runs
    assert page.testid("bench-sync").text.startswith("none")  # no central database: results stay here
    states = [e.text for e in page.driver.find_elements("css selector", "[data-testid=device-state]")]
    assert any(state.startswith(("reading: ", "idle; last sweep: ")) for state in states), states

    page.wait(lambda: page.testid("result-curve").find_elements("css selector", "svg"), "the curve", WAIT_S)
    curve = page.testid("result-curve")
    assert len(curve.find_elements("css selector", "svg polygon.band")) == 1
    assert len(curve.find_elements("css selector", "svg polyline.fit")) == 1
    assert len(curve.find_elements("css selector", "svg circle")) > 10
    assert re.fullmatch(r"\d+(\.\d+)? %", page.testid("result-eusama").text)
    verdict = page.testid("result-verdict")
    assert verdict.get_attribute("data-outcome") in ("pass", "fail", "check"), verdict.text
    assert "estimate" in page.by_id("result").text.lower()
    assert "tyre pressure 2.2 bar; operator A. Tester" in page.by_id("result-record").text
    SCREENSHOT.parent.mkdir(exist_ok=True)
    assert page.driver.save_screenshot(str(SCREENSHOT)), SCREENSHOT

    with service.client(VIEWER) as client:
        stored = client.get("/api/v1/sweeps", params={"vehicle_id": "WVW ZZZ 1JZ 3W386752"}).json()
    (sweep,) = stored["sweeps"]
    assert sweep["test"] == {
        "vehicle_id": "WVW ZZZ 1JZ 3W386752",
        "tyre_pressure_bar": 2.2,
        "operator_name": "A. Tester",
    }

    page.by_id("dl-json").click()
    saved = page.downloads / f"job-{sweep['latest_job_id']}.json"
    page.wait(saved.is_file, "the result JSON saved")
    assert json.loads(saved.read_text())["result"]["curves"][0]["force_N"]
    page.by_id("dl-csv").click()
    saved = page.downloads / f"sweep-{sweep['id']}.csv"
    page.wait(saved.is_file, "the recording CSV saved")
    assert "t,x_s,x_t,x_r" in saved.read_text()

    page.by_id("run-doctor").click()
    page.wait(lambda: page.by_id("doctor-text").text, "the model doctor's report")
    assert page.by_id("doctor-text").text.startswith("# Model doctor")

    from selenium.webdriver.common.keys import Keys

    page.fill("history-filter", "WVW ZZZ 1JZ 3W386752")
    page.by_id("history-filter").send_keys(Keys.ENTER)
    page.wait(lambda: len(page.all_testid("history-row")) == 1, "the history filtered to the vehicle")
    assert lane in page.all_testid("history-row")[0].text  # each test says which lane ran it
    page.driver.execute_script("document.getElementById('result').hidden = true")
    page.all_testid("history-row")[0].send_keys(Keys.ENTER)
    page.wait(lambda: page.by_id("result").is_displayed(), "the result opened from the history")
    page.wait(lambda: page.testid("result-curve").find_elements("css selector", "svg"), "its curve")
    assert page.by_id("result-title").text.startswith(f"Result of sweep {sweep['id']}")


def test_the_emergency_stop_button_stops_the_plate_in_one_click(page: Page, service: ServeProcess) -> None:
    page.sign_in(OPERATOR)
    page.start_sweep(duration_s=300, vehicle_id="ESTOP-1")
    page.wait(lambda: page.phase() == "sweeping", "the plate sweeping")
    page.testid("emergency-stop").click()
    page.wait(lambda: page.by_id("estop-status").text.startswith("Stopped"), "the stop acknowledged")
    page.wait(lambda: "idle" in page.testid("bench-status").text, "the bench idle")
    with service.client(VIEWER) as client:
        (sweep,) = client.get("/api/v1/sweeps", params={"vehicle_id": "ESTOP-1"}).json()["sweeps"]
        bench = client.get("/api/v1/bench").json()
    assert sweep["status"] == "failed" and "emergency stop" in sweep["reason"]
    assert bench["busy"] is False
    page.wait(lambda: "emergency stop" in page.by_id("result-curves").text, "the page says why")


def test_a_sweep_setting_the_api_refuses_is_shown_beside_its_field(page: Page) -> None:
    page.expected_errors = (
        "/api/v1/sweeps - Failed to load resource: the server responded with a status of 422",
    )
    page.sign_in(OPERATOR)
    page.fill("duration-s", "0.2")
    page.testid("start-sweep").click()
    error = page.by_id("duration-s-error")
    page.wait(lambda: error.text, "the field's error")
    assert "duration_s" in error.text
    assert page.by_id("duration-s").get_attribute("aria-invalid") == "true"
    assert page.by_id("start-error").text == ""


def test_an_unknown_key_is_refused_and_not_kept(page: Page) -> None:
    page.expected_errors = (
        "/api/v1/whoami - Failed to load resource: the server responded with a status of 401",
    )
    page.testid("login-key").send_keys("not-a-key-of-this-service")
    page.testid("login-submit").click()
    page.wait(lambda: page.by_id("login-error").text, "the sign-in error")
    assert "not valid" in page.by_id("login-error").text
    assert page.driver.execute_script("return sessionStorage.length") == 0
    assert not page.by_id("app").is_displayed()


def test_a_viewer_sees_no_enabled_control_and_the_api_refuses_it(page: Page, service: ServeProcess) -> None:
    page.sign_in(VIEWER)
    for control in ("start-sweep", "emergency-stop"):
        assert not page.testid(control).is_enabled(), control
    assert not page.by_id("abort-sweep").is_enabled()
    assert not page.by_id("run-doctor").is_enabled()
    assert not page.by_id("schedules-title").is_displayed()
    page.fill("vehicle-id", "VIEWER-1")
    page.driver.execute_script("document.getElementById('start-form').requestSubmit()")  # Enter in a field
    with service.client(VIEWER) as client:
        refused = client.post("/api/v1/sweeps", json={"vehicle_toml": VEHICLE_TOML, "duration_s": 2})
        assert refused.status_code == 403
        assert client.get("/api/v1/sweeps", params={"vehicle_id": "VIEWER-1"}).json()["total"] == 0


def test_the_page_is_labelled_and_fits_a_tablet(page: Page) -> None:
    page.sign_in(ADMIN)
    unlabelled = page.driver.execute_script(
        "return [...document.querySelectorAll('input, select, textarea')]"
        ".filter(e => !e.labels.length && !e.getAttribute('aria-label')).map(e => e.id)"
    )
    assert unlabelled == []
    for width, height in ((1280, 800), (800, 1280)):
        set_viewport(page.driver, width, height)
        overflow = page.driver.execute_script(
            "return document.documentElement.scrollWidth - document.documentElement.clientWidth"
        )
        assert overflow <= 0, f"{overflow} px wider than a {width} px screen"
        assert page.testid("emergency-stop").is_displayed()


def test_an_admin_schedules_a_test_and_cancels_it(page: Page, service: ServeProcess) -> None:
    page.sign_in(ADMIN)
    page.wait(lambda: page.by_id("schedules-title").is_displayed(), "the schedules shown to an admin")
    page.driver.execute_script("document.getElementById('schedule-at').value = '2099-01-01T06:30'")
    page.by_id("vehicle-id").clear()
    page.by_id("vehicle-id").send_keys("SCHED 42")
    page.by_id("schedule-form").find_element("css selector", "button[type=submit]").click()
    page.wait(lambda: "scheduled" in page.by_id("schedule-status").text, "the test scheduled")
    with service.client(VIEWER) as client:
        newest = client.get("/api/v1/schedules").json()["tests"][0]
    assert newest["test"]["vehicle_id"] == "SCHED 42"  # the test's record goes with the schedule
    cancel = page.wait(
        lambda: page.by_id("schedule-body").find_elements("css selector", "button"),
        "a waiting test to cancel",
    )
    cancel[0].click()
    page.wait(lambda: "cancelled" in page.by_id("schedule-body").text, "the test cancelled")


def run_module(page: Page, script: str) -> Any:
    """Run `script` in the page as the body of an async function given the page's modules as `web`
    (web.live, web.result, ...); answers what the script returns."""
    wrapper = """
        const done = arguments[arguments.length - 1];
        const names = ["axes", "curve", "live", "result"];
        Promise.all(names.map((name) => import(`/web/${name}.js`)))
          .then(async (modules) => {
            const web = Object.fromEntries(names.map((name, i) => [name, modules[i]]));
            done({ value: await (async () => { %s })() });
          })
          .catch((error) => done({ error: String(error) }));"""
    answer = page.driver.execute_async_script(wrapper % script)
    assert "error" not in answer, answer["error"]
    return answer["value"]


def test_the_event_stream_parser_joins_events_split_across_chunks(page: Page) -> None:
    events = run_module(
        page,
        """
        const seen = [];
        const parser = new web.live.SseParser((name, data) => seen.push([name, data]));
        const text = ': keep-alive\\n\\nid: 1\\nevent: state\\ndata: {"busy":true}\\n\\n' +
          'id: 2\\r\\nevent: samples\\r\\ndata: {"t_s":[0.01,0.02]}\\r\\n\\r\\n';
        for (let i = 0; i < text.length; i += 7) parser.feed(text.slice(i, i + 7));
        return seen;""",
    )
    assert events == [["state", {"busy": True}], ["samples", {"t_s": [0.01, 0.02]}]]


def test_an_axle_result_shows_left_and_right_curves_and_figures(page: Page) -> None:
    page.sign_in(VIEWER)
    curve = {
        "velocity_m_s": [-0.4, -0.2, 0.0, 0.2, 0.4],
        "force_N": [-600.0, -350.0, 0.0, 500.0, 900.0],
        "force_N_low": [-650.0, -380.0, -20.0, 470.0, 850.0],
        "force_N_high": [-550.0, -320.0, 20.0, 530.0, 950.0],
        "tanh": {"c_s": 800.0, "kappa": 300.0, "mu": 10.0, "beta": 0.1},
        "outliers": [],
    }
    corner = {"eusama_percent": 48.0, "phase_shift_min_deg": 41.0, "damping_ratio": 0.3}
    result = {
        "curves": [{**curve, "corner": "left"}, {**curve, "corner": "right"}],
        "masses_kg": {"sprung": 750.0, "unsprung": 45.0},
        "stiffness_N_per_m": {
            "spring": 26000.0,
            "tyre": 210000.0,
            "anti_roll_bar": 18000.0,
            "identified": [],
        },
        "tyre_damping_Ns_per_m": 1500.0,
        "tyre_model": "maxwell",
        "gap_m": 0.0002,
        "gap_diverged": False,
        "inspection": {
            "left": corner,
            "right": {**corner, "eusama_percent": 30.0},
            "imbalance": {"eusama_difference_points": 18.0, "damping_difference_percent": 5.0},
        },
        "verdict": {
            "outcome": "fail",
            "thresholds_version": "test",
            "reasons": ["left/right EUSAMA differ by 37.5% (> 20%)"],
        },
    }
    sweep = {"id": 99, "test": {"vehicle_id": "AXLE-1"}, "links": {"self": "/api/v1/sweeps/99"}}
    job = {"id": 98, "links": {"self": "/api/v1/jobs/98"}}
    run_module(page, f"web.result.showResult({json.dumps(sweep)}, {json.dumps({**job, 'result': result})});")
    titles = [t.text for t in page.testid("result-curve").find_elements("css selector", "svg .chart-title")]
    assert titles == ["Left damper", "Right damper"]
    assert page.testid("result-eusama").text == "left 48 %, right 30 %"
    lane = page.by_id("lane-figures").text
    assert "Left/right EUSAMA difference 18 points" in lane and "Minimum phase angle right 41 °" in lane
    assert page.testid("result-verdict").get_attribute("data-outcome") == "fail"
    assert "37.5%" in page.testid("result-verdict").text
    assert "Anti-roll bar 18 kN/m" in page.by_id("model-figures").text
    assert "Frame guides" not in page.by_id("model-figures").text  # a vehicle on a plate has none


def test_a_lab_rig_s_result_shows_its_frame_guides_friction(page: Page) -> None:
    """identify fits the friction of a lab rig's frame guides where its vehicle file states them: the model
    figures show both with their 95% intervals."""
    page.sign_in(VIEWER)
    curve = {
        "velocity_m_s": [-0.1, 0.0, 0.1],
        "force_N": [-1.2, 0.0, 1.5],
        "force_N_low": [-1.3, -0.1, 1.4],
        "force_N_high": [-1.1, 0.1, 1.6],
        "tanh": {"c_s": 12.0, "kappa": 0.2, "mu": 0.3, "beta": 0.01},
        "outliers": [],
    }
    result = {
        "curves": [curve],
        "masses_kg": {"sprung": 2.6, "unsprung": 0.9},
        "stiffness_N_per_m": {"spring": 950.0, "tyre": 3100.0, "identified": ["spring", "tyre"]},
        "tyre_damping_Ns_per_m": 4.0,
        "tyre_model": "maxwell",
        "gap_m": 0.0002,
        "gap_diverged": False,
        "effects": {"guide_body_friction_N": 0.167, "guide_wheel_friction_N": 0.164},
        "effects_interval": {
            "guide_body_friction_N": [0.134, 0.201],
            "guide_wheel_friction_N": [0.112, 0.216],
        },
        "inspection": {"eusama_percent": 55.0, "phase_shift_min_deg": 38.0, "damping_ratio": 0.2},
    }
    sweep = {"id": 97, "test": {"vehicle_id": "LAB-RIG"}, "links": {"self": "/api/v1/sweeps/97"}}
    job = {"id": 96, "links": {"self": "/api/v1/jobs/96"}}
    run_module(page, f"web.result.showResult({json.dumps(sweep)}, {json.dumps({**job, 'result': result})});")
    figures = page.by_id("model-figures").text
    assert "Frame guides' friction, body 0.167 N (identified) (95%: 0.134–0.201 N)" in figures
    assert "Frame guides' friction, wheel 0.164 N (identified) (95%: 0.112–0.216 N)" in figures


def test_without_chromium_the_tests_skip_except_in_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(headless_chromium.shutil, "which", lambda _name: None)
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="chromium and chromium-driver not installed"):
        find_chromium()
    monkeypatch.setenv("CI", "1")
    with pytest.raises(pytest.fail.Exception, match="CI is set, so the browser tests must run"):
        find_chromium()


def test_a_lane_whose_central_database_is_away_says_so(chromium: Chromium, tmp_path: Path) -> None:
    """serve --database naming a central database that does not answer: the lane runs on its local store
    (issue 18, item 7), and the bench view says the central database is away and how many results wait."""
    keys = tmp_path / "keys.toml"
    keys.write_text(f'operator = ["{OPERATOR}"]\n')
    central = "postgresql+psycopg://nobody@127.0.0.1:1/central"  # nothing listens on port 1
    service = serve_process(
        tmp_path, "serve", "--simulated", "--data", str(tmp_path / "data"), "--keys", str(keys),
        "--database", central,
    )  # fmt: skip
    try:
        wait_until(lambda: service.answers(OPERATOR), SERVE_STARTUP_TIMEOUT_S, "service ready", 0.2)
        with chromium_driver(chromium, tmp_path / "downloads") as driver:
            page = Page(driver, service.url + "/", tmp_path / "downloads")
            page.sign_in(OPERATOR)
            sync = page.testid("bench-sync")
            page.wait(lambda: sync.text.startswith("away"), "the central database shown away")
            assert "results are kept here; 0 results waiting to sync" in sync.text
            assert "Connection refused" in sync.text or "connection" in sync.text.lower()
            assert not console_errors(driver, page.expected_errors)
    finally:
        service.stop()
