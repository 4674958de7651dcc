"""The page at ``/`` in a real browser (Debian's chromium + chromedriver, driven by selenium), checked as a
user sees it: results drawn, errors next to the field at fault and inside the window, jobs back after a
reload, progress that moves while a job runs.

Skipped with the reason when chromium, its driver or selenium is missing. Saves screenshots
``page-*.png`` under ``FLATBODY_SCREENSHOT_DIR`` (``docs/img`` refreshes the documentation's, in a 256-colour
palette), else under the test's tmp dir.
"""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import pytest

WAIT_S = 300.0
"""Longest the tests wait for the page, a job's row or its end before they fail: a hang guard, not a speed check
(each default test runs in 7–25 s on a quiet 2-core machine, a job in a few seconds; beside four busy processes
and other work on the same two cores, 30 s waits and 120 s for a 3-s job ran out)."""

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")

pytestmark = pytest.mark.skipif(
    CHROMIUM is None or DRIVER is None,
    reason="needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)",
)


def _chrome(*extra: str, size: str = "1200,1700"):
    webdriver = pytest.importorskip("selenium.webdriver", reason="needs selenium (pip install selenium)")
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    opts.binary_location = CHROMIUM
    for arg in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        f"--window-size={size}",
        *extra,
    ):
        opts.add_argument(arg)
    driver = webdriver.Chrome(service=Service(DRIVER), options=opts)
    driver.set_page_load_timeout(WAIT_S)
    return driver


@pytest.fixture
def window():
    """A browser window of 1400 × 900 px, as a user's, that can reach this machine only."""
    driver = _chrome("--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1", size="1400,900")
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


