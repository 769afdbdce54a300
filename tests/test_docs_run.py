"""Every shell example of the README and of ``docs/*.md`` runs, in order, as a new user runs
them: README first, then the pages in the order the README's documentation table lists them,
one after another in the same fresh home folder (``~/graded`` is new), from a fresh copy of the
clone's folder whose sample photos are made small (so that CI stays quick). A command that
fails (non-zero exit) fails the test, with its page, line and output.

A few commands are not run, each for a reason listed in :data:`NOT_RUN` (installing packages,
the test suite itself, benchmarks that take minutes); ``wbcgrade explore`` (a server until
Ctrl-C) is started, waited for until it serves its page, then stopped with Ctrl-C.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.test_readme import README, ROOT, bash_blocks

#: Commands not run: (pattern of the command, why). A line whose every command is one of these
#: is not run; in a line with others, they are replaced by ``true``.
NOT_RUN = [
    (r"(python -m )?pip install [^&;|#]*", "installs packages (the test runs in the installed "
                                           "environment)"),
    (r"python -m pytest [^&;|#]*", "the test suite itself"),
    (r"python benchmarks/[\w.]+\.py[^&;|#]*",
     "a benchmark: minutes each, run by hand (docs/benchmarks.md, docs/performance.md)"),
]
#: The long side of the sample photos in the fresh folder.
SMALL = 256


def pages_in_order() -> list[Path]:
    """The README, then every docs page in the order the README's documentation table lists
    them (then any page it does not list)."""
    table = re.findall(r"^\| \[(docs/[\w.-]+\.md)\]", README.read_text("utf-8"), re.M)
    listed = [ROOT / p for p in table]
    rest = [p for p in sorted((ROOT / "docs").glob("*.md")) if p not in listed]
    return [README, *listed, *rest]


def logical_lines(code: str) -> list[str]:
    """The lines of a shell block, continuation lines joined, comment-only and empty lines
    dropped."""
    joined = code.replace("\\\n", " ")
    return [line for line in joined.splitlines()
            if line.strip() and not line.strip().startswith("#")]


def without_skipped(line: str) -> str | None:
    """``line`` with the commands of :data:`NOT_RUN` replaced by ``true``; None when nothing
    is left to run."""
    out = line
    for pattern, _ in NOT_RUN:
        out = re.sub(r"(?<![\w/.-])" + pattern, "true ", out)
    words = [w for w in re.split(r"\s*(?:&&|;|\|\|)\s*", out.split(" #", 1)[0].strip()) if w]
    return None if all(w.strip() == "true" for w in words) else out


def examples() -> list[tuple[str, str]]:
    """(page:line, shell line) of every example, in the order a reader runs them."""
    found = []
    for page in pages_in_order():
        for start, code in bash_blocks(page.read_text("utf-8")):
            for line in logical_lines(code):
                found.append((f"{page.relative_to(ROOT).as_posix()}:{start}", line))
    return found


def fresh_clone(folder: Path) -> Path:
    """A copy of the clone's folder with the sample photos made small: the photos (long side
    :data:`SMALL`), the clip as it is, the rest of ``samples/`` and the folders the examples
    read linked."""
    from PIL import Image

    clone = folder / "clone"
    samples = clone / "samples"
    samples.mkdir(parents=True)
    for item in (ROOT / "samples").iterdir():
        if item.suffix.lower() in (".jpg", ".jpeg"):
            with Image.open(item) as image:
                exif = image.info.get("exif")
                image.thumbnail((SMALL, SMALL))
                image.save(samples / item.name, quality=90, **({"exif": exif} if exif else {}))
        else:
            (samples / item.name).symlink_to(item)
    for name in ("examples", "benchmarks", "presets", "pyproject.toml"):
        (clone / name).symlink_to(ROOT / name)
    return clone


def shims(folder: Path) -> Path:
    """A ``bin`` folder whose ``wbcgrade`` and ``python`` are this interpreter's."""
    bin_dir = folder / "bin"
    bin_dir.mkdir()
    for name, target in (("wbcgrade", f'"{sys.executable}" -m wbcgrade'),
                         ("python", f'"{sys.executable}"')):
        shim = bin_dir / name
        shim.write_text(f'#!/bin/sh\nexec {target} "$@"\n')
        shim.chmod(0o755)
    return bin_dir


