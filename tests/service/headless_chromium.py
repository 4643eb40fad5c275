"""Debian's chromium, headless, driven by selenium through Debian's chromium-driver, for the operator page's
tests: where the two are (a clear skip without them, a failure when the environment variable CI is set:
CI installs them, .ci/run), a driver that records the browser's console, and the console's errors.

No browser is downloaded at run time: the driver and the browser are given by path, so selenium's own
manager never runs."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

BROWSERS = ("chromium", "chromium-browser")
DRIVERS = ("chromedriver", "chromium-driver")


@dataclass(frozen=True)
class Chromium:
    browser: str
    driver: str


def find_chromium() -> Chromium:
    """The system's chromium and chromium-driver; skips the test without them, or fails it in CI."""
    browser = next((path for name in BROWSERS if (path := shutil.which(name))), None)
    driver = next((path for name in DRIVERS if (path := shutil.which(name))), None)
    if browser is None or driver is None:
        missing = " and ".join(n for n, p in (("chromium", browser), ("chromium-driver", driver)) if not p)
        reason = f"{missing} not installed (apt-get install chromium chromium-driver)"
        if os.environ.get("CI"):
            pytest.fail(f"CI is set, so the browser tests must run: {reason}")
        pytest.skip(reason)
    return Chromium(browser, driver)


@contextmanager
def chromium_driver(
    chromium: Chromium, downloads: Path, width: int = 1280, height: int = 800
) -> Iterator[object]:
    """A headless Chromium with a viewport of width x height CSS pixels, whose console log is kept
    (`console_errors`), and which saves downloads in the folder `downloads` without asking."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = chromium.browser
    for argument in (
        "--headless=new",
        "--no-sandbox",  # root in a container
        "--disable-dev-shm-usage",
        "--disable-gpu",
        "--no-first-run",
        "--disable-extensions",
        "--disable-background-networking",
        f"--window-size={width},{height}",
    ):
        options.add_argument(argument)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    prefs = {"download.default_directory": str(downloads), "download.prompt_for_download": False}
    options.add_experimental_option("prefs", prefs)
    driver = webdriver.Chrome(options=options, service=Service(chromium.driver))
    try:
        set_viewport(driver, width, height)
        behaviour = {"behavior": "allow", "downloadPath": str(downloads)}
        driver.execute_cdp_cmd("Page.setDownloadBehavior", behaviour)  # type: ignore[attr-defined]
        yield driver
    finally:
        driver.quit()


def set_viewport(driver: object, width: int, height: int) -> None:
    """Make the page's viewport exactly width x height CSS pixels (the window's size includes more)."""
    metrics = {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False}
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", metrics)  # type: ignore[attr-defined]


def console_errors(driver: object, expected: tuple[str, ...] = ()) -> list[str]:
    """The browser console's errors (level SEVERE) since the last call, except those containing one of
    `expected` (a request the test makes fail on purpose logs its status as an error)."""
    entries = driver.get_log("browser")  # type: ignore[attr-defined]
    return [
        e["message"]
        for e in entries
        if e["level"] == "SEVERE" and not any(text in e["message"] for text in expected)
    ]
