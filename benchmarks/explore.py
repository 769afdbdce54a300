"""Latency of ``wbcgrade explore``: from a move to the new LUT (and pixels).

    python benchmarks/explore.py [--photo samples/chelsea.jpg] [--presets warm,faded]
                                 [--moves 40] [--browser] [--baseline REV] [--look-only]

**Look moves** (the page's default mode, the grade ``apply`` gives): a studio on
the photo with the first preset, every shipped preset in its picker; over HTTP
(``api/look``, the map and what it is) it times ``--moves`` strength moves and
preset switches, each preset's first visit (loaded then: its styles and look)
and later ones, and the first visits once the background prefetch has loaded
every preset (what a user gets a few seconds after the page opens). With
``--browser``, in headless Chromium, from picking a preset to its pixels drawn
(the page's own measurement).

**Palette moves**: for each preset, starts a studio on the photo (the server and its
job worker, as ``wbcgrade explore`` does), waits for the exact map of the fitted weights,
then replays a drag: ``--moves`` small steps of the point (each moving the
weights by about 0.02 in L1) on a loop around the fitted weights. It times

- **move -> LUT (server)**: what the server computes for one move (the fast
  map on 32^3 grids and a 9^3 smooth map, the correction by the nearest exact
  map, the 33^3 LUT): ``Studio.preview``;
- **move -> LUT (HTTP)**: the same through an HTTP request to the running
  server, the LUT received (what the page waits for);
- with ``--browser``, in headless Chromium, from the pointer event to the
  preview canvas painted (the page's own measurement; needs selenium,
  chromium and chromedriver): **move -> first pixels** (the page's instant
  step, extrapolated from the last exact map and the fast map's slopes
  there) and **move -> server preview pixels** (the fast map drawn);

and how close each preview is to the exact grade (what ``apply
--no-regrain`` gives and the export holds), on the preview picture, in
1/255: at weights an L1 distance d from the nearest exact map known (the
fitted one): extrapolated (the page's first step), the fast map corrected by
the exact map (the server's preview), the fast map alone; and the time of
one exact map (which the page shows once the point rests).

Prints the machine's load average too: the 2-core development machine is
shared, and timings scale with what else runs. ``--baseline REV`` (a git
revision, e.g. ``main``) measures that revision's code in the same run: each
preset is measured in a fresh process for REV (its tree exported from git)
and for this tree, one after the other, so both see the same load.
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if "PYTHONPATH" not in os.environ:  # run from a checkout: its package (--baseline sets it)
    sys.path.insert(0, str(ROOT))


def drag_path(center: np.ndarray, moves: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Weights along a loop around ``center``, each step about 0.02 in L1."""
    n = len(center)
    a, b = rng.normal(size=n), rng.normal(size=n)
    a -= a.mean()
    b -= b.mean()
    a /= np.abs(a).sum()
    b /= np.abs(b).sum()
    radius = 0.02 * moves / (2 * np.pi)
    path = []
    for k in range(moves):
        angle = 2 * np.pi * k / moves
        w = np.clip(center + radius * (np.cos(angle) * a + np.sin(angle) * b), 0, None)
        path.append(w / w.sum())
    return path


def post(port: int, token: str, route: str, body: dict) -> bytes:
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=600)
    data = json.dumps(body).encode()
    connection.request("POST", f"/{token}/api/{route}", data,
                       {"Content-Type": "application/json"})
    response = connection.getresponse()
    payload = response.read()
    connection.close()
    if response.status != 200:
        raise RuntimeError(f"{route}: HTTP {response.status}: {payload[:200]!r}")
    return payload


def summary(values_s: list[float]) -> str:
    ms = sorted(1000 * v for v in values_s)
    p90 = ms[min(len(ms) - 1, int(round(0.9 * (len(ms) - 1))))]
    return f"{statistics.median(ms):7.0f} {p90:7.0f} {ms[-1]:7.0f}"


def headless_chromium(width: int, height: int):
    """A Selenium driver of Debian's headless Chromium (its own throwaway profile)."""
    import shutil

    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", f"--window-size={width},{height}",
                 f"--user-data-dir={tempfile.mkdtemp(prefix='wbcgrade-bench-')}"):
        options.add_argument(flag)
    return webdriver.Chrome(service=Service(shutil.which("chromedriver")
                                            or "/usr/bin/chromedriver"), options=options)


