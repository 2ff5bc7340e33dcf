"""The frame-proof kernels against readable numpy and against plain usd-core skinning."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Usd, UsdSkel, Vt

from references.usd_fixture import build_test_stage, clip_skel, naive_skin
from references.usd_reference import part_distances, tightest
from colossus.validators import frameproof as fp
from colossus.validators.asset import LoadedAsset


@pytest.fixture(scope="module")
def asset():
    return LoadedAsset(build_test_stage())


def _random_rig(rng, n=300, b=6, k=4, f=5):
    pts = rng.normal(size=(n, 3)).astype(np.float32)
    ji = rng.integers(0, b, size=(n, k)).astype(np.int32)
    jw = rng.random((n, k)).astype(np.float32)
    jw[:, -1] = 0
    jw /= jw.sum(1, keepdims=True)
    m = np.repeat(np.eye(4)[None, None], f, 0).repeat(b, 1)
    m[..., :3, :3] += 0.3 * rng.normal(size=(f, b, 3, 3))
    m[..., :3, 3] = rng.normal(size=(f, b, 3))
    return pts, ji, jw, m


def test_wrappers_validate_inputs():
    rng = np.random.default_rng(3)
    pts, ji, jw, m = _random_rig(rng)
    with pytest.raises(ValueError, match="joint_weights"):
        fp.skin_frames(pts, ji, jw[:, :2], m)
    with pytest.raises(ValueError, match="joint_indices"):
        fp.skin_frames(pts, ji + 100, jw, m)
    with pytest.raises(ValueError, match="centers"):
        fp.part_farthest(pts, ji, jw, m, [0, 1], [0], np.zeros((1, 1, 3)))


def test_nan_vertex_counts_as_infinitely_far():
    pts = np.array([[0, 0, 0], [np.nan, 0, 0]], np.float32)
    ji = np.zeros((2, 1), np.int32)
    jw = np.ones((2, 1), np.float32)
    d, v = fp.part_farthest(pts, ji, jw, np.eye(4)[None, None], [0, 2], [0, 1], np.zeros((1, 1, 3)))
    assert np.isinf(d[0, 0]) and v[0, 0] == 1


def _usd_skin(stage, times):
    """Plain usd-core: SkinningQuery + SkelQuery of the bound clip -> (f, n, 3) world points."""
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(stage.GetDefaultPrim())
    cache.Populate(root, Usd.TraverseInstanceProxies())
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/Tube/Skeleton"))
    sq = cache.GetSkelQuery(skel)
    mesh = stage.GetPrimAtPath("/Tube/Collider")
    skq = cache.GetSkinningQuery(mesh)
    pts0 = mesh.GetAttribute("points").Get()
    out = []
    for t in times:
        xf = sq.ComputeSkinningTransforms(Usd.TimeCode(t))
        p = Vt.Vec3fArray(pts0)
        assert skq.ComputeSkinnedPoints(xf, p, Usd.TimeCode(t))
        out.append(np.array(p))
    return np.array(out)


@pytest.mark.parametrize("geom_bind", [None, "scaled"])
def test_proof_skinning_agrees_with_usd_skinning_query(geom_bind):
    gb = None
    if geom_bind:
        gb = np.eye(4)
        gb[:3, :3] *= 1.5
        gb[:3, 3] = [0.2, -0.4, 0.1]
    stage = build_test_stage(geom_bind=gb)
    a = LoadedAsset(stage)
    clip = a.clips[0]  # the bound animationSource
    skel = a.skel_transforms(a.anim_local(clip, clip.times))
    ours = fp.skin_frames(a.points, a.jidx, a.jw,
                          fp.skinning_transforms(skel, a.inv_bind, a.geom_bind, a.skel_world))
    ref = _usd_skin(stage, clip.times)
    np.testing.assert_allclose(ours, ref, atol=2e-5)


def test_proof_skinning_agrees_with_skin_points_lbs_on_unbound_clip(asset):
    clip = next(c for c in asset.clips if c.name == "twist")
    skel = asset.skel_transforms(asset.anim_local(clip, clip.times))
    # independent: the fixture's own transforms
    times, skel_ref = clip_skel("twist", 12)
    np.testing.assert_array_equal(clip.times, times)
    np.testing.assert_allclose(skel, skel_ref, atol=1e-6)
    ours = fp.skin_frames(asset.points, asset.jidx, asset.jw,
                          fp.skinning_transforms(skel, asset.inv_bind, asset.geom_bind, asset.skel_world))
    for f in range(len(times)):
        xf = Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray((skel[f] @ asset.inv_bind).transpose(0, 2, 1)))
        p = Vt.Vec3fArray.FromNumpy(asset.points)
        UsdSkel.SkinPointsLBS(Gf.Matrix4d(1), xf, Vt.IntArray.FromNumpy(asset.jidx.ravel()),
                              Vt.FloatArray.FromNumpy(asset.jw.ravel()), asset.k, p)
        np.testing.assert_allclose(ours[f], np.array(p), atol=2e-5)


def test_chunking_does_not_change_the_result(asset):
    whole = fp.prove(asset, chunk_frames=1000)
    tiny = fp.prove(asset, chunk_frames=5)
    one = fp.prove(asset, chunk_frames=1)
    for a, b, c in zip(whole.results, tiny.results, one.results):
        assert (a.excess, a.time, a.vertex) == (b.excess, b.time, b.vertex) == (c.excess, c.time, c.vertex)
    np.testing.assert_array_equal(whole.tightest, tiny.tightest)


def test_proof_memory_does_not_grow_with_frames():
    """The proof never holds the skinned points of all frames: measured with tracemalloc (which
    sees every numpy allocation) on a 2,402-vertex, 600-frame asset whose skinned points would
    take 17 MB, prove()'s peak stays a small fraction of that (measured 0.6 MB; skinning each
    chunk with skin_frames first would peak at 32 MB)."""
    import tracemalloc

    asset = LoadedAsset(build_test_stage(rings=60, segments=40, clips=(("wiggle", 600),)))
    full = 600 * asset.n * 3 * 4  # float32 (frames, vertices, 3)
    assert asset.n == 2402 and full > 16e6
    fp.prove(LoadedAsset(build_test_stage(clips=(("wiggle", 3),))))  # lazy imports, kernel loading
    tracemalloc.start()
    try:
        probe = np.empty((600, asset.n, 3), np.float32)  # the instrument sees such an array
        probe_peak = tracemalloc.get_traced_memory()[1]
        del probe
        tracemalloc.reset_peak()
        proof = fp.prove(asset)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert probe_peak >= full
    assert proof.frames == 600
    assert peak < full / 8, f"prove() peaked at {peak / 1e6:.1f} MB, all skinned frames are {full / 1e6:.1f} MB"


def test_chunk_size_respects_the_byte_budget():
    from colossus.validators import tolerances as tol
    for joints, parts in ((200, 200), (3, 3), (5000, 1000)):
        c = fp.chunk_size(joint_count=joints, part_count=parts)
        assert 1 <= c <= tol.CHUNK_FRAMES
        # either the budget holds, or a single frame already exceeds it (never zero frames)
        assert c == 1 or c * joints * 16 * 8 * 3 <= tol.CHUNK_BYTES


def test_subframes_check_in_between_times(asset):
    p0 = fp.prove(asset)
    p3 = fp.prove(asset, subframes=3)
    assert p0.subframe_times == 0 and p3.subframe_times == 3 * (23 + 11)
    assert p3.frames == p0.frames == 36
    assert p0.not_checked == [] and any("certified for every time in [first, last]" in s for s in p0.checked)
    assert any("3 in-between" in s for s in p3.checked)
    times, fidx, is_sub = fp.clip_times(np.array([0.0, 1.0, 2.0]), 3)
    np.testing.assert_allclose(times, [0, 0.25, 0.5, 0.75, 1, 1.25, 1.5, 1.75, 2])
    np.testing.assert_array_equal(fidx, [0, 0, 0, 0, 1, 1, 1, 1, 2])
    np.testing.assert_array_equal(is_sub, [0, 1, 1, 1, 0, 1, 1, 1, 0])


def test_subframes_catch_a_failure_between_frames(tmp_path):
    """Frames at +-0.9 rad, straight in between; off-axis sphere centres with radii exactly as
    tight as the frames allow, so only the in-between (straight) pose fails."""
    from colossus.validators import check_asset
    stage = build_test_stage(clips=(("swing", 2),))
    col = stage.GetPrimAtPath("/Tube/Collider")
    c = np.array(col.GetAttribute("colossus:parts:centers").Get())
    c[:] = [0.5, 0.5, 0]  # off-axis centres: the straight pose is farthest from them
    col.GetAttribute("colossus:parts:centers").Set(Vt.Vec3fArray.FromNumpy(c.astype(np.float32)))
    # the tightest radii that hold on the two frames, from usd-core's skinning (not the proof's)
    path = str(tmp_path / "swing.usda")
    stage.GetRootLayer().Export(path)
    tight = tightest(part_distances(path)[0])
    col.GetAttribute("colossus:parts:radii").Set(Vt.FloatArray.FromNumpy((tight * (1 + 1e-6) + 1e-5).astype(np.float32)))
    r0 = check_asset(stage, subframes=0, select=["COL403"])
    assert r0.passed, [f.message for f in r0.findings]
    assert r0.stats["frameproof"]["subframe_times"] == 0
    r1 = check_asset(stage, subframes=1, select=["COL403"])
    assert r1.stats["frameproof"]["subframe_times"] == 1
    fs = r1.by_code("COL403")
    assert fs, "the in-between pose must be caught"
    assert {f.time for f in fs} == {0.5} and {f.frame for f in fs} == {0}
    assert any("1 in-between" in c for c in r1.stats["frameproof"]["checked"])
    # the continuous certificate (on by default) catches it without any subframe, with its interval
    r2 = check_asset(stage, select=["COL407"])
    fs = r2.by_code("COL407")
    assert fs and {tuple(f.interval) for f in fs} == {(0.0, 1.0)} and all(f.excess > 0 for f in fs)
    assert r2.to_dict()["findings"][0]["interval"] == [0.0, 1.0]  # the contract's JSON field
