"""``colossus validate ASSET --source FILE`` (COL6xx): the asset against the export it was made from."""

from __future__ import annotations

import shutil
import subprocess
import sys

import numpy as np
import pytest
from pxr import Gf, Usd, Vt

from paths import ROOT, SAMPLES
from colossus.validators import check_asset


@pytest.fixture(scope="module")
def limb(tmp_path_factory):
    """``samples/limb.glb`` imported: (asset path, source path)."""
    from colossus.pipeline.run import import_asset

    d = tmp_path_factory.mktemp("source")
    out = d / "limb.usda"
    import_asset(SAMPLES / "limb.glb", out)
    return out, SAMPLES / "limb.glb"


def _copy(path, tmp_path, name="edited.usda"):
    dst = tmp_path / name
    shutil.copy(path, dst)
    return dst


def _codes(report, prefix="COL6"):
    return sorted({f.code for f in report.findings if f.code.startswith(prefix)})


def test_matching_source_is_clean(limb):
    asset, src = limb
    rep = check_asset(str(asset), source=str(src))
    assert rep.passed and _codes(rep) == []
    assert {"COL601", "COL602", "COL603", "COL604", "COL605"} <= set(rep.rules_run)


def test_same_rig_in_another_format_still_matches(limb):
    """The Blender FBX of the same rig moves the same way: only the sha256 differs (a warning)."""
    asset, _ = limb
    rep = check_asset(str(asset), source=str(SAMPLES / "limb.fbx"))
    assert rep.passed, [(f.code, f.message) for f in rep.findings]
    assert _codes(rep) == ["COL602"]
    assert rep.by_code("COL602")[0].severity == "warning"


def test_col601_motion_changed(limb, tmp_path):
    asset, src = limb
    bad = _copy(asset, tmp_path)
    stage = Usd.Stage.Open(str(bad))
    anim = stage.GetPrimAtPath("/limb/bend")
    rot = anim.GetAttribute("rotations")
    t = rot.GetTimeSamples()[12]
    q = np.array(rot.Get(t))
    q[1] = [0.0, 0.0, np.sin(0.3), np.cos(0.3)]  # the middle joint turned on frame 12 only
    rot.Set(Vt.QuatfArray.FromNumpy(q.astype(np.float32)), t)
    stage.GetRootLayer().Save()
    rep = check_asset(str(bad), source=str(src))
    f = rep.by_code("COL601")
    assert f and f[0].severity == "error" and not rep.passed
    assert f[0].location["clip"] == "bend" and f[0].location["frame"] == 12
    assert "x model size" in f[0].message


def test_col602_other_bytes_same_rig(limb, tmp_path):
    asset, src = limb
    other = tmp_path / "limb.glb"
    other.write_bytes(src.read_bytes() + b"\0" * 8)  # trailing bytes after the GLB: same content
    rep = check_asset(str(asset), source=str(other))
    assert _codes(rep) == ["COL602"] and rep.passed


def test_col603_clip_missing_or_retimed(limb, tmp_path):
    asset, src = limb
    bad = _copy(asset, tmp_path)
    stage = Usd.Stage.Open(str(bad))
    for attr in stage.GetPrimAtPath("/limb/bend").GetAttributes():
        ts = attr.GetTimeSamples()
        if ts:
            attr.ClearAtTime(ts[-1])  # one frame fewer
    stage.GetRootLayer().Save()
    rep = check_asset(str(bad), source=str(src))
    msgs = [f.message for f in rep.by_code("COL603")]
    assert msgs and "frames" in msgs[0] and not rep.passed


def test_col604_vertex_moved(limb, tmp_path):
    asset, src = limb
    bad = _copy(asset, tmp_path)
    stage = Usd.Stage.Open(str(bad))
    pts = stage.GetPrimAtPath("/limb/Collider").GetAttribute("points")
    p = np.array(pts.Get())
    p[7] += [0.5, 0.0, 0.0]
    pts.Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)))
    stage.GetRootLayer().Save()
    rep = check_asset(str(bad), source=str(src))
    msgs = " ".join(f.message for f in rep.by_code("COL604"))
    assert "1 asset vertices" in msgs and "1 source vertices" in msgs


def test_col605_unreadable_source(limb, tmp_path):
    asset, src = limb
    broken = tmp_path / "broken.glb"
    broken.write_bytes(src.read_bytes()[:200])
    rep = check_asset(str(asset), source=str(broken))
    assert _codes(rep) == ["COL605"] and not rep.passed


def test_cli_exit_status(limb, tmp_path):
    asset, src = limb
    run = lambda *a: subprocess.run([sys.executable, "-m", "colossus", "validate", *map(str, a)],
                                    capture_output=True, text=True, cwd=ROOT)
    assert run(asset, "--source", src).returncode == 0
    assert run(asset, "--source", SAMPLES / "limb.fbx").returncode == 0  # a warning only
    assert run(asset, "--source", SAMPLES / "creature.glb").returncode == 1
    missing = run(asset, "--source", tmp_path / "nope.glb")
    assert missing.returncode == 2 and "no such file" in missing.stderr


def test_centimetre_mesh_bound_by_scaled_joints_judged_at_its_posed_size(tmp_path):
    """``realworld/playcanvas_lumberjack.glb`` binds a centimetre mesh by x100 joints and moves
    it in metres: its bind pose is 265 units across, its posed body 2.4.  COL601 judges motion
    at the posed size (a 3 mm shift of one frame is caught; against the bind pose's size it
    would pass under 2.6 cm), and allows each clip the half3 storage bound it states (its
    stretch bones), so the fresh import matches its own source."""
    src = ROOT.parent / "shared" / "corpus" / "realworld" / "playcanvas_lumberjack.glb"
    if not src.is_file():
        pytest.skip("corpus file absent")
    from colossus.pipeline.run import import_asset
    from colossus.validators.asset import LoadedAsset, open_stage
    from colossus.validators.source import compare_source

    out = tmp_path / "lumberjack.usda"
    import_asset(src, out)
    rep = check_asset(str(out), source=str(src))
    assert rep.passed and "COL601" not in _codes(rep), [(f.code, f.message) for f in rep.findings][:3]
    c = compare_source(LoadedAsset(open_stage(str(out)), str(out)), src)
    assert c.size > 100 and 2.0 < c.clip_size["Walk"] < 3.0, (c.size, c.clip_size)
    assert 0 < c.clip_storage["Walk"] < 1e-3
    bad = _copy(out, tmp_path)
    stage = Usd.Stage.Open(str(bad))
    anim = stage.GetPrimAtPath("/playcanvas_lumberjack/Walk")
    tr = anim.GetAttribute("translations")
    t = tr.GetTimeSamples()[10]
    v = np.array(tr.Get(t))
    v[0] += [0.003, 0.0, 0.0]  # the root joint moved by 3 mm on frame 10
    tr.Set(Vt.Vec3fArray.FromNumpy(v.astype(np.float32)), t)
    stage.GetRootLayer().Save()
    f = check_asset(str(bad), source=str(src)).by_code("COL601")
    assert f and f[0].location["clip"] == "Walk" and f[0].location["frame"] == 10, f