def browser_latencies(url: str, moves: int) -> tuple[list[float], list[float]]:
    """Move-to-pixels latencies (s) measured by the page in headless Chromium:
    (first pixels of each move, pixels of the server's preview)."""
    from selenium.webdriver.common.action_chains import ActionChains

    driver = headless_chromium(1280, 900)
    try:
        driver.get(url)
        deadline = time.monotonic() + 600
        while not driver.execute_script("const p = window.wbcgradeExplore;"
                                        "return p && p.mode() === 'look' && p.grade();"):
            if time.monotonic() > deadline:
                raise RuntimeError("the page did not show its look in 10 min")
            time.sleep(0.1)
        driver.find_element("id", "mode-palette").click()
        while not driver.execute_script(
                "const p = window.wbcgradeExplore, s = p && p.shown();"
                "return s && s.kind === 'exact' && s.version === p.current()"
                " && p.extrapolates();"):
            if time.monotonic() > deadline:
                raise RuntimeError("the page did not get its exact map and slopes in 10 min")
            time.sleep(0.1)
        driver.execute_script("window.wbcgradeExplore.latencies.length = 0")
        point = driver.find_element("id", "point")
        driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", point)
        chain = ActionChains(driver, duration=0).click_and_hold(point)
        for k in range(moves):  # a slow drag: one small step every 120 ms
            angle = 2 * np.pi * k / moves
            chain = chain.move_by_offset(round(4 * np.cos(angle)), round(4 * np.sin(angle))) \
                .pause(0.12)
        chain.release().perform()
        time.sleep(1.0)
        records = driver.execute_script("return window.wbcgradeExplore.latencies")
        return ([r["ms"] / 1000 for r in records if r["first"]],
                [r["ms"] / 1000 for r in records if r["kind"] == "preview"])
    finally:
        driver.quit()


def run_case(photo: str, preset: str, moves: int, browser: bool, rng) -> dict:
    from wbcgrade.color.mapping.remap import apply_color_map
    from wbcgrade.explore.app import start_studio
    from wbcgrade.explore.engine import ExactGrader
    from wbcgrade.explore.settings import settings_from_json

    server = start_studio(photo, preset=preset, prefetch=False)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    studio = server.studio
    session = studio.session
    n = session.n_styles
    try:
        studio.worker.reference(studio.fitted)  # what the page waits for first
        fitted = np.array(studio.fitted.weights)
        path = drag_path(fitted, moves, rng)
        server_s = []
        for seq, w in enumerate(path):
            settings = settings_from_json({"weights": list(w)}, n)
            start = time.perf_counter()
            studio.preview(settings, "bench", seq)
            server_s.append(time.perf_counter() - start)
        http_s = []
        for seq, w in enumerate(drag_path(fitted, moves, rng)):
            start = time.perf_counter()
            post(server.port, server.token, "preview",
                 {"weights": list(w), "client": "http", "seq": seq})
            http_s.append(time.perf_counter() - start)
        first_s, drawn_s = browser_latencies(server.url, moves) if browser else ([], [])
        # accuracy: the preview against the exact grade at distances from the reference
        grader = ExactGrader(session.grader_state())
        picture = session.preview / np.float32(255)
        reference = studio.worker.reference(studio.fitted)
        start = time.perf_counter()
        slopes = grader.slopes(studio.fitted)
        slopes_s = time.perf_counter() - start
        accuracy = []
        direction = np.eye(n)[int(np.argmin(fitted))]  # towards the least used style
        for distance in (0.05, 0.1, 0.2, 0.4):
            step = direction - fitted
            w = fitted + step * min(1.0, distance / max(np.abs(step).sum(), 1e-9))
            settings = settings_from_json({"weights": list(w)}, n)
            start = time.perf_counter()
            exact = grader.color_map(settings)
            exact_s = time.perf_counter() - start
            truth = apply_color_map(picture, exact)
            fast = session.fast_map(settings)
            row = {"distance": float(np.abs(np.array(settings.weights) - np.array(
                reference.settings.weights)).sum()), "exact_s": exact_s}
            move = np.array(settings.weights) - np.array(reference.settings.weights)
            move -= move.sum() * np.array(reference.settings.weights)
            extrapolated = np.clip(reference.exact + np.tensordot(move, slopes, 1), 0, 1)
            for name, lut in (("extrapolated", extrapolated),
                              ("corrected", session.preview_lut(fast, reference.offset)),
                              ("fast", session.preview_lut(fast, None))):
                diff = np.abs(apply_color_map(picture, lut) - truth) * 255
                row[name] = (float(diff.mean()), float(np.percentile(diff, 99)))
            accuracy.append(row)
    finally:
        server.shutdown()
        server.close()
    return {"preset": preset, "styles": n, "server": server_s, "http": http_s,
            "first": first_s, "drawn": drawn_s, "accuracy": accuracy, "slopes_s": slopes_s,
            "preview": f"{session.preview.shape[1]}x{session.preview.shape[0]}"}


