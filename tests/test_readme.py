"""The README's and the ``docs/`` pages' shell commands run on a fresh clone and never write
into it; their shell examples use only the options ``--help-all`` lists (palette-fit options with
``--mode palette``); their Python examples run as written; every relative link leads to a file
of the repository (and, with ``#anchor``, to one of its headings).

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
#: The pages checked: the README, the changelog and every page of docs/.
PAGES = [README, ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").glob("*.md"))]
#: Options whose value is a file or folder the command writes.
OUTPUT_FLAGS = {"-o", "--output", "--output-dir", "--out", "--lut", "--report", "--save-grade"}
#: Words that separate commands on one line.
SEPARATORS = {"&&", "||", ";", "|"}
PLACEHOLDER = re.compile(r"^[A-Z][A-Z0-9_]+(\.[a-z0-9]+)?/?$")


def code_blocks(text: str, languages: tuple[str, ...]) -> list[tuple[int, str]]:
    """(line number, code) of every fenced block in one of ``languages``."""
    blocks, current, start = [], None, 0
    for number, line in enumerate(text.splitlines(), start=1):
        fence = line.strip()
        if current is None and fence.startswith("```"):
            current, start = ([] if fence[3:].strip() in languages else False), number + 1
        elif current is not None and fence.startswith("```"):
            if current is not False:
                blocks.append((start, "\n".join(current)))
            current = None
        elif current not in (None, False):
            current.append(line)
    return blocks


def bash_blocks(text: str) -> list[tuple[int, str]]:
    """(line number, code) of every ```bash (or sh, shell) block."""
    return code_blocks(text, ("bash", "sh", "shell"))


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


def _name(page: Path) -> str:
    return page.relative_to(ROOT).as_posix()


ALL = [(f"{_name(page)}:{line}", command) for page in PAGES
       for line, code in bash_blocks(page.read_text("utf-8")) for command in commands(code)]


def test_the_readme_has_commands():
    assert len(ALL) > 20
    assert any(c[:2] == ["wbcgrade", "apply"] for where, c in ALL if where.startswith("README"))
    assert {where.split(":")[0] for where, _ in ALL} >= {"README.md", "docs/grading.md",
                                                          "docs/video.md"}


@pytest.mark.parametrize("line, command", ALL, ids=[f"{line}-{' '.join(c)[:40]}"
                                                     for line, c in ALL])
def test_readme_command_runs_on_a_clone_and_writes_outside_it(line, command, tmp_path):
    text = " ".join(command)
    placeholders = [w for w in command if PLACEHOLDER.match(w) or w.startswith("[")]
    assert not placeholders, (f"{line}: {text!r} has placeholders "
                              f"{placeholders}: put synopses in ```text blocks")
    inside = [p for p in outputs(command) if inside_clone(p, tmp_path / "home")]
    assert not inside, (f"{line}: {text!r} writes {inside} into the source "
                        "tree; write to ~/graded/ (or another folder outside the clone)")
    if len(command) > 1 and command[0].startswith("python") and command[1].endswith(".py") \
            and (ROOT / command[1]).exists():
        writes_here = re.search(r'add_argument\("--out", type=Path, default=ROOT',
                                (ROOT / command[1]).read_text("utf-8"))
        assert not writes_here or "--out" in command, (
            f"{line}: {text!r} writes into the clone by default; give --out")
    for word in command:
        if re.match(r"^(samples|examples|benchmarks|presets)/", word) and "*" not in word:
            assert (ROOT / word).exists(), f"{line}: {word} is not in the repository"


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


PYTHON = [(f"{_name(page)}:{line}", code) for page in PAGES
          for line, code in code_blocks(page.read_text("utf-8"), ("python",))]


@pytest.mark.slow
@pytest.mark.parametrize("line, code", PYTHON, ids=[line for line, _ in PYTHON])
def test_readme_python_example_runs_as_written(line, code, tmp_path):
    """Each ```python block runs in a fresh interpreter from the clone's folder."""
    import subprocess
    import sys

    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
        "WBCGRADE_CACHE_DIR": str(tmp_path / "cache")}
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, f"{line}: the example fails:\n{run.stderr[-2000:]}"


