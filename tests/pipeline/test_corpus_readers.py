"""The readers on real third-party files (``../shared/corpus``, issue 9): every character a user
downloads imports whole, moves as its format says, and passes its own validator.

Each test names the corpus file whose quirk it shows; all skip cleanly when the corpus is absent.
Motion against independent references is ``tests/references/test_motion.py``; these check the
structure the readers must get right (meshes, joints, clips, frames, counts, refusals).
"""

from __future__ import annotations

import base64
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from paths import ROOT, fbx_road

CORPUS = ROOT.parent / "shared" / "corpus"
COLOSSUS = [sys.executable, "-m", "colossus"]


def corpus_file(rel):
    p = CORPUS / rel
    if not p.is_file():
        pytest.skip(f"third-party corpus file {rel} is absent")
    return p


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    """Import a corpus file once per module: ``get(rel, **settings) -> (ImportResult, out path)``."""
    from colossus.pipeline.run import ImportSettings, import_asset

    cache = {}
    base = tmp_path_factory.mktemp("corpus")

    def get(rel, **settings):
        key = (rel, tuple(sorted((k, tuple(v) if isinstance(v, list) else v) for k, v in settings.items())))
        if key not in cache:
            src = corpus_file(rel)
            out = base / f"{len(cache)}_{src.stem}.usda"
            cache[key] = (import_asset(src, out, ImportSettings(**settings)), out)
        return cache[key]

    return get


def _read(result):
    return next(r for r in result.reports if r.stage == "read")


# ------------------------------------------------------------------------------ crashes
@pytest.mark.parametrize("rel, vertices_in, skinned", [
    ("assimp/huesitos.fbx", {"assimp": 256, "ufbx": 62}, 1),
    ("realworld/ufbx_maya_kenney_character_7700_binary.fbx", {"assimp": 3256, "ufbx": 804}, 1),
    ("realworld/ufbx_blender_293_barbarian_7400_binary.fbx", {"assimp": 4053, "ufbx": 709}, 2),
])
def test_fbx_bones_without_weights_import(imported, rel, vertices_in, skinned):
    """These FBX files have bones with no weights (assimp gives them no buffer): they crashed
    with 'all the input arrays must have same number of dimensions'.  (assimp splits vertices
    per face corner, ufbx reads the control points.)"""
    from colossus import validators

    res, out = imported(rel)
    rc = _read(res).counts
    assert rc["vertices"] == vertices_in[fbx_road()] and rc["skinned_meshes"] == skinned
    rep = validators.check_asset(str(out))
    assert rep.passed, [(f.code, f.message) for f in rep.findings if f.severity == "error"]


def test_barbarian_unweighted_vertices_follow_their_node(imported):
    """Blender's barbarian has 14 hair vertices with no weight: they stay with their mesh's node
    (an armature deforms only weighted vertices), bound rigidly to it."""
    res, _ = imported("realworld/ufbx_blender_293_barbarian_7400_binary.fbx")
    warn = [w for w in _read(res).warnings if "no skin weight" in w]
    assert len(warn) == 1 and "'Sphere'" in warn[0] and "'hair'" in warn[0]
    assert "hair" in res.mesh.joint_names
    m = res.mesh
    hair = m.joint_names.index("hair")
    rigid = np.flatnonzero((m.joint_indices[:, 0] == hair) & (m.joint_weights[:, 0] == 1.0))
    assert len(rigid) > 0


def test_anim_test_x_bones_without_a_node_are_static_roots(imported):
    """anim_test.x: bones joint3/joint4 carry weights but have no frame; they become unanimated
    root joints at their bind pose (assimp has nothing that could move them)."""
    res, out = imported("assimp/anim_test.x")
    m = res.mesh
    for name in ("joint3", "joint4"):
        j = m.joint_names.index(name)
        assert m.parents[j] == -1
        for c in m.clips:
            np.testing.assert_allclose(c.local[:, j], np.broadcast_to(m.rest_transforms[j], c.local[:, j].shape), atol=1e-6)  # float32-stored
    assert any("no node in the scene" in w for w in _read(res).warnings)


