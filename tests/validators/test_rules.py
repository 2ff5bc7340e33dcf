"""Every rule: a broken asset (a good one edited with pxr) that fails it, and the good one that passes."""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdSkel, Vt

from references.usd_fixture import build_test_stage, open_copy, write_test_asset
from colossus.validators import all_rules, check_asset

MESH, SKEL, ROOT = "/Tube/Collider", "/Tube/Skeleton", "/Tube"


@pytest.fixture(scope="module")
def good_path(tmp_path_factory):
    return write_test_asset(tmp_path_factory.mktemp("good") / "tube.usda")


@pytest.fixture(scope="module")
def good_report(good_path):
    return check_asset(good_path)


def _attr(s, path, name):
    return s.GetPrimAtPath(path).GetAttribute(name)


def _edit(s, path, name, fn, time=Usd.TimeCode.Default()):
    """Apply ``fn`` to the attribute's value as a numpy array and write it back."""
    a = _attr(s, path, name)
    v = a.Get(time)
    arr = np.array(v)
    out = fn(arr.copy())
    a.Set(type(v).FromNumpy(out) if hasattr(type(v), "FromNumpy") else type(v)(out.tolist()), time)


def _set_item(i, value):
    def f(a):
        a[i] = value
        return a
    return f


def _weights(s, fn):
    pv = UsdSkel.BindingAPI(s.GetPrimAtPath(MESH)).GetJointWeightsPrimvar()
    k = pv.GetElementSize()
    w = np.array(pv.Get()).reshape(-1, k)
    pv.Set(Vt.FloatArray.FromNumpy(fn(w).astype(np.float32).ravel()))


def _indices(s, fn):
    pv = UsdSkel.BindingAPI(s.GetPrimAtPath(MESH)).GetJointIndicesPrimvar()
    k = pv.GetElementSize()
    w = np.array(pv.Get()).reshape(-1, k)
    pv.Set(Vt.IntArray.FromNumpy(fn(w).astype(np.int32).ravel()))


def _mat_edit(s, name, j, fn):
    a = _attr(s, SKEL, name)
    m = list(a.Get())
    m[j] = fn(Gf.Matrix4d(m[j]))
    a.Set(Vt.Matrix4dArray(m))


def _tris(s, fn):
    _edit(s, MESH, "faceVertexIndices", lambda a: fn(a.reshape(-1, 3)).ravel().astype(np.int32))


def _clip_attr_edit(s, clip, name, time, fn):
    a = _attr(s, f"{ROOT}/{clip}", name)
    v = list(a.Get(time))
    fn(v)
    a.Set(type(a.Get(time))(v), time)


# ---------------------------------------------------------------------------- breakers
def b101(s):
    UsdSkel.BindingAPI.Apply(UsdGeom.Xform.Define(s, "/Other").GetPrim())


def b103(s):
    s.GetRootLayer().pseudoRoot.ClearInfo("metersPerUnit")


def b104(s):
    UsdSkel.Root.Define(s, "/Other")


def b105(s):
    a = _attr(s, SKEL, "bindTransforms")
    a.Set(Vt.Matrix4dArray(list(a.Get())[:2]))


def b106(s):
    UsdPhysics.MeshCollisionAPI(s.GetPrimAtPath(MESH)).GetApproximationAttr().Set("convexHull")


def b107(s):
    s.GetPrimAtPath(MESH).RemoveProperty("colossus:parts:radii")


def b108(s):
    _edit(s, MESH, "colossus:parts:radii", lambda a: a[:2])


def b109(s):
    _attr(s, MESH, "colossus:parts:joints").Set(["root", "root/nope", "root/mid/tip"])


def b110(s):
    s.GetPrimAtPath(MESH).ClearCustomDataByKey("colossus")


def b201(s):
    _edit(s, MESH, "faceVertexCounts", lambda a: np.r_[4, 2, a[2:]].astype(np.int32))


def b202(s):
    _edit(s, MESH, "faceVertexIndices", _set_item(0, 100000))


def b203(s):
    _edit(s, MESH, "points", _set_item(5, np.nan))


def b204(s):
    _tris(s, lambda t: (t.__setitem__((0, 2), t[0, 0]), t)[1])


def b205(s):
    _edit(s, MESH, "points", lambda a: np.vstack([a, [[9, 9, 9]]]).astype(np.float32))