def color_names_used(code: str) -> tuple[set[str], set[str]]:
    """(modules of ``wbcgrade.color`` an example imports, names it takes from the package):
    ``import wbcgrade.color as wc`` then ``wc.NAME``, or ``from wbcgrade.color import NAME``."""
    import ast

    modules, names, aliases = set(), set(), set()
    tree = ast.parse(code)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("wbcgrade.color"):
                    modules.add(alias.name)
                    aliases.add(alias.asname or alias.name)
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("wbcgrade"):
            if node.module == "wbcgrade" and any(a.name == "color" for a in node.names):
                modules.add("wbcgrade.color")
                aliases.update(a.asname or a.name for a in node.names if a.name == "color")
            elif node.module.startswith("wbcgrade.color"):
                modules.add(node.module)
                names.update(alias.name for alias in node.names)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and ast.unparse(node.value) in aliases:
            names.add(node.attr)
    return modules, names


def test_python_examples_use_only_the_colour_front_door():
    """The README's and docs' Python examples reach the colour library through
    ``wbcgrade.color``'s front door alone (its ``__all__``)."""
    import wbcgrade.color as wc

    assert len(wc.__all__) <= 15
    for where, code in PYTHON:
        modules, names = color_names_used(code)
        assert modules <= {"wbcgrade.color"}, f"{where}: imports {sorted(modules)}"
        assert names <= set(wc.__all__), f"{where}: uses {sorted(names - set(wc.__all__))}"
    assert color_names_used("from wbcgrade.color.grade.grading import grade_array")[0] \
        == {"wbcgrade.color.grade.grading"}
    assert color_names_used("import wbcgrade.color as wc\nwc.resolve_preset('x')")[1] \
        == {"resolve_preset"}


def _wbcgrade_lines() -> list[tuple[int, list[str]]]:
    """Every ``wbcgrade ...`` command of the README's bash and text blocks (synopses too),
    split into words: brackets and ``A|B`` alternatives opened up."""
    found = []
    for page in PAGES:
        for start, code in code_blocks(page.read_text("utf-8"), ("bash", "sh", "shell", "text")):
            for offset, raw in enumerate(code.splitlines()):
                for part in re.split(r"&&|;|\|(?=\s*wbcgrade )", raw.split("#", 1)[0]):
                    words = part.replace("[", " ").replace("]", " ").split()
                    if words[:1] == ["wbcgrade"]:
                        found.append((f"{_name(page)}:{start + offset}", words))
    return found


SHELL = _wbcgrade_lines()


def _help_of(words: list[str]) -> tuple[list[str], str]:
    """The command path (e.g. ["look", "extract"]) and its ``--help-all`` text (every
    option; ``--help`` where the command has no ``--help-all``)."""
    import click
    from click.testing import CliRunner

    from wbcgrade.cli import main

    command, path = main, []
    for word in words[1:]:
        if not isinstance(command, click.Group) or word.startswith("-"):
            break
        sub = command.get_command(None, word)
        if sub is None:
            break
        command, path = sub, path + [word]
    result = CliRunner().invoke(main, [*path, "--help-all"], terminal_width=200)
    if result.exit_code == 2 and "No such option" in result.output:  # a group's own help
        result = CliRunner().invoke(main, [*path, "--help"], terminal_width=200)
    if result.exit_code != 0 and "pip install" in result.output:  # an extra not installed
        pytest.skip(result.output.strip())
    assert result.exit_code == 0, result.output
    return path, result.output


@pytest.mark.parametrize("line, words", SHELL, ids=[f"{line}-{' '.join(w)[:40]}"
                                                    for line, w in SHELL])
def test_readme_shell_example_uses_options_the_help_lists(line, words):
    from wbcgrade.cli.grading_options import PALETTE_ONLY

    path, text = _help_of(words)
    assert path, f"{line}: {' '.join(words)!r} names no wbcgrade command"
    listed = set(re.findall(r"(?<![\w-])(--?[a-zA-Z][\w-]*)", text))
    flags = [w.split("=", 1)[0] for w in words if re.match(r"^--?[a-zA-Z]", w)]
    unknown = [f for f in flags if f not in listed and f not in ("-h", "--help")]
    assert not unknown, (f"{line}: {' '.join(words)!r} uses {unknown}, which "
                         f"`wbcgrade {' '.join(path)} --help-all` does not list")
    palette_only = set(PALETTE_ONLY.values()) & set(flags)
    grading = path[0] in ("apply", "batch", "report", "video")  # shape has its own --loss
    if grading and palette_only and "--look" not in flags:
        assert "palette" in words[words.index("--mode") + 1:words.index("--mode") + 2] \
            if "--mode" in words else False, (
            f"{line}: {sorted(palette_only)} need --mode palette (refused "
            "otherwise)")


