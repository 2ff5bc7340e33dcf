"""Motion of every corpus character against an independent reference (issue 9, item 2).

(a) The references themselves, checked against things colossus did not make: the UsdSkel
    evaluator against Pixar's baked ``openusd_lbs`` and against ``UsdSkel.BakeSkinning``; the glTF
    evaluator against a tiny glTF written here with hand-computed poses (STEP, LINEAR slerp on the
    shorter arc, CUBICSPLINE, matrix nodes, sparse and normalised accessors, .gltf/.glb/.bin), its
    bind pose against the mesh positions under the inverse binds, and its static scene against
    trimesh's glTF loader; the Maya-truth loader against the OBJ counts and the README's times.
(b) Every corpus character imported with today's importer, skinned by plain usd-core at (at most
    20) evenly spaced source keys and (at most 20) mid-key instants per clip, compared with its
    reference: within 1e-4 x model size where the keys sit on the asset's frame grid (1e-3 where
    they do not), no clip missing or misnamed, no reference vertex missing.  Cases that fail today
    are marked ``xfail(strict=True)`` with the measured error and its cause
    (``tests/references/FINDINGS.md``); a fixed reader turns them into XPASS failures: drop the mark.

Skips cleanly when ``../shared/corpus`` is absent.
"""

from __future__ import annotations

import base64
import json
import pathlib
import struct

import numpy as np
import pytest

from references import compare, fbx_truth, gltf_eval, usd_eval
from references.diagnose import CHARACTERS

ROOT = pathlib.Path(__file__).resolve().parents[2]
CORPUS = ROOT.parent / "shared" / "corpus"


@pytest.fixture(scope="module")
def corpus():
    if not CORPUS.is_dir():
        pytest.skip("third-party corpus ../shared/corpus is absent")
    return CORPUS


def _size(p):
    p = np.asarray(p).reshape(-1, 3)
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))


# =============================================================================== (a) USD
def test_usd_reference_matches_pixar_baked_lbs(corpus):
    """UsdSkel skinning of lbs.usda (meshes, curves, rigid gprims) = OpenUSD's own baked result."""
    src = corpus / "realworld" / "openusd_lbs.usda"
    baked = corpus / "realworld" / "truth" / "openusd_lbs.baked.usda"
    ref = usd_eval.load(src)
    kinds = {t.path.rsplit("/", 1)[-1]: t.kind for t in ref.targets}
    assert kinds == {"Mesh": "skinned", "MeshWithFaceVaryingNormals": "skinned", "MeshWithNormals": "skinned",
                     "Curves": "skinned", "Sphere": "rigid", "Cube": "rigid", "Cylinder": "rigid"}
    size = _size(np.concatenate([p for p in ref.pose(1.0) if len(p)]))
    worst = 0.0
    for t in range(1, 31):  # the baked file holds samples at frames 1..30
        truth = usd_eval.baked_pose(baked, t)
        rigid = ref.rigid_transforms(t)
        for target, pts in zip(ref.targets, ref.pose(t)):
            if target.vertex_count:
                worst = max(worst, float(np.abs(pts - truth[target.path]).max()))
            else:
                worst = max(worst, float(np.abs(rigid[target.path] - truth[target.path]).max()))
    assert worst <= 1e-6 * size, worst


@pytest.mark.parametrize("name, interval, times", [
    ("assimp/simple-skin-animation-test.usda", (0, 40), (0, 7, 20, 40)),
    ("realworld/usdwg_CesiumMan.usdz", (1, 48), (1, 13, 30, 48)),
    ("realworld/usdwg_SoC-ElephantWithMonochord.usdc", (0, 12), (0, 1, 5, 10)),
])
def test_usd_reference_matches_bake_skinning(corpus, name, interval, times):
    """The reference's world-space points = UsdSkel.BakeSkinning on an in-memory copy."""
    from pxr import Gf, Usd, UsdGeom, UsdSkel

    src = corpus / name
    copy = Usd.Stage.Open(Usd.Stage.Open(str(src)).Flatten())
    assert UsdSkel.BakeSkinning(copy.Traverse(), Gf.Interval(*interval))
    ref = usd_eval.load(src)
    for t in times:
        xf = UsdGeom.XformCache(Usd.TimeCode(t))
        for target, pts in zip(ref.targets, ref.pose(t)):
            prim = copy.GetPrimAtPath(target.path)
            w = np.array(xf.GetLocalToWorldTransform(prim)).reshape(4, 4)
            baked = np.asarray(UsdGeom.PointBased(prim).GetPointsAttr().Get(t), dtype=np.float64) @ w[:3, :3] + w[3, :3]
            assert np.abs(baked - pts).max() <= 1e-6 * _size(pts), (target.path, t)


