"""The command line as users drive it (the README's commands)."""

import json
import subprocess
import sys

from conftest import SAMPLES

COLOSSUS = [sys.executable, "-m", "pipeline.cli"]


def test_help_lists_every_command():
    out = subprocess.run(COLOSSUS + ["--help"], capture_output=True, text=True, check=True).stdout
    for cmd in ("import", "validate", "bench"):
        assert cmd in out


def test_readme_import_example_and_json(tmp_path):
    out = tmp_path / "creature.usda"
    proc = subprocess.run(COLOSSUS + ["import", str(SAMPLES / "creature.fbx"), "-o", str(out), "--json"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    assert s["vertices_in"] == 20464 and s["vertices_out"] == 5056
    assert s["faces_flipped"] == 0 and s["parts"] == 16 and s["clips"] == 2 and s["frames"] == 86
    assert set(s["stage_seconds"]) == {"read", "bake", "weld", "orient", "bind", "parts", "spheres", "write"}
    assert out.exists()
    proc = subprocess.run(COLOSSUS + ["validate", str(out)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "1 assets, 1 passed, 0 failed" in proc.stdout


def test_text_summary_and_options(tmp_path):
    out = tmp_path / "limb.usdc"
    proc = subprocess.run(COLOSSUS + ["import", str(SAMPLES / "limb.glb"), "-o", str(out), "--up-axis", "Z",
                                      "--meters-per-unit", "0.01", "--max-influences", "2", "--parts", "any"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "weld" in proc.stdout and "spheres" in proc.stdout and "total" in proc.stdout
    from pxr import Usd, UsdGeom
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 0.01
    pts = stage.GetDefaultPrim().GetChild("Collider").GetAttribute("points").Get()
    import numpy as np
    p = np.asarray(pts)
    # the limb is 3.5 m long along Blender's Z: in a Z-up centimetre stage it spans ~350 units of Z
    assert 340 < p[:, 2].max() - p[:, 2].min() < 360
    ind = stage.GetDefaultPrim().GetChild("Collider").GetAttribute("primvars:skel:jointIndices")
    assert ind.GetMetadata("elementSize") == 2


def test_mesh_option_unknown_name(tmp_path):
    out = tmp_path / "o.usda"
    proc = subprocess.run(COLOSSUS + ["import", str(SAMPLES / "creature.glb"), "-o", str(out), "--mesh", "Nope"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1 and "no mesh named 'Nope'" in proc.stderr and "Creature" in proc.stderr
    proc = subprocess.run(COLOSSUS + ["import", str(SAMPLES / "creature.glb"), "-o", str(out), "--mesh", "Creature"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr


def test_progress_bar_on_request(tmp_path):
    out = tmp_path / "limb.usda"
    proc = subprocess.run(COLOSSUS + ["import", str(SAMPLES / "limb.glb"), "-o", str(out), "--progress"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "importing" in proc.stderr and "8/8" in proc.stderr
    assert "importing" not in proc.stdout
