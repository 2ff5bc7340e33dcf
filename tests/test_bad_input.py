"""Bad input: exit 1 (2 for usage), one clear line naming the file, no traceback, no warning, no
output left.  In process through click's CliRunner on the real ``colossus`` group (the statuses
come from ``pipeline.cli.maps_errors``); ``capfd`` also catches anything a C library writes
straight to the file descriptors.  tests/test_cli.py keeps one subprocess smoke test of the
installed entry point."""

import os
import shutil
import warnings

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import SAMPLES

#: Warning categories Python hides by default (what a user running ``colossus`` never sees).
HIDDEN = (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning)


class Run:
    """One in-process ``colossus`` run: exit status, Python-level stdout/stderr (CliRunner), what
    reached the file descriptors (capfd), and every warning shown to a user."""

    def __init__(self, args, capfd):
        from pipeline.cli import main
        capfd.readouterr()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            r = CliRunner().invoke(main, [str(a) for a in args], prog_name="colossus")
        fd_out, fd_err = capfd.readouterr()
        self.returncode, self.stdout, self.stderr = r.exit_code, r.stdout, r.stderr
        self.exception = r.exception
        self.fd_output = fd_out + fd_err
        self.warnings = [f"{w.category.__name__}: {w.message}" for w in caught if not issubclass(w.category, HIDDEN)]


@pytest.fixture
def colossus(capfd):
    return lambda *args: Run(args, capfd)


@pytest.fixture
def run_import(colossus):
    return lambda src, out, *extra: colossus("import", src, "-o", out, *extra)


def assert_clean_failure(proc, out, needle, code=1):
    assert proc.returncode == code, proc.stderr
    assert isinstance(proc.exception, SystemExit), proc.exception  # exited; nothing escaped
    assert proc.stdout == "" and proc.fd_output == "", (proc.stdout, proc.fd_output)
    assert proc.warnings == []
    err = proc.stderr.strip()
    assert "Traceback" not in err
    assert len(err.splitlines()) == 1, err
    assert err.startswith("error: ")
    assert needle in err, err
    assert not os.path.exists(out)
    folder = os.path.dirname(out) or "."
    if os.path.isdir(folder):
        assert not [f for f in os.listdir(folder) if f.startswith(".colossus-")]


@pytest.fixture
def work(tmp_path):
    return tmp_path


def _edit_usd(tmp_path, fn, name="edited.usda"):
    from pxr import Usd
    dst = tmp_path / name
    shutil.copy(SAMPLES / "limb.usda", dst)
    stage = Usd.Stage.Open(str(dst))
    mesh = next(p for p in stage.Traverse() if p.GetTypeName() == "Mesh")
    fn(stage, mesh)
    stage.GetRootLayer().Save()
    return dst


def test_missing_path(work, run_import):
    out = work / "o.usda"
    assert_clean_failure(run_import(work / "nope.glb", out), out, "nope.glb: no such file")


@pytest.mark.parametrize("ext", ["glb", "fbx", "usda"])
def test_zero_byte(work, ext, run_import):
    src = work / f"empty.{ext}"
    src.write_bytes(b"")
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, f"empty.{ext}: file is empty")


@pytest.mark.parametrize("ext", ["glb", "fbx", "usda"])
def test_truncated(work, ext, run_import):
    data = (SAMPLES / f"creature.{ext}").read_bytes()
    src = work / f"trunc.{ext}"
    src.write_bytes(data[: len(data) // 3])
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, f"trunc.{ext}")


@pytest.mark.parametrize("ext", ["glb", "fbx", "dae", "usda", "usdc"])
def test_random_bytes(work, ext, run_import):
    src = work / f"random.{ext}"
    src.write_bytes(np.random.default_rng(7).integers(0, 256, 50_000, dtype=np.uint8).tobytes())
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, f"random.{ext}")


