"""The page in a real headless Chromium: it loads, shows the grade, a drag re-grades the
preview, and the exported LUT applied to the photo is what the page's `wbcgrade apply`
command writes (within 1/255).

Needs Debian's ``chromium`` and ``chromium-driver`` (``.ci/run`` installs them) and the
``selenium`` package (the ``test`` extra); skipped with the reason when they are missing.
"""

from __future__ import annotations

import shlex
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from tests.explore.conftest import WBCGRADE, command_env
from wbcgrade.color.imageio import read_image
from wbcgrade.color.lut import read_cube
from wbcgrade.color.remap import apply_color_map

webdriver = pytest.importorskip("selenium.webdriver", reason="needs selenium (pip install "
                                "'wbcgrade[test]')")
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
DRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
if not (Path(CHROMIUM).exists() and Path(DRIVER).exists()):
    pytest.skip("needs chromium and chromedriver (apt-get install chromium chromium-driver)",
                allow_module_level=True)

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--window-size=1280,900")


@pytest.fixture(scope="module")
def downloads(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("downloads")


@pytest.fixture(scope="module")
def browser(tmp_path_factory, downloads):
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}")
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    driver.execute_cdp_cmd("Browser.setDownloadBehavior",
                           {"behavior": "allow", "downloadPath": str(downloads)})
    yield driver
    driver.quit()


def wait(driver, script, timeout=300.0, poll=0.1):
    """The first truthy value ``script`` returns (JavaScript), or a failed test."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = driver.execute_script(script)
        if value:
            return value
        time.sleep(poll)
    raise AssertionError(f"timed out waiting for: {script}")


def pixels(driver, canvas: str) -> np.ndarray:
    data = driver.execute_script(
        f"const c = document.getElementById('{canvas}');"
        "return [c.width, c.height, Array.from(c.getContext('2d')"
        ".getImageData(0, 0, c.width, c.height).data)];")
    width, height, flat = data
    return np.asarray(flat, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]


def exact_shown(driver) -> dict:
    """What the page shows once it shows the exact map of its current settings."""
    return wait(driver, "const p = window.wbcgradeExplore, s = p && p.shown();"
                        "return s && s.kind === 'exact' && s.version === p.current() && s;")


def test_the_page_grades_drags_and_exports_what_apply_writes(server, browser, downloads,
                                                            photo):
    studio = server.studio
    browser.get(server.url)
    # it loads, and the fitted grade is shown: first the preview, then the exact map
    wait(browser, "return window.wbcgradeExplore && window.wbcgradeExplore.renders > 0")
    shown = exact_shown(browser)
    assert shown["weights"] == list(studio.fitted.weights)
    before, after = pixels(browser, "before"), pixels(browser, "after")
    assert np.array_equal(before, studio.session.preview)
    assert np.abs(after.astype(int) - before).mean() > 3  # the grade is visible
    # the page applies the LUT as the library does (trilinear), to the 8-bit preview
    exact = studio.worker.reference(studio.fitted).exact
    expected = apply_color_map(before / np.float32(255), exact) * 255
    assert np.abs(after - expected).max() <= 1.0
    # a drag of the point re-grades the preview
    from selenium.webdriver.common.action_chains import ActionChains

    renders = browser.execute_script("return window.wbcgradeExplore.renders")
    point = browser.find_element("id", "point")
    ActionChains(browser).click_and_hold(point).move_by_offset(-20, 25).pause(0.2) \
        .move_by_offset(-25, 20).release().perform()
    wait(browser, f"return window.wbcgradeExplore.renders > {renders + 1}")
    weights = browser.execute_script("return window.wbcgradeExplore.weights()")
    assert min(weights) >= 0 and sum(weights) == pytest.approx(1, abs=1e-9)
    assert np.abs(np.subtract(weights, studio.fit.weights)).sum() > 0.1
    moved = pixels(browser, "after")
    assert np.abs(moved.astype(int) - after).mean() > 0.5
    # once the point rests, the exact map of the new weights is shown
    shown = exact_shown(browser)
    assert shown["weights"] == pytest.approx(weights, abs=1e-4)
    # export the .cube (33) from the page, and run the command the page gives
    browser.find_element("id", "export-cube").click()
    name = wait(browser, "return document.body.dataset.exported")
    lut_path = downloads / name
    deadline = time.monotonic() + 60
    while not lut_path.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    table = read_cube(lut_path).table
    assert table.shape == (33, 33, 33, 3)
    command = browser.find_element("id", "command").text
    assert f"--weights {shown['weightsText']} --no-regrain" in command
    args = shlex.split(command)
    assert args[:3] == ["wbcgrade", "apply", str(photo)]
    run = subprocess.run([*WBCGRADE, *args[1:]], capture_output=True, text=True, timeout=600,
                         env=command_env())
    assert run.returncode == 0, run.stderr
    graded = read_image(photo.with_name(f"{photo.stem}_graded.png")).pixels[:, :, :3]
    original = read_image(photo).pixels[:, :, :3]
    through_lut = apply_color_map(original, table.astype(np.float32))
    assert np.abs(graded - through_lut).max() <= 1 / 255 + 1e-6