# ------------------------------------------------------------------------------ what is written
def test_sausage_keeps_scene_time_and_a_real_frame_rate(imported):
    """ufbx's sausage: no fixed frame rate in CustomFrameRate (-1) but TimeMode 24 fps; three stacks
    placed one after another on the scene's timeline keep their own times."""
    from pxr import Usd

    res, out = imported("realworld/ufbx_maya_game_sausage_7500_binary_combined.fbx")
    stage = Usd.Stage.Open(str(out))
    assert stage.GetTimeCodesPerSecond() == 24.0 and stage.GetFramesPerSecond() == 24.0
    frames = {c.name: (c.times[0], c.times[-1], c.frame_count) for c in res.mesh.clips}
    assert frames == {"wiggle": (1.0, 20.0, 20), "spin": (20.0, 40.0, 21), "deform": (40.0, 60.0, 21)}


def test_write_refuses_what_usd_core_cannot_open(tmp_path):
    """The written file is re-opened before the rename: a framesPerSecond of -1 never lands."""
    from pxr import Sdf

    from colossus.pipeline.errors import OutputError
    from colossus.pipeline.stages.write import _check_written

    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\n(\n    defaultPrim = "A"\n    framesPerSecond = -1\n    timeCodesPerSecond = -1\n)\n'
                   'def SkelRoot "A"\n{\n}\n')
    with pytest.raises(OutputError, match="not valid USD|cannot re-open"):
        _check_written(str(bad), str(tmp_path / "out.usda"), Sdf.Path("/A"), 24.0)
    good = tmp_path / "good.usda"
    good.write_text('#usda 1.0\n(\n    defaultPrim = "A"\n    framesPerSecond = 24\n    timeCodesPerSecond = 24\n)\n'
                    'def SkelRoot "A"\n{\n}\n')
    _check_written(str(good), str(tmp_path / "out.usda"), Sdf.Path("/A"), 24.0)


# ------------------------------------------------------------------------------ missing parts
def test_robot_expressive_rigid_parts_and_small_ones(imported):
    """RobotExpressive: 7214 vertices, only the hands (1108) skinned; the rest are meshes parented
    to bone nodes, bound with weight 1 to their joint.  Hand weights up to 1.755 are normalised and
    counted; the head's 3 morph targets (on its 3 primitives) are carried as blend shapes (issue 21),
    so nothing is named about them and nothing is left out (no not-carried item)."""
    res, out = imported("realworld/threejs_r121_RobotExpressive.glb")
    rep = _read(res)
    assert rep.counts["vertices"] == 7214
    info = rep.details["meshes"]
    assert sum(x["vertices"] for x in info if x["kind"] == "skinned") == 1108
    assert sum(x["vertices"] for x in info if x["kind"] == "rigid") == 7214 - 1108
    assert {x["joint"] for x in info if x["name"] == "Torso"} == {"Body"}
    wn = rep.details["weights_normalised"]
    assert wn["vertices"] == 752 and wn["max_sum"] == pytest.approx(1.7551, abs=1e-3)
    assert not [w for w in rep.warnings if "morph targets" in w]
    shapes = [b.name for b in res.mesh.blend_shapes]
    assert len(shapes) == 9 and all(n.startswith("Head_") for n in shapes), shapes
    assert res.mesh.source["not_carried"] == []
    np.testing.assert_allclose(res.mesh.joint_weights.sum(axis=1), 1.0, atol=1e-5)
    # every rigid vertex has one influence of weight 1
    rigid = res.mesh.joint_weights[:, 0] == 1.0
    assert rigid.sum() > 0.5 * res.mesh.vertex_count


def test_elephant_two_skeletons_become_one(imported):
    """ElephantWithMonochord: two SkelRoots with a Skeleton each (27 and 2 joints) become one
    Skeleton with two roots, the bound animations playing together as one clip."""
    from pxr import Usd, UsdSkel

    res, out = imported("realworld/usdwg_SoC-ElephantWithMonochord.usdc")
    m = res.mesh
    assert m.joint_count == 29 and int((m.parents < 0).sum()) == 2
    assert m.vertex_count > 0 and _read(res).counts["vertices"] == 1312 + 62
    assert [c.name for c in m.clips] == ["_anim"]
    stage = Usd.Stage.Open(str(out))
    assert len([p for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton)]) == 1
    narrowed, _ = imported("realworld/usdwg_SoC-ElephantWithMonochord.usdc", meshes=["Elefant1"])
    assert narrowed.mesh.joint_count == 27 and _read(narrowed).counts["vertices"] == 1312


def test_cesium_man_unnamed_animations_and_light_weights(imported):
    """CesiumMan (old revision): 19 unnamed animations are named by position; 210 vertices with
    weight sums down to 0.185 are normalised and counted."""
    res, _ = imported("realworld/threejs_r121_CesiumMan.glb")
    assert [c.name for c in res.mesh.clips] == [f"animation_{i}" for i in range(19)]
    wn = _read(res).details["weights_normalised"]
    assert wn["vertices"] == 210 and wn["min_sum"] == pytest.approx(0.1847, abs=1e-3)