# =============================================================================== (a) glTF
def _tiny_gltf():
    """A 2-joint skin, a rigid prop under a matrix node, and three animations, with the buffer.

    Joints: ``root`` (node 0) at the origin, ``tip`` (node 1) at x = 1.  The skinned mesh node
    (node 2) carries a translation that glTF says to ignore.  ``prop`` (node 3) is a matrix node
    under ``tip`` (translate y + 1) holding an unskinned triangle whose POSITION is a sparse
    accessor over zeros.  Skinned vertices: (0,0,0) on root, (1,0,0) half/half (normalised
    UNSIGNED_BYTE weights 100/255 each, so they sum to 0.784 as written), (2,0,0) on tip; an
    interleaved buffer view (POSITION + WEIGHTS_0, byteStride 16) and a second JOINTS/WEIGHTS set.
    """
    buf = bytearray()

    def add(data: bytes, align=4):
        while len(buf) % align:
            buf.append(0)
        off = len(buf)
        buf.extend(data)
        return off

    views, accessors = [], []

    def view(data, stride=None):
        v = {"buffer": 0, "byteOffset": add(data), "byteLength": len(data)}
        if stride:
            v["byteStride"] = stride
        views.append(v)
        return len(views) - 1

    def acc(**kw):
        accessors.append(kw)
        return len(accessors) - 1

    pos = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], dtype=np.float32)
    w8 = np.array([[255, 0, 0, 0], [100, 100, 0, 0], [0, 255, 0, 0]], dtype=np.uint8)
    inter = b"".join(pos[i].tobytes() + w8[i].tobytes() for i in range(3))
    iv = view(inter, stride=16)
    a_pos = acc(bufferView=iv, byteOffset=0, componentType=5126, count=3, type="VEC3", min=[0, 0, 0], max=[2, 0, 0])
    a_w0 = acc(bufferView=iv, byteOffset=12, componentType=5121, normalized=True, count=3, type="VEC4")
    a_j0 = acc(bufferView=view(np.array([[0, 1, 0, 0]] * 3, dtype=np.uint8).tobytes()), componentType=5121, count=3, type="VEC4")
    a_j1 = acc(bufferView=view(np.zeros((3, 4), dtype=np.uint16).tobytes()), componentType=5123, count=3, type="VEC4")
    a_w1 = acc(bufferView=view(np.zeros((3, 4), dtype=np.float32).tobytes()), componentType=5126, count=3, type="VEC4")
    a_idx = acc(bufferView=view(np.array([0, 1, 2], dtype=np.uint16).tobytes()), componentType=5123, count=3, type="SCALAR")
    ibm = np.stack([np.eye(4), np.array([[1, 0, 0, -1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])])
    a_ibm = acc(bufferView=view(ibm.transpose(0, 2, 1).astype(np.float32).tobytes()), componentType=5126, count=2, type="MAT4")
    sp_idx = view(np.array([1], dtype=np.uint8).tobytes())
    sp_val = view(np.array([0.5, 0, 0], dtype=np.float32).tobytes())
    a_prop = acc(componentType=5126, count=3, type="VEC3", min=[0, 0, 0], max=[0.5, 0, 0],
                 sparse={"count": 1, "indices": {"bufferView": sp_idx, "componentType": 5121},
                         "values": {"bufferView": sp_val}})

    def f32(a):
        return np.asarray(a, dtype=np.float32).tobytes()

    s45, c45 = np.sin(np.pi / 4), np.cos(np.pi / 4)
    t3 = acc(bufferView=view(f32([0, 1, 2])), componentType=5126, count=3, type="SCALAR", min=[0], max=[2])
    t2 = acc(bufferView=view(f32([0, 1])), componentType=5126, count=2, type="SCALAR", min=[0], max=[1])
    t02 = acc(bufferView=view(f32([0, 2])), componentType=5126, count=2, type="SCALAR", min=[0], max=[2])
    step_out = acc(bufferView=view(f32([[0, 0, 0], [0, 1, 0], [0, 2, 0]])), componentType=5126, count=3, type="VEC3")
    # 90 degrees about z written with w < 0: slerp must take the shorter arc (45 degrees at u = 0.5)
    rot_out = acc(bufferView=view(f32([[0, 0, 0, 1], [0, 0, -s45, -c45]])), componentType=5126, count=2, type="VEC4")
    # CUBICSPLINE translation: key 0 (in 0, value (1,0,0), out-tangent (1,0,0)), key 1 (in 0, value (3,0,0), out 0)
    cub_t = acc(bufferView=view(f32([[0, 0, 0], [1, 0, 0], [1, 0, 0], [0, 0, 0], [3, 0, 0], [0, 0, 0]])),
                componentType=5126, count=6, type="VEC3")
    cub_r = acc(bufferView=view(f32([[0, 0, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, s45, c45], [0, 0, 0, 0]])),
                componentType=5126, count=6, type="VEC4")
    morph_out = acc(bufferView=view(f32([0, 1])), componentType=5126, count=2, type="SCALAR")
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 2]}],
        "nodes": [
            {"name": "root", "children": [1]},
            {"name": "tip", "translation": [1, 0, 0], "children": [3]},
            {"name": "skinned", "mesh": 0, "skin": 0, "translation": [5, 5, 5]},
            {"name": "prop", "mesh": 1, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 1, 0, 1]},
        ],
        "skins": [{"joints": [0, 1], "inverseBindMatrices": a_ibm}],
        "meshes": [
            {"name": "body", "primitives": [{"attributes": {"POSITION": a_pos, "JOINTS_0": a_j0, "WEIGHTS_0": a_w0,
                                                            "JOINTS_1": a_j1, "WEIGHTS_1": a_w1}, "indices": a_idx}],
             "weights": [0]},
            {"name": "propmesh", "primitives": [{"attributes": {"POSITION": a_prop}}]},
        ],
        "animations": [
            {"name": "steps_and_slerp", "samplers": [{"input": t3, "output": step_out, "interpolation": "STEP"},
                                                     {"input": t2, "output": rot_out}],
             "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}},
                          {"sampler": 1, "target": {"node": 1, "path": "rotation"}}]},
            {"name": "cubic", "samplers": [{"input": t02, "output": cub_t, "interpolation": "CUBICSPLINE"},
                                           {"input": t02, "output": cub_r, "interpolation": "CUBICSPLINE"}],
             "channels": [{"sampler": 0, "target": {"node": 1, "path": "translation"}},
                          {"sampler": 1, "target": {"node": 0, "path": "rotation"}}]},
            {"samplers": [{"input": t2, "output": morph_out}],
             "channels": [{"sampler": 0, "target": {"node": 2, "path": "weights"}}]},
        ],
        "accessors": accessors, "bufferViews": views,
    }
    while len(buf) % 4:
        buf.append(0)
    doc["buffers"] = [{"byteLength": len(buf)}]
    return doc, bytes(buf)


