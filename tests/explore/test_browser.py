"""The page in a real headless Chromium, as a user drives it.

- It opens on the grade `wbcgrade apply` gives (a preset's look; a style folder's look),
  says which with the source and strength `apply --json` reports; the strength slider
  (from the keyboard), the preset picker, undo and redo steer it; the graded photo it saves
  and the LUT it exports are what the page's `wbcgrade apply` command writes (within
  1/255), and the server writes nothing outside the save folder.
- In the palette mode a drag re-grades the preview, and the exported LUT is what the
  page's command writes.

Needs Debian's ``chromium`` and ``chromium-driver`` (``.ci/run`` installs them) and the
``selenium`` package (the ``test`` extra); skipped with the reason when they are missing.
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from tests.color.conftest import SAMPLES, small_copy
from tests.explore.conftest import WBCGRADE, command_env
from wbcgrade.color.io.images import read_image
from wbcgrade.color.mapping.lut import read_cube
from wbcgrade.color.mapping.remap import apply_color_map, identity_map
from wbcgrade.color.outcome import GradeOutcome, change_words

webdriver = pytest.importorskip("selenium.webdriver", reason="needs selenium (pip install "
                                "'wbcgrade[test]')")
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
DRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
if not (Path(CHROMIUM).exists() and Path(DRIVER).exists()):
    pytest.skip("needs chromium and chromedriver (apt-get install chromium chromium-driver)",
                allow_module_level=True)

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--window-size=1400,900")


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
    # the page's own size, whatever the window's decorations take
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride",
                           {"width": 1400, "height": 900, "deviceScaleFactor": 1,
                            "mobile": False})
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


def look_shown(driver, source: int) -> dict:
    """The grade the page states once it shows the look of picker entry ``source``."""
    exact_shown(driver)
    return wait(driver, f"const p = window.wbcgradeExplore; return p.mode() === 'look' && "
                        f"p.source() === {source} && p.grade();")


def serve(photo: Path, save_dir: Path, **sources):
    from wbcgrade.explore.app import start_studio

    server = start_studio(str(photo), save_dir=save_dir, prefetch=False, **sources)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.1},
                              daemon=True)
    thread.start()
    return server, thread


def stop(server, thread) -> None:
    server.shutdown()
    server.close()
    thread.join(5)


def files(*folders: Path) -> dict:
    """Every file under ``folders`` with its size and modification time."""
    out = {}
    for folder in folders:
        for path in folder.rglob("*"):
            if path.is_file():
                stat = path.stat()
                out[str(path)] = (stat.st_size, stat.st_mtime_ns)
    return out


def apply_json(*args) -> dict:
    """``wbcgrade apply ARGS --json`` (the same photo, another output)."""
    run = subprocess.run([*WBCGRADE, "apply", *map(str, args), "--json"], capture_output=True,
                         text=True, timeout=600, env=command_env())
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


def run_command(command: str, output: Path) -> np.ndarray:
    """Run the page's ``wbcgrade apply`` command, writing ``output``; -> its pixels."""
    args = shlex.split(command)
    assert args[:2] == ["wbcgrade", "apply"]
    run = subprocess.run([*WBCGRADE, *args[1:], "-o", str(output)], capture_output=True,
                         text=True, timeout=600, env=command_env())
    assert run.returncode == 0, run.stderr
    return read_image(output).pixels[:, :, :3]


def downloaded(downloads: Path, name: str) -> Path:
    path = downloads / name
    deadline = time.monotonic() + 60
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    return path


def click(driver, element_id: str) -> None:
    driver.find_element("id", element_id).click()