@pytest.mark.slow  # long: the page test below keeps the browser in the default run
def test_api_docs_render_without_internet_access(offline_browser, live_service):
    """/docs (Swagger UI) and /redoc draw the service's API from its own scripts: the browser reaches
    nothing but the service."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    _, url, _ = live_service
    wait = WebDriverWait(offline_browser, WAIT_S)
    offline_browser.get(url + "/docs")
    wait.until(
        lambda d: (
            "flatbody analysis service"
            in " ".join(e.text for e in d.find_elements(By.CSS_SELECTOR, ".swagger-ui .info .title"))
        )
    )
    paths = {
        e.text.replace("\u200b", "") for e in offline_browser.find_elements(By.CSS_SELECTOR, ".opblock-summary-path")
    }
    assert {"/health", "/ellipses", "/jobs"} <= paths
    offline_browser.get(url + "/redoc")
    wait.until(lambda d: "flatbody analysis service" in d.find_element(By.TAG_NAME, "body").text)
    assert "/ellipses" in offline_browser.find_element(By.TAG_NAME, "body").text
    # every resource the page asked for came from the service (ReDoc's footer logo included)
    asked = offline_browser.execute_script("return performance.getEntriesByType('resource').map(e => e.name)")
    assert asked and all(u.startswith(url) or u.startswith(("data:", "blob:")) for u in asked), asked


def _ready(driver, url):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get(url + "/")
    WebDriverWait(driver, WAIT_S).until(
        lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-ready") == "yes"
    )


def _type(driver, field: str, value: str) -> None:
    from selenium.webdriver.common.by import By

    el = driver.find_element(By.ID, field)
    el.clear()
    el.send_keys(value)


def _shot(driver, tmp_path: Path, name: str) -> Path:
    """Save a screenshot as ``page-NAME.png`` (under FLATBODY_SCREENSHOT_DIR when set)."""
    folder = Path(os.environ.get("FLATBODY_SCREENSHOT_DIR") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"page-{name}.png"
    driver.save_screenshot(str(path))
    assert path.stat().st_size > 10_000
    if os.environ.get("FLATBODY_SCREENSHOT_DIR"):  # the documentation's copies: a 256-colour palette, as record-shots
        from flatbody_env.recording.viewer import _compact_png

        _compact_png(path, 256)
    return path


def _full_height(driver) -> None:
    """Make the window as tall as the page (for a screenshot of all of it)."""
    height = driver.execute_script("return document.documentElement.scrollHeight")
    driver.set_window_size(1400, min(int(height) + 120, 6000))
    driver.execute_script("window.scrollTo(0, 0)")
    time.sleep(0.3)


def _in_viewport(driver, element) -> bool:
    return driver.execute_script(
        "const r = arguments[0].getBoundingClientRect();"
        "return r.width > 0 && r.top >= 0 && r.left >= 0 && r.bottom <= window.innerHeight && r.right <= window.innerWidth;",
        element,
    )


def test_page_finds_ellipses_runs_jobs_draws_their_results_and_keeps_them_over_a_reload(window, live_service, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support import expected_conditions as EC
    from selenium.webdriver.support.ui import Select, WebDriverWait

    browser = window
    _, url, data_dir = live_service
    wait = WebDriverWait(browser, WAIT_S)
    _ready(browser, url)
    assert "service ok" in browser.find_element(By.ID, "health").text
    scene_names = [o.get_attribute("value") for o in Select(browser.find_element(By.ID, "scene")).options]
    assert "default" in scene_names and "regular" in scene_names
    method = Select(browser.find_element(By.ID, "method"))
    assert method.first_selected_option.get_attribute("value") == "auto"  # the API's default, offered and chosen
    assert "DOP853" in [o.get_attribute("value") for o in method.options]
    # the icon is served (no 404 on every load)
    assert (
        browser.execute_script("return fetch('/favicon.ico').then(r => r.status + ' ' + r.headers.get('content-type'))")
        == "200 image/x-icon"
    )

    # a V1 body with s3 p_theta > 0: the closed form has exactly one stationary ellipse; Enter in a field finds it
    Select(browser.find_element(By.ID, "potential")).select_by_value("V1")
    for field, value in (("k", "1"), ("J", "1"), ("J3", "1"), ("s3", "2"), ("p_theta", "0.5")):
        _type(browser, field, value)
    browser.find_element(By.ID, "p_theta").send_keys(Keys.ENTER)
    wait.until(EC.text_to_be_present_in_element((By.ID, "ellipses-status"), "stationary ellipse"))
    rows = browser.find_elements(By.CSS_SELECTOR, "#ellipses-table tbody tr")
    assert len(rows) == 1
    cells = [c.text for c in rows[0].find_elements(By.TAG_NAME, "td")]
    # the page shows what POST /ellipses answers: omega3 = 1 for this body (energy 3.5), and a stability class
    # columns: #, a drawing of the ellipse, λ, μ, ϱ, ω₃, θ̇, H, stability, max Re, the row's actions
    assert rows[0].find_element(By.CSS_SELECTOR, "td.shape svg.ellipse-icon")
    assert float(cells[5]) == pytest.approx(1.0, abs=1e-5)
    assert float(cells[7]) == pytest.approx(3.5, abs=1e-6)
    assert cells[6] == "0"  # theta_dot: round-off (|x| < 1e-12) is shown as 0, never as 1.11022e-16
    assert all("e-" not in c for c in cells)
    assert cells[8] in ("elliptic", "hyperbolic", "degenerate")
    assert "simulate from here" in cells[10] and "use as target" in cells[10]
    assert "V1, s3 = 2, p_θ = 0.5" in browser.find_element(By.ID, "ellipses-status").text
    assert "stale" not in browser.find_element(By.ID, "ellipses-table").get_attribute("class")
    assert "dimensionless" in browser.find_element(By.ID, "units-note").text

    # picking a scene changes the body: the ellipse table no longer answers the form, greyed out and said so
    Select(browser.find_element(By.ID, "scene")).select_by_value("default")
    assert "stale" in browser.find_element(By.ID, "ellipses-table").get_attribute("class")
    assert "form has changed" in browser.find_element(By.ID, "ellipses-status").text

    # a simulation job: λ, μ, ϱ, s3 and H drawn against t, and the ellipse
    _type(browser, "t_end", "2")
    _type(browser, "samples", "41")
    browser.find_element(By.ID, "t_end").send_keys(Keys.ENTER)  # Enter in the run form: a simulation job
    card = wait.until(lambda d: d.find_element(By.CSS_SELECTOR, "#runs article[data-kind=simulate]"))
    lines = wait.until(lambda d: card.find_elements(By.CSS_SELECTOR, "svg.chart path.line"))
    assert {p.get_attribute("data-name") for p in lines} == {"λ", "μ", "ϱ", "s₃", "H", "H − H₀"}
    # each variable in the colour the recordings and the rgb_array frames give it: λ red, μ green, ϱ blue, ...
    from flatbody_env.env.rendering import COLORS

    palette = {"λ": "lambda", "μ": "mu", "ϱ": "rho", "s₃": "s3", "H": "energy", "H − H₀": "energy"}
    drawn = {
        p.get_attribute("data-name"): browser.execute_script("return getComputedStyle(arguments[0]).stroke", p)
        for p in lines
    }
    assert drawn == {name: "rgb({}, {}, {})".format(*COLORS[key]) for name, key in palette.items()}, drawn
    assert all(len(p.get_attribute("d")) > 100 for p in lines)
    assert card.find_element(By.CSS_SELECTOR, "svg.chart").size["width"] > 400
    assert card.find_element(By.CSS_SELECTOR, "svg.ellipse ellipse.now").get_attribute("rx")
    assert "t (model time unit)" in card.text and "energy drift H − H₀" in card.text

    # a small recording job: a preview (frames and the trajectory's plots), the file under a name of its own, what to run
    _type(browser, "t_end", "1")
    _type(browser, "samples", "11")
    browser.find_element(By.ID, "start-record").click()
    rec = wait.until(lambda d: d.find_element(By.CSS_SELECTOR, "#runs article[data-kind=record]"))
    link = rec.find_element(By.PARTIAL_LINK_TEXT, "Download flatbody-record-")
    name = link.text.removeprefix("Download ")
    assert name.startswith("flatbody-record-") and name.endswith(".rrd") and f"rerun {name}" in rec.text
    assert "/artifact?name=recording.rrd" in link.get_attribute("href")
    wait.until(lambda d: rec.find_elements(By.CSS_SELECTOR, "svg.chart path.line"))
    preview = rec.find_element(By.CSS_SELECTOR, "img.preview")
    wait.until(lambda d: d.execute_script("return arguments[0].complete && arguments[0].naturalWidth", preview))
    row = browser.find_element(By.CSS_SELECTOR, "#jobs tr[data-kind=record]")
    assert row.get_attribute("data-status") == "done", row.text
    assert "took" in row.text
    rrd = list(Path(data_dir).glob("jobs/*/recording.rrd"))
    assert len(rrd) == 1 and rrd[0].stat().st_size > 1000

    # a small stability map and a family: full-width pictures, captioned with their parameters
    _type(browser, "map-grid", "8")
    browser.find_element(By.ID, "start-map").click()
    browser.find_element(By.ID, "start-family").click()
    loaded = "return [...document.querySelectorAll('#pictures img')].map(i => i.complete ? i.naturalWidth : 0)"
    wait.until(lambda d: len(d.execute_script(loaded)) == 2 and all(w > 0 for w in d.execute_script(loaded)))
    captions = [c.text for c in browser.find_elements(By.CSS_SELECTOR, "#pictures figcaption")]
    assert any("Family of stationary ellipses over s3 from 0.05 to 4" in c and "p_θ = 1.77" in c for c in captions), (
        captions
    )
    assert any("Stability map of 8 × 8 shapes" in c for c in captions), captions
    img = browser.find_element(By.CSS_SELECTOR, "#pictures img")
    assert img.size["width"] > 900  # the section's full width, not capped at 500 px
    img.click()  # click to enlarge
    zoom = browser.find_element(By.ID, "zoom")
    assert zoom.is_displayed() and zoom.find_element(By.TAG_NAME, "img").get_attribute("src") == img.get_attribute(
        "src"
    )
    zoom.find_element(By.CSS_SELECTOR, "button.close").click()
    assert not zoom.is_displayed()
    assert not browser.find_element(By.ID, "error").is_displayed()
    _full_height(browser)
    _shot(browser, tmp_path, "results")
    browser.set_window_size(1400, 900)

    # a reload: every job and its results come back (the page reads GET /jobs)
    jobs_before = {r.get_attribute("id") for r in browser.find_elements(By.CSS_SELECTOR, "#jobs tbody tr")}
    browser.refresh()
    _ready(browser, url)
    wait.until(lambda d: len(d.execute_script(loaded)) == 2 and all(w > 0 for w in d.execute_script(loaded)))
    wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, "#runs article[data-kind=simulate] svg.chart path.line"))
    assert {r.get_attribute("id") for r in browser.find_elements(By.CSS_SELECTOR, "#jobs tbody tr")} == jobs_before
    assert len(jobs_before) == 4
    assert browser.find_elements(By.CSS_SELECTOR, "#runs article[data-kind=record]")


@pytest.mark.slow  # long: refusals are checked over HTTP in the default run
def test_bad_input_is_refused_next_to_the_field_inside_the_window(window, live_service, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select, WebDriverWait

    browser = window
    _, url, _ = live_service
    wait = WebDriverWait(browser, WAIT_S)
    _ready(browser, url)
    # two pictures shown first, so that the page is long (the old error box landed far below the window)
    _type(browser, "map-grid", "6")
    browser.find_element(By.ID, "start-map").click()
    browser.find_element(By.ID, "start-map").click()
    wait.until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#pictures img")) == 2)
    posted = "return performance.getEntriesByType('resource').filter(e => /\\/(ellipses|jobs)$/.test(e.name)).length"

    def message_for(field):
        label = browser.find_element(By.ID, field).find_element(By.XPATH, "./ancestor::label[1]")
        msg = wait.until(lambda d: label.find_elements(By.CSS_SELECTOR, ".msg"))[0]
        assert "bad" in label.get_attribute("class")
        assert _in_viewport(browser, msg), f"the message for {field} is outside the window"
        return msg.text

    # the service refuses J = 1e7: its message, in the form's words, next to J and inside the window
    _type(browser, "J", "1e7")
    browser.find_element(By.ID, "start-map").click()
    text = message_for("J")
    assert text.startswith("J: ") and "body.params" not in text and "1×10⁶" in text and "e+" not in text, text
    summary = browser.find_element(By.ID, "map-error")
    assert summary.is_displayed() and "J" in summary.text
    _shot(browser, tmp_path, "field-error")

    # an empty field and a half-typed number are refused in the browser: nothing is sent
    before = browser.execute_script(posted)
    _type(browser, "J", "1")
    _type(browser, "J3", "")
    browser.find_element(By.ID, "find-ellipses").click()
    assert message_for("J3") == "J3: enter a number"
    _type(browser, "J3", "1e")
    browser.find_element(By.ID, "find-ellipses").click()
    assert "not a number" in message_for("J3")
    assert browser.execute_script(posted) == before

    # from > to in a family: refused before sending, at "to", in the form's words
    _type(browser, "J3", "1")
    _type(browser, "vary-from", "3")
    _type(browser, "vary-to", "1")
    browser.find_element(By.ID, "start-family").click()
    text = message_for("vary-to")
    assert text.startswith("to: must be greater than from") and "stop" not in text
    assert browser.execute_script(posted) == before
    # a body constant's range starting at 0: refused at "from"
    Select(browser.find_element(By.ID, "vary")).select_by_value("kappa")
    _type(browser, "vary-from", "0")
    _type(browser, "vary-to", "2")
    browser.find_element(By.ID, "start-family").click()
    assert "must be at least 1×10⁻⁶" in message_for("vary-from")
    assert browser.execute_script(posted) == before


def _progress_seen(browser, kind: str, timeout: float) -> tuple[list[float], list[str], str]:
    """Sample the progress bar of the newest ``kind`` job in the page until it is done: the values and texts seen."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(browser, WAIT_S).until(
        lambda d: d.find_elements(By.CSS_SELECTOR, f"#jobs tbody tr[data-kind='{kind}']")
    )
    values: list[float] = []
    texts: list[str] = []
    deadline = time.monotonic() + timeout
    status = ""
    while time.monotonic() < deadline:
        row = browser.find_element(By.CSS_SELECTOR, f"#jobs tbody tr[data-kind='{kind}']")
        status = row.get_attribute("data-status") or ""
        value = float(row.find_element(By.TAG_NAME, "progress").get_attribute("data-value") or 0)
        if not values or value != values[-1]:
            values.append(value)
            texts.append(row.find_element(By.CSS_SELECTOR, ".pct").text)
        if status in ("done", "failed"):
            break
        time.sleep(0.05)
    return values, texts, status


