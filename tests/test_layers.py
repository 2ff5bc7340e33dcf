"""Imports flow one way: ``runtime`` (lowest) <- ``pipeline`` <- ``validators``, the CLI on top.

Every module of the three packages is parsed (``ast``); every import is an edge, lazy ones inside
functions included.  A library module may import only its own package and the packages below it;
only command-line modules (``*cli*.py``) may reach across floors.  No two modules may import each
other, directly or through others (no cycle), whatever their floor.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FLOORS = {"runtime": 0, "pipeline": 1, "validators": 2}
#: What the game runtime's library modules may import at module level besides the standard library
#: and ``runtime`` itself (lazy imports of optional backends, e.g. trimesh, are allowed).
RUNTIME_THIRD_PARTY = {"numpy", "numba", "pxr"}


def _modules():
    out = {}
    for pkg in FLOORS:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            rel = f.relative_to(ROOT).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = f
    return out


def _imports(name, path):
    """(imported module, lineno, top_level) for every import in the file, made absolute."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_pkg = path.name == "__init__.py"
    pkg = name.split(".") if is_pkg else name.split(".")[:-1]
    top = {id(n) for n in tree.body}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                found.append((a.name, node.lineno, id(node) in top))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg[: len(pkg) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module
            found.append((mod, node.lineno, id(node) in top))
            for a in node.names:  # ``from . import x`` may name a submodule
                found.append((f"{mod}.{a.name}", node.lineno, id(node) in top))
    return found


def _graph():
    mods = _modules()
    edges = {}
    for name, path in mods.items():
        tgt = {}
        for mod, line, top in _imports(name, path):
            while mod and mod not in mods:
                mod = mod.rpartition(".")[0]
            if mod and mod != name and FLOORS.get(mod.split(".")[0]) is not None:
                tgt.setdefault(mod, line)
        edges[name] = tgt
    return mods, edges


def _is_cli(name):
    return "cli" in name.rsplit(".", 1)[-1]


def test_no_upward_imports():
    mods, edges = _graph()
    bad = []
    for src, tgts in edges.items():
        if _is_cli(src):
            continue
        f_src = FLOORS[src.split(".")[0]]
        for dst, line in tgts.items():
            if FLOORS[dst.split(".")[0]] > f_src:
                bad.append(f"{mods[src].relative_to(ROOT)}:{line} imports {dst} (a higher floor)")
    assert not bad, "upward imports:\n" + "\n".join(bad)


def test_no_import_cycles():
    mods, edges = _graph()
    # Tarjan's strongly connected components
    index, low, stack, on, sccs = {}, {}, [], set(), []
    sys.setrecursionlimit(10_000)

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, {}):
            # a package's __init__ importing its own submodules is not a cycle worth refusing
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                sccs.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    # edges from a package to its own submodules (re-exports in __init__) make trivial loops with
    # any submodule that imports the package: only count cycles among non-__init__ modules
    real = [c for c in sccs if len([m for m in c if mods[m].name != "__init__.py"]) > 1
            and not _init_only_cycle(c, mods, edges)]
    assert not real, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in real)


def _init_only_cycle(comp, mods, edges):
    """True when the component stays connected only through package ``__init__`` modules."""
    plain = [m for m in comp if mods[m].name != "__init__.py"]
    sub = {m: [w for w in edges[m] if w in plain] for m in plain}
    # does any plain module reach another and back without an __init__?
    for a in plain:
        seen, todo = set(), list(sub[a])
        while todo:
            x = todo.pop()
            if x == a:
                return False
            if x not in seen:
                seen.add(x)
                todo += sub[x]
    return True


def test_runtime_needs_only_numpy_numba_pxr():
    """The game runtime pulls in nothing of the importer or the validators, and at module level
    only numpy, numba, pxr and the standard library."""
    stdlib = set(sys.stdlib_module_names)
    mods = _modules()
    bad = []
    for name, path in mods.items():
        if not name.startswith("runtime") or _is_cli(name) or name.endswith("bench"):
            continue
        for mod, line, top in _imports(name, path):
            root = (mod or "").split(".")[0]
            if not top or root in stdlib or root in RUNTIME_THIRD_PARTY or root in ("runtime", "__future__"):
                continue
            bad.append(f"{path.relative_to(ROOT)}:{line} imports {mod}")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("pkg", sorted(FLOORS))
def test_graph_sees_every_module(pkg):
    """Guard against a parser that silently finds nothing (the tests above would pass vacuously)."""
    mods, edges = _graph()
    names = [m for m in mods if m.split(".")[0] == pkg]
    assert len(names) >= 5
    assert sum(len(edges[m]) for m in names) >= 5
