"""Debian's chromium, headless, driven by selenium: one home for the viewer's browser test and
benchmark. Nothing is downloaded: chromedriver and chromium are the system's (``/usr/bin``), so
selenium-manager never runs. Every wait has a deadline."""
from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Iterator

CHROMIUM, CHROMEDRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
#: Headless, no GPU (WebGL falls back to software rendering), nothing that phones home.
FLAGS = ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--window-size=1280,800")


@contextlib.contextmanager
def headless_chromium(page_load_timeout: float = 60.0) -> Iterator[object]:
    """A selenium Chrome driver on the system chromium; chromium and chromedriver end on exit."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in FLAGS:
        options.add_argument(flag)
    service = Service(str(CHROMEDRIVER))
    driver = webdriver.Chrome(service=service, options=options)
    driver.set_page_load_timeout(page_load_timeout)
    try:
        yield driver
    finally:
        try:
            driver.quit()
        finally:
            service.stop()


def page_text(driver) -> str:
    return driver.execute_script("return document.body ? document.body.innerText : ''") or ""


def wait_text(driver, text: str, timeout: float) -> float:
    """Seconds until ``text`` is on the page; AssertionError with the page's text after ``timeout``."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if text in page_text(driver):
            return time.monotonic() - t0
        time.sleep(0.1)
    raise AssertionError(f"{text!r} not on the page within {timeout} s; page text: {page_text(driver)[-1500:]!r}")


def wait_page(driver, url: str, timeout: float) -> None:
    """Load ``url`` once its server answers (it may start after the caller)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            driver.get(url)
            return
        except Exception:  # noqa: BLE001 - connection refused until the server is up
            if time.monotonic() > deadline:
                raise
            time.sleep(0.5)
