"""The package's import graph: no cycles, no stage importing a later stage, and every
module importable by its dotted name.

The graph is read from the source with ``ast``: every ``import`` and ``from ... import``
statement of every module, at module level or inside functions and classes, relative
or absolute. An import of ``a.b.c`` is an edge to ``a.b.c`` (parent packages run
first, but what their ``__init__`` imports is counted as their own edges);
``from a.b import c`` is an edge to the module ``a.b.c`` when there is one, else to
``a.b``.
"""

from __future__ import annotations

import ast
import functools
import importlib
import importlib.machinery
import importlib.util
import types
from pathlib import Path

import pytest

PACKAGE = "calibproj"
SOURCE = Path(__file__).resolve().parents[1] / "python" / PACKAGE


def module_files(source: Path = SOURCE, package: str = PACKAGE) -> dict[str, Path]:
    """Dotted name -> file of every Python module of the package's source tree."""
    modules = {}
    for path in sorted(source.rglob("*.py")):
        parts = [package, *path.relative_to(source).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts.pop()
        modules[".".join(parts)] = path
    return modules


def is_module(name: str, modules: dict[str, Path]) -> bool:
    """A Python module of the tree, or an extension module of its package (``_core``):
    built into the tree, or installed beside the package that is imported."""
    if name in modules:
        return True
    parent, _, last = name.rpartition(".")
    folder = modules.get(parent)
    if folder is None or folder.name != "__init__.py":
        return False
    if any((folder.parent / (last + suffix)).exists() for suffix in importlib.machinery.EXTENSION_SUFFIXES):
        return True
    spec = importlib.util.find_spec(name)
    # An editable install wraps the extension's loader; its origin still names the library.
    return spec is not None and (isinstance(spec.loader, importlib.machinery.ExtensionFileLoader) or
                                 str(spec.origin).endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES)))


def imported_names(module: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The modules ``module`` imports, anywhere in its file."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for alias in node.names:
                submodule = f"{base}.{alias.name}"
                names.add(submodule if is_module(submodule, modules) else base)
    return names


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the modules of the package it imports."""
    return {
        module: {name for name in imported_names(module, path, modules)
                 if name != module and (name == PACKAGE or name.startswith(PACKAGE + "."))}
        for module, path in modules.items()
    }


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the graph as ``[a, b, ..., a]``, or None (depth-first search)."""
    state: dict[str, str] = {}  # "open" while on the current path, "done" after
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = "open"
        path.append(node)
        for successor in sorted(graph.get(node, ())):
            if state.get(successor) == "open":
                return path[path.index(successor):] + [successor]
            if successor not in state:
                cycle = visit(successor)
                if cycle:
                    return cycle
        path.pop()
        state[node] = "done"
        return None

    for node in sorted(graph):
        if node not in state:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


MODULES = module_files()


def test_the_walk_sees_every_kind_of_import(tmp_path: Path) -> None:
    """The graph builder on a package made up here: module-level, function-level,
    relative and absolute imports are all edges, and a cycle is found and named."""
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("from pkg.a import f\n")
    (package / "a.py").write_text("def f():\n    from .sub import b\n    return b\n")
    (package / "sub" / "__init__.py").write_text("")
    (package / "sub" / "b.py").write_text("from .. import c\n")
    (package / "c.py").write_text("import pkg.sub.d\n")
    (package / "sub" / "d.py").write_text("class D:\n    def m(self):\n        from pkg import a\n")
    modules = module_files(package, "pkg")
    graph = {m: {n for n in imported_names(m, p, modules) if n.startswith("pkg")} for m, p in modules.items()}
    assert graph == {"pkg": {"pkg.a"}, "pkg.a": {"pkg.sub.b"}, "pkg.sub": set(), "pkg.sub.b": {"pkg.c"},
                     "pkg.c": {"pkg.sub.d"}, "pkg.sub.d": {"pkg.a"}}
    assert find_cycle(graph) == ["pkg.a", "pkg.sub.b", "pkg.c", "pkg.sub.d", "pkg.a"]
    graph["pkg.sub.d"] = set()
    assert find_cycle(graph) is None


def test_the_package_import_graph_has_no_cycle() -> None:
    assert len(MODULES) > 40 and "calibproj.cli.main" in MODULES
    graph = import_graph(MODULES)
    assert "calibproj._core" in graph["calibproj.registration.driver"]  # extension modules are nodes too
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


# The package's stages in the order data flows through them, as the C++ core's: a
# module may import its own stage and the stages before it, never one after it. The
# top-level ``calibproj`` (its lazy map of exported names) and ``__main__`` come last.
STAGES = ("_core", "_bench", "version", "common", "formats", "sequence", "simulate", "ingest", "selfcal",
          "scale", "registration", "uncertainty", "evaluation", "report", "board", "pipeline", "check",
          "capture", "study", "cli", "__main__", "")


def stage_of(module: str) -> str:
    """``calibproj.a.b`` -> ``a``; the package itself -> ``""``."""
    return module.split(".")[1] if "." in module else ""


def upward_imports(graph: dict[str, set[str]], stages: tuple[str, ...] = STAGES) -> list[str]:
    """Every edge from a module to a later stage's, as ``"a -> b"``."""
    rank = {stage: index for index, stage in enumerate(stages)}
    return sorted(f"{module} -> {name}" for module, names in graph.items() for name in names
                  if rank[stage_of(name)] > rank[stage_of(module)])


def test_an_upward_import_is_found_and_named() -> None:
    graph = {"calibproj.formats.tracks": {"calibproj._core"},
             "calibproj.scale.metric": {"calibproj.formats.tracks", "calibproj.registration.driver"},
             "calibproj.cli.main": {"calibproj.scale.metric"}}
    assert upward_imports(graph) == ["calibproj.scale.metric -> calibproj.registration.driver"]


def test_every_module_belongs_to_a_stage_and_imports_no_later_stage() -> None:
    unplaced = sorted(module for module in MODULES if stage_of(module) not in STAGES)
    assert not unplaced, "modules outside the stages (a flat module, or a stage missing from STAGES): " + \
        ", ".join(unplaced)
    upward = upward_imports(import_graph(MODULES))
    assert not upward, "imports of a later stage:\n" + "\n".join(upward)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_every_module_is_importable_by_its_dotted_name(name: str) -> None:
    module = importlib.import_module(name)
    assert isinstance(module, types.ModuleType) and module.__name__ == name
    # What "import a.b.c as m" and attribute access see: no name in a package's
    # namespace hides a submodule of the same name.
    parts = name.split(".")
    reached = functools.reduce(getattr, parts[1:], importlib.import_module(parts[0]))
    assert reached is module, f"{name} is shadowed by {reached!r}"
