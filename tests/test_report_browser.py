"""The report page in headless Chromium (Selenium, Debian's chromium + chromium-driver, WebGL in
SwiftShader): it opens without errors, colours change the pixels, picking shows a point's values,
line layers pick and toggle, no WebGL gives a message, an index page works, 1 M points load.

Screenshots are kept in tests/artifacts/report/ (git-ignored).
"""
from __future__ import annotations

import io as _io
import os
import re
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.actions.action_builder import ActionBuilder
from selenium.webdriver.common.by import By

from lidarfx.cloud import PointCloud
from lidarfx.report import Report
from lidarfx.report._encode import encode_attribute

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
ARTIFACTS = Path(__file__).resolve().parent / "artifacts" / "report"
FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--window-size=1280,900",
         "--force-device-scale-factor=1"]


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    missing = [str(p) for p in (CHROMIUM, CHROMEDRIVER) if not p.exists()]
    if missing:
        pytest.fail(f"browser tests need Debian's Chromium: {', '.join(missing)} missing; install them with "
                    "'apt-get install -y chromium chromium-driver' (.ci/run does)", pytrace=False)
    os.environ.setdefault("SE_AVOID_STATS", "true")  # Selenium Manager: no statistics, and no download
    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for flag in FLAGS + [f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}"]:
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=opts)
    driver.set_page_load_timeout(90)
    driver.set_script_timeout(30)
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    yield driver
    driver.quit()


def open_page(driver, page: Path, timeout: float = 60.0) -> float:
    """Load ``page`` and wait for the viewer to be ready (or to fail); seconds from the request."""
    t0 = time.perf_counter()
    driver.get(page.as_uri())
    state = None
    while time.perf_counter() - t0 < timeout:
        state = driver.execute_script(
            "const h = window.lidarfxViewer; return h && {ready: h.ready, errors: h.errors, webgl: h.webgl};")
        if state is None or state["ready"] or state["errors"] or state.get("webgl") is False:
            break
        time.sleep(0.05)
    return time.perf_counter() - t0


def hook(driver, expr: str, *args):
    return driver.execute_script(f"return window.lidarfxViewer.{expr};", *args)


def next_frames(driver) -> None:
    """Wait until two animation frames have passed (a requested redraw is on screen)."""
    driver.execute_async_script("const done = arguments[0]; requestAnimationFrame(() => requestAnimationFrame(done));")