@pytest.fixture(scope="module", params=["embedded", "external", "glb"])
def tiny(request, tmp_path_factory):
    doc, buf = _tiny_gltf()
    d = tmp_path_factory.mktemp(request.param)
    if request.param == "embedded":
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(buf).decode()
        path = d / "tiny.gltf"
        path.write_text(json.dumps(doc))
    elif request.param == "external":
        doc["buffers"][0]["uri"] = "tiny%20data.bin"
        (d / "tiny data.bin").write_bytes(buf)
        path = d / "tiny.gltf"
        path.write_text(json.dumps(doc))
    else:
        js = json.dumps(doc).encode()
        js += b" " * (-len(js) % 4)
        body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(buf), 0x004E4942) + buf
        path = d / "tiny.glb"
        path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    return gltf_eval.load(path)


def _rz(deg):
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def test_gltf_tiny_metadata_and_accessors(tiny):
    prims = {p.node_name: p for p in tiny.primitives}
    assert set(prims) == {"skinned", "prop"}
    assert prims["skinned"].skinned and not prims["prop"].skinned
    assert prims["skinned"].vertex_count == 3 and prims["skinned"].morph_targets == 0
    np.testing.assert_allclose(prims["skinned"].weight_sum_range, (200 / 255, 1.0))
    j, w = tiny.influences(prims["skinned"])
    assert j.shape == w.shape == (3, 8)  # two JOINTS/WEIGHTS sets
    np.testing.assert_allclose(w[1, :2], [100 / 255, 100 / 255])  # normalised UNSIGNED_BYTE
    np.testing.assert_allclose(tiny.positions(prims["prop"]), [[0, 0, 0], [0.5, 0, 0], [0, 0, 0]])  # sparse
    assert tiny.moves_with_skeleton(prims["prop"])
    names = [a.name for a in tiny.animations]
    assert names == ["steps_and_slerp", "cubic", "animation_2"]
    a0, a1, a2 = tiny.animations
    np.testing.assert_allclose(a0.key_times, [0, 1, 2])
    assert a0.interpolations == ("LINEAR", "STEP") and a1.interpolations == ("CUBICSPLINE",)
    assert a2.morph_channels == 1 and len(a2.key_times) == 0