@pytest.mark.slow  # long: progress and cancel are checked over HTTP in the default run
def test_progress_moves_while_a_job_runs_and_a_running_job_can_be_cancelled(window, live_service, tmp_path):
    from selenium.common.exceptions import StaleElementReferenceException
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    browser = window
    _, url, _ = live_service
    _ready(browser, url)
    _type(browser, "map-grid", "60")  # about 3 s on an idle core, reported row by row
    browser.find_element(By.ID, "start-map").click()
    row = WebDriverWait(browser, WAIT_S).until(
        lambda d: d.find_element(By.CSS_SELECTOR, "#jobs tr[data-kind='stability-map'][data-status=running]")
    )
    assert (
        "its progress is in Jobs below" in browser.find_element(By.ID, "map-error").text
    )  # said where the user clicked
    WebDriverWait(browser, WAIT_S).until(lambda d: "left" in row.text)
    browser.execute_script("arguments[0].scrollIntoView({block: 'end'})", row)
    _shot(browser, tmp_path, "progress")
    values, texts, status = _progress_seen(browser, "stability-map", WAIT_S)
    assert status == "done"
    between = [v for v in values if 0 < v < 1]
    assert len(set(between)) >= 3, values  # the worker's own progress, seen by the page while it runs
    assert values == sorted(values), values
    assert any("elapsed" in t for t in texts) and any("left" in t for t in texts), texts

    # cancel a running job from the page: it stops and goes
    _type(browser, "map-grid", "200")
    browser.find_element(By.ID, "start-map").click()
    row = WebDriverWait(browser, WAIT_S).until(
        lambda d: d.find_element(By.CSS_SELECTOR, "#jobs tr[data-kind='stability-map'][data-status=running]")
    )
    # the page redraws a row's buttons as progress comes in: look the button up afresh until a click lands
    row_id = row.get_attribute("id")
    WebDriverWait(browser, WAIT_S, ignored_exceptions=(StaleElementReferenceException,)).until(
        lambda d: d.find_element(By.CSS_SELECTOR, f"#{row_id} button.cancel").click() is None
    )
    WebDriverWait(browser, WAIT_S, ignored_exceptions=(StaleElementReferenceException,)).until(
        lambda d: d.find_element(By.ID, row_id).get_attribute("data-status") == "cancelled"
    )
    jobs = browser.execute_script("return fetch('/jobs').then(r => r.json())")["jobs"]
    assert [j["status"] for j in jobs] == ["done"]