def b206(s):
    _edit(s, MESH, "points", lambda a: (a.__setitem__(1, a[0]), a)[1])


def b207(s):
    def f(t):
        extra = np.array([[t[0, 0], t[0, 1], t.max()]])
        return np.vstack([t, extra])
    _tris(s, f)
    _edit(s, MESH, "faceVertexCounts", lambda a: np.r_[a, 3].astype(np.int32))


def b208(s):
    _tris(s, lambda t: (t.__setitem__(5, t[5, ::-1]), t)[1])


def b209(s):
    _tris(s, lambda t: t[:, ::-1].copy())


def b302(s):
    _weights(s, lambda w: (w.__setitem__(0, [1.2, -0.2, 0, 0]), w)[1])


def b303(s):
    _weights(s, lambda w: (w.__setitem__(0, w[0] * 0.5), w)[1])


def b304(s):
    _indices(s, lambda j: (j.__setitem__((0, 0), 7), j)[1])


def b305(s):
    _weights(s, lambda w: (w.__setitem__(0, 0), w)[1])


def b306(s):
    _attr(s, SKEL, "joints").Set(["root/mid", "root", "root/mid/tip"])


def b307(s):
    _mat_edit(s, "bindTransforms", 1, lambda m: m.SetScale(Gf.Vec3d(1, 0, 1)) and None or m)


def b308(s):
    _mat_edit(s, "restTransforms", 1, lambda m: m.SetTranslateOnly(Gf.Vec3d(0, 1.5, 0)))


def b309(s):
    UsdSkel.BindingAPI(s.GetPrimAtPath(MESH)).GetJointWeightsPrimvar().SetInterpolation("constant")


def b310(s):
    pv = UsdSkel.BindingAPI(s.GetPrimAtPath(MESH)).GetJointWeightsPrimvar()
    w = np.array(pv.Get()).reshape(-1, 4)
    v = int(np.argmax((w[:, 1] > 0.1) & (w[:, 1] < w[:, 0])))
    _weights(s, lambda w: (w.__setitem__((v, slice(0, 2)), w[v, 1::-1]), w)[1])
    _indices(s, lambda j: (j.__setitem__((v, slice(0, 2)), j[v, 1::-1]), j)[1])


def b318(s):
    _mat_edit(s, "restTransforms", 1, lambda m: m.SetScale(Gf.Vec3d(1, 0, 1)) and None or m)


def b401(s):
    _edit(s, MESH, "colossus:parts:faces", lambda a: a[:-1].astype(np.int32))
    _edit(s, MESH, "colossus:parts:faceOffsets", lambda a: (a.__setitem__(-1, a[-1] - 1), a)[1].astype(np.int32))


def b402(s):
    _edit(s, MESH, "colossus:parts:centers", lambda a: (a.__setitem__(0, a[0] + [5, 0, 0]), a)[1].astype(np.float32))


def b403(s):
    # frame 10 of "bend": the tip joint jumps 2 units along its bone; vertices shared with mid lag behind.
    _clip_attr_edit(s, "bend", "translations", 10, lambda v: v.__setitem__(2, Gf.Vec3f(0, 3, 0)))


def b404(s):
    _edit(s, MESH, "colossus:parts:radii", lambda a: (a * 3).astype(np.float32))
    for p in range(3):  # the guide spheres kept in agreement (COL408 judges them, not this)
        r = UsdGeom.Sphere(s.GetPrimAtPath(f"{ROOT}/PartSpheres/part{p}")).GetRadiusAttr()
        r.Set(float(np.float32(r.Get()) * np.float32(3)))


def b405(s):
    _edit(s, MESH, "colossus:parts:radii", _set_item(1, 0.0))


def b406(s):
    p = s.GetPrimAtPath(MESH)
    _attr(s, MESH, "colossus:parts:joints").Set(list(p.GetAttribute("colossus:parts:joints").Get()) + ["root"])
    _edit(s, MESH, "colossus:parts:centers", lambda a: np.vstack([a, [[0, 0, 0]]]).astype(np.float32))
    _edit(s, MESH, "colossus:parts:radii", lambda a: np.r_[a, 0.5].astype(np.float32))
    _edit(s, MESH, "colossus:parts:faceOffsets", lambda a: np.r_[a, a[-1]].astype(np.int32))