def test_gltf_tiny_step_and_shortest_slerp(tiny):
    prims = [p.node_name for p in tiny.primitives]
    for t, root_y, angle in ((-1.0, 0, 0), (0.5, 0, 45), (1.0, 1, 90), (1.99, 1, 90), (5.0, 2, 90)):
        pose = dict(zip(prims, tiny.pose(0, t)))
        tip = np.eye(4)
        tip[:3, :3] = _rz(angle)
        tip[:3, 3] = (1, root_y, 0)
        # skinned: the mesh node's (5, 5, 5) is ignored; vertex 2 rides the tip, vertex 1 half/half
        v2 = tip[:3, :3] @ np.array([1.0, 0, 0]) + tip[:3, 3]
        v1 = 0.5 * np.array([1.0, root_y, 0]) + 0.5 * tip[:3, 3]
        np.testing.assert_allclose(pose["skinned"], [[0, root_y, 0], v1, v2], atol=1e-6)
        # rigid: tip @ translate(0, 1, 0) @ p
        prop = (tip[:3, :3] @ (np.array([[0, 1, 0], [0.5, 1, 0], [0, 1, 0]]).T)).T + tip[:3, 3]
        np.testing.assert_allclose(pose["prop"], prop, atol=1e-6)


def test_gltf_tiny_weights_as_written(tiny):
    sk = [p for p in tiny.primitives if p.skinned][0]
    world = tiny.world(tiny.local_transforms(None, [0.0]))[0]
    raw = tiny.skin_points(sk, world[tiny.skin_joints(0)], normalise=False)
    np.testing.assert_allclose(raw[1], [200 / 255, 0, 0], atol=1e-6)  # sum w * M p with w summing to 0.784
    np.testing.assert_allclose(tiny.skin_points(sk, world[tiny.skin_joints(0)])[1], [1, 0, 0], atol=1e-6)


def test_gltf_tiny_cubicspline(tiny):
    for t, u in ((1.0, 0.5), (0.5, 0.25)):
        h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
        x = h00 * 1 + 2 * h10 * 1 + h01 * 3 + 2 * h11 * 0  # Appendix C with td = 2
        w = tiny.world(tiny.local_transforms(1, [t]))[0]
        np.testing.assert_allclose(w[1, :3, 3], w[0, :3, :3] @ [x, 0, 0], atol=1e-9)  # tip at x in root space
        # the root's rotation: Hermite of identity and 90 degrees about z with zero tangents, normalised
        q = np.array([0, 0, h01 * np.sin(np.pi / 4), h00 + h01 * np.cos(np.pi / 4)])
        angle = np.degrees(2 * np.arctan2(q[2], q[3]))
        np.testing.assert_allclose(w[0, :3, :3], _rz(angle), atol=1e-9)
    w = tiny.world(tiny.local_transforms(1, [3.0]))[0]  # clamped after the last key
    np.testing.assert_allclose(w[1, :3, 3], _rz(90) @ [3, 0, 0], atol=1e-9)