# ------------------------------------------------------------------------------ the frame grid
@pytest.mark.parametrize("rel, fps", [
    ("khronos/RiggedSimple.gltf", 24.0),          # was timeCodesPerSecond 0.98
    ("khronos/Fox.glb", 120.0),                   # Run's keys are on 120 fps, not on 24
    ("realworld/godot_mannequiny.glb", 120.0),    # keys 0.8 frame off the 24 fps grid
    ("realworld/playcanvas_lumberjack.glb", 120.0),
    ("assimp/animation_with_skeleton.fbx", 24.0),  # keys with gaps on the 24 fps grid
])
def test_clips_on_a_regular_grid_pass_the_validator(imported, rel, fps):
    """Every clip is sampled on one regular grid holding every source key; the asset passes COL502
    (and the frame proof COL403 on the frames it holds)."""
    from colossus import validators

    res, out = imported(rel)
    m = res.mesh
    assert m.time_codes_per_second == fps
    for c in m.clips:
        assert np.array_equal(c.times, np.arange(c.times[0], c.times[-1] + 1))
    for info in _read(res).details["clips"]:
        assert info["keys_on_grid"], info
    rep = validators.check_asset(str(out), select=["COL5", "COL403"])
    assert rep.passed, [(f.code, f.message) for f in rep.findings if f.severity == "error"]


def test_off_grid_keys_state_their_error_bound(imported):
    """Fox forced to --fps 30: its keys (on 24 and 120 fps) fall between frames.  Each clip states
    a resampling error bound that holds against the independent glTF reference at every source
    key, is not loose by more than 30 %, and a bound over 1e-3 x size is a warning."""
    from references import compare

    from colossus.cli.import_ import format_summary

    res, out = imported("khronos/Fox.glb", fps=30.0)
    clips = {c["name"]: c for c in _read(res).details["clips"]}
    assert all(not c["keys_on_grid"] for c in clips.values())
    rep = compare.compare(corpus_file("khronos/Fox.glb"), out, max_instants=1000)
    for c in rep.clips:
        bound = clips[c.name]["error_bound_relative"]
        assert c.err_keys <= bound <= 1.3 * c.err_keys + 1e-6, (c.name, c.err_keys, bound)
    assert "off-grid error <=" in format_summary(res)
    warned = [w for w in _read(res).warnings if "fall between" in w]
    assert len(warned) == sum(c["error_bound_relative"] > 1e-3 for c in clips.values()) > 0