@pytest.mark.slow
def test_progress_strictly_increases_during_a_ten_second_job(window, live_service):
    """A stability map of 120 × 120 shapes (about 10 s or more): every value the page shows is higher than the last."""
    from selenium.webdriver.common.by import By

    browser = window
    _, url, _ = live_service
    _ready(browser, url)
    _type(browser, "map-grid", "120")
    started = time.monotonic()
    browser.find_element(By.ID, "start-map").click()
    values, texts, status = _progress_seen(browser, "stability-map", WAIT_S)
    took = time.monotonic() - started
    assert status == "done"
    assert took > 8, f"the job took {took:.1f} s: too short to check"
    assert all(b > a for a, b in zip(values, values[1:])), values
    assert len(values) >= 10, values
    elapsed = [t for t in texts if "elapsed" in t]
    assert len(elapsed) >= 5, texts


def _overflow(driver) -> int:
    """How far the page reaches past the window's right edge (px; 0: nothing off screen)."""
    return driver.execute_script("return document.documentElement.scrollWidth - window.innerWidth")


@pytest.mark.slow  # long: a page-behaviour check of tens of seconds
def test_errors_go_when_their_fields_are_fixed_without_moving_the_form(window, live_service, tmp_path):
    """A message under a field is a bubble (the row does not reflow), the summary beside the button goes once every
    field it names is changed, and every number in a message is written one way (1×10⁶, never 1e+06 beside it)."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    browser = window
    _, url, _ = live_service
    _ready(browser, url)
    grid = browser.find_element(By.CSS_SELECTOR, "#body-panel .grid:nth-of-type(2)")
    before = grid.size["height"]
    for field, value in (("J", "1e7"), ("J3", ""), ("a", "-1"), ("b", "1e300")):
        _type(browser, field, value)
    browser.find_element(By.ID, "find-ellipses").click()
    summary = browser.find_element(By.ID, "ellipses-error")
    # refused in the page: J3 empty and a < 0 (J and b are the service's to refuse)
    assert summary.is_displayed() and summary.text.startswith("2 fields to fix"), summary.text
    assert grid.size["height"] == before  # the messages float over what lies below: the row keeps its height
    msgs = [m.text for m in browser.find_elements(By.CSS_SELECTOR, "label.bad .msg")]
    assert len(msgs) == 2 and not any("e+" in m or "e-0" in m for m in msgs), msgs
    _shot(browser, tmp_path, "field-error")
    _type(browser, "J3", "1")
    assert summary.is_displayed()  # a is still wrong: the summary stays
    _type(browser, "a", "1")
    WebDriverWait(browser, 5).until(lambda d: not summary.is_displayed())  # every field it named fixed: gone
    assert not browser.find_elements(By.CSS_SELECTOR, "label.bad")
    # the service's refusal of J, in the form's words and the page's number format
    _type(browser, "b", "1")
    browser.find_element(By.ID, "start-map").click()
    msg = WebDriverWait(browser, 30).until(lambda d: d.find_element(By.CSS_SELECTOR, "label.bad .msg")).text
    assert msg.startswith("J: ") and "at most 1×10⁶, got 1×10⁷" in msg and "e+" not in msg and "<=" not in msg, msg


def test_the_page_on_a_phone_keeps_everything_on_screen_and_readable(live_service, tmp_path):
    """At 390 px wide: nothing off screen (the jobs table becomes one card per job) and the plots' text stays
    ≥ 10 px (the plots are drawn at the width they are shown at, not shrunk)."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    browser = _chrome("--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1", size="390,844")
    try:
        _, url, _ = live_service
        _ready(browser, url)
        _type(browser, "t_end", "20")
        browser.find_element(By.ID, "start-simulate").click()
        _type(browser, "map-grid", "6")
        browser.find_element(By.ID, "start-map").click()
        wait = WebDriverWait(browser, 180)
        wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, "#runs article[data-kind=simulate] svg.chart text.tick"))
        wait.until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#jobs tr[data-status=done]")) == 2)
        assert _overflow(browser) <= 0, _overflow(browser)
        for sel in ("#jobs tr[data-kind=simulate] .files a", "#jobs tr[data-kind=simulate] button.delete"):
            el = browser.find_element(By.CSS_SELECTOR, sel)
            browser.execute_script("arguments[0].scrollIntoView({block: 'center'})", el)
            assert _in_viewport(browser, el), sel
        sizes = browser.execute_script(  # each text's font size on screen: its size in the drawing × the drawing's scale
            "return [...document.querySelectorAll('#runs svg.chart text')].map(t => { const s = t.ownerSVGElement;"
            " return parseFloat(getComputedStyle(t).fontSize) * s.getBoundingClientRect().width / s.viewBox.baseVal.width; })"
        )
        assert sizes and min(sizes) >= 10, sizes  # was ~4 px: a 640-wide drawing shrunk to the phone's width
        browser.execute_script("window.scrollTo(0, 0)")
        height = browser.execute_script("return document.documentElement.scrollHeight")
        browser.set_window_size(390, min(int(height) + 120, 7000))
        time.sleep(0.5)
        _shot(browser, tmp_path, "390")
    finally:
        browser.quit()