def test_gltf_tiny_bind_pose(tiny):
    pose = dict(zip([p.node_name for p in tiny.primitives], tiny.bind_pose()))
    np.testing.assert_allclose(pose["skinned"], [[0, 0, 0], [1, 0, 0], [2, 0, 0]], atol=1e-9)
    np.testing.assert_allclose(pose["prop"], [[1, 1, 0], [1.5, 1, 0], [1, 1, 0]], atol=1e-9)


GLTF_FILES = [c for c in CHARACTERS if c.endswith((".gltf", ".glb"))]


@pytest.mark.parametrize("name", GLTF_FILES)
def test_gltf_bind_pose_is_positions_under_inverse_binds(corpus, name):
    """At the bind pose (every joint at inv(IBM)) a skinned vertex is its POSITION."""
    doc = gltf_eval.load(corpus / name)
    skinned = [p for p in doc.primitives if p.skinned]
    assert skinned
    for prim, pts in zip(doc.primitives, doc.bind_pose()):
        if not prim.skinned:
            continue
        p = doc.positions(prim)
        np.testing.assert_allclose(pts[prim.used], p[prim.used], atol=1e-6 * max(_size(p), 1e-9))
        raw = doc.skin_points(prim, np.linalg.inv(doc.inverse_binds(prim.skin)), normalise=False)
        _, w = doc.influences(prim)
        np.testing.assert_allclose(raw, p * w.sum(axis=1, keepdims=True), atol=1e-6 * max(_size(p), 1e-9))


@pytest.mark.parametrize("name", ["realworld/threejs_r121_RobotExpressive.glb", "realworld/playcanvas_lumberjack.glb",
                                  "assimp/quad_skin.glb", "khronos/RiggedFigure.gltf"])
def test_gltf_static_scene_matches_trimesh(corpus, name):
    """Node hierarchy, TRS and matrix nodes: the scene as written equals trimesh's reading of it."""
    trimesh = pytest.importorskip("trimesh")
    from scipy.spatial import cKDTree

    scene = trimesh.load(str(corpus / name), force="scene", process=False)
    theirs = np.concatenate([g.vertices for g in scene.dump(concatenate=False)])
    doc = gltf_eval.load(corpus / name)
    world = doc.static_world()
    ours = np.concatenate([doc.positions(p) @ world[p.node][:3, :3].T + world[p.node][:3, 3] for p in doc.primitives])
    assert len(ours) == len(theirs)
    size = _size(ours)
    assert cKDTree(theirs).query(ours)[0].max() <= 1e-6 * size
    assert cKDTree(ours).query(theirs)[0].max() <= 1e-6 * size


# =============================================================================== (a) FBX truth
@pytest.mark.parametrize("name, mesh_vertices, faces, frames", [
    ("ufbx_maya_kenney_character_7700_binary.fbx", 804, 826, 2),
    ("ufbx_maya_game_sausage_7500_binary_combined.fbx", 24, 22, 6),
])
def test_fbx_truth_loader(corpus, name, mesh_vertices, faces, frames):
    truth = fbx_truth.load(corpus / "realworld" / name)
    assert truth.control_points.shape == (mesh_vertices, 3) and truth.used.all()
    assert truth.unit_scale_factor == 1.0 and truth.meters_per_unit == 0.01 and truth.up_axis == "Y"
    assert truth.frame_rate == 24.0
    assert truth.rest_spread < 1e-9 * _size(truth.rest)
    assert len(truth.frames) == frames
    for fr in truth.frames:
        v, nf = fbx_truth.load_obj(corpus / "realworld" / "truth" / fr.obj)
        assert v.shape == (mesh_vertices, 3) and nf == faces
        assert np.array_equal(truth.pose(fr), v)
        start, stop = truth.stacks[fr.clip]
        assert start - 1e-9 <= fr.seconds <= stop + 1e-9  # global scene time inside its stack
    if "sausage" in name:  # the README: wiggle 1/24-20/24 s, spin 20/24-40/24, deform 40/24-60/24
        np.testing.assert_allclose([truth.stacks[s] for s in ("wiggle", "spin", "deform")],
                                   [(1 / 24, 20 / 24), (20 / 24, 40 / 24), (40 / 24, 60 / 24)], atol=1e-12)
        assert round(truth.stacks["wiggle"][0] * fbx_truth.FBX_TICKS_PER_SECOND) == 1_924_423_250


