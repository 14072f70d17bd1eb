"""The import graph keeps the floors of the layout (docs/concepts/architecture.md): a walk over the sources.

Floors, each importing only the floors under it:

0. ``estimator/``: pure numerics. Inside it the model core (its top-level modules) imports neither the
   online estimators (``estimator.online``) nor the offline identification and diagnosis
   (``estimator.offline``), and the online estimators never import the offline ones. The package's
   ``__init__`` is the library's public face, not part of the core: it names the public classes and
   functions of all three (loaded on first use) and nothing inside ``estimator/`` imports it.
1. ``teleop/``: what every process shares (messages, codec, keys, transport, config, clocks, recording).
2. ``recorded/``: the readers of measured data sets (KAIST, MRD, a recording's format) and the calibration on
   recorded MRD runs; it imports ``estimator/`` and ``teleop/`` only.
3. ``slave/`` and ``master/``: one side each; they never import each other.
4. ``study/``: the offline study (analyses, reports, scenario generators, the lumped simulator); it may use the
   simulated rigs of ``slave/``, never ``master/`` or the live application.
5. ``live/``: the ``teleop`` command and the live session; the command line dispatches ``teleop analyze``
   to ``study/``.

No two modules import each other, directly or round a circle, and no module imports another module's
private (``_name``) helper. Modules keep to 600 lines (past 400 the docstring says why) and functions to
80; the compiled kernels named in ``LONG_KERNELS`` are the exceptions, each with its reason. No package,
benchmark or example puts anything on ``sys.path``: they import the installed package.
"""
from __future__ import annotations

import ast
import functools
from pathlib import Path
from typing import NamedTuple

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("estimator", "teleop", "recorded", "slave", "master", "study", "live")

#: Import circles that exist today (each set is one strongly connected component allowed to remain,
#: or to shrink). A new circle, or a module joining one of these, fails the test.
KNOWN_CYCLES: tuple[frozenset[str], ...] = ()

