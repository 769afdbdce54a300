"""The README's shell commands run on a fresh clone and never write into it.

Every line of a ```bash block is a command a reader may paste, in order
(synopses with placeholders go in ```text blocks). Checked without running
them (some take minutes or need the network): each file they read from the
repository exists, no placeholder is left, and every output they name (``-o``,
``--output-dir``, ``--out``, ``--lut``, ``--report``, ``>``, the folder of
``mkdir``/``cp``) lies outside the clone (the examples write to ``~/graded``).
"""

from __future__ import annotations

import os
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: Options whose value is a file or folder the command writes.
OUTPUT_FLAGS = {"-o", "--output", "--output-dir", "--out", "--lut", "--report"}
#: Words that separate commands on one line.
SEPARATORS = {"&&", "||", ";", "|"}
PLACEHOLDER = re.compile(r"^[A-Z][A-Z0-9_]+(\.[a-z0-9]+)?/?$")


def bash_blocks(text: str) -> list[tuple[int, str]]:
    """(line number, code) of every ```bash block."""
    blocks, current, start = [], None, 0
    for number, line in enumerate(text.splitlines(), start=1):
        fence = line.strip()
        if current is None and fence.startswith("```"):
            if fence[3:].strip() in ("bash", "sh", "shell"):
                current, start = [], number + 1
            elif fence[3:].strip():
                current, start = False, number  # another language: skip its body
        elif current is not None and fence.startswith("```"):
            if current is not False:
                blocks.append((start, "\n".join(current)))
            current = None
        elif current not in (None, False):
            current.append(line)
    return blocks


def commands(code: str) -> list[list[str]]:
    """The commands of a block: continuation lines joined, comments dropped, split at
    ``&&``, ``;``, ``|``."""
    joined = code.replace("\\\n", " ")
    found = []
    for line in joined.splitlines():
        lexer = shlex.shlex(line, posix=True, punctuation_chars=";&|<>")
        lexer.whitespace_split = True
        lexer.commenters = "#"
        words, command = list(lexer), []
        for word in words:
            if word in SEPARATORS:
                if command:
                    found.append(command)
                command = []
            else:
                command.append(word)
        if command:
            found.append(command)
    return found


def outputs(command: list[str]) -> list[str]:
    """The paths a command writes."""
    targets = []
    for i, word in enumerate(command[:-1]):
        if word in OUTPUT_FLAGS or word in (">", ">>"):
            targets.append(command[i + 1])
        elif "=" in word and word.split("=", 1)[0] in OUTPUT_FLAGS:
            targets.append(word.split("=", 1)[1])
    if command and command[0] == "mkdir":
        targets += [w for w in command[1:] if not w.startswith("-")]
    if command and command[0] in ("cp", "mv") and len(command) > 2:
        targets.append(command[-1])
    return targets


def inside_clone(path: str, home: Path) -> bool:
    expanded = path.replace("${HOME}", str(home)).replace("$HOME", str(home))
    if expanded.startswith("~"):
        expanded = str(home) + expanded[1:]
    resolved = (ROOT / expanded).resolve() if not os.path.isabs(expanded) \
        else Path(expanded).resolve()
    return resolved == ROOT or ROOT in resolved.parents


ALL = [(line, command) for line, code in bash_blocks(README.read_text("utf-8"))
       for command in commands(code)]


def test_the_readme_has_commands():
    assert len(ALL) > 20
    assert any(c[:2] == ["wbcgrade", "apply"] for _, c in ALL)


@pytest.mark.parametrize("line, command", ALL, ids=[f"line{line}-{' '.join(c)[:40]}"
                                                     for line, c in ALL])
def test_readme_command_runs_on_a_clone_and_writes_outside_it(line, command, tmp_path):
    text = " ".join(command)
    placeholders = [w for w in command if PLACEHOLDER.match(w) or w.startswith("[")]
    assert not placeholders, (f"README line {line}: {text!r} has placeholders "
                              f"{placeholders}: put synopses in ```text blocks")
    inside = [p for p in outputs(command) if inside_clone(p, tmp_path / "home")]
    assert not inside, (f"README line {line}: {text!r} writes {inside} into the source "
                        "tree; write to ~/graded/ (or another folder outside the clone)")
    if len(command) > 1 and command[0].startswith("python") and command[1].endswith(".py") \
            and (ROOT / command[1]).exists():
        writes_here = re.search(r'add_argument\("--out", type=Path, default=ROOT',
                                (ROOT / command[1]).read_text("utf-8"))
        assert not writes_here or "--out" in command, (
            f"README line {line}: {text!r} writes into the clone by default; give --out")
    for word in command:
        if re.match(r"^(samples|examples|benchmarks|presets)/", word) and "*" not in word:
            assert (ROOT / word).exists(), f"README line {line}: {word} is not in the repository"


def test_the_checks_catch_what_they_should(tmp_path):
    home = tmp_path / "home"
    found = commands("wbcgrade apply samples/a.jpg -o out.jpg --lut ~/x.cube > log.json "
                     "&& mkdir -p graded/ # a comment -o here.jpg")
    assert found[0][:2] == ["wbcgrade", "apply"] and found[1] == ["mkdir", "-p", "graded/"]
    assert outputs(found[0]) == ["out.jpg", "~/x.cube", "log.json"]
    assert [inside_clone(p, home) for p in outputs(found[0])] == [True, False, True]
    assert inside_clone("graded/", home) and not inside_clone("$HOME/graded", home)
    assert PLACEHOLDER.match("PHOTO") and PLACEHOLDER.match("IN.mov")
    assert not PLACEHOLDER.match("samples/chelsea.jpg")
