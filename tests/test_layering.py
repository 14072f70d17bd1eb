"""The import graph keeps the floors of ARCHITECTURE.md ("Layout"): a walk over the packages' sources.

Floors: estimator/ (0) imports nothing of the project; inside it the model core (its top-level
modules) imports neither the online estimator (estimator.online) nor the offline identification and
diagnosis (estimator.offline), and the online estimator never imports the offline one; teleop/ base
(1) imports only estimator/; master/ and slave/ (2) never import each other; the application (3,
teleop.app) may import anything. No two modules import each other, directly or
round a circle, and no module imports another module's private (``_name``) helper.

What is not done yet is listed below as the currently allowed set, so that the test fails on any new
violation; shrink the sets as the work lands, never grow them.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("estimator", "teleop", "slave", "master")

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


def _graph():
    """modules -> list of (imported module, name or None, typing only), over the project's packages."""
    files = {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    graph: dict[str, list[tuple[str, str | None, bool]]] = {}
    for mod, path in files.items():
        is_pkg = path.name == "__init__.py"
        edges = []
        try:
            tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        except SyntaxError as e:
            UNPARSED.append(f"{path.relative_to(ROOT)}:{e.lineno}: {e.msg}")
            tree = ast.Module(body=[], type_ignores=[])
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
    return files, graph


UNPARSED: list[str] = []
FILES, GRAPH = _graph()


def _floor(mod: str) -> str:
    parts = mod.split(".")
    if parts[0] == "teleop" and parts[1:2] == ["app"]:
        return "app"
    if parts[0] == "estimator" and parts[1:2] in (["online"], ["offline"]):
        return f"estimator.{parts[1]}"
    return parts[0]


#: For each floor, the floors it must not import.
FORBIDDEN = {
    "estimator": {"estimator.online", "estimator.offline", "teleop", "app", "slave", "master"},
    "estimator.online": {"estimator.offline", "teleop", "app", "slave", "master"},
    "estimator.offline": {"teleop", "app", "slave", "master"},
    "teleop": {"app", "slave", "master"},
    "slave": {"master", "app"},
    "master": {"slave", "app"},
    "app": set(),
}


def test_every_source_parses():
    assert not UNPARSED, f"not Python: {UNPARSED}"


def test_the_walk_sees_the_packages():
    assert {"estimator.sheath", "estimator.online.distal", "estimator.offline.diagnosis", "teleop.messages",
            "teleop.app.cli", "slave.node", "master.node"} <= set(GRAPH)
    assert any(dep == "estimator.sheath" for dep, _, _ in GRAPH["slave.simulated"])


@pytest.mark.parametrize("floor", sorted(FORBIDDEN))
def test_no_import_breaks_the_floors(floor):
    bad = sorted(f"{mod} -> {dep}" for mod, edges in GRAPH.items() if _floor(mod) == floor
                 for dep, _, _ in edges if _floor(dep) in FORBIDDEN[floor])
    assert not bad, f"{floor} must not import {sorted(FORBIDDEN[floor])}: " + "; ".join(bad)


def _components() -> list[frozenset[str]]:
    """Strongly connected components (Tarjan) of the runtime import graph, of more than one module."""
    adj = {m: sorted({d for d, _, typing_only in e if d in GRAPH and d != m and not typing_only})
           for m, e in GRAPH.items()}
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
    found = {(mod, dep, name) for mod, edges in GRAPH.items() for dep, name, _ in edges
             if name is not None and name.startswith("_") and not name.startswith("__") and dep != mod}
    new = sorted(found - KNOWN_PRIVATE)
    assert not new, f"private helpers imported across modules: {new}"