def test_the_readme_has_shell_and_python_examples():
    assert len(SHELL) > 20 and len(PYTHON) >= 2


def _prose(text: str) -> str:
    """``text`` without its fenced code blocks and inline code spans (lines kept)."""
    lines, fenced = [], False
    for line in text.splitlines():
        if line.strip().startswith("```"):
            fenced = not fenced
            lines.append("")
        else:
            lines.append("" if fenced else re.sub(r"`[^`]*`", "", line))
    return "\n".join(lines)


def anchors(text: str) -> set[str]:
    """The ``#anchor`` of every heading of a Markdown page, as GitHub makes them: lower case,
    punctuation dropped, spaces made hyphens, a repeated one numbered (``-1``, ``-2``)."""
    found: set[str] = set()
    fenced = False
    for line in text.splitlines():
        fenced ^= line.strip().startswith("```")
        heading = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line.replace("`", ""))
        if fenced or not heading:
            continue
        slug = re.sub(r"[^\w\- ]", "", heading.group(1).lower()).replace(" ", "-")
        unique, n = slug, 0
        while unique in found:
            n += 1
            unique = f"{slug}-{n}"
        found.add(unique)
    return found


LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
LINKS = [(f"{_name(page)}:{number}", page, target) for page in PAGES
         for number, line in enumerate(_prose(page.read_text("utf-8")).splitlines(), start=1)
         for target in LINK.findall(line)
         if not re.match(r"^[a-z]+:", target)]  # http:, https:, mailto: are not checked


def test_the_pages_link_to_each_other():
    assert len(LINKS) > 40
    linked = {(page.parent / target.split("#")[0]).resolve() for _, page, target in LINKS
              if target.split("#")[0]}
    unreached = [_name(p) for p in PAGES if p != README and p.resolve() not in linked]
    assert not unreached, f"no page links to {unreached}"
    readme_links = {(ROOT / t.split("#")[0]).resolve() for _, page, t in LINKS if page == README}
    docs = [_name(p) for p in PAGES if p.parent.name == "docs" and p.suffix == ".md"]
    assert not [d for d in docs if (ROOT / d).resolve() not in readme_links], \
        "every docs/ page is linked from the README"


@pytest.mark.parametrize("where, page, target", LINKS, ids=[f"{w}-{t[:40]}" for w, _, t in LINKS])
def test_relative_link_leads_to_a_file_and_heading(where, page, target):
    path, _, anchor = target.partition("#")
    resolved = (page.parent / path).resolve() if path else page.resolve()
    assert resolved.exists(), f"{where}: {target} leads to no file"
    assert ROOT in resolved.parents or resolved == ROOT, f"{where}: {target} leaves the repository"
    if anchor and resolved.suffix == ".md":
        assert anchor in anchors(resolved.read_text("utf-8")), (
            f"{where}: {resolved.name} has no heading #{anchor}")


def test_the_link_checks_catch_what_they_should():
    assert anchors("# A (b) `c`\n## A (b) c\n```\n# not a heading\n```\n## Shapes (§5.3–5.4)") \
        == {"a-b-c", "a-b-c-1", "shapes-5354"}
    assert LINK.findall("see [x](docs/a.md#b) and ![y](z.png) but not `[u](v)`") == \
        ["docs/a.md#b", "z.png", "v"]
    assert "v" not in LINK.findall(_prose("`[u](v)`"))


def test_ci_runs_the_readme_test_command_verbatim():
    """The README's second set-up command (install with the test extra, run the tests) is
    the one ``.ci/run`` runs: the two are kept in step."""
    setup = bash_blocks(README.read_text("utf-8"))[:2]
    assert "pytest" in setup[1][1] and "pip install ." in setup[0][1], setup
    ci = (ROOT / ".ci" / "run").read_text("utf-8").splitlines()
    assert setup[1][1].strip() in [line.strip() for line in ci]
