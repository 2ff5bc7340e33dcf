"""Bad input: exit 1 (2 for usage), one clear line naming the file, no traceback, no output left."""

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from conftest import SAMPLES

COLOSSUS = [sys.executable, "-m", "pipeline.cli"]


def run_import(src, out):
    return subprocess.run(COLOSSUS + ["import", str(src), "-o", str(out)], capture_output=True, text=True, timeout=120)


def assert_clean_failure(proc, out, needle, code=1):
    assert proc.returncode == code, proc.stderr
    err = proc.stderr.strip()
    assert "Traceback" not in err
    assert len(err.splitlines()) == 1, err
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


def test_missing_path(work):
    out = work / "o.usda"
    assert_clean_failure(run_import(work / "nope.glb", out), out, "nope.glb: no such file")


@pytest.mark.parametrize("ext", ["glb", "fbx", "usda"])
def test_zero_byte(work, ext):
    src = work / f"empty.{ext}"
    src.write_bytes(b"")
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, f"empty.{ext}: file is empty")


@pytest.mark.parametrize("ext", ["glb", "fbx", "usda"])
def test_truncated(work, ext):
    data = (SAMPLES / f"creature.{ext}").read_bytes()
    src = work / f"trunc.{ext}"
    src.write_bytes(data[: len(data) // 3])
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, f"trunc.{ext}")


@pytest.mark.parametrize("ext", ["glb", "fbx", "dae", "usda", "usdc"])
def test_random_bytes(work, ext):
    src = work / f"random.{ext}"
    src.write_bytes(np.random.default_rng(7).integers(0, 256, 50_000, dtype=np.uint8).tobytes())
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, f"random.{ext}")


def test_nan_positions(work):
    def nan(stage, mesh):
        pts = mesh.GetAttribute("points").Get()
        pts[5] = (float("nan"), 0.0, 0.0)
        mesh.GetAttribute("points").Set(pts)
    src = _edit_usd(work, nan)
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "NaN or infinite")


def test_infinite_positions(work):
    def inf(stage, mesh):
        pts = mesh.GetAttribute("points").Get()
        pts[0] = (float("inf"), 0.0, 0.0)
        mesh.GetAttribute("points").Set(pts)
    src = _edit_usd(work, inf)
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "NaN or infinite")


def test_joint_index_out_of_range(work):
    def bad(stage, mesh):
        attr = mesh.GetAttribute("primvars:skel:jointIndices")
        v = attr.Get()
        v[3] = 99
        attr.Set(v)
    src = _edit_usd(work, bad)
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "out of range")


def test_mesh_without_skin(work):
    import trimesh
    src = work / "box.glb"
    trimesh.creation.box().export(src)
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "no skinned mesh")


def test_empty_scene_usd(work):
    from pxr import Usd
    src = work / "empty_scene.usda"
    stage = Usd.Stage.CreateNew(str(src))
    stage.Save()
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "has no mesh")


def test_empty_scene_gltf(work):
    src = work / "empty_scene.gltf"
    src.write_text('{"asset": {"version": "2.0"}, "scenes": [{"nodes": []}], "scene": 0}')
    out = work / "o.usda"
    proc = run_import(src, out)
    assert_clean_failure(proc, out, "empty_scene.gltf")


def test_unsupported_extension(work):
    src = work / "notes.txt"
    src.write_text("hello")
    out = work / "o.usda"
    assert_clean_failure(run_import(src, out), out, "unsupported file type")


def test_output_dir_missing(work):
    out = work / "no" / "such" / "dir" / "o.usda"
    assert_clean_failure(run_import(SAMPLES / "limb.glb", out), out, "does not exist")


def test_output_dir_not_writable(work):
    out = "/proc/colossus-test.usda"  # not writable, even for root
    proc = run_import(SAMPLES / "limb.glb", out)
    assert_clean_failure(proc, out, "colossus-test.usda")


def test_output_bad_extension(work):
    out = work / "o.obj"
    assert_clean_failure(run_import(SAMPLES / "limb.glb", out), out, "output must end in")


def test_usage_error_exit_2(work):
    proc = subprocess.run(COLOSSUS + ["import", str(SAMPLES / "limb.glb")], capture_output=True, text=True)
    assert proc.returncode == 2
    proc = subprocess.run(COLOSSUS + ["import", str(SAMPLES / "limb.glb"), "-o", str(work / "o.usda"),
                                      "--max-influences", "0"], capture_output=True, text=True)
    assert proc.returncode == 2 and not (work / "o.usda").exists()


def test_unweighted_vertex_is_error_then_nearest_bone(work):
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
    proc = subprocess.run(COLOSSUS + ["import", str(src), "-o", str(out), "--unweighted", "nearest-bone"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert out.exists()


def test_allocation_cap(work, monkeypatch):
    """A file may not make the importer allocate beyond its size times a fixed factor."""
    from pipeline.errors import InputError
    from pipeline.readers import common, read

    monkeypatch.setattr(common, "ALLOC_FACTOR", 2)
    monkeypatch.setattr(common, "ALLOC_FLOOR", 0)
    with pytest.raises(InputError, match="budget"):
        read(SAMPLES / "creature.glb")
