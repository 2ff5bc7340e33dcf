"""Imports flow one way through the floors of the one ``colossus`` package:

    runtime (0) <- pipeline (1) <- validators (2) <- render (3) <- cli, bench (4)

Every module of every floor is parsed (``ast``); every import is an edge, lazy ones inside
functions included.  A module may import only its own floor and the floors below it (no name is
exempt: the command line and the benchmarks are floors of their own, on top); ``colossus._version``
is below everything.  No two modules may import each other, directly or through others (no cycle),
whatever their floor.  The floors' folders are the repository's top-level folders, installed under
``colossus`` by ``pyproject.toml``'s ``package-dir``; these tests read that mapping, so the wheel and
the tests see the same package.
"""

from __future__ import annotations

import ast
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
#: installed package -> repository folder (pyproject's package-dir)
PACKAGE_DIR = PYPROJECT["tool"]["setuptools"]["package-dir"]
FLOORS = {"colossus._version": -1, "colossus.runtime": 0, "colossus.pipeline": 1, "colossus.validators": 2,
          "colossus.render": 3, "colossus.cli": 4, "colossus.bench": 4, "colossus.__main__": 5,
          "colossus": 5}
#: What the game runtime's modules may import at module level besides the standard library and
#: ``colossus.runtime`` itself (lazy imports of optional backends, e.g. trimesh, are allowed).
RUNTIME_THIRD_PARTY = {"numpy", "numba", "pxr"}
#: The repository's folders: importing them by their bare names would load a second copy.
BARE = {folder for pkg, folder in PACKAGE_DIR.items() if pkg != "colossus"}


def floor(mod):
    """The floor of the module ``mod`` (dotted, absolute): its longest prefix in :data:`FLOORS`."""
    parts = mod.split(".")
    for k in range(len(parts), 0, -1):
        f = FLOORS.get(".".join(parts[:k]))
        if f is not None:
            return f
    return None


def _modules():
    out = {}
    for pkg, folder in sorted(PACKAGE_DIR.items()):
        base = ROOT / folder
        files = sorted(base.rglob("*.py")) if pkg != "colossus" else sorted(base.glob("*.py"))
        for f in files:
            rel = f.relative_to(base).with_suffix("")
            parts = pkg.split(".") + list(rel.parts)
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
            if mod and mod != name and floor(mod) is not None:
                tgt.setdefault(mod, line)
        edges[name] = tgt
    return mods, edges


def test_no_upward_imports():
    mods, edges = _graph()
    bad = []
    for src, tgts in edges.items():
        for dst, line in tgts.items():
            if floor(dst) > floor(src):
                bad.append(f"{mods[src].relative_to(ROOT)}:{line} imports {dst} (a higher floor)")
    assert not bad, "upward imports:\n" + "\n".join(bad)


def test_no_bare_folder_imports():
    """``import pipeline`` (the folder's name, not ``colossus.pipeline``) would load a second copy of
    every module when the repository root is on ``sys.path``: nothing, tests and tools included,
    imports the folders by their bare names."""
    files = list(_modules().values()) + sorted((ROOT / "tests").rglob("*.py")) + [ROOT / "tools" / "compile-profile"]
    bad = []
    for f in files:
        for node in ast.walk(ast.parse(f.read_text(), filename=str(f))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module] if isinstance(node, ast.ImportFrom) and not node.level and node.module else [])
            bad += [f"{f.relative_to(ROOT)}:{node.lineno} imports {n}" for n in names if n.split(".")[0] in BARE]
    assert not bad, "imports of a folder's bare name (use colossus.<floor>):\n" + "\n".join(bad)


def test_every_package_is_installed():
    """Every folder with an ``__init__.py`` under a floor is a package the wheel lists (a package
    left out of ``[tool.setuptools] packages`` would be missing from the wheel only)."""
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    found = {m for m, f in _modules().items() if f.name == "__init__.py"}
    assert found == listed, f"in the tree, not listed: {sorted(found - listed)}; listed, absent: {sorted(listed - found)}"


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
        if not name.startswith("colossus.runtime"):
            continue
        for mod, line, top in _imports(name, path):
            root = (mod or "").split(".")[0]
            if not top or root in stdlib or root in RUNTIME_THIRD_PARTY or root == "__future__" or (mod or "").startswith("colossus.runtime"):
                continue
            bad.append(f"{path.relative_to(ROOT)}:{line} imports {mod}")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("pkg", ["colossus.runtime", "colossus.pipeline", "colossus.validators",
                                 "colossus.render", "colossus.cli", "colossus.bench"])
