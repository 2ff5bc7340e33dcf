"""The import pipeline on real Blender exports: counts, cross-format agreement, usd-core skinning."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from pipeline.model import skel_transforms, skin_points
from pipeline.tolerances import model_scale

FORMATS = ("glb", "fbx", "usda")
MODELS = ("limb", "creature")


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("ext", FORMATS)
def test_import_counts_match_blender(imported, samples_meta, model, ext):
    result, out = imported(model, ext)
    meta = samples_meta[model]
    m = result.mesh
    assert out.exists()
    assert m.vertex_count == meta["blender_vertices"]  # welded count = what Blender shows
    assert m.face_count == meta["blender_triangles"]
    assert set(m.joint_names) == set(meta["bones"])
    clips = {c.name: c.frame_count for c in m.clips}
    if ext == "usda":  # Blender's USD export writes only the active action
        assert len(clips) == 1
    else:
        assert clips == {k: v + 1 for k, v in meta["actions"].items()}  # frames 0..N inclusive
    assert m.up_axis == "Y" and m.meters_per_unit == 1.0
    assert m.joint_indices.shape[1] == 4
    np.testing.assert_allclose(m.joint_weights.sum(axis=1), 1.0, atol=1e-5)
    assert result.summary()["faces_flipped"] == 0
    # every triangle is in a part and every part sphere holds the bind pose
    assert np.array_equal(np.unique(m.parts.faces), np.arange(m.face_count))


def _matched(a_result, b_result):
    a, b = a_result.mesh, b_result.mesh
    d, idx = cKDTree(a.positions).query(b.positions)
    return a, b, d, idx


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("other", ("fbx", "usda"))
def test_cross_format_same_collider(imported, model, other):
    ra, _ = imported(model, "glb")
    rb, _ = imported(model, other)
    a, b, d, idx = _matched(ra, rb)
    tol = 1e-4 * model_scale(a.positions)
    assert a.vertex_count == b.vertex_count
    assert d.max() < tol  # same rest points
    assert len(np.unique(idx)) == a.vertex_count
    common = [c.name for c in b.clips if c.name in {x.name for x in a.clips}]
    assert common
    for name in common:
        ca, cb = a.clip(name), b.clip(name)
        assert ca.frame_count == cb.frame_count
        pa = skin_points(a, skel_transforms(ca.local, a.parents))
        pb = skin_points(b, skel_transforms(cb.local, b.parents))
        err = np.abs(pa[:, idx] - pb).max()
        assert err < tol, f"{name}: skinned points differ by {err}"


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("ext", FORMATS)
def test_usd_core_skinning_matches_pipeline(imported, model, ext):
    """Skinning the written asset with plain usd-core reproduces the pipeline's skinned points."""
    from pxr import Usd, UsdSkel

    result, out = imported(model, ext)
    m = result.mesh
    stage = Usd.Stage.Open(str(out))
    root = UsdSkel.Root(stage.GetDefaultPrim())
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.PrimDefaultPredicate)
    (binding,) = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
    (sq,) = binding.GetSkinningTargets()
    skel_query = cache.GetSkelQuery(binding.GetSkeleton())
    tol = 1e-5 * model_scale(m.positions)
    pts = stage.GetPrimAtPath(sq.GetPrim().GetPath()).GetAttribute("points").Get()
    for clip in m.clips:
        anim = UsdSkel.Animation(stage.GetDefaultPrim().GetChild(clip.name))
        assert anim, clip.name
        skel_query.GetSkeleton().GetPrim()  # keep alive
        UsdSkel.BindingAPI(binding.GetSkeleton().GetPrim()).GetAnimationSourceRel().SetTargets([anim.GetPath()])
        cache2 = UsdSkel.Cache()
        cache2.Populate(root, Usd.PrimDefaultPredicate)
        sk = cache2.GetSkelQuery(binding.GetSkeleton())
        ours = skin_points(m, skel_transforms(clip.local, m.parents))
        for f, t in enumerate(clip.times):
            xf = sk.ComputeSkinningTransforms(Usd.TimeCode(t))
            p = type(pts)(pts)
            assert sq.ComputeSkinnedPoints(xf, p, Usd.TimeCode(t))
            err = np.abs(np.asarray(p) - ours[f]).max()
            assert err < tol, f"{clip.name} frame {f}: {err}"


def test_flipped_sample_comes_out_outward(imported, samples_meta):
    import trimesh

    result, _ = imported("limb_flipped", "glb")
    good, _ = imported("limb", "glb")
    assert result.summary()["faces_flipped"] == samples_meta["limb_flipped"]["flipped_triangles"]
    m = result.mesh
    tm = trimesh.Trimesh(m.positions, m.triangles, process=False)
    assert tm.is_winding_consistent and tm.volume > 0
    assert np.array_equal(np.sort(np.sort(m.triangles, 1), 0), np.sort(np.sort(good.mesh.triangles, 1), 0))


@pytest.mark.parametrize("model,ext", [(m, e) for m in MODELS for e in FORMATS] + [("limb_flipped", "glb")])
def test_imported_assets_pass_every_validator(imported, model, ext):
    import validators

    _, out = imported(model, ext)
    report = validators.check_asset(str(out))
    assert report.passed, [f.message for f in report.findings]
    assert not [f for f in report.findings if f.severity in ("error", "warning")]


def test_provenance_and_metadata(imported):
    from pxr import Usd, UsdGeom

    from pipeline.run import sha256_of
    from conftest import SAMPLES

    _, out = imported("creature", "fbx")
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageUpAxis(stage) == "Y"
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == 24.0
    root = stage.GetDefaultPrim()
    assert root.GetTypeName() == "SkelRoot"
    mesh = root.GetChild("Collider")
    prov = mesh.GetCustomDataByKey("colossus")
    assert prov["source"] == "creature.fbx"
    assert prov["sourceSha256"] == sha256_of(SAMPLES / "creature.fbx")
    assert prov["importer"].startswith("colossus ")
    assert prov["settings"]["max_influences"] == 4
    assert [c.GetName() for c in root.GetChildren() if c.GetTypeName() == "SkelAnimation"] == ["roar", "walk"]


def test_several_meshes_merged_or_chosen(tmp_path):
    """Default: every mesh skinned to the skeleton, merged; --mesh NAME picks (repeatable)."""
    import shutil

    from pxr import Gf, Sdf, Usd

    from conftest import SAMPLES
    from pipeline.run import ImportSettings, import_asset

    src = tmp_path / "two_limbs.usda"
    shutil.copy(SAMPLES / "limb.usda", src)
    stage = Usd.Stage.Open(str(src))
    layer = stage.GetRootLayer()
    assert Sdf.CopySpec(layer, "/root/LimbArmature/Limb", layer, "/root/LimbArmature/Limb2")
    pts = stage.GetPrimAtPath("/root/LimbArmature/Limb2/Limb").GetAttribute("points")
    pts.Set([p + Gf.Vec3f(2.0, 0, 0) for p in pts.Get()])  # a second limb, 2 m along X
    stage.GetRootLayer().Save()

    both = import_asset(src, tmp_path / "both.usda").mesh
    assert both.vertex_count == 2 * 386 and both.face_count == 2 * 768
    one = import_asset(src, tmp_path / "one.usda", ImportSettings(meshes=["/root/LimbArmature/Limb2/Limb"])).mesh
    assert one.vertex_count == 386
    # the chosen copy sits 2 m to the side of the original (Blender X stays X in Y-up output)
    assert abs((one.positions[:, 0].mean() - both.positions[:386, 0].mean()) - 2.0) < 1e-4