# =============================================================================== the harness itself
def test_harness_catches_a_time_shift_and_a_unit_error(corpus, tmp_path):
    """A correct asset compares clean; the same asset one frame late, or in the wrong units, does not."""
    from pxr import Sdf, UsdGeom

    from colossus.pipeline.run import import_asset

    src = corpus / "realworld" / "usdwg_CesiumMan.usdz"
    good = tmp_path / "good.usda"
    import_asset(src, good)
    assert compare.compare(src, good).problems() == []
    layer = Sdf.Layer.FindOrOpen(str(good))
    late = tmp_path / "late.usda"
    layer.Export(str(late))
    shifted = Sdf.Layer.FindOrOpen(str(late))
    shifted.timeCodesPerSecond = shifted.timeCodesPerSecond * 1.05
    shifted.Save()
    rep = compare.compare(src, late)
    assert rep.err_keys > 1e-3 and rep.problems()
    from pxr import Usd

    wrong = tmp_path / "units.usda"
    st = Usd.Stage.Open(str(good))
    UsdGeom.SetStageMetersPerUnit(st, 0.5)
    st.Export(str(wrong))
    rep = compare.compare(src, wrong)
    assert rep.missing == rep.reference_vertices  # nothing sits where the reference says


# =============================================================================== KHR_animation_pointer
SAMPLE_LIMB = ROOT / "samples" / "limb.glb"


def _glb_json(path):
    data = pathlib.Path(path).read_bytes()
    n = struct.unpack_from("<I", data, 12)[0]
    return json.loads(data[20:20 + n]), data[20 + n:]


def _write_glb(path, j, rest):
    js = json.dumps(j).encode()
    js += b" " * (-len(js) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + rest
    pathlib.Path(path).write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)
    return path