def b408(s):
    """A part's radius grown in colossus:parts:radii but not on its guide sphere."""
    _edit(s, MESH, "colossus:parts:radii", lambda a: (a.__setitem__(1, a[1] * 1.1), a)[1].astype(np.float32))


def test_col408_guide_sphere_breakages(good_path):
    """Each way a guide sphere can disagree with the parts is named: moved centre, wrong joint,
    not guide purpose, a missing one, one naming no part; the good asset's spheres agree."""
    def findings(edit):
        stage = open_copy(good_path)
        edit(stage)
        r = check_asset(stage)
        assert not r.by_code("COL002"), [f.message for f in r.by_code("COL002")]
        return [f.message for f in r.by_code("COL408")]

    sph = f"{ROOT}/PartSpheres/part1"

    def moved(s):
        a = UsdSkel.BindingAPI(s.GetPrimAtPath(sph)).GetGeomBindTransformAttr()
        m = Gf.Matrix4d(a.Get())
        m.SetTranslateOnly(m.ExtractTranslation() + Gf.Vec3d(0.01, 0, 0))
        a.Set(m)
    (m,) = findings(moved)
    assert "part 1" in m and "centre" in m
    (m,) = findings(lambda s: UsdSkel.BindingAPI(s.GetPrimAtPath(sph)).GetJointIndicesPrimvar().Set(Vt.IntArray([2])))
    assert "not rigidly bound" in m
    (m,) = findings(lambda s: UsdGeom.Imageable(s.GetPrimAtPath(sph)).GetPurposeAttr().Set("default"))
    assert "purpose" in m
    (m,) = findings(lambda s: s.RemovePrim(sph))
    assert "1 of 3 parts have no guide sphere" in m
    (m,) = findings(lambda s: UsdGeom.Sphere.Define(s, f"{ROOT}/PartSpheres/stray"))
    assert "names no part" in m


def _clip_vset_spec(s):
    return s.GetRootLayer().GetPrimAtPath(ROOT).variantSets["clip"]


def b509(s):
    """An asset whose 'twist' clip no USD tool can reach: its variant is gone."""
    vs = _clip_vset_spec(s)
    vs.RemoveVariant(vs.variants["twist"])


def test_col509_clip_variant_breakages(good_path):
    """Each way the clip variants can fail other tools is named: a variant binding another clip, a
    selection other than the first clip, a local animationSource overriding the variants, no
    variant set at all."""
    def findings(edit):
        stage = open_copy(good_path)
        edit(stage)
        r = check_asset(stage)
        assert not r.by_code("COL002"), [f.message for f in r.by_code("COL002")]
        return [f.message for f in r.by_code("COL509")]

    def wrong_target(s):
        v = _clip_vset_spec(s).variants["twist"].primSpec
        v.nameChildren["Skeleton"].relationships["skel:animationSource"].targetPathList.explicitItems = [
            Sdf.Path(f"{ROOT}/bend")]
    (m,) = findings(wrong_target)
    assert "variant 'twist' binds" in m
    (m,) = findings(lambda s: s.GetPrimAtPath(ROOT).GetVariantSets().GetVariantSet("clip").SetVariantSelection("twist"))
    assert "selection is 'twist'" in m
    (m,) = findings(lambda s: s.GetPrimAtPath(SKEL).GetRelationship("skel:animationSource").SetTargets(
        [Sdf.Path(f"{ROOT}/bend")]))
    assert "stronger than every variant" in m
    (m,) = findings(lambda s: s.GetRootLayer().GetPrimAtPath(ROOT).variantSetNameList.ClearEdits() or
                    s.GetRootLayer().GetPrimAtPath(ROOT).variantSets.__delitem__("clip"))
    assert "no variant set 'clip'" in m


def test_clip_variants_bind_every_clip(good_path):
    """The fixture, as the contract says: switching the SkelRoot's 'clip' variant binds that clip
    (the composed skel:animationSource), the first the default, and the validator is clean under
    every selection."""
    stage = open_copy(good_path)
    vset = stage.GetPrimAtPath(ROOT).GetVariantSets().GetVariantSet("clip")
    assert vset.GetVariantNames() == ["bend", "twist"] and vset.GetVariantSelection() == "bend"
    for clip in ("twist", "bend"):
        vset.SetVariantSelection(clip)
        rel = stage.GetPrimAtPath(SKEL).GetRelationship("skel:animationSource")
        assert [str(t) for t in rel.GetTargets()] == [f"{ROOT}/{clip}"]
    r = check_asset(stage)
    assert r.findings == [], [(f.code, f.message) for f in r.findings]


