"""The package's layers, read from its own imports (those inside functions too).

docs/architecture.md: core (arrays) <- domains (colour, BRDF, shape) <- applications
(photos, batch, video, explore) <- command line; imports point downwards only, no module
imports one that imports it (directly or round a longer circle), no package (a sub-package
of the colour library, a domain, an application) imports one that imports it, and the
package's own modules are imported at the top of a module, not inside a function (the
command line's lazy loading excepted).
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "wbcgrade"


def _modules() -> dict[str, Path]:
    found = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        found[name] = path
    return found


def import_graph() -> dict[str, set[str]]:
    """module -> the package's modules it imports (a submodule named in ``from X import
    sub`` counts as the submodule, not as X)."""
    modules = _modules()
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                for alias in node.names:
                    sub = f"{node.module}.{alias.name}"
                    targets.append(sub if sub in modules else node.module)
            elif isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            graph[name].update(t for t in targets if t in modules and t != name)
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph[node]):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            group = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                group.append(top)
                if top == node:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_the_finder_sees_a_circle():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _circles({"a": {"b"}, "b": set()}) == []


def test_no_module_imports_one_that_imports_it():
    graph = import_graph()
    assert len(graph) > 100 and graph["wbcgrade.photos.workflow"]  # the files were read
    assert _circles(graph) == []


def package_of(module: str) -> str:
    """The package a module belongs to for the package-level layers: a sub-package of the
    colour library (``wbcgrade.color.io``), a module of ``wbcgrade.color`` itself
    (``wbcgrade.color.colorspace``), else the top-level package (``wbcgrade.batch``)."""
    parts = module.split(".")
    if parts[:2] == ["wbcgrade", "color"]:
        return ".".join(parts[:3])
    return ".".join(parts[:2])


def package_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """package -> the other packages its modules import (:func:`package_of`)."""
    packages: dict[str, set[str]] = {}
    for module, imported in graph.items():
        mine = package_of(module)
        packages.setdefault(mine, set()).update(
            package_of(t) for t in imported if package_of(t) != mine)
    return packages


#: Package circles left, each with why (the set may only shrink): none.
KNOWN_PACKAGE_CIRCLES: list[list[str]] = []


def test_no_package_imports_one_that_imports_it():
    assert package_of("wbcgrade.color.io.images") == "wbcgrade.color.io"
    assert package_of("wbcgrade.color.outcome") == "wbcgrade.color.outcome"
    assert package_of("wbcgrade.batch.plan") == "wbcgrade.batch"
    assert _circles(package_graph({"wbcgrade.color.io.a": {"wbcgrade.color.io.b"},
                                   "wbcgrade.color.io.b": {"wbcgrade.color.grade.c"},
                                   "wbcgrade.color.grade.c": {"wbcgrade.color.io.a"}})) \
        == [["wbcgrade.color.grade", "wbcgrade.color.io"]]
    assert _circles(package_graph(import_graph())) == KNOWN_PACKAGE_CIRCLES


def imports_inside_functions() -> dict[str, int]:
    """module -> how many of the package's own modules it imports inside a function."""
    found: dict[str, int] = {}
    for name, path in _modules().items():
        for function in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(function):
                if isinstance(node, ast.ImportFrom) and not node.level \
                        and (node.module or "").split(".")[0] == "wbcgrade":
                    found[name] = found.get(name, 0) + 1
                elif isinstance(node, ast.Import) and any(
                        a.name.split(".")[0] == "wbcgrade" for a in node.names):
                    found[name] = found.get(name, 0) + 1
    return found


def test_the_package_is_imported_at_the_top_of_its_modules():
    """No module imports the package's own modules inside a function, outside the command
    line (whose commands import the library lazily so that ``--help`` stays light)."""
    found = {module: count for module, count in imports_inside_functions().items()
             if not module.startswith("wbcgrade.cli")}
    assert found == {}, "import these at the top of the module"


def test_imports_point_downwards():
    """core imports no domain; a domain imports no application, no command line and no other
    domain; an application imports the domains and the applications below it (video and
    explore grade with the colour library and write its photos' reports)."""
    allowed = {
        "core": set(),
        "color": {"core"},
        "brdf": {"core"},
        "shape": {"core"},
        "photos": {"core", "color"},
        "batch": {"core", "color", "photos"},
        "video": {"core", "color", "photos"},
        "explore": {"core", "color", "photos"},
    }
    wrong = []
    for module, imported in import_graph().items():
        parts = module.split(".")
        layer = parts[1] if len(parts) > 1 else ""
        if layer not in allowed:
            continue
        for target in imported:
            other = target.split(".")[1] if target.count(".") else ""
            if other in allowed and other != layer and other not in allowed[layer]:
                wrong.append(f"{module} -> {target}")
            if other == "cli":
                wrong.append(f"{module} -> {target}")
    assert wrong == []


#: Private modules every layer may import (docs/architecture.md, layers: shared).
SHARED_PRIVATE = {"wbcgrade._publish", "wbcgrade._names", "wbcgrade._executor"}


def test_no_private_name_is_imported_from_another_module():
    """What one module uses of another has a public name: no ``from m import _x`` (inside
    the core, its own internals excepted) and no private module of another layer."""
    modules = _modules()

    def layer(module: str) -> str:
        return module.split(".")[1] if module.count(".") else ""

    wrong = []
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not (isinstance(node, ast.ImportFrom) and node.module and not node.level
                    and node.module.startswith("wbcgrade")):
                continue
            for alias in node.names:
                target = f"{node.module}.{alias.name}"
                module = target if target in modules else node.module
                private_module = any(p.startswith("_") for p in module.split(".")[1:]) \
                    and module not in SHARED_PRIVATE and layer(module) != layer(name)
                private_name = module != target and alias.name.startswith("_") \
                    and not alias.name.startswith("__") \
                    and not layer(name) == layer(module) == "core"
                if private_module or private_name:
                    wrong.append(f"{name} <- {target}")
    assert wrong == []