def severe(driver) -> list[dict]:
    return [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def canvas_pixels(driver, name: str) -> np.ndarray:
    canvas = driver.find_element(By.CSS_SELECTOR, "canvas.lfx-canvas")
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", canvas)
    png = canvas.screenshot_as_png
    path = ARTIFACTS / f"{name}.png"
    path.write_bytes(png)
    print(f"screenshot: {path}")
    return np.asarray(Image.open(_io.BytesIO(png)).convert("RGB")).astype(np.int16)


def click_at(driver, x: float, y: float) -> None:
    """Click the canvas at CSS pixels (x, y) from its top-left corner (the nearest whole pixel of
    the viewport: the W3C pointer actions take integer positions)."""
    left, top = driver.execute_script(
        "const c = document.querySelector('canvas.lfx-canvas'); c.scrollIntoView({block: 'center'});"
        "const r = c.getBoundingClientRect(); return [r.left, r.top];")
    actions = ActionBuilder(driver)
    actions.pointer_action.move_to_location(round(left + x), round(top + y))
    actions.pointer_action.click()
    actions.perform()


def panel_rows(driver) -> dict[str, str]:
    panel = driver.find_element(By.CSS_SELECTOR, ".lfx-pick")
    rows = panel.find_elements(By.CSS_SELECTOR, "tr")
    return {r.get_attribute("data-name"): r.find_element(By.TAG_NAME, "td").text for r in rows}


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A 4,000-point tilted plane (classes by x, planarity along y) with a wire layer above it."""
    rng = np.random.default_rng(7)
    n = 4000
    x, y = rng.uniform(0, 60, n), rng.uniform(0, 40, n)
    xyz = np.column_stack([x + 652_000.0, y + 6_862_000.0, 0.1 * x + 100.0])
    cloud = PointCloud(xyz, {
        "classification": np.where(x < 30, 2, 6).astype(np.uint8),
        "intensity": rng.integers(0, 3000, n).astype(np.uint16),
        "planarity": (y / 40.0).astype(np.float32),
    })
    wire = np.array([[652_005.0, 6_862_005.0, 115.0], [652_055.0, 6_862_035.0, 119.0]])
    rep = Report("Browser test scene", command="pytest tests/test_report_browser.py")
    rep.add_summary({"points": n, "wires": 1})
    rep.add_cloud(cloud, labels={"classification": {6: "roof"}})
    rep.add_lines("wires", [wire], properties=[{"span_m": 58.4, "sag_m": 1.25}])
    page = rep.write(tmp_path_factory.mktemp("scene"))
    step = encode_attribute("planarity", cloud["planarity"])[0]["scale"]
    return {"page": page, "cloud": cloud, "wire": wire, "planarity_step": step}


def test_opens_and_draws_without_errors(browser, scene):
    seconds = open_page(browser, scene["page"])
    assert hook(browser, "errors") == [] and hook(browser, "ready") is True, f"not ready after {seconds:.1f} s"
    assert severe(browser) == []
    assert browser.title == "Browser test scene"
    assert hook(browser, "attributes") == ["classification", "z", "intensity", "planarity"]
    legend = browser.find_element(By.CSS_SELECTOR, ".lfx-legend").text
    assert "2 ground" in legend and "6 roof" in legend
    px = canvas_pixels(browser, "scene-classification")
    assert (np.abs(px - px[0, 0]).sum(axis=2) > 30).mean() > 0.01  # points drawn over the background


def test_colour_attribute_changes_pixels(browser, scene):
    open_page(browser, scene["page"])
    before = canvas_pixels(browser, "scene-before")
    hook(browser, "colourBy('planarity')")
    next_frames(browser)
    after = canvas_pixels(browser, "scene-planarity")
    changed = (np.abs(after - before).sum(axis=2) > 30).mean()
    assert changed > 0.03, changed
    assert "planarity (2–98 %)" in browser.find_element(By.CSS_SELECTOR, ".lfx-legend").text
    assert browser.find_element(By.ID, "lfx-colour").get_attribute("value") == "planarity"
    assert hook(browser, "errors") == [] and severe(browser) == []


def test_pick_shows_the_point_values(browser, scene):
    open_page(browser, scene["page"])
    cloud = scene["cloud"]
    for i in range(0, len(cloud), 37):
        s = hook(browser, "screenOf(arguments[0])", i)
        if s and hook(browser, "pickAt(arguments[0], arguments[1])", *s) == i and \
                hook(browser, "viewer.lineAt(arguments[0], arguments[1])", *s) is None:
            break
    else:
        pytest.fail("no point of the scene is pickable at its own screen position")
    click_at(browser, *s)
    title = browser.find_element(By.CSS_SELECTOR, ".lfx-pick-title").text
    assert title == f"point {i}"
    rows = panel_rows(browser)
    for k, axis in enumerate("xyz"):
        assert abs(float(rows[axis]) - cloud.xyz[i, k]) < 2e-3
    cls = int(cloud["classification"][i])
    assert rows["classification"] == f"{cls} ({'ground' if cls == 2 else 'roof'})"
    assert rows["intensity"] == str(cloud["intensity"][i])
    assert abs(float(rows["planarity"]) - cloud["planarity"][i]) <= scene["planarity_step"]
    next_frames(browser)
    canvas_pixels(browser, "scene-picked")
    assert hook(browser, "errors") == [] and severe(browser) == []


def test_line_layer_picks_and_toggles(browser, scene):
    open_page(browser, scene["page"])
    mid = scene["wire"].mean(axis=0)
    s = hook(browser, "screenOfXYZ(arguments[0], arguments[1], arguments[2])", *mid.tolist())
    click_at(browser, *s)
    assert browser.find_element(By.CSS_SELECTOR, ".lfx-pick-title").text == "wires: line 1"
    assert panel_rows(browser) == {"vertices": "2", "span_m": "58.4", "sag_m": "1.25"}
    browser.find_element(By.CSS_SELECTOR, ".lfx-close").click()
    next_frames(browser)
    with_wire = canvas_pixels(browser, "scene-wire-on")
    browser.find_element(By.CSS_SELECTOR, "input[data-layer='wires']").click()
    next_frames(browser)
    without = canvas_pixels(browser, "scene-wire-off")
    assert (np.abs(with_wire - without).sum(axis=2) > 30).sum() > 50
    assert hook(browser, "errors") == [] and severe(browser) == []


def test_without_webgl_a_message(browser, scene):
    script = browser.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {
        "source": "HTMLCanvasElement.prototype.getContext = function () { return null; };"})
    try:
        open_page(browser, scene["page"])
        text = browser.find_element(By.ID, "lidarfx-viewer").text
    finally:
        browser.execute_cdp_cmd("Page.removeScriptToEvaluateOnNewDocument", {"identifier": script["identifier"]})
    assert "WebGL 2 is not available" in text
    assert hook(browser, "webgl") is False and hook(browser, "errors") == [] and severe(browser) == []
    assert "Browser test scene" in browser.find_element(By.TAG_NAME, "h1").text  # the rest of the page is there


def test_index_page_without_cloud(browser, tmp_path):
    rep = Report("All runs")
    rep.add_link("run 1", "run1/index.html", "6 wires")
    rep.add_table("runs", [{"run": 1, "wires": 6, "seconds": 12.5}])
    page = rep.write(tmp_path)
    browser.get(page.as_uri())
    assert browser.execute_script("return window.lidarfxViewer === undefined")
    link = browser.find_element(By.LINK_TEXT, "run 1")
    assert link.get_attribute("href").endswith("run1/index.html")
    assert severe(browser) == []


def test_a_million_points(browser, tmp_path):
    rng = np.random.default_rng(1)
    n = 1_000_000
    x, y = rng.uniform(0, 500, n), rng.uniform(0, 300, n)
    z = 5 * np.sin(x / 40) + 3 * np.cos(y / 30) + rng.normal(0, 0.05, n)
    cloud = PointCloud(np.column_stack([x + 652_000.0, y + 6_862_000.0, z + 100.0]), {
        "classification": rng.choice([1, 2, 3, 5, 6], n).astype(np.uint8),
        "intensity": rng.integers(0, 4000, n).astype(np.uint16),
        "planarity": rng.random(n).astype(np.float32),
        "gps_time": rng.uniform(3e8, 3e8 + 1000, n),
    })
    rep = Report("One million points")
    rep.add_cloud(cloud)
    page = rep.write(tmp_path)
    t0 = time.perf_counter()
    seconds = open_page(browser, page, timeout=90)
    assert hook(browser, "ready") is True and hook(browser, "errors") == [], f"not ready after {seconds:.1f} s"
    next_frames(browser)  # the first frame is on screen
    drawn = time.perf_counter() - t0
    assert hook(browser, "n") == n
    print(f"1 M points: page {page.stat().st_size / 1e6:.1f} MB, ready after {seconds:.1f} s, "
          f"first frame on screen after {drawn:.1f} s")
    assert drawn < 60
    # from the top the highest point is the one seen at its own position
    browser.execute_script("window.lidarfxViewer.viewer.fitView(true)")
    top = int(np.argmax(cloud.z))
    s = hook(browser, "screenOf(arguments[0])", top)
    t0 = time.perf_counter()
    assert hook(browser, "pickAt(arguments[0], arguments[1])", *s) == top
    print(f"1 M points: pickAt {time.perf_counter() - t0:.2f} s")
    click_at(browser, *s)
    assert browser.find_element(By.CSS_SELECTOR, ".lfx-pick-title").text == f"point {top}"
    assert re.fullmatch(r"\d+ \(.+\)", panel_rows(browser)["classification"])
    next_frames(browser)
    canvas_pixels(browser, "million-top-picked")
    assert hook(browser, "errors") == [] and severe(browser) == []