@pytest.mark.slow
def test_a_preset_opens_on_apply_s_grade_and_saves_what_apply_writes(browser, downloads,
                                                                     tmp_path):
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.select import Select

    folder = tmp_path / "photos"
    folder.mkdir()
    photo = small_copy(SAMPLES / "coffee.jpg", folder / "coffee.png", width=120)
    save_dir = tmp_path / "saved"
    save_dir.mkdir()
    expected = apply_json(photo, "--preset", "warm", "--no-regrain", "-o", tmp_path / "a.png")
    before = files(folder, SAMPLES)
    server, thread = serve(photo, save_dir, preset=["warm"])
    try:
        browser.get(server.url)
        grade = look_shown(browser, 0)
        # the page states the grade apply gives: its source and strength
        outcome = expected["outcome"]
        assert grade["source"] == outcome["source"] == "preset-look"
        assert grade["strength"] == outcome["strength"] == 1.0
        words = browser.find_element("id", "grade-words").text
        assert "preset warm" in words and "the preset's own look" in words
        assert "this photo's colours move " + change_words(outcome["mean_change_255"]) in words
        # the page shows that grade: apply's map on the preview picture
        studio = server.studio
        look = studio.source(0).session.look_grade()
        preview = studio.session.preview / np.float32(255)
        shown = pixels(browser, "after")
        assert np.abs(shown - apply_color_map(preview, look.color_map) * 255).max() <= 1.0
        # save and export stay in view at 1400 x 900
        for element_id in ("save", "export-cube", "command", "undo"):
            box = browser.execute_script(
                f"return document.getElementById('{element_id}').getBoundingClientRect();")
            assert 0 <= box["top"] and box["bottom"] <= 900, (element_id, box)
        # the strength, from the keyboard: 40 steps down
        slider = browser.find_element("id", "strength")
        slider.send_keys(*[Keys.ARROW_LEFT] * 40)
        wait(browser, "return window.wbcgradeExplore.strength() === 0.6")
        weaker = pixels(browser, "after")
        expected_weaker = apply_color_map(preview, look.color_map, 0.6) * 255
        assert np.abs(weaker - expected_weaker).max() <= 1.0
        # another preset from the picker
        picker = Select(browser.find_element("id", "source-pick"))
        labels = [option.text for option in picker.options]
        assert labels[0] == "preset warm" and "preset faded" in labels
        picker.select_by_visible_text("preset faded")
        faded = labels.index("preset faded")
        grade = look_shown(browser, faded)
        assert grade["source"] == "preset-look"
        assert np.abs(pixels(browser, "after").astype(int) - weaker).mean() > 0.5
        # undo goes back to warm at 60 %, redo to faded
        assert browser.execute_script("return window.wbcgradeExplore.history()") == [3, 0]
        browser.find_element("tag name", "body").send_keys(Keys.CONTROL, "z")
        look_shown(browser, 0)
        assert browser.execute_script("return window.wbcgradeExplore.strength()") == 0.6
        click(browser, "redo")
        look_shown(browser, faded)
        # save the graded photo, export the LUT, run the command the page gives
        click(browser, "save")
        saved_name = wait(browser, "return document.body.dataset.saved")
        click(browser, "export-cube")
        lut_name = wait(browser, "return document.body.dataset.exported")
        command = browser.find_element("id", "command").text
        assert command == browser.execute_script("return document.body.dataset.savedCommand")
        assert "--preset faded" in command and "--strength 0.6" in command
        # a blend of two looks: 30 % warm into faded, saved with its grade file
        Select(browser.find_element("id", "blend-pick")).select_by_visible_text(
            "with preset warm")
        browser.find_element("id", "blend-amount").send_keys(*[Keys.ARROW_LEFT] * 20)
        wait(browser, "const b = window.wbcgradeExplore.blend(); return b && b.amount === 0.3")
        blended = wait(browser, "const g = window.wbcgradeExplore.grade();"
                                "return g.source === 'blend' && g.amount === 0.3 && g;")
        assert "70 % preset faded and 30 % preset warm" in blended["words"]
        warm = studio.source(0).session.look_grade().color_map
        mixed = 0.7 * studio.source(faded).session.look_grade().color_map + 0.3 * warm
        expected_blend = apply_color_map(preview, mixed, 0.6) * 255
        wait(browser, "const s = window.wbcgradeExplore.shown();"
                      "return s.kind === 'exact' && s.version === window.wbcgradeExplore"
                      ".current();")
        assert np.abs(pixels(browser, "after") - expected_blend).max() <= 1.0
        click(browser, "save")
        blend_name = wait(browser, f"const n = document.body.dataset.saved;"
                                   f"return n !== '{saved_name}' && n;")
        blend_command = browser.find_element("id", "command").text
        assert "--look" in blend_command and blend_command.endswith("--no-regrain")
    finally:
        stop(server, thread)
    after = files(folder, SAMPLES)
    assert after == before, "the server wrote beside the photo or the samples"
    blend_grade = Path(blend_name).stem + ".grade.json"
    assert sorted(p.name for p in save_dir.iterdir()) == sorted([saved_name, blend_name,
                                                                blend_grade])
    blended_by_apply = run_command(blend_command, tmp_path / "blend.png")
    saved_blend = read_image(save_dir / blend_name).pixels[:, :, :3]
    assert np.abs(saved_blend - blended_by_apply).max() <= 1 / 255 + 1e-6
    applied = run_command(command, tmp_path / "applied.png")
    saved = read_image(save_dir / saved_name).pixels[:, :, :3]
    assert saved.shape == applied.shape == read_image(photo).pixels[:, :, :3].shape
    assert np.abs(saved - applied).max() <= 1 / 255 + 1e-6
    table = read_cube(downloaded(downloads, lut_name)).table
    through_lut = apply_color_map(read_image(photo).pixels[:, :, :3], table.astype(np.float32))
    assert np.abs(applied - through_lut).max() <= 1 / 255 + 1e-6