def pointer_limb(path, harmless=True):
    """samples/limb.glb with every animation channel moved into ``KHR_animation_pointer``
    (``target: {path: "pointer", extensions: {KHR_animation_pointer: {pointer: "/nodes/i/trs"}}}``,
    no ``node``, as the extension says), plus, when ``harmless``, a channel pointing at a
    material's base colour (driven by a VEC4 sampler of the clip): nothing a collider carries."""
    j, rest = _glb_json(SAMPLE_LIMB)
    j["extensionsUsed"] = sorted(set(j.get("extensionsUsed") or []) | {"KHR_animation_pointer"})
    for a in j["animations"]:
        for ch in a["channels"]:
            t = ch["target"]
            ch["target"] = {"path": "pointer", "extensions": {
                "KHR_animation_pointer": {"pointer": f"/nodes/{t['node']}/{t['path']}"}}}
        if harmless:
            vec4 = next(c["sampler"] for c in a["channels"]
                        if c["target"]["extensions"]["KHR_animation_pointer"]["pointer"].endswith("/rotation"))
            j.setdefault("materials", []).append({"pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1]}})
            a["channels"].append({"sampler": vec4, "target": {"path": "pointer", "extensions": {"KHR_animation_pointer": {
                "pointer": f"/materials/{len(j['materials']) - 1}/pbrMetallicRoughness/baseColorFactor"}}}})
    return _write_glb(path, j, rest)


def test_gltf_evaluator_plays_animation_pointer_channels_as_plain_ones(tmp_path):
    """The spec evaluator, extended to KHR_animation_pointer: the limb with its channels moved
    into pointers poses exactly as the plain limb at every key and between keys."""
    plain = gltf_eval.load(SAMPLE_LIMB)
    ptr = gltf_eval.load(pointer_limb(tmp_path / "pointer.glb"))
    assert [a.name for a in ptr.animations] == [a.name for a in plain.animations]
    for a, b in zip(plain.animations, ptr.animations):
        assert len(b.channels) == len(a.channels) > 0  # the material pointer is not a node channel
        np.testing.assert_array_equal(a.key_times, b.key_times)
        times = np.concatenate([a.key_times, (a.key_times[1:] + a.key_times[:-1]) / 2])
        for pa, pb in zip(plain.poses(a.index, times), ptr.poses(b.index, times)):
            for x, y in zip(pa, pb):
                np.testing.assert_array_equal(x, y)
    # and a pointer channel does move the evaluator's pose (it is not ignored)
    rest = ptr.pose(None, 0.0)
    travel = max(float(np.abs(x - y).max()) for t in ptr.animations[0].key_times
                 for x, y in zip(ptr.pose(0, float(t)), rest))
    assert travel > 0.1 * _size(np.concatenate(rest))


def test_gltf_animation_pointer_limb_moves_as_the_plain_limb_and_the_evaluator(tmp_path):
    """KHR_animation_pointer node channels (issue 20 item 7) are read as ordinary channels: the
    asset of the pointer limb moves as the plain limb's asset (1e-6 x size) and as the spec
    evaluator says (1e-4 x size at keys and between keys); nothing is named as not carried."""
    from colossus.pipeline.run import import_asset

    src = pointer_limb(tmp_path / "pointer.glb")
    a_ptr, a_plain = tmp_path / "pointer.usda", tmp_path / "plain.usda"
    r = import_asset(src, a_ptr)
    import_asset(SAMPLE_LIMB, a_plain)
    summary = r.summary()
    assert summary["not_carried"] == [] and not any("KHR_animation_pointer" in w for w in summary["warnings"])
    rig_p, rig_q = compare.AssetRig(a_plain), compare.AssetRig(a_ptr)
    assert rig_p.clips == rig_q.clips and rig_p.clips
    size = _size(rig_p.rest())
    for clip in rig_p.clips:
        tc = rig_p.clip_times(clip)
        np.testing.assert_array_equal(tc, rig_q.clip_times(clip))
        tc = np.concatenate([tc, (tc[1:] + tc[:-1]) / 2])
        err = np.abs(rig_p.points(clip, tc) - rig_q.points(clip, tc)).max() / size
        assert err <= 1e-6, (clip, err)
    rep = compare.compare(src, a_ptr, max_instants=0)
    assert rep.missing == 0 and rep.reference_vertices > 0
    assert rep.problems() == [], rep.problems()
    assert all(c.err_keys is not None and c.err_mid is not None for c in rep.clips)


# =============================================================================== (b) the corpus
#: measured on the issue-9 importer (``python -m tests.references.diagnose``); see FINDINGS.md
XFAIL = {
    "realworld/godot_mannequiny.glb": "at on-grid keys 4.9e-5 (within 1e-4 since the writer corrects translations for "
                                      "the rounded half3 stretch scales); halfway between frames 1.9e-4 .. 2.1e-4: "
                                      "UsdSkel lerps half3 scales and rounds the result to half (FINDINGS F2, decided)",
    "realworld/playcanvas_lumberjack.glb": "Rigify DEF stretch scales (0.97..1.03) down 5-bone chains: 1.8e-4 at keys "
                                           "(stated storage bound 3.2e-4; was 3.8e-4), 4.3e-4 between frames, UsdSkel's "
                                           "half3 scales (FINDINGS F2, decided)",
}


def _case(name):
    marks = [pytest.mark.xfail(strict=True, reason=XFAIL[name])] if name in XFAIL else []
    return pytest.param(name, marks=marks, id=name.split("/")[-1])


#: corpus-relative name -> (asset path, FileReport): each character is imported and compared once
_COMPARED = {}


def _compared(corpus, tmp_path_factory, name):
    from colossus.pipeline.run import import_asset

    if name not in _COMPARED:
        src = corpus / name
        ref = compare.reference_for(src)
        out = tmp_path_factory.mktemp("ref") / (src.name + ".usda")
        import_asset(src, out)
        _COMPARED[name] = (out, compare.compare(src, out, max_instants=compare.MAX_INSTANTS, reference=ref))
    return _COMPARED[name]


@pytest.mark.parametrize("name", [_case(n) for n in CHARACTERS])
def test_corpus_character_moves_as_its_reference(corpus, tmp_path_factory, name):
    _, rep = _compared(corpus, tmp_path_factory, name)
    assert rep.reference_vertices > 0
    assert rep.problems() == []


@pytest.mark.parametrize("name", list(XFAIL))
def test_stretched_rig_stated_storage_bound_holds_at_keys(corpus, tmp_path_factory, name):
    """The xfail characters' animated stretch scales: at the source's keys (on the asset's frames)
    the error stays within the storage bound each clip states in its customData, and mannequiny's
    within the 1e-4 the issue asks (the writer's translation correction; was 2.0e-4)."""
    from pxr import Usd, UsdSkel

    out, rep = _compared(corpus, tmp_path_factory, name)
    stage = Usd.Stage.Open(str(out))
    stated = {p.GetName(): float(p.GetCustomDataByKey("colossus:source")["storageErrorBoundRelative"])
              for p in stage.Traverse() if p.IsA(UsdSkel.Animation)
              and "storageErrorBoundRelative" in (p.GetCustomDataByKey("colossus:source") or {})}
    checked = 0
    rig = compare.AssetRig(out)
    for c in rep.clips:
        if c.err_keys is None or c.asset_clip not in stated:
            continue
        # the comparison is relative to the reference's shown size, the stated bound to the clip's
        # posed size (its first frame): compared in stage units
        first = rig.points(c.asset_clip, rig.clip_times(c.asset_clip)[:1])[0]
        posed = float(np.linalg.norm(first.max(0) - first.min(0)))
        got, allowed = c.err_keys * rep.size, stated[c.asset_clip] * posed
        assert got <= allowed * 1.05 + 1e-6 * rep.size, (c.name, got, allowed)
        checked += 1
    assert checked > 0
    if "mannequiny" in name:
        assert rep.err_keys < 1e-4, rep.err_keys


def test_reference_code_imports_nothing_of_the_project():
    """The references must be independent of what they judge: no module of tests/references (its
    test modules aside) imports the project, under its name or a folder's bare name."""
    import ast

    for f in sorted((ROOT / "tests" / "references").glob("*.py")):
        if f.name.startswith("test_"):
            continue
        tree = ast.parse(f.read_text(), filename=str(f))
        for node in ast.walk(tree):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
            for n in names:
                assert n.split(".")[0] not in {"colossus", "pipeline", "validators", "runtime"}, (f.name, node.lineno, n)


@pytest.mark.parametrize("name", ["realworld/playcanvas_lumberjack.glb", "assimp/huesitos.fbx"])
def test_corpus_guide_spheres_and_clip_variants_as_usd_bakes_them(corpus, tmp_path, name):
    """Issue 24 items 2 and 3 on real characters (the lumberjack: a centimetre mesh bound by scaled
    joints, 3 clips): one ``clip`` variant per clip, the first the default; each variant baked by
    ``UsdSkel.BakeSkinning`` is the runtime's pose of that clip, and the guide spheres baked with it
    are the runtime's ``pose.spheres``, within 1e-6 x size (8 frames of each clip)."""
    from colossus.pipeline.run import import_asset
    from usdskel_bake import bake_every_variant

    out = tmp_path / "asset.usda"
    result = import_asset(corpus / name, out)
    b = bake_every_variant(out, frames_per_clip=8)
    assert sorted(b["variants"]) == sorted(b["clips"]) and b["default"] == b["clips"][0]  # USD sorts variant names
    assert b["guides"] == len(result.mesh.parts)
    assert b["spheres"] <= 1e-6 * b["size"] and b["mesh"] <= 1e-6 * b["size"], (b["spheres"] / b["size"],
                                                                                b["mesh"] / b["size"])