@pytest.mark.slow  # long: a page-behaviour check of tens of seconds
def test_a_long_run_is_drawn_as_its_envelope_zooms_and_shows_its_energy_drift(window, live_service, tmp_path):
    """20 001 samples over t = 0 … 3000: a series faster than the pixels is a band of its range around its mean (no
    aliasing pattern), the energy drift H − H₀ has a plot on its own scale with its size in the title, the last time
    label stays inside the plot, and dragging across a plot zooms every plot to that window."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select, WebDriverWait

    browser = window
    _, url, _ = live_service
    _ready(browser, url)
    Select(browser.find_element(By.ID, "scene")).select_by_value("long-horizon")
    _type(browser, "t_end", "3000")
    _type(browser, "samples", "20001")
    browser.find_element(By.ID, "start-simulate").click()
    card = WebDriverWait(browser, 180).until(
        lambda d: d.find_element(By.CSS_SELECTOR, "#runs article[data-kind=simulate]")
    )
    WebDriverWait(browser, 30).until(lambda d: card.find_elements(By.CSS_SELECTOR, "svg.chart path.band"))
    titles = [t.text for t in card.find_elements(By.CSS_SELECTOR, "svg.chart text.title")]
    assert any(t.startswith("energy drift H − H₀") for t in titles), titles
    drift = next(t for t in titles if t.startswith("energy drift"))
    assert "largest |H − H₀| =" in drift and "of |H₀|" in drift, drift
    # every tick label inside its plot (no "1000(" cut at the right edge)
    out = browser.execute_script(
        "return [...arguments[0].querySelectorAll('svg.chart')].flatMap(s => [...s.querySelectorAll('text.tick')]"
        ".filter(t => t.getBBox().x + t.getBBox().width > s.viewBox.baseVal.width + 0.5).map(t => t.textContent))",
        card,
    )
    assert not out, out
    browser.execute_script("arguments[0].scrollIntoView({block: 'start'})", card)
    time.sleep(0.3)
    _shot(browser, tmp_path, "long-sim")
    # drag across the spin plot from 40 % to 45 % of its width: every plot shows that window
    chart = card.find_elements(By.CSS_SELECTOR, "svg.chart")[1]
    w = chart.size["width"]
    ActionChains(browser).move_to_element_with_offset(chart, int(-0.1 * w), 0).click_and_hold().move_by_offset(
        int(0.05 * w), 0
    ).release().perform()
    WebDriverWait(browser, 10).until(lambda d: card.find_elements(By.CSS_SELECTOR, "button.whole-run"))
    ticks = [
        float(t.text)
        for t in card.find_elements(By.CSS_SELECTOR, "svg.chart")[0].find_elements(By.CSS_SELECTOR, "text.tick")[-3:]
    ]
    assert max(ticks) < 3000 * 0.6 and min(ticks) > 3000 * 0.2, ticks  # the time axis shows the window
    assert not card.find_elements(By.CSS_SELECTOR, "svg.chart path.band")  # zoomed in, every sample drawn
    browser.execute_script("arguments[0].scrollIntoView({block: 'start'})", card)
    time.sleep(0.3)
    _shot(browser, tmp_path, "long-sim-zoom")
    card.find_element(By.CSS_SELECTOR, "button.whole-run").click()
    WebDriverWait(browser, 10).until(lambda d: not card.find_elements(By.CSS_SELECTOR, "button.whole-run"))


@pytest.mark.slow  # long: a page-behaviour check of tens of seconds
def test_a_family_over_decades_a_recording_preview_and_the_ellipse_table_actions(window, live_service, tmp_path):
    """A family over J from 10⁻⁶ to 10⁶ (both ends allowed) is done, followed in ln J, and says where its branch
    ends; a recording job shows its preview; an ellipse of the table starts a simulation from itself and can be
    used as a target; the header says when the service has stopped."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select, WebDriverWait

    browser = window
    proc, url, _ = live_service
    wait = WebDriverWait(browser, 240)
    _ready(browser, url)
    Select(browser.find_element(By.ID, "vary")).select_by_value("J")
    _type(browser, "vary-from", "1e-6")
    _type(browser, "vary-to", "1e6")
    browser.find_element(By.ID, "start-family").click()
    fig = wait.until(lambda d: d.find_element(By.CSS_SELECTOR, "#pictures figure[data-kind=family] .family-ends"))
    assert "the range spans decades: followed in ln J" in fig.text
    assert "branch 0: from J = 1×10⁻⁶ (the range's end) to J = 1×10⁶ (the range's end)" in fig.text, fig.text
    row = browser.find_element(By.CSS_SELECTOR, "#jobs tr[data-kind=family]")
    assert row.get_attribute("data-status") == "done" and "J1" not in row.text
    # the ellipse table: a drawing of each ellipse, "simulate from here", "use as target"
    browser.find_element(By.ID, "find-ellipses").click()
    tr = wait.until(lambda d: d.find_element(By.CSS_SELECTOR, "#ellipses-table tbody tr"))
    assert tr.find_element(By.CSS_SELECTOR, "svg.ellipse-icon ellipse")
    tr.find_element(By.CSS_SELECTOR, "button.as-target").click()
    assert "Target: ellipse 0" in browser.find_element(By.ID, "target-note").text
    _type(browser, "t_end", "10")
    tr.find_element(By.CSS_SELECTOR, "button.from-here").click()
    card = wait.until(lambda d: d.find_element(By.CSS_SELECTOR, "#runs article[data-kind=simulate]"))
    assert "ellipse 0" in card.text
    wait.until(lambda d: card.find_elements(By.CSS_SELECTOR, "svg.ellipse ellipse.target-shape"))
    assert card.find_elements(By.CSS_SELECTOR, "svg.chart line.target")  # λ*, μ*, ϱ* as faint bands
    # a recording job: the body at four times and the recorded trajectory
    _type(browser, "t_end", "20")
    browser.find_element(By.ID, "start-record").click()
    rec = wait.until(lambda d: d.find_element(By.CSS_SELECTOR, "#runs article[data-kind=record]"))
    preview = rec.find_element(By.CSS_SELECTOR, "img.preview")
    wait.until(lambda d: d.execute_script("return arguments[0].complete && arguments[0].naturalWidth", preview) > 1000)
    wait.until(lambda d: rec.find_elements(By.CSS_SELECTOR, "svg.chart path.line"))
    browser.execute_script("arguments[0].scrollIntoView({block: 'start'})", rec)
    time.sleep(0.5)
    _shot(browser, tmp_path, "record-preview")
    browser.set_window_size(1400, 1400)  # the chart and what is said under it
    figure = browser.find_element(By.CSS_SELECTOR, "#pictures figure[data-kind=family]")
    browser.execute_script("arguments[0].scrollIntoView({block: 'start'})", figure)
    time.sleep(0.5)
    _shot(browser, tmp_path, "family-decades")
    _full_height(browser)
    _shot(browser, tmp_path, "1400")
    browser.set_window_size(1400, 900)
    # the service stops: the header no longer says "service ok"
    from flatbody_env.service.launch import stop_service

    stop_service(proc)
    WebDriverWait(browser, 20).until(lambda d: "unreachable" in d.find_element(By.ID, "health").text)
