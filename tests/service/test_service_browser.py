"""The page at ``/`` in a real browser (Debian's chromium + chromedriver, driven by selenium).

Skipped with the reason when chromium, its driver or selenium is missing. Saves a screenshot
(``docs/img/service-page.png`` when ``FLATBODY_SCREENSHOT`` names it, else under the test's tmp dir).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")

pytestmark = pytest.mark.skipif(CHROMIUM is None or DRIVER is None,
                                reason="needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)")


def _chrome(*extra: str):
    webdriver = pytest.importorskip("selenium.webdriver", reason="needs selenium (pip install selenium)")
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1200,1700", *extra):
        opts.add_argument(arg)
    driver = webdriver.Chrome(service=Service(DRIVER), options=opts)
    driver.set_page_load_timeout(60)
    return driver


@pytest.fixture
def browser():
    driver = _chrome()
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture
def offline_browser():
    """A browser that can reach this machine only (every other host name fails to resolve)."""
    driver = _chrome("--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1")
    try:
        yield driver
    finally:
        driver.quit()


def test_api_docs_render_without_internet_access(offline_browser, live_service):
    """/docs (Swagger UI) and /redoc draw the service's API from its own scripts: the browser reaches
    nothing but the service."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    _, url, _ = live_service
    wait = WebDriverWait(offline_browser, 60)
    offline_browser.get(url + "/docs")
    wait.until(lambda d: "flatbody analysis service" in " ".join(e.text for e in d.find_elements(By.CSS_SELECTOR, ".swagger-ui .info .title")))
    paths = {e.text.replace("\u200b", "") for e in offline_browser.find_elements(By.CSS_SELECTOR, ".opblock-summary-path")}
    assert {"/health", "/ellipses", "/jobs"} <= paths
    offline_browser.get(url + "/redoc")
    wait.until(lambda d: "flatbody analysis service" in d.find_element(By.TAG_NAME, "body").text)
    assert "/ellipses" in offline_browser.find_element(By.TAG_NAME, "body").text


def test_page_finds_ellipses_runs_a_recording_job_and_shows_a_chart(browser, live_service, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC
    from selenium.webdriver.support.ui import Select, WebDriverWait

    _, url, data_dir = live_service
    wait = WebDriverWait(browser, 180)
    browser.get(url + "/")
    wait.until(lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-ready") == "yes")
    assert "service ok" in browser.find_element(By.ID, "health").text
    scene_names = [o.get_attribute("value") for o in Select(browser.find_element(By.ID, "scene")).options]
    assert "default" in scene_names and "regular" in scene_names

    # a V1 body with s3 p_theta > 0: the closed form has exactly one stationary ellipse (lambda mu = (s3/p)^2 ...)
    Select(browser.find_element(By.ID, "potential")).select_by_value("V1")
    for field, value in (("k", "1"), ("J", "1"), ("J3", "1"), ("s3", "2"), ("p_theta", "0.5")):
        el = browser.find_element(By.ID, field)
        el.clear()
        el.send_keys(value)
    browser.find_element(By.ID, "find-ellipses").click()
    wait.until(EC.text_to_be_present_in_element((By.ID, "ellipses-status"), "stationary ellipse"))
    rows = browser.find_elements(By.CSS_SELECTOR, "#ellipses-table tbody tr")
    assert len(rows) == 1
    cells = [c.text for c in rows[0].find_elements(By.TAG_NAME, "td")]
    # the page shows what POST /ellipses answers: omega3 = 1 for this body (energy 3.5), and a stability class
    assert float(cells[4]) == pytest.approx(1.0, abs=1e-5)
    assert float(cells[6]) == pytest.approx(3.5, abs=1e-6)
    assert cells[7] in ("elliptic", "hyperbolic", "degenerate")

    assert "V1, s3 = 2, p_θ = 0.5" in browser.find_element(By.ID, "ellipses-status").text
    assert "stale" not in browser.find_element(By.ID, "ellipses-table").get_attribute("class")

    # a small recording job of the default scene, watched to completion; picking the scene changes
    # the body, so the ellipse table no longer answers the form: greyed out and said so
    Select(browser.find_element(By.ID, "scene")).select_by_value("default")
    assert "stale" in browser.find_element(By.ID, "ellipses-table").get_attribute("class")
    assert "form has changed" in browser.find_element(By.ID, "ellipses-status").text
    for field, value in (("t_end", "1"), ("samples", "11")):
        el = browser.find_element(By.ID, field)
        el.clear()
        el.send_keys(value)
    browser.find_element(By.ID, "start-record").click()
    wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, "#jobs tr[data-kind=record][data-status=done]")
               or d.find_elements(By.CSS_SELECTOR, "#jobs tr[data-kind=record][data-status=failed]"))
    row = browser.find_element(By.CSS_SELECTOR, "#jobs tr[data-kind=record]")
    assert row.get_attribute("data-status") == "done", row.text
    link = row.find_element(By.LINK_TEXT, "recording (.rrd)")
    assert "/artifact?name=recording.rrd" in link.get_attribute("href")
    assert "rerun recording.rrd" in row.text
    rrd = list(Path(data_dir).glob("jobs/*/recording.rrd"))
    assert len(rrd) == 1 and rrd[0].stat().st_size > 1000

    # a small stability map: the picture appears on the page
    el = browser.find_element(By.ID, "map-grid")
    el.clear()
    el.send_keys("8")
    browser.find_element(By.ID, "start-map").click()
    browser.find_element(By.ID, "start-family").click()
    wait.until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#pictures img")) == 2)
    loaded = "return [...document.querySelectorAll('#pictures img')].map(i => i.complete ? i.naturalWidth : 0)"
    wait.until(lambda d: all(w > 0 for w in d.execute_script(loaded)))
    assert all(w > 100 for w in browser.execute_script(loaded))
    captions = {c.text for c in browser.find_elements(By.CSS_SELECTOR, "#pictures figcaption")}
    assert captions == {"family", "stability-map"}
    assert not browser.find_element(By.ID, "error").is_displayed()

    shot = Path(os.environ.get("FLATBODY_SCREENSHOT") or tmp_path / "service-page.png")
    shot.parent.mkdir(parents=True, exist_ok=True)
    browser.save_screenshot(str(shot))
    assert shot.stat().st_size > 10_000