def browser_look_latencies(url: str, sources: int) -> list[float]:
    """Pick-a-preset-to-pixels latencies (s) measured by the page in headless Chromium,
    each preset picked in turn (after the first round: all loaded)."""
    from selenium.webdriver.support.select import Select

    driver = headless_chromium(1400, 900)
    try:
        driver.get(url)
        shown = ("const p = window.wbcgradeExplore, s = p && p.shown();"
                 "return s && s.kind === 'exact' && s.version === p.current()"
                 " && p.source() === {};")
        deadline = time.monotonic() + 600
        while not driver.execute_script(shown.format(0)):
            if time.monotonic() > deadline:
                raise RuntimeError("the page did not show its look in 10 min")
            time.sleep(0.05)
        driver.execute_script("window.wbcgradeExplore.latencies.length = 0")
        picker = Select(driver.find_element("id", "source-pick"))
        for index in [*range(1, sources), 0] * 2:
            picker.select_by_index(index)
            while not driver.execute_script(shown.format(index)):
                time.sleep(0.02)
        records = driver.execute_script("return window.wbcgradeExplore.latencies")
        return [r["ms"] / 1000 for r in records if r["kind"] == "look"]
    finally:
        driver.quit()


def look_case(photo: str, preset: str, moves: int, browser: bool) -> dict:
    """Look moves over HTTP: strength moves, preset switches (first and later visits), and
    first visits after the background prefetch."""
    from wbcgrade.explore.app import start_studio

    def timed(server, body) -> float:
        start = time.perf_counter()
        post(server.port, server.token, "look", body)
        return time.perf_counter() - start

    out: dict = {"preset": preset}
    for prefetch in (False, True):
        start = time.perf_counter()
        server = start_studio(photo, preset=preset, prefetch=prefetch)
        started = time.perf_counter() - start
        thread = threading.Thread(target=server.serve_forever, daemon=True)
        thread.start()
        try:
            sources = len(server.studio.choices)
            if prefetch:  # what a user gets a few seconds after the page opens
                deadline = time.monotonic() + 600
                while len(server.studio._studios) < sources or not all(
                        s.session._look is not None for s in server.studio._studios.values()):
                    if time.monotonic() > deadline:
                        raise RuntimeError("the prefetch did not end in 10 min")
                    time.sleep(0.1)
                out["prefetched"] = [timed(server, {"source": i}) for i in range(sources)]
                out["prefetch_s"] = time.perf_counter() - start
                if browser:
                    out["browser"] = browser_look_latencies(server.url, sources)
                continue
            out["start_s"] = started
            out["strength"] = [timed(server, {"strength": round(float(s), 3)})
                               for s in np.linspace(0.0, 2.0, moves)]
            out["first"] = [timed(server, {"source": i}) for i in range(1, sources)]
            out["later"] = [timed(server, {"source": i % sources, "strength": 0.8})
                            for i in range(moves)]
            out["sources"] = sources
        finally:
            server.shutdown()
            server.close()
    return out


def print_look_table(case: dict, photo: str) -> None:
    print(f"look moves (HTTP, api/look: the 33^3 map and what it is), photo {Path(photo).name}, "
          f"opened on preset {case['preset']}, {case['sources']} presets in the picker; "
          f"start {case['start_s']:.1f} s, every preset prefetched {case['prefetch_s']:.1f} s "
          f"after start")
    print(f"{'measure':<44} {'n':>4} {'median':>7} {'p90':>7} {'max':>7}  (ms)")
    rows = [("strength move", case["strength"]),
            ("preset switch, first visit (not prefetched)", case["first"]),
            ("preset switch, later visits", case["later"]),
            ("preset switch, first visit after prefetch", case["prefetched"])]
    if case.get("browser"):
        rows.append(("pick a preset -> pixels drawn (Chromium)", case["browser"]))
    for name, values in rows:
        print(f"{name:<44} {len(values):>4} {summary(values)}")
    print()
    sys.stdout.flush()