def run_server(line: str, cwd: Path, env: dict[str, str], log: Path,
               timeout: float = 120) -> tuple[int, str]:
    """Start a command that serves until Ctrl-C (``--no-browser`` added), wait until it prints
    its address, then send Ctrl-C. Returns (exit status, output): 0 when it served and then
    stopped cleanly."""
    with open(log, "w") as out:
        process = subprocess.Popen(["bash", "-c", f"exec {line} --no-browser"], cwd=cwd,
                                   env=env, stdout=out, stderr=subprocess.STDOUT)
        try:
            deadline = time.monotonic() + timeout
            while (time.monotonic() < deadline and process.poll() is None
                   and "http://127.0.0.1" not in log.read_text()):
                time.sleep(0.2)
            served = "http://127.0.0.1" in log.read_text()
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
                process.wait(30)
        finally:  # never left running, whatever happened here
            if process.poll() is None:
                process.kill()
                process.wait()
    stopped = process.returncode in (0, 130, -signal.SIGINT)
    return (0 if served and stopped else process.returncode or 1), log.read_text()


def test_not_run_covers_only_what_it_says():
    assert without_skipped("python -m pip install '.[test]' && python -m pytest -q") is None
    assert without_skipped("python -m pip install . && mkdir -p ~/graded && wbcgrade apply x") \
        == "true && mkdir -p ~/graded && wbcgrade apply x"
    assert without_skipped("python benchmarks/apply.py --floors   # a comment") is None
    assert without_skipped("wbcgrade apply samples/a.jpg -o ~/graded/b.jpg") is not None
    assert pages_in_order()[0] == README and len(pages_in_order()) == len(
        list((ROOT / "docs").glob("*.md"))) + 1


@pytest.mark.slow
def test_every_shell_example_runs_in_order(tmp_path):
    clone, home = fresh_clone(tmp_path), tmp_path / "home"
    home.mkdir()
    env = {**os.environ, "HOME": str(home), "PATH": f"{shims(tmp_path)}{os.pathsep}"
           f"{os.environ.get('PATH', '')}", "PYTHONPATH": os.pathsep.join(
               filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
           "WBCGRADE_CACHE_DIR": str(tmp_path / "cache"), "BROWSER": "true"}
    env.pop("XDG_CACHE_HOME", None)
    failed, ran, times = [], 0, []
    for where, line in examples():
        command = without_skipped(line)
        if command is None:
            continue
        started = time.monotonic()
        if re.match(r"\s*wbcgrade explore ", command):
            status, output = run_server(command.split(" #", 1)[0], clone, env,
                                        tmp_path / "server.log")
        else:
            run = subprocess.run(["bash", "-euo", "pipefail", "-c", command], cwd=clone,
                                 env=env, capture_output=True, text=True, timeout=600)
            status, output = run.returncode, run.stdout + run.stderr
        times.append((time.monotonic() - started, where, line[:70]))
        ran += 1
        if status != 0:
            failed.append(f"{where}: `{line.strip()}` exits {status}:\n{output[-1500:]}")
    slowest = sorted(times, reverse=True)[:5]
    print("slowest:", *(f"{t:5.1f} s {w} {c}" for t, w, c in slowest), sep="\n  ")
    assert ran > 40
    assert not failed, "\n\n".join(failed)
    assert not list(clone.glob("samples/*_graded*")), "an example wrote beside the samples"
    shutil.rmtree(tmp_path / "cache", ignore_errors=True)
