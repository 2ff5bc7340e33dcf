"""The wheel installs one import package, ``colossus``, and a runtime-only install works.

The wheel is built from this tree (``pip wheel --no-build-isolation``: no network) and its file
list is read; the runtime-only check runs the installed package in a child process in which every
optional dependency (the ``pipeline`` and ``render`` extras, Dask) refuses to import, so any import
of them on the load / pose / query path fails the test.  A real fresh-venv install with no extras is
measured in the README (it needs the registry, so it is not run here).
"""

from __future__ import annotations

import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
#: Modules of the optional extras: a runtime-only install has none of them.
EXTRAS_MODULES = ("assimp_py", "scipy", "trimesh", "meshio", "fast_simplification", "pyvista", "vtk",
                  "vtkmodules", "matplotlib", "PIL", "imageio", "dask", "distributed", "embreex", "rtree")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    """The wheel, built from a copy of the tree (a build writes build/ and *.egg-info beside the
    sources)."""
    import shutil

    out = tmp_path_factory.mktemp("wheel")
    src = tmp_path_factory.mktemp("src") / "colossus"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, src / name)
    for folder in set(PYPROJECT["tool"]["setuptools"]["package-dir"].values()):
        shutil.copytree(ROOT / folder, src / folder, ignore=shutil.ignore_patterns("__pycache__", "*.nb[ic]"))
    p = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                        "-w", str(out), str(src)], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    (whl,) = out.glob("*.whl")
    return whl


def test_wheel_installs_only_colossus(wheel):
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        meta = next(z.read(n).decode() for n in names if n.endswith(".dist-info/METADATA"))
    tops = {n.split("/")[0] for n in names}
    dist_info = {t for t in tops if t.endswith(".dist-info")}
    assert tops - dist_info == {"colossus"}, sorted(tops)
    assert wheel.name.startswith("colossus_colliders-")
    # the floors, the licence and the entry point
    for pkg in ("runtime", "pipeline", "validators", "render", "cli", "bench"):
        assert f"colossus/{pkg}/__init__.py" in names
    assert "colossus/runtime/kernels/skin.py" in names and "colossus/__main__.py" in names
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    eps = next(z for z in [zipfile.ZipFile(wheel)]).read(
        next(n for n in names if n.endswith(".dist-info/entry_points.txt"))).decode()
    assert "colossus = colossus.cli:main" in eps
    # no test, sample or tool ships
    assert not [n for n in names if n.startswith(("tests/", "samples/", "tools/")) or "/tests/" in n]
    # the core requirements are the runtime's (numpy, numba, usd-core) and click for the command line
    core = sorted(line.split(":", 1)[1].strip().split(">")[0].split("=")[0].split("[")[0].strip()
                  for line in meta.splitlines() if line.startswith("Requires-Dist:") and "extra ==" not in line)
    assert core == ["click", "numba", "numpy", "usd-core"], core


def test_every_source_module_is_in_the_wheel(wheel):
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
    for pkg, folder in PYPROJECT["tool"]["setuptools"]["package-dir"].items():
        base = ROOT / folder
        files = base.glob("*.py") if pkg == "colossus" else base.rglob("*.py")
        for f in files:
            if "__pycache__" in f.parts:
                continue
            rel = "/".join(pkg.split(".") + list(f.relative_to(base).parts))
            assert rel in names, f"{f.relative_to(ROOT)} is not in the wheel"


_RUNTIME_ONLY = r"""
import importlib.abc, sys
BLOCKED = set(sys.argv[2].split(","))

class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r} (blocked: not a runtime dependency)", name=name)

sys.meta_path.insert(0, Block())
import numpy as np
from colossus import load_collider
import colossus
col = load_collider(sys.argv[1])
pose = col.pose(col.clips[0], float(col.frame_times(col.clips[0])[3]))
lo, hi = pose.points.min(0), pose.points.max(0)
o = np.array([(lo + hi) / 2 + np.array([0.0, 0.0, 10.0 * float(np.linalg.norm(hi - lo))])])
hits = pose.raycast(o, np.array([[0.0, 0.0, -1.0]]))
cs = pose.sphere_contacts(pose.points[0], 0.05 * float(np.linalg.norm(hi - lo)))
assert np.isfinite(hits.distance[0]) and len(cs.triangle) > 0
loaded = sorted({m.split(".")[0] for m in sys.modules} & BLOCKED)
print("ok", colossus.__version__, len(col.triangles), loaded)
"""


def test_runtime_only_install_loads_and_queries(imported, tmp_path):
    """Load, pose, raycast and sphere-contact a collider with every optional extra unimportable."""
    _, asset = imported("creature", "glb")
    p = subprocess.run([sys.executable, "-c", _RUNTIME_ONLY, str(asset), ",".join(EXTRAS_MODULES)],
                       capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert p.returncode == 0, p.stderr[-3000:]
    assert p.stdout.startswith("ok 0.1.0") and p.stdout.rstrip().endswith("[]"), p.stdout


def test_help_without_extras(tmp_path):
    """``colossus --help`` and ``python -m colossus --help`` need none of the extras; a command that
    needs a missing extra says which one in one line."""
    code = _RUNTIME_ONLY.split("import numpy as np")[0] + (
        "from colossus.cli import main\n"
        "sys.argv = ['colossus'] + sys.argv[3:]\n"
        "main(prog_name='colossus')\n")
    run = lambda *args: subprocess.run([sys.executable, "-c", code, "-", ",".join(EXTRAS_MODULES), *args],
                                       capture_output=True, text=True, timeout=600, cwd=tmp_path)
    p = run("--help")
    assert p.returncode == 0 and "import" in p.stdout and "validate" in p.stdout, p.stderr
    p = run("import", str(ROOT / "samples" / "limb.glb"), "-o", str(tmp_path / "x.usda"))
    assert p.returncode == 2 and not (tmp_path / "x.usda").exists()
    assert p.stderr.count("\n") == 1 and "colossus-colliders[pipeline]" in p.stderr, p.stderr
    m = subprocess.run([sys.executable, "-m", "colossus", "--version"], capture_output=True, text=True,
                       timeout=600, cwd=tmp_path)
    assert m.returncode == 0 and m.stdout.strip() == "colossus, version 0.1.0"