def measured_in(tree: Path, args, preset: str) -> dict:
    """:func:`run_case` in a fresh process on the package in ``tree`` (run from there, so
    that the studio's job worker, started with ``python -m``, imports it too)."""
    with tempfile.NamedTemporaryFile(suffix=".json") as out:
        subprocess.run([sys.executable, str(Path(__file__).resolve()),
                        "--photo", str(Path(args.photo).resolve()), "--presets", preset,
                        "--moves", str(args.moves), "--seed", str(args.seed),
                        *(["--browser"] if args.browser else []), "--json", out.name],
                       env={**os.environ, "PYTHONPATH": str(tree)}, cwd=tree, check=True)
        return json.loads(Path(out.name).read_text())[0]


def print_tables(cases: list[dict], moves: int, photo: str, load: tuple[float, float]) -> None:
    print(f"photo {Path(photo).name}, {moves} moves per drag, "
          f"load average {load[0]:.1f} -> {load[1]:.1f} ({os.cpu_count()} cores)")
    print()
    print(f"{'preset (styles)':<16} {'code':<10} {'measure':<22} {'median':>7} {'p90':>7} "
          f"{'max':>7}  (ms)")
    print(f"{'':<16} {'':<10} {'(pixels: ' + cases[0]['preview'] + ' preview)':<22}")
    for case in cases:
        label = f"{case['preset']} ({case['styles']})"
        rows = [("move -> LUT (server)", case["server"]), ("move -> LUT (HTTP)", case["http"])]
        if case["first"]:
            rows.append(("move -> first pixels", case["first"]))
        if case["drawn"]:
            rows.append(("move -> server preview", case["drawn"]))
        for name, values in rows:
            print(f"{label:<16} {case['code']:<10} {name:<22} {summary(values)}")
            label = ""
    print()
    print("preview vs exact grade on the preview picture (1/255: mean / p99), at an L1 "
          "distance d from the nearest exact map")
    print(f"{'preset':<10} {'code':<10} {'d':>5}  {'extrapolated':>14}  {'fast, corrected':>15}  "
          f"{'fast alone':>13}  {'exact map (s)':>13}")
    for case in cases:
        for row in case["accuracy"]:
            cells = "  ".join(f"{row[k][0]:6.2f} / {row[k][1]:5.2f}"
                              for k in ("extrapolated", "corrected", "fast"))
            print(f"{case['preset']:<10} {case['code']:<10} {row['distance']:5.2f}  {cells}  "
                  f"{row['exact_s']:13.1f}")
        print(f"{case['preset']:<10} {case['code']:<10} slopes for {case['styles']} styles: "
              f"{case['slopes_s']:.1f} s (in the worker, after each exact map)")
    sys.stdout.flush()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--photo", default=str(ROOT / "samples" / "chelsea.jpg"))
    parser.add_argument("--presets", default="warm,faded")
    parser.add_argument("--look-only", action="store_true",
                        help="measure the look moves only (no palette drags)")
    parser.add_argument("--moves", type=int, default=40)
    parser.add_argument("--browser", action="store_true",
                        help="also measure move -> pixels in headless Chromium")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--baseline", metavar="REV",
                        help="also measure this git revision's code, in the same run")
    parser.add_argument("--json", help=argparse.SUPPRESS)  # one process's cases, for --baseline
    args = parser.parse_args()
    load_before = os.getloadavg()
    if not args.json:
        print_look_table(look_case(args.photo, args.presets.split(",")[0], args.moves,
                                   args.browser), args.photo)
        if args.look_only:
            return
    if args.baseline:
        with tempfile.TemporaryDirectory(prefix="wbcgrade-baseline-") as tree:
            archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.baseline],
                                     check=True, capture_output=True).stdout
            subprocess.run(["tar", "-x", "-C", tree], input=archive, check=True)
            cases = []
            for preset in args.presets.split(","):
                for code, where in ((args.baseline, Path(tree)), ("this tree", ROOT)):
                    cases.append({**measured_in(where, args, preset), "code": code})
    else:
        rng = np.random.default_rng(args.seed)
        cases = [{**run_case(args.photo, preset, args.moves, args.browser, rng),
                  "code": "this tree"} for preset in args.presets.split(",")]
    if args.json:
        Path(args.json).write_text(json.dumps(cases))
        return
    print_tables(cases, args.moves, args.photo, (load_before[0], os.getloadavg()[0]))


if __name__ == "__main__":
    main()