def b501(s):
    UsdSkel.Animation.Define(s, f"{ROOT}/idle").CreateJointsAttr(["root", "root/mid", "root/mid/tip"])


def b502(s):
    a = _attr(s, f"{ROOT}/bend", "translations")
    a.Set(a.Get(12), 12.5)


def b503(s):
    _clip_attr_edit(s, "bend", "rotations", 5, lambda v: v.__setitem__(1, Gf.Quatf(float("nan"), 0, 0, 0)))


def b504(s):
    UsdSkel.Animation.Define(s, f"{SKEL}/bend").CreateJointsAttr(["root", "root/mid", "root/mid/tip"])


def b505(s):
    _attr(s, f"{ROOT}/bend", "joints").Set(["root", "root/mid/tip", "root/mid"])


def b506(s):
    s.RemovePrim(f"{ROOT}/bend")
    s.RemovePrim(f"{ROOT}/twist")
    s.GetPrimAtPath(SKEL).GetRelationship("skel:animationSource").ClearTargets(True)


def b507(s):
    UsdSkel.Animation.Define(s, f"{SKEL}/extra").CreateJointsAttr(["root", "root/mid", "root/mid/tip"])


def b518(s):
    _clip_attr_edit(s, "bend", "scales", 4, lambda v: v.__setitem__(0, Gf.Vec3h(0, 0, 0)))


def b508(s):
    s.GetPrimAtPath(SKEL).GetRelationship("skel:animationSource").SetTargets([Sdf.Path(f"{ROOT}/twist")])


def _bind_shape(s, offsets, name="smile"):
    shape = UsdSkel.BlendShape.Define(s, f"{MESH}/{name}")
    shape.CreateOffsetsAttr(Vt.Vec3fArray([Gf.Vec3f(*o) for o in offsets]))
    shape.CreatePointIndicesAttr(Vt.IntArray(list(range(len(offsets)))))
    b = UsdSkel.BindingAPI(s.GetPrimAtPath(MESH))
    b.CreateBlendShapesAttr([name])
    b.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
    return shape


def _animate_shape(s, weights, name="smile"):
    """Every clip animates shape ``name`` from ``weights[0]`` to ``weights[-1]`` over its frames."""
    for prim in s.Traverse():
        if prim.IsA(UsdSkel.Animation):
            a = UsdSkel.Animation(prim)
            times = sorted(a.GetRotationsAttr().GetTimeSamples())
            a.CreateBlendShapesAttr([name])
            w = a.CreateBlendShapeWeightsAttr()
            for k, t in enumerate(times):
                w.Set(Vt.FloatArray([float(np.interp(k, np.linspace(0, len(times) - 1, len(weights)), weights))]), t)


def b313(s):
    """A blend shape whose offset is not finite."""
    _bind_shape(s, [(float("nan"), 0.1, 0)])


def b314(s):
    """A clip whose blend-shape weight is not finite."""
    _bind_shape(s, [(0, 0.01, 0)])
    _animate_shape(s, [0.0, float("inf")])


def test_blend_shape_asset_is_posed_and_proven(good_path):
    """A mesh with a blend shape animated in every clip (COL311 retired): no finding about it, the
    frames under the shape are skinned exactly and the between-frames proof runs on them."""
    stage = open_copy(good_path)
    _bind_shape(stage, [(0, 0.002, 0), (0.002, 0, 0)])
    _animate_shape(stage, [0.0, 1.0, -0.5])
    _edit(stage, MESH, "colossus:parts:radii", lambda r: (r * 1.3).astype(np.float32))
    r = check_asset(stage)
    bad = [f for f in r.findings if f.code in ("COL311", "COL313", "COL314", "COL403", "COL407")]
    assert not bad, [(f.code, f.message) for f in bad]
    fp = r.stats["frameproof"]
    assert fp["tiers"]["exact"] > 0 and sum(fp["intervals"].values()) > 0


def b312(s):
    """A skinning method no UsdSkel consumer knows (Maya's per-vertex blend has no token)."""
    s.GetPrimAtPath(MESH).CreateAttribute("primvars:skel:skinningMethod", Sdf.ValueTypeNames.Token,
                                          custom=False, variability=Sdf.VariabilityUniform).Set("blended")