def test_graph_sees_every_module(pkg):
    """Guard against a parser that silently finds nothing (the tests above would pass vacuously)."""
    mods, edges = _graph()
    names = [m for m in mods if m == pkg or m.startswith(pkg + ".")]
    assert len(names) >= 4
    assert sum(len(edges[m]) for m in names) >= 4


def test_no_test_module_imports_another():
    """Shared test code lives in tests/references (independent references and fixtures' builders),
    tests/paths.py and conftest.py fixtures: no module imports a ``test_*`` module or a conftest."""
    bad = []
    for f in sorted((ROOT / "tests").rglob("*.py")):
        for node in ast.walk(ast.parse(f.read_text(), filename=str(f))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module] if isinstance(node, ast.ImportFrom) and node.module else [])
            bad += [f"{f.relative_to(ROOT)}:{node.lineno} imports {n}" for n in names
                    if n.split(".")[-1].startswith("test_") or n.split(".")[-1] == "conftest"]
    assert not bad, "\n".join(bad)


def test_no_private_name_crosses_a_floor():
    """A ``_name`` is its floor's own: no module imports one from another floor, or reads one off a
    module of another floor (``from colossus.runtime.kernels import query as Q; Q._raycast``); and a
    package's face (``__init__``) re-exports no private name."""
    mods = _modules()
    bad = []
    for name, path in mods.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        is_pkg = path.name == "__init__.py"
        pkg = name.split(".") if is_pkg else name.split(".")[:-1]
        foreign = {}  # local name -> the other floor's module or name it is bound to
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                mod = ".".join(pkg[: len(pkg) - (node.level - 1)] + ([node.module] if node.module else [])) \
                    if node.level else node.module
                for a in node.names:
                    private = a.name.startswith("_") and not a.name.startswith("__")
                    if private and (is_pkg or floor(mod or "") != floor(name)):
                        bad.append(f"{path.relative_to(ROOT)}:{node.lineno} imports {mod}.{a.name}")
                    if floor(mod or "") is not None and floor(mod) != floor(name):
                        foreign[a.asname or a.name] = f"{mod}.{a.name}"
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if floor(a.name) is not None and floor(a.name) != floor(name):
                        foreign[a.asname or a.name.split(".")[0]] = a.name
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in foreign
                    and node.attr.startswith("_") and not node.attr.startswith("__")):
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno} reads {foreign[node.value.id]}.{node.attr}")
    assert not bad, "private names across floors:\n" + "\n".join(bad)


def test_every_kernel_lives_with_the_kernels_and_names_its_fast_math():
    """Every numba kernel (``@njit``, ``@numba.jit``...) lives under ``runtime/kernels/`` or in a
    ``_kernels.py`` module beside its driver, and takes ``fastmath=`` from a named policy of
    ``runtime/kernels/config.py`` (never a literal, never numba's default by omission)."""
    config = ast.parse((ROOT / "runtime" / "kernels" / "config.py").read_text())
    policies = {t.id for node in config.body if isinstance(node, ast.Assign) for t in node.targets
                if isinstance(t, ast.Name) and t.id.startswith("FASTMATH_")}
    assert policies
    jits = {"njit", "jit", "generated_jit", "vectorize", "guvectorize", "stencil", "cfunc"}

    def is_jit(f):
        return (isinstance(f, ast.Name) and f.id in jits) or (isinstance(f, ast.Attribute) and f.attr in jits)

    bad, found = [], 0
    for name, path in _modules().items():
        tree = ast.parse(path.read_text(), filename=str(path))
        where = f"{path.relative_to(ROOT)}"
        home = name.startswith("colossus.runtime.kernels") or path.name.endswith("_kernels.py")
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                bad += [f"{where}:{d.lineno} {node.name}: a bare @{ast.unparse(d)} (no fastmath=)"
                        for d in node.decorator_list if is_jit(d)]
            if not (isinstance(node, ast.Call) and is_jit(node.func)):
                continue
            found += 1
            if not home:
                bad.append(f"{where}:{node.lineno}: a kernel outside runtime/kernels/ and *_kernels.py")
            fm = [k.value for k in node.keywords if k.arg == "fastmath"]
            if not (fm and isinstance(fm[0], ast.Name) and fm[0].id in policies):
                bad.append(f"{where}:{node.lineno}: fastmath= is not one of {sorted(policies)}")
    assert found >= 50, f"found only {found} kernels: the scan is broken"
    assert not bad, "\n".join(sorted(set(bad)))
