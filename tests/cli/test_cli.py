"""The command line as users drive it (the README's commands), in process through click's
CliRunner on the real ``colossus`` group, plus one smoke test of the installed entry point in a
subprocess (the only place fd-level output, the console script and a cold interpreter show)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from click.testing import CliRunner
from scipy.spatial import cKDTree

from paths import SAMPLES

#: Every command, in the README's order (``colossus --help`` lists every command).
COMMANDS = ("import", "validate", "build", "check", "config", "inspect", "render", "play", "bench")


def colossus(*args):
    """``colossus ARGS...`` in process; returns click's Result (exit_code, stdout, stderr)."""
    from colossus.cli import main
    return CliRunner().invoke(main, [str(a) for a in args], prog_name="colossus")


def entry_point():
    """The installed console script, else ``python -m colossus``."""
    script = Path(sys.executable).with_name("colossus")
    return [str(script)] if script.exists() else [sys.executable, "-m", "colossus"]


def test_help_lists_every_command():
    r = colossus("--help")
    assert r.exit_code == 0, r.output
    listed = [line.split()[0] for line in r.stdout.split("Commands:")[1].splitlines() if line.strip()]
    assert listed == list(COMMANDS)
    for cmd in COMMANDS:  # and each one loads and has its own help
        sub = colossus(cmd, "--help")
        assert sub.exit_code == 0 and sub.stdout.startswith(f"Usage: colossus {cmd}"), (cmd, sub.output)


def test_entry_point_smoke(tmp_path):
    """The real console script in a fresh interpreter: --help, then a bad input (exit 1, exactly
    one line on stderr at the file-descriptor level, no traceback or warning, nothing written)."""
    env = dict(os.environ, PYTHONWARNINGS="default")  # show every warning a user could see
    help_ = subprocess.run(entry_point() + ["--help"], capture_output=True, text=True, timeout=120, env=env)
    assert help_.returncode == 0 and help_.stderr == "", help_.stderr
    assert all(f"  {cmd} " in help_.stdout for cmd in COMMANDS)
    src = tmp_path / "random.glb"
    src.write_bytes(np.random.default_rng(7).integers(0, 256, 50_000, dtype=np.uint8).tobytes())
    out = tmp_path / "o.usda"
    proc = subprocess.run(entry_point() + ["import", str(src), "-o", str(out)], capture_output=True,
                          text=True, timeout=120, env=env)
    assert proc.returncode == 1 and proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "random.glb" in lines[0], proc.stderr
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["random.glb"]


def test_readme_import_example_and_json(tmp_path):
    out = tmp_path / "creature.usda"
    r = colossus("import", SAMPLES / "creature.fbx", "-o", out, "--json")
    assert r.exit_code == 0, r.output
    assert r.stderr == ""
    s = json.loads(r.stdout)
    assert s["vertices_in"] == 5056 and s["vertices_out"] == 5056  # ufbx reads control points
    assert s["faces_flipped"] == 0 and s["parts"] == 16 and s["clips"] == 2 and s["frames"] == 86
    assert set(s["stage_seconds"]) == {"read", "bake", "weld", "degenerate", "orient", "bind", "parts", "quantize",
                                       "spheres", "write"}
    assert s["degenerate_dropped"] == 0 and s["stages"]["write"]["counts"]["check_seconds"] > 0
    assert out.exists()
    r = colossus("validate", out)
    assert r.exit_code == 0, r.output
    assert r.stdout.splitlines()[0] == f"{out}: PASS (0 errors, 0 warnings)"
    assert r.stdout.splitlines()[-1] == "1 assets, 1 passed, 0 failed"


def test_text_summary_and_options(tmp_path):
    """Z up, centimetres, 2 influences, --parts any: the limb comes out exactly as Blender has it
    (Blender is Z up too), x100, every vertex where Blender's own USD export puts it."""
    from pxr import Usd, UsdGeom
    out = tmp_path / "limb.usdc"
    r = colossus("import", SAMPLES / "limb.glb", "-o", out, "--up-axis", "Z", "--meters-per-unit", "0.01",
                 "--max-influences", "2", "--parts", "any")
    assert r.exit_code == 0, r.output
    lines = r.stdout.splitlines()
    assert lines[0] == f"colossus import limb.glb -> {out}"
    stages = [ln.split()[0] for ln in lines[3:14]]
    assert stages == ["read", "bake", "weld", "degenerate", "orient", "bind", "parts", "quantize", "spheres", "write",
                      "total"]
    assert "Y-up 1 m/unit -> Z-up 0.01 m/unit (x100)" in r.stdout
    assert "parts (any)" in r.stdout
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 0.01
    collider = stage.GetDefaultPrim().GetChild("Collider")
    p = np.asarray(collider.GetAttribute("points").Get(), dtype=np.float64)
    # the limb is 3.5 m along Blender's +Z, from -0.25 m (the base cap) to 3.25 m (the tip)
    assert abs(p[:, 2].min() - -25.0) < 1e-4 and abs(p[:, 2].max() - 325.0) < 1e-4
    bstage = Usd.Stage.Open(str(SAMPLES / "limb.usda"))
    blender = np.asarray(next(q for q in bstage.Traverse() if q.GetTypeName() == "Mesh")
                         .GetAttribute("points").Get(), dtype=np.float64)
    d, idx = cKDTree(100.0 * blender).query(p)  # the limb's objects sit at the origin, unrotated
    assert d.max() < 1e-4 and len(np.unique(idx)) == len(p) == len(blender)
    ind = collider.GetAttribute("primvars:skel:jointIndices")
    assert ind.GetMetadata("elementSize") == 2


def test_mesh_option_unknown_name(tmp_path):
    out = tmp_path / "o.usda"
    r = colossus("import", SAMPLES / "creature.glb", "-o", out, "--mesh", "Nope")
    assert r.exit_code == 1 and r.stdout == ""
    (line,) = r.stderr.splitlines()
    assert line.startswith("error: ") and "no mesh named 'Nope'" in line and "Creature" in line
    assert not out.exists()
    r = colossus("import", SAMPLES / "creature.glb", "-o", out, "--mesh", "Creature")
    assert r.exit_code == 0, r.output
    assert out.exists()


def test_progress_bar_on_request(tmp_path):
    out = tmp_path / "limb.usda"
    r = colossus("import", SAMPLES / "limb.glb", "-o", out, "--progress")
    assert r.exit_code == 0, r.output
    assert "importing" in r.stderr and "10/10" in r.stderr
    assert "importing" not in r.stdout