def test_dual_quaternion_asset_is_not_col312_and_is_proven_with_dqs(good_path):
    """A dualQuaternion mesh is posed and proven with DQS: no COL312, every frame skinned exactly
    (tests K and D bound linear blends only), the between-frames proof still runs."""
    stage = open_copy(good_path)
    UsdSkel.BindingAPI(stage.GetPrimAtPath(MESH)).CreateSkinningMethodAttr().Set(UsdSkel.Tokens.dualQuaternion)
    _edit(stage, MESH, "colossus:parts:radii", lambda r: (r * 1.3).astype(np.float32))  # room for DQS's shape
    r = check_asset(stage)
    assert "COL312" not in r.codes() and "COL403" not in r.codes(), [(f.code, f.message) for f in r.findings]
    fp = r.stats["frameproof"]
    assert fp["tiers"]["K"] == 0 and fp["tiers"]["D"] == 0 and fp["tiers"]["exact"] > 0
    assert sum(fp["intervals"].values()) > 0


def test_dual_quaternion_escape_between_frames_is_col407(good_path):
    """b407's in-between escape on a dualQuaternion mesh: caught with its interval."""
    stage = open_copy(good_path)
    UsdSkel.BindingAPI(stage.GetPrimAtPath(MESH)).CreateSkinningMethodAttr().Set(UsdSkel.Tokens.dualQuaternion)
    b407(stage)
    r = check_asset(stage)
    assert "COL403" not in r.codes(), [f.message for f in r.by_code("COL403")]
    fs = r.by_code("COL407")
    assert fs and all(f.interval is not None and f.interval[1] - f.interval[0] == 1.0 for f in fs)


def b407(s):
    """Fails only between frames: ``bend`` swings mid and tip +-0.9 rad on alternate frames
    (straight half-way), centres moved off-axis, radii exactly as tight as the frames allow (the
    exact farthest vertex over every frame, from the proof run without its continuous part)."""
    from references.usd_fixture import clip_locals
    from colossus.validators import frameproof as fp
    from colossus.validators.asset import LoadedAsset

    times, _, q, _ = clip_locals("swing", 24)
    ra = _attr(s, f"{ROOT}/bend", "rotations")
    for i, tc in enumerate(times):
        ra.Set(Vt.QuatfArray.FromNumpy(np.ascontiguousarray(q[i], dtype=np.float32)), tc)
    _edit(s, MESH, "colossus:parts:centers", lambda c: np.tile(np.float32([0.5, 0.5, 0.0]), (len(c), 1)))
    asset = LoadedAsset(s)
    tight = fp.tightest(asset, fp.prove(asset, continuous=False), 0.0)
    _edit(s, MESH, "colossus:parts:radii", lambda r: (tight * (1 + 1e-6) + 1e-5).astype(np.float32))


def b701(s):
    # a proxy (its provenance says it was simplified) that lost its deviation
    s.GetPrimAtPath(MESH).SetCustomDataByKey("colossus:proxy:sourceFaces", 100000)


BREAKERS = {int(name[1:]): fn for name, fn in globals().items() if name.startswith("b") and name[1:].isdigit()}
BREAKERS = {f"COL{k:03d}": v for k, v in BREAKERS.items()}
#: Codes whose failing fixture is not an edited stage (files on disk, options, a crashing rule).
SPECIAL = {"COL001", "COL002", "COL003", "COL004", "COL102", "COL301",
           "COL601", "COL602", "COL603", "COL604", "COL605"}  # --source: tests/validators/test_validate_source.py; COL004: tests/pipeline/test_references.py


def test_good_asset_is_clean(good_report):
    assert good_report.passed
    assert good_report.findings == [], [f.message for f in good_report.findings]
    assert good_report.skipped == {}


def test_every_code_has_a_failing_fixture():
    codes = {r.code for r in all_rules()}
    assert codes == set(BREAKERS) | SPECIAL, sorted(codes ^ (set(BREAKERS) | SPECIAL))


@pytest.mark.parametrize("code", sorted(BREAKERS))
def test_rule_fails_broken_asset_and_passes_good(code, good_path, good_report):
    assert code not in good_report.codes()
    stage = open_copy(good_path)
    BREAKERS[code](stage)
    report = check_asset(stage)
    assert code in report.codes(), (code, [(f.code, f.message) for f in report.findings], report.skipped)
    assert not any(f.code == "COL002" for f in report.findings), [f.message for f in report.by_code("COL002")]
    f = report.by_code(code)[0]
    assert f.severity == next(r.severity for r in all_rules() if r.code == code)
    assert f.message and f.rule