def test_nan_positions(work, run_import):
    def nan(stage, mesh):
        pts = mesh.GetAttribute("points").Get()
        pts[5] = (float("nan"), 0.0, 0.0)
        mesh.GetAttribute("points").Set(pts)
    src = _edit_usd(work, nan)
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "NaN or infinite")


def test_infinite_positions(work, run_import):
    def inf(stage, mesh):
        pts = mesh.GetAttribute("points").Get()
        pts[0] = (float("inf"), 0.0, 0.0)
        mesh.GetAttribute("points").Set(pts)
    src = _edit_usd(work, inf)
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "NaN or infinite")


def test_joint_index_out_of_range(work, run_import):
    def bad(stage, mesh):
        attr = mesh.GetAttribute("primvars:skel:jointIndices")
        v = attr.Get()
        v[3] = 99
        attr.Set(v)
    src = _edit_usd(work, bad)
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "out of range")


def test_mesh_without_skin(work, run_import):
    import trimesh
    src = work / "box.glb"
    trimesh.creation.box().export(src)
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "no skinned mesh")


def test_empty_scene_usd(work, run_import):
    from pxr import Usd
    src = work / "empty_scene.usda"
    stage = Usd.Stage.CreateNew(str(src))
    stage.Save()
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "has no mesh")


def test_empty_scene_gltf(work, run_import):
    src = work / "empty_scene.gltf"
    src.write_text('{"asset": {"version": "2.0"}, "scenes": [{"nodes": []}], "scene": 0}')
    out = work / "o.usda"
    proc = run_import(src, out)
    assert_clean_failure(proc, out, "empty_scene.gltf")


def test_unsupported_extension(work, run_import):
    src = work / "notes.txt"
    src.write_text("hello")
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "unsupported file type")


def test_output_dir_missing(work, run_import):
    out = work / "no" / "such" / "dir" / "o.usda"
    assert_clean_failure(run_import(SAMPLES / "limb.glb", out), out, "does not exist")


def test_output_dir_not_writable(work, run_import):
    out = "/proc/colossus-test.usda"  # not writable, even for root
    proc = run_import(SAMPLES / "limb.glb", out)
    assert_clean_failure(proc, out, "colossus-test.usda")


def test_output_bad_extension(work, run_import):
    out = work / "o.obj"
    assert_clean_failure(run_import(SAMPLES / "limb.glb", out), out, "output must end in")


def test_usage_error_exit_2(work, colossus):
    proc = colossus("import", SAMPLES / "limb.glb")
    assert proc.returncode == 2 and "Missing option '-o'" in proc.stderr and proc.stdout == ""
    proc = colossus("import", SAMPLES / "limb.glb", "-o", work / "o.usda", "--max-influences", "0")
    assert proc.returncode == 2 and "--max-influences" in proc.stderr and not (work / "o.usda").exists()
    assert "Traceback" not in proc.stderr and proc.warnings == []


def test_unweighted_vertex_is_error_then_nearest_bone(work, run_import):
    def unweight(stage, mesh):
        attr = mesh.GetAttribute("primvars:skel:jointWeights")
        v = attr.Get()
        k = attr.GetMetadata("elementSize") or 1
        for i in range(k):
            v[10 * k + i] = 0.0
        attr.Set(v)
    src = _edit_usd(work, unweight)
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "no skin weight")
    proc = run_import(src, out, "--unweighted", "nearest-bone")
    assert proc.returncode == 0, proc.stderr
    assert out.exists() and proc.warnings == []


def test_allocation_cap(work, monkeypatch):
    """A file may not make the importer allocate beyond its size times a fixed factor."""
    from pipeline.errors import InputError
    from pipeline.readers import common, read

    monkeypatch.setattr(common, "ALLOC_FACTOR", 2)
    monkeypatch.setattr(common, "ALLOC_FLOOR", 0)
    with pytest.raises(InputError, match="budget"):
        read(SAMPLES / "creature.glb")