@pytest.mark.slow
def test_a_style_folder_opens_on_its_look_with_apply_s_strength(browser, tmp_path,
                                                              monkeypatch):
    styles = tmp_path / "styles"
    styles.mkdir()
    for name in ("flower", "sunset", "astronaut"):
        small_copy(SAMPLES / f"{name}.jpg", styles / f"{name}.png", width=96)
    folder = tmp_path / "photos"
    folder.mkdir()
    photo = small_copy(SAMPLES / "chelsea.jpg", folder / "cat.png", width=120)
    save_dir = tmp_path / "saved"
    save_dir.mkdir()
    cache = tmp_path / "cache"
    monkeypatch.setenv("WBCGRADE_CACHE_DIR", str(cache))
    before = files(folder, styles)
    server, thread = serve(photo, save_dir, style_dir=str(styles))
    try:
        browser.get(server.url)
        grade = look_shown(browser, 0)
        words = browser.find_element("id", "grade-words").text
        # a faint set look made stronger: 150 %, from the keyboard
        from selenium.webdriver.common.keys import Keys

        browser.find_element("id", "strength").send_keys(*[Keys.ARROW_RIGHT] * 50)
        wait(browser, "return window.wbcgradeExplore.strength() === 1.5")
        studio = server.studio
        look = studio.session.look_grade()
        stronger = np.clip(identity_map(33) + 1.5 * (look.color_map - identity_map(33)), 0, 1)
        expected_pixels = apply_color_map(studio.session.preview / np.float32(255), stronger)
        assert np.abs(pixels(browser, "after") - expected_pixels * 255).max() <= 1.0
        stated = wait(browser, "const g = window.wbcgradeExplore.grade();"
                               "return g.blend === 1.5 && g;")
        assert stated["strength"] == pytest.approx(1.5 * grade["strength"], abs=1e-3)
        click(browser, "save")
        saved_name = wait(browser, "return document.body.dataset.saved")
        command = browser.find_element("id", "command").text
    finally:
        stop(server, thread)
    assert files(folder, styles) == before, "the server wrote beside the photo or the styles"
    assert sorted(p.name for p in save_dir.iterdir()) == [saved_name]
    # apply --json on the same photo (the look read back from the same cache)
    expected = apply_json(photo, "--style", styles, "--no-regrain", "-o", tmp_path / "a.png")
    outcome = expected["outcome"]
    assert grade["source"] == outcome["source"]
    assert grade["source"] in ("set-look", "own-scene")
    assert grade["strength"] == pytest.approx(outcome["strength"], abs=1e-4)
    assert grade["look_strength"] == pytest.approx(outcome["look_strength"], abs=1e-4)
    assert grade["blend"] == outcome["blend"] == 1.0
    # the page says what apply says: the set look's sureness, the share applied, the strength
    what, strength = GradeOutcome.from_dict(outcome).source_words()
    said = what if strength is None else f"{what}, strength {strength:.2f}"
    assert said in words and "style folder styles" in words
    assert "--strength 1.5" in command
    applied = run_command(command, tmp_path / "applied.png")
    saved = read_image(save_dir / saved_name).pixels[:, :, :3]
    assert np.abs(saved - applied).max() <= 1 / 255 + 1e-6
    assert os.environ["WBCGRADE_CACHE_DIR"] == str(cache)


@pytest.mark.slow
def test_the_palette_mode_drags_and_exports_what_apply_writes(server, browser, downloads,
                                                             photo, tmp_path):
    studio = server.studio
    browser.get(server.url)
    look_shown(browser, 0)
    click(browser, "mode-palette")
    # the fitted mix is shown: first the preview, then the exact map
    shown = exact_shown(browser)
    assert browser.execute_script("return window.wbcgradeExplore.mode()") == "palette"
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
    browser.execute_script("arguments[0].scrollIntoView({block: 'center'})", point)
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
    click(browser, "export-cube")
    name = wait(browser, "return document.body.dataset.exported")
    table = read_cube(downloaded(downloads, name)).table
    assert table.shape == (33, 33, 33, 3)
    command = browser.find_element("id", "command").text
    assert f"--weights {shown['weightsText']} --no-regrain" in command
    assert shlex.split(command)[:3] == ["wbcgrade", "apply", str(photo)]
    graded = run_command(command, tmp_path / "palette.png")
    original = read_image(photo).pixels[:, :, :3]
    through_lut = apply_color_map(original, table.astype(np.float32))
    assert np.abs(graded - through_lut).max() <= 1 / 255 + 1e-6
    # undo: back to the fitted mix
    click(browser, "undo")
    shown = exact_shown(browser)
    assert shown["weights"] == list(studio.fitted.weights)