def test_col001_corrupt_and_truncated(tmp_path, good_path):
    rnd = tmp_path / "random.usdc"
    rnd.write_bytes(os.urandom(4096))
    bad_text = tmp_path / "garbage.usda"
    bad_text.write_text("#usda 1.0\n(\n  upAxis = \ndef Mesh \"x\" {{{{\n")
    usdc = tmp_path / "good.usdc"
    Usd.Stage.Open(good_path).Export(str(usdc))
    data = usdc.read_bytes()
    trunc = tmp_path / "truncated.usdc"
    trunc.write_bytes(data[: len(data) // 2])
    for p in (rnd, bad_text, trunc):
        r = check_asset(p)
        assert [f.code for f in r.findings] == ["COL001"], (p, r.findings)
        assert not r.passed
    assert check_asset(usdc).passed


def test_col002_checker_error_is_kept_apart(monkeypatch, good_path):
    from colossus.validators import registry

    def boom(asset, ctx):
        raise ZeroDivisionError("kaboom")
        yield

    monkeypatch.setitem(registry._RULES, "COL205", dataclasses.replace(registry._RULES["COL205"], func=boom))
    r = check_asset(good_path)
    assert r.codes() == {"COL002"}
    f = r.findings[0]
    assert "COL205" in f.message and "kaboom" in f.message and f.validator == "COL205"
    assert "COL403" in r.rules_run  # the other rules still ran


def test_col003_missing_path(tmp_path):
    r = check_asset(tmp_path / "nope.usda")
    assert r.codes() == {"COL003"} and not r.passed


def test_col102_usd_validation_warnings_pass_through(monkeypatch, good_path):
    from colossus.validators.rules import structure
    monkeypatch.setattr(structure, "_usd_validation",
                        lambda asset: [("Warn", "some:Validator.Thing", "a note", ["/Tube"])])
    r = check_asset(good_path)
    assert r.codes() == {"COL102"} and r.passed
    assert r.findings[0].validator == "some:Validator.Thing" and r.findings[0].prim == "/Tube"


def test_col301_max_influences(good_path):
    r = check_asset(good_path, max_influences=2)
    assert r.codes() == {"COL301"}
    assert check_asset(good_path, max_influences=4).codes() == set()
    wide = build_test_stage(max_influences=6)
    assert "COL301" in check_asset(wide).codes()
    assert check_asset(wide, max_influences=6).passed


def test_col403_names_clip_frame_part_joint_vertex_excess(good_path):
    stage = open_copy(good_path)
    b403(stage)
    r = check_asset(stage)
    fs = r.by_code("COL403")
    assert fs and not r.passed
    f = fs[0]
    assert f.clip == "bend" and f.time == 10 and f.frame == 10
    assert f.joint in ("root/mid", "root/mid/tip") and f.part in (1, 2)
    assert f.vertex >= 0 and f.excess > 0 and 0 < f.fraction
    assert f.count == 1  # only frame 10 fails
    excess = [x.excess for x in fs]
    assert excess == sorted(excess, reverse=True)  # worst first
    assert "COL403" in r.rules_run and "twist" not in {x.clip for x in fs}


def test_col404_reports_ratio(good_path):
    stage = open_copy(good_path)
    b404(stage)
    fs = check_asset(stage).by_code("COL404")
    assert len(fs) == 3 and all(2.9 < f.ratio < 3.2 for f in fs)
    stage = open_copy(good_path)
    b404(stage)
    assert check_asset(stage, slack_ratio=4).by_code("COL404") == []


def test_shrunk_spheres_fail_somewhere():
    r = check_asset(build_test_stage(radius_scale=0.9))
    assert {"COL402", "COL403"} <= r.codes()


def test_geom_bind_transform_is_honoured():
    gb = np.eye(4)
    gb[:3, :3] *= 2.0
    gb[:3, 3] = [0.5, -1, 0.25]
    r = check_asset(build_test_stage(geom_bind=gb))
    assert r.findings == [], [f.message for f in r.findings]


def test_select_ignore_longest_prefix_wins(good_path):
    stage = open_copy(good_path)
    b404(stage)
    b110(stage)
    assert check_asset(stage).codes() == {"COL404", "COL110"}
    assert check_asset(stage, ignore=["COL4"]).codes() == {"COL110"}
    assert check_asset(stage, select=["COL4"]).codes() == {"COL404"}
    assert check_asset(stage, select=["COL404"], ignore=["COL4"]).codes() == {"COL404"}
    assert check_asset(stage, select=["COL4"], ignore=["COL40"]).codes() == set()
    r = check_asset(stage, severities={"COL404": "error"})
    assert not r.passed and r.by_code("COL404")[0].severity == "error"
    with pytest.raises(ValueError):
        check_asset(stage, select=["COL9"])


def test_broken_prerequisite_skips_dependent_rules_with_reason(good_path):
    stage = open_copy(good_path)
    b107(stage)
    r = check_asset(stage)
    assert "COL107" in r.codes()
    assert "COL403" in r.skipped and "radii" in r.skipped["COL403"]
    assert r.stats["frameproof"]["not_checked"]


def _scale(s, joint, time, value):
    _clip_attr_edit(s, "bend", "scales", time, lambda v: v.__setitem__(joint, Gf.Vec3h(*value)))


def _mat(s, name, joint, row, value):
    a = _attr(s, SKEL, name)
    m = [np.array(x) for x in a.Get()]
    m[joint][row] = value  # USD's row-vector layout: row 3 is the translation, column 3 (0, 0, 0, 1)
    a.Set(Vt.Matrix4dArray([Gf.Matrix4d(*x.ravel().tolist()) for x in m]))


@pytest.mark.parametrize("case, code, needle", [
    ("zero scale", "COL518", "joint 'root' has a scale of 0 on an axis"),
    ("zero scale, part joint", "COL518", "joint 'root/mid/tip' has a scale of 0 on an axis"),
    ("scale flips sign", "COL518", "joint 'root/mid' has a scale that changes sign between times 3 and 4"),
    ("scale 2^-23", "COL518", "joint 'root/mid' has a scale of 1.19209e-07 on an axis"),
    ("unanimated joint, singular rest", "COL518", "joint 'root/mid/tip' has a transform that is not invertible"),
    ("bind not affine", "COL307", "bind transform of joint 'root/mid' is not an invertible affine matrix"),
    ("rest not affine", "COL318", "rest transform of joint 'root/mid' is not an invertible affine matrix"),
])
def test_singular_joint_transform_is_a_finding_not_a_crash(good_path, case, code, needle):
    """Fuzz campaign 12, case 1781 (a translation line swapped into the scales: a scale of
    (0, 0, 0) on frame 4) made the frame proof invert a singular joint pose: 'COL002 rule COL403
    (holds-on-all-frames) crashed: LinAlgError: Singular matrix'.  Every file-supplied matrix the
    proof inverts is now checked first: a singular (or non-affine) bind transform is COL307, a
    rest transform COL318, a pose on a frame or between frames COL518; the proof does not run
    on them (COL403/404/407 skipped, with the reason) and nothing crashes."""
    import warnings
    stage = open_copy(good_path)
    if case == "zero scale":
        _scale(stage, 0, 4, (0, 0, 0))
    elif case == "zero scale, part joint":
        _scale(stage, 2, 4, (0, 1, 1))
    elif case == "scale flips sign":  # never 0 on a frame: UsdSkel's lerp crosses 0 at time 3.5
        _scale(stage, 1, 4, (-1, 1, 1))
    elif case == "scale 2^-23":  # the half-precision lerp towards it can round it to exactly 0
        _scale(stage, 1, 4, (2.0 ** -23, 1, 1))
    elif case == "unanimated joint, singular rest":  # the clip leaves the tip at its rest transform
        anim = stage.GetPrimAtPath(f"{ROOT}/bend")
        anim.GetAttribute("joints").Set(["root", "root/mid"])
        for name in ("translations", "rotations", "scales"):
            a = anim.GetAttribute(name)
            for t in a.GetTimeSamples():
                a.Set(a.Get(t)[:2], t)
        _mat(stage, "restTransforms", 2, 0, (0, 0, 0, 0))
    elif case == "bind not affine":  # an invertible 3x3 part, a singular 4x4
        _mat(stage, "bindTransforms", 1, 3, (0, 1, 0, 0))
    elif case == "rest not affine":
        _mat(stage, "restTransforms", 1, 3, (0, 1, 0, 0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = check_asset(stage)
    assert "COL002" not in r.codes(), [f.message for f in r.by_code("COL002")]
    assert any(needle in f.message for f in r.by_code(code)), (code, [(f.code, f.message) for f in r.findings])
    if code != "COL318":  # the rest transform of a joint every clip animates is never inverted
        assert {"COL403", "COL407"} <= set(r.skipped), r.skipped


def test_proof_guard_singular_pose_between_frames_is_never_certified(good_path):
    """The guard behind COL518: a pose that is singular between frames (the proof run without the
    readiness check that refuses it) leaves that interval undecided, never certified, and neither
    raises (LinAlgError) nor warns."""
    import warnings

    from colossus.validators.asset import LoadedAsset
    from colossus.validators.frameproof import prove
    stage = open_copy(good_path)
    _scale(stage, 1, 4, (-1, 1, 1))
    asset = LoadedAsset(stage, "flip.usda")
    assert not asset.ready("proof")[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        proof = prove(asset, clips=["bend"])
    assert proof.intervals["undecided"] + proof.intervals["failed"] > 0
    assert any(b["t0"] == 3.0 and b["bound"] == np.inf for b in proof.between)


def test_col701_proxy_deviation_within_max_deviation(good_path):
    from colossus.runtime import schema

    stage = open_copy(good_path)
    mesh = stage.GetPrimAtPath(MESH)
    faces = len(np.array(UsdGeom.Mesh(mesh).GetFaceVertexCountsAttr().Get()))
    mesh.SetCustomDataByKey(schema.PROXY_SOURCE_FACES, faces * 5)
    mesh.SetCustomDataByKey(schema.PROXY_MAX_DEVIATION, 0.02)
    assert "COL701" not in check_asset(stage).codes()
    assert "COL701" not in check_asset(stage, max_deviation="0.05").codes()
    bad = check_asset(stage, max_deviation="0.01").by_code("COL701")
    assert bad and bad[0].severity == "error" and abs(bad[0].location["excess"] - 0.01) < 1e-9
    # relative to the model size (the tube is 3 units long: 0.1% is 0.003)
    assert "COL701" in check_asset(stage, max_deviation="0.1%").codes()
    assert "COL701" not in check_asset(stage, max_deviation="50%").codes()
    mesh.SetCustomDataByKey(schema.PROXY_MAX_DEVIATION, float("nan"))
    assert "COL701" in check_asset(stage).codes()
    mesh.SetCustomDataByKey(schema.PROXY_MAX_DEVIATION, 0.0)
    mesh.SetCustomDataByKey(schema.PROXY_SOURCE_FACES, 3)  # fewer faces than the proxy has
    assert "COL701" in check_asset(stage).codes()
    with pytest.raises(Exception):
        check_asset(stage, max_deviation="wide")


@pytest.mark.parametrize("arc", ["reference", "payload", "none"])
def test_col004_looks_inside_variants(good_path, tmp_path, arc):
    """The clip variants are local opinions, not arcs to files: an asset with them is read and
    passes; a reference or payload to another file authored inside a variant is COL004 (read from
    the layer alone, the named file never opened) and the runtime refuses it."""
    from colossus.runtime import ColliderError, load_collider

    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "o.usda").write_text("#usda 1.0\n")
    layer = Sdf.Layer.OpenAsAnonymous(str(good_path))
    variant = layer.GetPrimAtPath(ROOT).variantSets["clip"].variants["twist"].primSpec
    if arc != "none":
        spec = Sdf.PrimSpec(variant, "Extra", Sdf.SpecifierOver)
        arcs = spec.referenceList if arc == "reference" else spec.payloadList
        arcs.Prepend(Sdf.Reference("outside/o.usda") if arc == "reference" else Sdf.Payload("outside/o.usda"))
    asset = tmp_path / "a.usda"
    asset.write_text(layer.ExportToString())
    r = check_asset(str(asset))
    if arc == "none":
        assert r.findings == [], [(f.code, f.message) for f in r.findings]
        assert load_collider(asset).clips == ["bend", "twist"]
        return
    assert r.codes() == {"COL004"} and "outside/o.usda" in r.findings[0].message
    with pytest.raises(ColliderError, match="names other files"):
        load_collider(asset)