#: (importer, imported module, private name) imports across modules that exist today.
KNOWN_PRIVATE: frozenset[tuple[str, str, str]] = frozenset()


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or \
        (isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING")


def _walk(tree: ast.AST):
    """Yield (import node, under TYPE_CHECKING) for every import, at any depth (lazy ones too)."""
    stack: list[tuple[ast.AST, bool]] = [(tree, False)]
    while stack:
        node, typing_only = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node, typing_only
        for child in ast.iter_child_nodes(node):
            stack.append((child, typing_only or (isinstance(node, ast.If) and _is_type_checking(node)
                                                 and child in node.body)))


class _Project(NamedTuple):
    """The project's packages parsed: each module's file and syntax tree (empty where it does not parse), its
    imports as (imported module, name or None, typing only), and the files that do not parse."""

    files: dict[str, Path]
    trees: dict[str, ast.Module]
    graph: dict[str, list[tuple[str, str | None, bool]]]
    unparsed: list[str]


@functools.cache
def _graph() -> _Project:
    """The project's packages (:class:`_Project`), parsed once per process when a test first asks (not at
    collection)."""
    files = {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    trees: dict[str, ast.Module] = {}
    graph: dict[str, list[tuple[str, str | None, bool]]] = {}
    unparsed: list[str] = []
    for mod, path in files.items():
        is_pkg = path.name == "__init__.py"
        edges: list[tuple[str, str | None, bool]] = []
        try:
            tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        except SyntaxError as e:
            unparsed.append(f"{path.relative_to(ROOT)}:{e.lineno}: {e.msg}")
            tree = ast.Module(body=[], type_ignores=[])
        trees[mod] = tree
        for node, typing_only in _walk(tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.split(".")[0] in PACKAGES:
                        edges.append((a.name, None, typing_only))
                continue
            base = node.module or ""
            if node.level:
                anchor = mod.split(".") if is_pkg else mod.split(".")[:-1]
                anchor = anchor[:len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            if base.split(".")[0] not in PACKAGES:
                continue
            for a in node.names:
                sub = f"{base}.{a.name}"
                if sub in files:
                    edges.append((sub, None, typing_only))
                else:
                    edges.append((base, a.name, typing_only))
        graph[mod] = edges
    return _Project(files, trees, graph, unparsed)


#: The floor of ``estimator/__init__.py``: the public face, above the core, online and offline parts it names.
FACE = "estimator (public face)"


def _floor(mod: str) -> str:
    if mod == "estimator":
        return FACE
    parts = mod.split(".")
    if parts[0] == "estimator" and parts[1:2] in (["online"], ["offline"]):
        return f"estimator.{parts[1]}"
    return parts[0]


#: For each floor, the floors it must not import.
FORBIDDEN = {
    "estimator": {FACE, "estimator.online", "estimator.offline", "teleop", "recorded", "slave", "master", "study",
                  "live"},
    "estimator.online": {FACE, "estimator.offline", "teleop", "recorded", "slave", "master", "study", "live"},
    "estimator.offline": {FACE, "teleop", "recorded", "slave", "master", "study", "live"},
    FACE: {"teleop", "recorded", "slave", "master", "study", "live"},
    "teleop": {"recorded", "slave", "master", "study", "live"},
    "recorded": {"slave", "master", "study", "live"},
    "slave": {"master", "study", "live"},
    "master": {"slave", "study", "live"},
    "study": {"master", "live"},
    "live": set(),
}


def test_every_source_parses():
    unparsed = _graph().unparsed
    assert not unparsed, f"not Python: {unparsed}"


def test_the_walk_sees_the_packages():
    graph = _graph().graph
    assert {"estimator.sheath", "estimator.online.distal", "estimator.offline.diagnosis.selection",
            "teleop.wire.messages", "live.cli", "slave.node", "master.node"} <= set(graph)
    assert any(dep == "estimator.geometry" for dep, _, _ in graph["slave.simulated"])


@pytest.mark.parametrize("floor", sorted(FORBIDDEN))
def test_no_import_breaks_the_floors(floor):
    graph = _graph().graph
    bad = sorted(f"{mod} -> {dep}" for mod, edges in graph.items() if _floor(mod) == floor
                 for dep, _, _ in edges if _floor(dep) in FORBIDDEN[floor])
    assert not bad, f"{floor} must not import {sorted(FORBIDDEN[floor])}: " + "; ".join(bad)


def _components() -> list[frozenset[str]]:
    """Strongly connected components (Tarjan) of the runtime import graph, of more than one module."""
    graph = _graph().graph
    adj = {m: sorted({d for d, _, typing_only in e if d in graph and d != m and not typing_only})
           for m, e in graph.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[frozenset[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in adj[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(frozenset(comp))

    for v in sorted(adj):
        if v not in index:
            visit(v)
    return out


def test_no_new_import_circle():
    new = [sorted(c) for c in _components() if not any(c <= known for known in KNOWN_CYCLES)]
    assert not new, f"import circles: {new}"


def test_no_private_helper_imported_across_modules():
    found = {(mod, dep, name) for mod, edges in _graph().graph.items() for dep, name, _ in edges
             if name is not None and name.startswith("_") and not name.startswith("__") and dep != mod}
    new = sorted(found - KNOWN_PRIVATE)
    assert not new, f"private helpers imported across modules: {new}"


#: Compiled (numba) kernels allowed past the 80-line bound: one loop over samples whose state lives in
#: local variables, where splitting would cost a call per sample inside the compiled loop.
LONG_KERNELS: dict[str, str] = {
    "estimator.extended_loop.run_span": "one compiled pass of every catalogue effect per sample (batch and per cycle)",
}

#: Where the size bounds and the sys.path rule are checked: the packages, the benchmarks and the examples.
SOURCE_DIRS = PACKAGES + ("benchmarks", "examples")
#: A module is cut by concept: up to ``MODULE_LINES``; past ``EXPLAINED_LINES`` its docstring says why in one line
#: that starts with ``Over 400 lines:`` (one concept that does not split cleanly, and what it is).
EXPLAINED_LINES, MODULE_LINES, FUNCTION_LINES = 400, 600, 80
WHY = "Over 400 lines:"


def _sources():
    for d in SOURCE_DIRS:
        yield from sorted((ROOT / d).rglob("*.py"))


def test_modules_keep_to_600_lines():
    long = [f"{p.relative_to(ROOT)}: {n}" for p in _sources()
            if (n := p.read_text(encoding="utf-8").count("\n")) > MODULE_LINES]
    assert not long, f"modules over {MODULE_LINES} lines: {long}"


def test_a_module_over_400_lines_says_why():
    unexplained = []
    for p in _sources():
        text = p.read_text(encoding="utf-8")
        if text.count("\n") > EXPLAINED_LINES:
            doc = ast.get_docstring(ast.parse(text)) or ""
            if not any(line.strip().startswith(WHY) for line in doc.splitlines()):
                unexplained.append(str(p.relative_to(ROOT)))
    assert not unexplained, f"modules over {EXPLAINED_LINES} lines whose docstring has no '{WHY}' line: {unexplained}"


def test_functions_keep_to_80_lines():
    long = []
    for p in _sources():
        mod = ".".join(p.relative_to(ROOT).with_suffix("").parts)
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = (node.end_lineno or node.lineno) - node.lineno + 1
                if n > FUNCTION_LINES and f"{mod}.{node.name}" not in LONG_KERNELS:
                    long.append(f"{p.relative_to(ROOT)}:{node.lineno} {node.name}: {n}")
    assert not long, f"functions over {FUNCTION_LINES} lines: {long}"


def test_nothing_edits_sys_path():
    found = [str(p.relative_to(ROOT)) for p in _sources() if "sys.path.insert" in p.read_text(encoding="utf-8")
             or "sys.path.append" in p.read_text(encoding="utf-8")]
    assert not found, f"sys.path edited in {found}: import the installed package instead"


def test_every_package_says_what_it_holds():
    """Each package's ``__init__`` has a docstring: the room it is and what it may import."""
    bare = [str(p.relative_to(ROOT)) for pkg in PACKAGES for p in (ROOT / pkg).rglob("__init__.py")
            if len((ast.get_docstring(ast.parse(p.read_text(encoding="utf-8"))) or "").split()) < 8]
    assert not bare, f"packages without a docstring saying what they hold: {bare}"


@functools.cache
def _top_level_names(mod: str) -> tuple[frozenset[str], frozenset[str]]:
    """(names a module defines at its top level, names it imports there) of one project module (once a process:
    every import edge asks for its module's names)."""
    defined, imported = set(), set()
    for node in _graph().trees[mod].body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            defined.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            defined |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            imported |= {a.asname or a.name.split(".")[0] for a in node.names}
    return frozenset(defined), frozenset(imported)


def test_every_name_has_one_import_path():
    """No module other than a package's ``__init__`` hands on a name it imported: a name is imported from the
    module that defines it, and ``__all__`` lists only what its module defines."""
    files, trees, graph, _ = _graph()
    passed_on = []
    for mod, edges in graph.items():
        for dep, name, _ in edges:
            if name is None or dep not in files or files[dep].name == "__init__.py" or name.startswith("_"):
                continue
            defined, imported = _top_level_names(dep)
            if name not in defined and name in imported:
                passed_on.append(f"{mod} imports {name} from {dep}")
    for mod, path in files.items():
        if path.name == "__init__.py":
            continue
        defined, _ = _top_level_names(mod)
        for node in trees[mod].body:
            if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__"
                                                    for t in node.targets):
                listed = [e.value for e in getattr(node.value, "elts", ()) if isinstance(e, ast.Constant)]
                passed_on += [f"{mod}.__all__ lists {n}, defined elsewhere" for n in listed if n not in defined]
    assert not passed_on, "re-exports outside package __init__s: " + "; ".join(sorted(passed_on))