# ------------------------------------------------------------------------------ interpolation
def _tiny_gltf(path, interpolation, values, times=(0.0, 0.5, 1.0)):
    """One triangle skinned to one joint whose translation has a sampler of ``interpolation``."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    idx = np.array([0, 1, 2], np.uint16)
    joints = np.zeros((3, 4), np.uint16)
    weights = np.tile(np.array([1, 0, 0, 0], np.float32), (3, 1))
    ibm = np.eye(4, dtype=np.float32).T.reshape(-1)
    t = np.array(times, np.float32)
    v = np.asarray(values, np.float32).reshape(-1, 3)
    blobs = [pos.tobytes(), idx.tobytes() + b"\0\0", joints.tobytes(), weights.tobytes(), ibm.tobytes(),
             t.tobytes(), v.tobytes()]
    views, off = [], 0
    for b in blobs:
        views.append({"buffer": 0, "byteOffset": off, "byteLength": len(b)})
        off += len(b)
    acc = [
        {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
        {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
        {"bufferView": 2, "componentType": 5123, "count": 3, "type": "VEC4"},
        {"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC4"},
        {"bufferView": 4, "componentType": 5126, "count": 1, "type": "MAT4"},
        {"bufferView": 5, "componentType": 5126, "count": len(t), "type": "SCALAR", "min": [float(t[0])], "max": [float(t[-1])]},
        {"bufferView": 6, "componentType": 5126, "count": len(v), "type": "VEC3"},
    ]
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"name": "root"}, {"name": "tri", "mesh": 0, "skin": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "JOINTS_0": 2, "WEIGHTS_0": 3}, "indices": 1}]}],
        "skins": [{"joints": [0], "inverseBindMatrices": 4}],
        "animations": [{"channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
                        "samplers": [{"input": 5, "output": 6, "interpolation": interpolation}]}],
        "buffers": [{"byteLength": off, "uri": "data:application/octet-stream;base64,"
                     + base64.b64encode(b"".join(blobs)).decode()}],
        "bufferViews": views, "accessors": acc,
    }
    path.write_text(json.dumps(doc))
    return path


def test_step_sampler_holds_each_key_until_the_next(tmp_path):
    from colossus.pipeline.readers import read

    keys = [[0, 0, 0], [1, 0, 0], [3, 0, 0]]
    m = read(_tiny_gltf(tmp_path / "step.gltf", "STEP", keys))
    (c,) = m.clips
    assert m.time_codes_per_second == 24.0 and np.array_equal(c.times, np.arange(25.0))
    x = c.local[:, 0, 0, 3]
    np.testing.assert_array_equal(x, np.r_[np.zeros(12), np.ones(12), 3.0])
    assert m.source["clip_info"][0]["name"] == "animation_0"


def test_cubicspline_sampler_is_the_specs_hermite(tmp_path):
    """glTF 2.0 Appendix C: p(u) = (2u^3-3u^2+1) v0 + (u^3-2u^2+u) dt b0 + (-2u^3+3u^2) v1 + (u^3-u^2) dt a1."""
    from colossus.pipeline.readers import read

    # per key: in-tangent a, value v, out-tangent b
    a = np.array([[0, 0, 0], [2, 0, 0], [0, 0, 0]], float)
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0]], float)
    b = np.array([[4, 0, 0], [-2, 0, 0], [0, 0, 0]], float)
    m = read(_tiny_gltf(tmp_path / "cubic.gltf", "CUBICSPLINE", np.stack([a, v, b], 1)))
    (c,) = m.clips
    x = c.local[:, 0, 0, 3]
    dt = 0.5
    for f in range(25):
        k = min(f // 12, 1)
        u = (f - 12 * k) / 12.0
        if f == 24:
            k, u = 1, 1.0
        want = ((2 * u**3 - 3 * u**2 + 1) * v[k, 0] + (u**3 - 2 * u**2 + u) * dt * b[k, 0]
                + (-2 * u**3 + 3 * u**2) * v[k + 1, 0] + (u**3 - u**2) * dt * a[k + 1, 0])
        assert x[f] == pytest.approx(want, abs=1e-6), f
    assert x[0] == 0 and x[12] == 1 and x[24] == 1  # keys exact


# ------------------------------------------------------------------------------ refusals
@pytest.mark.parametrize("rel, needle", [
    ("khronos/older_versions/RiggedFigure_0589a6c_draft.gltf", "pre-release glTF 2.0 draft"),
    ("assimp/multiple_animations_test.fbx", "no skinned mesh"),
])
def test_files_fine_to_refuse_are_refused_in_one_line(tmp_path, rel, needle):
    src = corpus_file(rel)
    out = tmp_path / "o.usda"
    p = subprocess.run(COLOSSUS + ["import", str(src), "-o", str(out)], capture_output=True, text=True, timeout=300)
    assert p.returncode == 1
    err = p.stderr.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err and "internal error" not in err
    assert needle in err and src.name in err
    assert not out.exists() and not [f for f in os.listdir(tmp_path) if f.startswith(".colossus-")]


def test_collada_polygons_skin_and_clips_come_from_the_file(imported):
    """library_animation_clips.dae (Blender 2.6 <polygons>): assimp gives each vertex the weights
    of the Collada vertex before it; the reader uses the file's <vertex_weights> (Collada vertex
    0 is weighted 1 to the joint `Bone`, node id-bone-3) and the clips' own names and windows
    (`bend` 0.0417..0.625 s, `turn` 0..0.8333 s at 24 fps)."""
    from colossus import validators
    from colossus.pipeline.readers import read

    m = read(corpus_file("assimp/library_animation_clips.dae"))
    assert m.joint_names[m.joint_indices[0, 0]] == "id-bone-3" and m.joint_weights[0, 0] == 1.0
    assert all(m.joint_weights.sum(axis=1) > 0)  # assimp left vertex 0 without weight
    assert [(c.name, c.times[0], c.times[-1]) for c in m.clips] == [("bend", 1.0, 15.0), ("turn", 0.0, 20.0)]
    assert any("<vertex_weights>" in n for n in m.source["notes"])
    res, out = imported("assimp/library_animation_clips.dae")
    assert validators.check_asset(str(out)).passed
