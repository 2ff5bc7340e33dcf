"""Runtime: loading, posing (against plain usd-core UsdSkel) and queries (against an independent
numpy reference, on every frame of the samples, on the lazily skinned path game code takes)."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Usd, Vt

from colossus.runtime import ColliderError, SphereContacts, SurfacePoints, load_collider
from colossus.runtime.backends import PARALLEL_RAYS
from colossus.runtime.kernels.triangle import closest_on_triangle
from references.naive_queries import (closest_point_on_triangles, naive_raycast, naive_skin,
                                naive_sphere_contacts, ray_triangles)
from references.usd_reference import UsdSkelReference, read_parts


#: Query test assets: the two samples with dominant parts (every face in one part) and imported
#: with ``--parts any`` (faces in up to 3 parts: the dedup and first-part rules matter).
QUERY_ASSETS = {"limb": ("limb", "dominant"), "creature": ("creature", "dominant"),
                "limb-any": ("limb", "any"), "creature-any": ("creature", "any")}


@pytest.fixture(scope="session")
def query_path(imported):
    return lambda key: imported(QUERY_ASSETS[key][0], "glb", parts=QUERY_ASSETS[key][1])[1]


def tol(col):
    return 2e-6 * max(1.0, col.size())


# -- loading ------------------------------------------------------------------------------------


def test_load(creature, samples_meta):
    assert creature.clips == ["roar", "walk"]  # file order
    assert creature.triangles.shape == (10080, 3)
    for clip in creature.clips:
        t = creature.frame_times(clip)
        assert np.array_equal(t, np.arange(len(t)))
        lo, hi = samples_meta["creature"]["action_frame_ranges"][clip]
        assert len(t) == hi - lo + 1


def test_load_verified(limb_path):
    from colossus.validators import require_passing
    col = load_collider(limb_path, verify=require_passing)  # the validators' error rules, given by the caller
    assert col.clips == ["bend"]
    with pytest.raises(TypeError):
        load_collider(limb_path, verify=True)  # the runtime never imports the validators itself


def test_load_verified_reads_the_file_once(limb_path, monkeypatch):
    """The verifier checks the stage load_collider read: the validators never open the file
    again (their opener is made to fail), and a plain path verifier still gets the path."""
    from colossus.validators import asset as vasset
    from colossus.validators import require_passing

    def no_second_read(path):
        raise AssertionError(f"the validators opened {path} again")

    monkeypatch.setattr(vasset, "open_stage", no_second_read)
    from colossus.validators import runner
    monkeypatch.setattr(runner, "open_stage", no_second_read)
    col = load_collider(limb_path, verify=require_passing)
    assert col.clips == ["bend"]
    seen = []
    load_collider(limb_path, verify=seen.append)
    assert seen == [limb_path]


@pytest.mark.parametrize("content", [None, b"", b"#usda 1.0\n(\n garbage", b"\x00\x01binary junk" * 10,
                                     b"#usda 1.0\ndef Xform \"x\" {}\n"])
def test_bad_files(tmp_path, content):
    p = tmp_path / "bad.usda"
    if content is not None:
        p.write_bytes(content)
    with pytest.raises(ColliderError) as e:
        load_collider(p)
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg and len(msg) < 400


def test_verify_rejects_broken_asset(tmp_path, limb_path):
    """verify=require_passing raises on an asset the error rules reject; without it it still loads."""
    from references.usd_fixture import open_copy
    from colossus.validators import require_passing
    stage = open_copy(limb_path)  # never edit the layer the session's colliders share
    mesh = next(p for p in stage.Traverse() if p.GetTypeName() == "Mesh")
    radii = np.asarray(mesh.GetAttribute("colossus:parts:radii").Get()) * 0.3
    mesh.GetAttribute("colossus:parts:radii").Set(Vt.FloatArray(radii.tolist()))
    bad = tmp_path / "small-spheres.usda"
    stage.GetRootLayer().Export(str(bad))
    with pytest.raises(ColliderError, match="fails verification"):
        load_collider(bad, verify=require_passing)
    col = load_collider(bad)
    pose = col.pose("bend", 10)
    # culling never changes an answer even though the asset spheres do not hold
    assert (pose.cull[:, 3] >= pose.spheres[:, 3]).all()
    rng = np.random.default_rng(3)
    o = pose.points[rng.integers(0, len(pose.points), 200)] + rng.normal(size=(200, 3))
    d = rng.normal(size=(200, 3))
    a, b = pose.raycast(o, d), pose.raycast(o, d, backend="brute")
    assert np.array_equal(a.triangle, b.triangle)


# -- posing ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["creature", "limb", "odd", "odd_skel"])
def test_points_match_usdskel(name, creature_path, limb_path, odd_path, odd_skel_path):
    path = {"creature": creature_path, "limb": limb_path, "odd": odd_path, "odd_skel": odd_skel_path}[name]
    col = load_collider(path)
    ref = UsdSkelReference(path)
    pose = None
    for clip in col.clips:
        ref.use_clip(clip)
        ft = col.frame_times(clip)
        times = list(ft[::4]) + [ft[0] - 5, ft[-1] + 3.25, ft[0] + 0.5, ft[0] + 1.37, ft[-1] - 0.71,
                                 (ft[0] + ft[-1]) / 2 + 0.123]
        for t in times:
            pose = col.pose(clip, t, out=pose)
            assert np.abs(pose.points - ref.points(t)).max() < tol(col), (clip, t)
            assert np.allclose(pose.skel_transforms, ref.skel_transforms(t), atol=2e-5)


@pytest.mark.parametrize("name", ["odd", "odd_skel"])
def test_points_match_naive_skin(name, odd_path, odd_skel_path):
    col = load_collider({"odd": odd_path, "odd_skel": odd_skel_path}[name])
    d = col.data
    pose = col.pose("twist", 104.6)
    ref = naive_skin(d.rest_points, d.joint_indices, d.joint_weights, pose.skel_transforms,
                     d.inv_bind, d.geom_bind, pose.local_to_world)
    assert np.abs(pose.points - ref).max() < tol(col)


def test_spheres_move_with_joints(odd_path, creature):
    for col in (load_collider(odd_path), creature):
        d = col.data
        for clip in col.clips:
            ft = col.frame_times(clip)
            pose = col.pose(clip, ft[len(ft) // 2] + 0.5)
            world = pose.local_to_world @ pose.skel_transforms[d.part_joint]  # column-vector
            c = np.einsum("pij,pj->pi", world, np.c_[d.part_centers, np.ones(len(d.part_centers))])[:, :3]
            s = np.linalg.norm(world[:, :3, :3], axis=1).max(1)
            assert np.allclose(pose.spheres[:, :3], c, atol=1e-9)
            assert np.allclose(pose.spheres[:, 3], d.part_radii * s)
            # the culling spheres bound every vertex of their part
            for p in range(col.parts):
                v = d.verts[d.vert_offsets[p]:d.vert_offsets[p + 1]]
                far = np.linalg.norm(pose.points[v] - pose.cull[p, :3], axis=1).max()
                assert far <= pose.cull[p, 3]


def test_pose_buffers_reused(limb):
    a = limb.pose("bend", 3)
    pts = a.points
    b = limb.pose("bend", 20)
    keep = b.points.copy()
    a2 = limb.pose("bend", 10, out=a)
    assert a2 is a and a.points is pts and a.time == 10
    assert np.array_equal(b.points, keep)
    with pytest.raises(KeyError, match="no clip"):
        limb.pose("nope", 0)


@pytest.mark.parametrize("name", ["limb", "odd", "odd_skel"])
def test_rest_pose(name, limb_path, odd_path, odd_skel_path):
    """pose(None) is UsdSkel's unanimated pose (restTransforms, no animationSource)."""
    path = {"limb": limb_path, "odd": odd_path, "odd_skel": odd_skel_path}[name]
    col = load_collider(path)
    p = col.pose(None)
    ref = UsdSkelReference(path).use_clip(None)
    t = Usd.TimeCode.Default()
    assert p.points.shape == col.rest_points.shape
    assert np.abs(p.points - ref.points(t)).max() < tol(col)
    assert np.allclose(p.skel_transforms, ref.skel_transforms(t), atol=1e-9)
    if name == "limb":  # imported: rest = bind, identity skeleton transform and geomBind
        assert np.abs(p.points - col.rest_points).max() < tol(col)


# -- queries ----------------------------------------------------------------------------------------


def random_rays(points, rng, n, scale=0.02):
    """Rays from around ``points`` (V, 3), 70% aimed near a random point (hits), the rest random."""
    lo, hi = points.min(0), points.max(0)
    pad = 0.3 * (hi - lo)
    o = rng.uniform(lo - pad, hi + pad, size=(n, 3))
    target = points[rng.integers(0, len(points), n)] + rng.normal(scale=scale, size=(n, 3))
    d = np.where(rng.random((n, 1)) < 0.7, target - o, rng.normal(size=(n, 3)))
    return o, d


def check_hits(pose, o, d, h, max_distance=np.inf, first_part=None):
    """Hits ``h`` (already computed) against the numpy reference on ``pose.points``.

    Exact agreement on hit or miss and distance; the triangle too, except where the reference's
    nearest hit sits on an edge shared with the kernel's triangle: then the kernel's triangle
    must be hit by the reference at the same distance, on its edge.  ``first_part`` (F,): the
    lowest part holding each face, read from the file (runtime.face_part otherwise)."""
    pts = pose.points
    tris = pose.collider.triangles
    dist, tri, bary = naive_raycast(pts, tris, o, d, max_distance)
    assert np.array_equal(np.isinf(h.distance), np.isinf(dist))
    hit = np.isfinite(dist)
    assert np.allclose(h.distance[hit], dist[hit], rtol=1e-9, atol=1e-9)
    p = pts.astype(np.float64)
    for r in np.nonzero(h.triangle != tri)[0]:  # shared edge or vertex, equally near
        dn = d[r] / np.linalg.norm(d[r])
        t, u, v = ray_triangles(o[r], dn, *(p[tris[[h.triangle[r]], k]] for k in range(3)))
        assert t[0] == pytest.approx(dist[r], rel=1e-12, abs=1e-12), (r, "kernel triangle not as near")
        assert min(1 - u[0] - v[0], u[0], v[0]) < 1e-9 and min(bary[r]) < 1e-9, (r, "not an edge hit")
    same = h.triangle == tri
    assert np.allclose(h.barycentric[same], bary[same], atol=1e-9)
    assert (h.triangle[~hit] == -1).all() and (h.part[~hit] == -1).all()
    if hit.any():
        dn = d[hit] / np.linalg.norm(d[hit], axis=1)[:, None]
        assert np.allclose(h.point[hit], o[hit] + dist[hit, None] * dn, atol=1e-9)
        T = tris[h.triangle[hit]]
        n = np.cross(p[T[:, 1]] - p[T[:, 0]], p[T[:, 2]] - p[T[:, 0]])
        assert np.allclose(h.normal[hit], n / np.linalg.norm(n, axis=1)[:, None])
        assert np.allclose(np.einsum("rk,rkj->rj", h.barycentric[hit], p[T]), h.point[hit], atol=1e-6)
        owner = pose.collider.data.face_part if first_part is None else first_part
        assert (h.part[hit] == owner[h.triangle[hit]]).all()
    return h


def sort_contacts(cs):
    o = np.argsort(cs.triangle)
    return SphereContacts(cs.triangle[o], cs.point[o], cs.normal[o], cs.depth[o], cs.barycentric[o])


def check_contact_result(pose, center, radius, got):
    """Contacts ``got`` (already computed) against the numpy reference on ``pose.points``: the same
    triangles, each once (deduplicated), points, depths, barycentrics, normals, tracking."""
    assert len(np.unique(got.triangle)) == len(got)
    cs = sort_contacts(got)
    idx, q, depth, bary = naive_sphere_contacts(pose.points, pose.collider.triangles, center, radius)
    assert np.array_equal(cs.triangle, idx)
    assert np.allclose(cs.point, q, atol=1e-9)
    assert np.allclose(cs.depth, depth, atol=1e-9)
    assert np.allclose(cs.barycentric, bary, atol=1e-7)
    if len(cs):
        assert np.allclose(np.linalg.norm(cs.normal, axis=1), 1)
        far = np.linalg.norm(center - cs.point, axis=1) > 1e-9
        assert np.allclose(cs.normal[far], ((center - cs.point) / np.linalg.norm(center - cs.point, axis=1)[:, None])[far])
        assert np.allclose(pose.track(cs.triangle, cs.barycentric), cs.point, atol=1e-6)
    return cs


@pytest.mark.parametrize("key", list(QUERY_ASSETS))
def test_lazy_queries_every_frame(key, query_path):
    """Every frame of every clip, the path game code takes: re-pose a reused Pose (its buffer
    still holds the previous frame), query before reading ``pose.points`` (parts are skinned on
    demand), then compare with the numpy reference on the points read afterwards, and those
    points with usd-core.  Rays and contact spheres are placed from usd-core's points, so the
    runtime's own skinning never chooses where to look."""
    path = query_path(key)
    col = load_collider(path)
    ref = UsdSkelReference(path)
    first = read_parts(ref.stage).first_part
    big = key.startswith("creature")
    n_rays, n_spheres = (16, 2) if big else (48, 10)
    assert n_rays <= PARALLEL_RAYS  # the serial, lazy ray kernel
    rng = np.random.default_rng(len(key))
    size = col.size()
    pose = None
    frames = 0
    for clip in col.clips:
        ref.use_clip(clip)
        for t in col.frame_times(clip):
            truth = ref.points(t)
            o, d = random_rays(truth, rng, n_rays)
            spheres = [(truth[rng.integers(len(truth))] + rng.normal(scale=0.03 * size, size=3),
                        rng.uniform(0.005, 0.08) * size) for _ in range(n_spheres)]
            pose = col.pose(clip, t, out=pose)
            h = pose.raycast(o, d)
            contacts = [pose.sphere_contacts(c, r) for c, r in spheres]
            # still lazy: no query skinned the whole mesh (private flag: there is no public one)
            assert pose._full != pose._version
            assert np.abs(pose.points - truth).max() < tol(col), (clip, t)
            check_hits(pose, o, d, h, first_part=first)
            for (c, r), got in zip(spheres, contacts):
                check_contact_result(pose, c, r, got)
            b = pose.raycast(o, d, backend="brute")
            assert np.array_equal(h.triangle, b.triangle) and np.array_equal(h.part, b.part)
            # to the last bit only once lazy and full skinning agree (test_lazy_skinning_same_bits)
            assert np.allclose(h.distance, b.distance, rtol=1e-12, atol=0)
            frames += 1
    assert frames == sum(len(col.frame_times(c)) for c in col.clips)


def test_lazy_skinning_same_bits(query_path):
    """A lazy query (parts skinned on demand) gives bit for bit the answer brute force gives on
    the fully skinned pose, on every frame of the limb (one skinning kernel under one fast-math
    policy, runtime.kernels.skin: this failed while the lazy and full paths were two kernels)."""
    path = query_path("limb")
    col = load_collider(path)
    ref = UsdSkelReference(path).use_clip("bend")
    rng = np.random.default_rng(4)
    pose = None
    same = True
    for t in col.frame_times("bend"):
        o, d = random_rays(ref.points(t), rng, 48)
        pose = col.pose("bend", t, out=pose)
        h = pose.raycast(o, d)
        b = pose.raycast(o, d, backend="brute")
        same &= np.array_equal(h.distance, b.distance) and np.array_equal(h.triangle, b.triangle)
    assert same


def test_lazy_query_with_max_distance(limb):
    rng = np.random.default_rng(0)
    pose = None
    for t in limb.frame_times("bend"):
        pose = limb.pose("bend", t + rng.uniform(0, 0.5), out=pose)  # in between frames too
        truth = limb.pose("bend", pose.time).points  # a second, fully skinned pose
        o, d = random_rays(truth, rng, 20)
        h = pose.raycast(o, d, 0.3)
        check_hits(pose, o, d, h, 0.3)


def test_raycast_parallel_every_frame_creature(creature):
    """Above PARALLEL_RAYS rays (the parallel kernel), every frame: the same answers, bit for
    bit, as the serial culled kernel (which test_lazy_queries_every_frame holds to the numpy
    reference) on the same pose, and the numpy reference on some rays; brute force on every
    4th frame (it tests every triangle: the slow part)."""
    rng = np.random.default_rng(1)
    pose = None
    for clip in creature.clips:
        for i, t in enumerate(creature.frame_times(clip)):
            pose = creature.pose(clip, t, out=pose)
            o, d = random_rays(pose.points, rng, PARALLEL_RAYS + 4)
            a = pose.raycast(o, d)
            for lo in (0, 4):  # two serial batches covering every ray
                s = pose.raycast(o[lo:lo + PARALLEL_RAYS], d[lo:lo + PARALLEL_RAYS])
                for k in ("triangle", "part", "distance", "barycentric"):
                    assert np.array_equal(getattr(a, k)[lo:lo + PARALLEL_RAYS], getattr(s, k)), (clip, t, k)
            if i % 4 == 0:
                b = pose.raycast(o, d, backend="brute")
                assert np.array_equal(a.triangle, b.triangle) and np.array_equal(a.part, b.part)
                assert np.array_equal(a.distance, b.distance)
            sub = rng.choice(len(o), 8, replace=False)
            check_hits(pose, o[sub], d[sub], RayHitsView(a, sub))


class RayHitsView:
    """Rows ``idx`` of a RayHits."""

    def __init__(self, h, idx):
        for k in ("distance", "point", "normal", "triangle", "barycentric", "part"):
            setattr(self, k, getattr(h, k)[idx])


@pytest.mark.parametrize("name", ["limb", "creature"])
def test_raycast_matches_trimesh(name, limb, creature):
    """trimesh's own ray-triangle code (every 3rd limb frame, 3 creature poses, off-frame times
    included): the same hit or miss for every ray and the same distance.  trimesh tests
    barycentrics with a tolerance, so a ray grazing an edge could legitimately differ; such rays
    (hit within 1e-9 of an edge in either answer) are the only ones excused, at most 0.1%
    (measured: 0 of 6900 rays on 23 creature poses)."""
    import trimesh
    from trimesh.ray.ray_triangle import RayMeshIntersector

    col = {"limb": limb, "creature": creature}[name]
    poses = ([("bend", t + 0.5 * (i % 2)) for i, t in enumerate(col.frame_times("bend")[::3])] if name == "limb"
             else [("roar", 17.5), ("walk", 5.25), ("walk", 30.0)])
    rng = np.random.default_rng(2)
    excused = total = 0
    for clip, t in poses:
        pose = col.pose(clip, t)
        o, d = random_rays(pose.points, rng, 300)
        d /= np.linalg.norm(d, axis=1)[:, None]
        h = pose.raycast(o, d)
        p = pose.points.astype(np.float64)
        m = trimesh.Trimesh(p, col.triangles, process=False)
        loc, ray, tri = RayMeshIntersector(m).intersects_location(o, d, multiple_hits=True)
        dist = np.full(len(o), np.inf)
        for r, l in zip(ray, loc):
            dist[r] = min(dist[r], np.linalg.norm(l - o[r]))
        differ = np.isfinite(dist) != np.isfinite(h.distance)
        for r in np.nonzero(differ)[0]:
            if np.isfinite(h.distance[r]):  # we hit, trimesh misses: our hit must graze an edge
                assert h.barycentric[r].min() < 1e-9, (clip, t, r, "trimesh misses a hit")
            else:  # trimesh hits, we miss: its hit must graze an edge
                bc = trimesh.triangles.points_to_barycentric(p[col.triangles[tri[ray == r]]], loc[ray == r])
                assert np.abs(bc).min() < 1e-9, (clip, t, r, "we miss a hit")
        excused += differ.sum()
        total += len(o)
        both = np.isfinite(dist) & np.isfinite(h.distance)
        assert np.allclose(h.distance[both], dist[both], rtol=1e-9, atol=1e-9)
    assert excused <= 1e-3 * total, (excused, total)


def test_raycast_validation(limb):
    pose = limb.pose("bend", 0)
    with pytest.raises(ValueError, match="zero"):
        pose.raycast([[0, 0, 0]], [[0, 0, 0]])
    with pytest.raises(ValueError, match="shape"):
        pose.raycast(np.zeros((2, 3)), np.ones((3, 3)))
    top = pose.points[:, 1].max()
    h = pose.raycast([0, top + 5, 0], [0, -1, 0])  # a single ray, straight down the limb's axis
    assert h.distance.shape == (1,) and h.triangle.shape == (1,)
    dist, tri, bary = naive_raycast(pose.points, limb.triangles, np.array([[0, top + 5, 0]]),
                                    np.array([[0.0, -1.0, 0.0]]))
    assert np.isfinite(dist[0]) and h.triangle[0] == tri[0]
    assert h.distance[0] == pytest.approx(dist[0], rel=1e-12)
    assert 5 - 1e-9 <= h.distance[0] <= 5 + 1e-2 * limb.size()  # the cap, at or just below the top


def test_overlapping_parts_dedup_and_first_part(query_path):
    """--parts any: faces really are in several parts; a contact sphere over overlapping faces
    reports each triangle once, and a ray hitting one reports the lowest part holding it."""
    path = query_path("creature-any")
    col = load_collider(path)
    parts = read_parts(path)
    shared = np.nonzero(parts.face_count > 1)[0]
    assert parts.face_count.min() >= 1 and parts.face_count.max() >= 3
    assert col.data.faces_shared  # the contact query dedupes (a dominant-parts asset skips it)
    assert not load_collider(query_path("creature")).data.faces_shared
    assert len(shared) > 0.1 * len(parts.triangles)
    ref = UsdSkelReference(path).use_clip("walk")
    rng = np.random.default_rng(9)
    pose = None
    for t in (0.0, 11.0, 23.5, 40.0):
        truth = ref.points(t)
        pose = col.pose("walk", t, out=pose)
        # the whole body at once: every triangle exactly once
        cs = pose.sphere_contacts(truth.mean(0), 2 * col.size())
        assert np.array_equal(np.sort(cs.triangle), np.arange(len(col.triangles)))
        pose = col.pose("walk", t, out=pose)
        faces = rng.choice(shared, 16, replace=False)
        cent = truth[parts.triangles[faces]].mean(1)
        for f, c in zip(faces[:6], cent[:6]):  # spheres on shared faces
            got = pose.sphere_contacts(c, 0.02 * col.size())
            assert f in got.triangle and len(np.unique(got.triangle)) == len(got)
            check_contact_result(pose, c, 0.02 * col.size(), got)
        normals = np.cross(*(truth[parts.triangles[faces, k]] - truth[parts.triangles[faces, 0]] for k in (1, 2)))
        o = cent + 0.3 * normals / np.linalg.norm(normals, axis=1)[:, None]
        h = pose.raycast(o, cent - o)  # straight at each shared face's centroid
        check_hits(pose, o, cent - o, h, first_part=parts.first_part)
        assert (h.triangle >= 0).all()
        assert (parts.face_count[h.triangle] > 1).mean() > 0.5


def test_chunk_spheres_bound_their_faces(query_path):
    """The second culling level: each chunk's vertex CSR is exactly the distinct corners of its
    faces, and on a fresh pose every corner lies in its chunk's sphere (so skipping a chunk, or
    a face whose box is out of reach, never drops a contact; the every-frame test above checks
    the answers)."""
    col = load_collider(query_path("creature-any"))
    d = col.data
    for c in range(len(d.chunk_offsets) - 1):
        corners = np.unique(d.triangles[d.faces[d.chunk_offsets[c]:d.chunk_offsets[c + 1]]])
        assert np.array_equal(d.chunk_verts[d.chunk_vert_offsets[c]:d.chunk_vert_offsets[c + 1]], corners)
    pose = col.pose("walk", 17.25)
    pose.points  # skinned first, as the parallel ray path does before _all_chunks
    pose._all_chunks()
    for c in range(len(d.chunk_offsets) - 1):
        v = pose.points[d.chunk_verts[d.chunk_vert_offsets[c]:d.chunk_vert_offsets[c + 1]]].astype(np.float64)
        s = pose.chunk_spheres[c]
        assert np.linalg.norm(v - s[:3], axis=1).max() <= s[3]


def test_closest_point_kernel():
    rng = np.random.default_rng(5)
    pts = rng.normal(size=(300, 3)).astype(np.float32)
    tris = rng.integers(0, 300, size=(100, 3))
    tris[:5, 1] = tris[:5, 0]  # degenerate: two equal corners
    pts[tris[5, 2]] = (pts[tris[5, 0]] + pts[tris[5, 1]]) / 2  # degenerate: collinear
    out = np.empty(6)
    for _ in range(30):
        p = rng.normal(size=3) * 1.5
        q_ref, b_ref = closest_point_on_triangles(p, *(pts[tris[:, k]].astype(np.float64) for k in range(3)))
        for f in range(len(tris)):
            closest_on_triangle(p[0], p[1], p[2], pts, tris[f, 0], tris[f, 1], tris[f, 2], out)
            assert np.isclose(np.linalg.norm(out[:3] - p), np.linalg.norm(q_ref[f] - p), atol=1e-9)
            assert np.isclose(out[3:].sum(), 1) and (out[3:] >= -1e-12).all()
            assert np.allclose(out[3:] @ pts[tris[f]].astype(np.float64), out[:3], atol=1e-9)


# -- contact tracking (momentum inheritance) ---------------------------------------------------


def test_surface_points_carried_by_skin(limb):
    a = limb.pose("bend", 6)
    b = limb.pose("bend", 6.5)
    top = a.points[:, 1].argmax()
    cs = a.sphere_contacts(a.points[top] + [0, 0.02, 0], 0.05)
    assert len(cs)
    anchors = cs.anchors()
    assert np.allclose(anchors.at(a), cs.point, atol=1e-6)
    moved = anchors.at(b)
    T = limb.triangles[anchors.triangles]
    expect = np.einsum("ck,ckj->cj", anchors.barycentric, b.points[T].astype(np.float64))
    assert np.allclose(moved, expect)
    v = anchors.velocity(a, b)
    assert np.allclose(v, (moved - cs.point) / (0.5 / 24), atol=1e-3)
    va = anchors.velocity_at(limb, "bend", 6.25, step=0.25)
    assert np.allclose(va, v)
    # (u, v) barycentrics are accepted too
    assert np.allclose(SurfacePoints(anchors.triangles, anchors.barycentric[:, 1:]).at(b), moved)
    with pytest.raises(ValueError):
        a.track([10 ** 9], [[1, 0, 0]])


def test_surface_frame_and_tracking_are_lazy(creature):
    """Pose.surface_frame (a contact patch's centroid and mean normal), Pose.track and
    Pose.face_normals on a fresh pose skin only the parts holding their triangles, and agree
    with a numpy transcription on the points read afterwards."""
    rng = np.random.default_rng(5)
    T = creature.triangles
    pose = None
    for k, C in enumerate((1, 2, 5, 40)):
        pose = creature.pose("walk", 3.5 + 7 * k, out=pose)
        first = rng.integers(0, len(T))
        tri = np.clip(first + rng.integers(0, 30, C), 0, len(T) - 1)  # a patch: a few parts at most
        bary = rng.dirichlet([1, 1, 1], C)
        out = pose.surface_frame(SurfacePoints(tri, bary))
        at = pose.track(tri, bary)
        nrm = pose.face_normals(tri)
        assert pose._full != pose._version  # still lazy (private flag: there is no public one)
        P = pose.points.astype(np.float64)[T[tri]]  # numpy: (C, 3 corners, 3)
        n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
        n = n / np.linalg.norm(n, axis=1, keepdims=True)
        assert np.allclose(at, np.einsum("ck,ckj->cj", bary, P), atol=1e-9)
        assert np.allclose(nrm, n, atol=1e-9)
        assert np.allclose(out[:3], at.mean(0), atol=1e-9)
        assert np.allclose(out[3:], n.sum(0) / np.linalg.norm(n.sum(0)), atol=1e-9)
        again = np.full(6, np.nan)
        assert pose.surface_frame(SurfacePoints(tri, bary), out=again) is again and np.array_equal(again, out)
    assert np.array_equal(pose.surface_frame(SurfacePoints([], np.zeros((0, 3)))), np.zeros(6))
    with pytest.raises(ValueError, match="out of range"):
        pose.surface_frame(SurfacePoints([len(T)], [[1, 0, 0]]))
    with pytest.raises(ValueError, match="out of range"):
        pose.face_normals([-1])
    with pytest.raises(TypeError):
        pose.surface_frame(([0], [[1, 0, 0]]))
    with pytest.raises(ValueError, match="out must be"):
        pose.surface_frame(SurfacePoints([0], [[1, 0, 0]]), out=np.empty(6, dtype=np.float32))


# -- any pose (IK, ragdoll): pose_from_joints --------------------------------------------------


def _random_locals(col, rng, max_angle=np.pi):
    """Rest local transforms with every joint turned by a random rotation of up to ``max_angle``."""
    from scipy.spatial.transform import Rotation

    rest = col.rest_local
    J = len(rest)
    axis = rng.normal(size=(J, 3))
    rv = axis / np.linalg.norm(axis, axis=1, keepdims=True) * rng.uniform(0, max_angle, size=(J, 1))
    local = rest.copy()
    local[:, :3, :3] = rest[:, :3, :3] @ Rotation.from_rotvec(rv).as_matrix()
    return local


def _naive_points(col, local):
    """Skinned points of a joint-local pose with numpy only (column-vector, stage space)."""
    from references import naive

    d = col.data
    skel = naive.compose(local[None], d.parents)[0]
    world = (d.static_local_to_world if d.static_local_to_world is not None else np.eye(4))
    y = naive.naive_lbs(d.rest_points, d.joint_indices, d.joint_weights, (world @ skel @ d.inv_bind @ d.geom_bind)[None])
    return y[0]


@pytest.mark.parametrize("name", ["creature", "limb", "odd"])
def test_pose_from_joints_spheres_hold_and_queries_are_exact(name, creature_path, limb_path, odd_path):
    col = load_collider({"creature": creature_path, "limb": limb_path, "odd": odd_path}[name])
    d = col.data
    rng = np.random.default_rng(11)
    pose = None
    refits = 0
    for trial in range(6):
        local = _random_locals(col, rng)
        pose = col.pose_from_joints(local, out=pose)
        ref = _naive_points(col, local)
        assert np.abs(pose.points - ref).max() < tol(col)
        assert pose.refit.shape == (col.parts,) and pose.refit.dtype == bool
        refits += int(pose.refit.sum())
        for p in range(col.parts):
            v = d.verts[d.vert_offsets[p]:d.vert_offsets[p + 1]]
            far = np.linalg.norm(ref[v] - pose.spheres[p, :3], axis=1).max()
            assert far <= pose.spheres[p, 3] * (1 + 1e-9), (p, far, pose.spheres[p, 3])
            assert far <= pose.cull[p, 3]
        # the stored sphere moved with its joint, or grown (never shrunk)
        stored = col.pose_from_joints(local).spheres  # same numbers on a fresh pose
        assert np.array_equal(stored, pose.spheres)
        # queries on the lazily skinned pose (query first) equal brute force and numpy
        fresh = col.pose_from_joints(local)
        o, dirs = random_rays(pose.points, rng, 120)
        a = fresh.raycast(o, dirs)
        b = pose.raycast(o, dirs, backend="brute")
        assert np.array_equal(a.triangle, b.triangle) and np.array_equal(a.distance, b.distance)
        check_hits(pose, o[:30], dirs[:30], pose.raycast(o[:30], dirs[:30]))
        c = pose.points[rng.integers(len(pose.points))] + rng.normal(scale=0.01 * col.size(), size=3)
        check_contact_result(pose, c, 0.05 * col.size(), pose.sphere_contacts(c, 0.05 * col.size()))
    assert refits > 0  # random 180-degree poses do grow some spheres


def test_pose_from_joints_trs_and_validation(limb):
    from scipy.spatial.transform import Rotation

    rest = limb.rest_local
    J = len(rest)
    q = Rotation.random(J, random_state=3).as_quat()
    a = limb.pose_from_joints(rotations=q)
    local = rest.copy()
    local[:, :3, :3] = Rotation.from_quat(q).as_matrix()
    b = limb.pose_from_joints(local)
    assert np.allclose(a.points, b.points, atol=1e-6) and np.allclose(a.spheres, b.spheres)
    rest_pose = limb.pose_from_joints(rest)
    assert not rest_pose.refit.any()  # the rest pose is a pose the spheres were fitted for
    assert np.allclose(rest_pose.points, limb.pose(None).points, atol=1e-6)
    with pytest.raises(ValueError, match="skeleton joint"):
        limb.pose_from_joints(rest[:-1])
    with pytest.raises(ValueError, match="row-vector"):
        limb.pose_from_joints(rest.transpose(0, 2, 1) + _with_translation(rest))
    with pytest.raises(ValueError, match="rotations"):
        limb.pose_from_joints(translations=rest[:, :3, 3])
    assert limb.joints[0] == limb.data.joints[0]


def _with_translation(rest):
    """A row-vector matrix with a translation in its last row (what a USD-layout array looks like)."""
    m = np.zeros_like(rest)
    m[:, 3, 0] = 1.0
    return m


# -- the proof's tolerance, pinned on the real samples (audit A3) ------------------------------


@pytest.mark.parametrize("name", ["creature", "limb"])
def test_a_radius_shrunk_by_a_thousandth_fails_and_usd_agrees(name, imported, tmp_path):
    """Shrinking every part radius by 0.1 % of itself fails validation (COL403, or COL407 between
    frames), with the proof's own kernel; usd-core's skinning (UsdSkel.SkinningQuery) agrees that the
    named vertex is outside the shrunk sphere by the reported excess, and inside the written one."""
    from colossus.validators import check_asset

    path = imported(name, "glb")[1]
    assert check_asset(path).passed
    stage = Usd.Stage.Open(str(path))
    mesh = next(p for p in stage.Traverse() if p.GetTypeName() == "Mesh")
    r = np.asarray(mesh.GetAttribute("colossus:parts:radii").Get(), dtype=np.float64)
    mesh.GetAttribute("colossus:parts:radii").Set(Vt.FloatArray((r * (1 - 1e-3)).astype(np.float32).tolist()))
    bad = tmp_path / "shrunk.usda"
    stage.GetRootLayer().Export(str(bad))
    rep = check_asset(bad, select=["COL403", "COL407"])
    assert not rep.passed
    fs = rep.by_code("COL403")
    assert fs, "the frames themselves must fail: the spheres are tight at some frame"
    col = load_collider(bad)
    ref = UsdSkelReference(bad)
    failed_parts = {f.part for f in fs}
    assert len(failed_parts) >= max(1, col.parts // 2)  # most parts are tight somewhere
    for f in fs:
        ref.use_clip(f.clip)
        pts = ref.points(f.time)
        skel = ref.skel_transforms(f.time)  # column-vector
        world = pose_world(col, f.time) @ skel[col.data.part_joint[f.part]]
        c = world[:3, :3] @ col.data.part_centers[f.part] + world[:3, 3]
        R = float(np.float32(r[f.part] * (1 - 1e-3))) * np.linalg.norm(world[:3, :3], axis=0).max()
        excess = np.linalg.norm(pts[f.vertex] - c) - R
        assert excess == pytest.approx(f.excess, abs=2e-6 * col.size())
        assert excess > 0
        R0 = float(np.float32(r[f.part])) * np.linalg.norm(world[:3, :3], axis=0).max()
        v = col.data.verts[col.data.vert_offsets[f.part]:col.data.vert_offsets[f.part + 1]]
        assert np.linalg.norm(pts[v] - c, axis=1).max() <= R0 * (1 + 1e-5) + 1e-6 * col.size()


def pose_world(col, t):
    d = col.data
    return d.static_local_to_world if d.static_local_to_world is not None else np.eye(4)


# ---- the runtime refuses what it cannot honour (issue 27 item 5) ------------------------------
def test_huge_finite_direction_is_normalised_not_a_silent_miss(limb):
    import warnings
    pose = limb.pose("bend", limb.frame_times("bend")[0])
    lo, hi = pose.points.min(0), pose.points.max(0)
    o = np.array([(lo + hi) / 2 + [0.0, 0.0, 10.0 * float(np.linalg.norm(hi - lo))]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning either
        unit = pose.raycast(o, np.array([[0.0, 0.0, -1.0]]))
        huge = pose.raycast(o, np.array([[0.0, 0.0, -1e200]]))
        tiny = pose.raycast(o, np.array([[0.0, 0.0, -1e-300]]))
    assert np.isfinite(unit.distance[0])
    np.testing.assert_array_equal(huge.distance, unit.distance)
    np.testing.assert_array_equal(tiny.triangle, unit.triangle)


def test_pose_from_joints_refuses_overflowing_transforms(limb):
    J = len(limb.data.joints)
    local = np.repeat(np.eye(4)[None], J, 0)
    local[:, :3, :3] *= 1e200  # finite, but the chain's product overflows
    with pytest.raises(ValueError, match="overflow"):
        limb.pose_from_joints(local)
    assert np.isfinite(limb.pose_from_joints(np.repeat(np.eye(4)[None], J, 0)).spheres).all()


@pytest.mark.parametrize("value, what", [(float("nan"), "radii: part 0 radius is nan"),
                                         (-1.0, "radii: part 0 radius is -1.0")])
def test_load_refuses_bad_stored_radii(limb_path, tmp_path, value, what):
    from references.usd_fixture import open_copy
    s = open_copy(limb_path)
    mesh = next(p for p in s.Traverse() if p.GetTypeName() == "Mesh")
    a = mesh.GetAttribute("colossus:parts:radii")
    radii = list(a.Get())
    radii[0] = value
    a.Set(radii)
    out = tmp_path / "bad.usda"
    s.GetRootLayer().Export(str(out))
    with pytest.raises(ColliderError, match=what):
        load_collider(out)


# ---- names and seconds (issue 24 item 4) ------------------------------------------------------
def test_clip_source_names_seconds_and_looping(limb_path, tmp_path):
    """A clip is reached by its asset name or by the name it had in its source (the writer keeps
    it in the SkelAnimation's customData when the prim name differs); times in seconds, looped."""
    from colossus.runtime import schema
    from references.usd_fixture import open_copy
    s = open_copy(limb_path)
    anim = next(p for p in s.Traverse() if p.GetTypeName() == "SkelAnimation")
    anim.SetCustomDataByKey(schema.CLIP_NAME_KEY, "Bend Fast")
    out = tmp_path / "named.usda"
    s.GetRootLayer().Export(str(out))
    col = load_collider(out)
    assert col.clips == ["bend"] and col.fps == 24.0
    t = col.frame_times("bend")
    a, b = col.pose("bend", t[3]), col.pose("Bend Fast", t[3])
    assert b.clip == "bend"
    np.testing.assert_array_equal(a.points, b.points)
    span = (t[-1] - t[0]) / col.fps
    assert col.duration("Bend Fast") == pytest.approx(span)
    np.testing.assert_array_equal(col.pose_at_seconds("bend", 3 / col.fps).points, a.points)
    np.testing.assert_array_equal(col.pose_at_seconds("bend", span + 3 / col.fps).points, a.points)   # looped
    end = col.pose_at_seconds("bend", 10 * span, loop=False)
    np.testing.assert_array_equal(end.points, col.pose("bend", t[-1]).points)                      # held
    with pytest.raises(KeyError, match="no clip 'Take 001'"):
        col.pose("Take 001", 0.0)


def _world(angle, axis, scale, translation):
    """(4, 4) column-vector: translation @ rotation(angle about axis) @ uniform scale."""
    from scipy.spatial.transform import Rotation
    m = np.eye(4)
    m[:3, :3] = Rotation.from_rotvec(np.asarray(axis, float) / np.linalg.norm(axis) * angle).as_matrix() * scale
    m[:3, 3] = translation
    return m


@pytest.mark.parametrize("scale", [1.0, 0.01, 37.5])
def test_queries_in_world_space_equal_queries_on_inputs_transformed_by_hand(creature, scale):
    """Issue 24 item 4: ``world=`` (rotation, uniform scale, translation) places the collider in a
    game's world: rays and sphere contacts given in world space answer as the stage-space query on
    the inputs carried to stage space by hand, with points, normals, distances and depths carried
    back (triangles, parts, barycentric the same)."""
    from colossus.runtime import Placement

    W = _world(0.7, [1, 2, -0.5], scale, [12.0, -3.0, 250.0])
    inv = np.linalg.inv(W)
    rng = np.random.default_rng(4)
    pose = creature.pose_at_seconds("walk", 0.55)
    sph = pose.spheres
    # rays aimed at the parts, from world space
    o_stage = sph[:, :3] + rng.normal(size=(len(sph), 3)) * 2.0
    d_stage = sph[:, :3] + rng.normal(size=(len(sph), 3)) * 0.05 - o_stage
    o_world = o_stage @ W[:3, :3].T + W[:3, 3]
    d_world = d_stage @ W[:3, :3].T
    hw = pose.raycast(o_world, d_world, world=W)
    # by hand: world inputs -> stage, query, results -> world
    hs = pose.raycast(o_world @ inv[:3, :3].T + inv[:3, 3], d_world @ inv[:3, :3].T)
    size = creature.size()
    assert hs.hit.sum() >= len(sph) // 2
    np.testing.assert_array_equal(hw.triangle, hs.triangle)
    np.testing.assert_array_equal(hw.part, hs.part)
    np.testing.assert_allclose(hw.barycentric, hs.barycentric, atol=1e-9)
    h = hs.hit
    np.testing.assert_allclose(hw.distance[h], hs.distance[h] * scale, rtol=1e-9)
    assert np.isinf(hw.distance[~h]).all()
    np.testing.assert_allclose(hw.point[h], hs.point[h] @ W[:3, :3].T + W[:3, 3], atol=1e-9 * scale * size + 1e-9 * 250)
    n = hs.normal[h] @ W[:3, :3].T / scale
    np.testing.assert_allclose(hw.normal[h], n, atol=1e-9)
    # the world hit point is the world ray at the world distance
    u = d_world / np.linalg.norm(d_world, axis=1)[:, None]
    np.testing.assert_allclose(hw.point[h], o_world[h] + hw.distance[h, None] * u[h], atol=1e-6 * scale * size)
    # max_distance is a world distance
    cut = np.median(hw.distance[h])
    hm = pose.raycast(o_world, d_world, max_distance=cut, world=W)
    assert (hm.hit == (h & (hw.distance <= cut))).all()
    # sphere contacts
    for p in (0, 5, 9):
        c_stage, r_stage = sph[p, :3] + [0.05, 0.1, 0.0], 0.6 * sph[p, 3]
        c_world = W[:3, :3] @ c_stage + W[:3, 3]
        cw = pose.sphere_contacts(c_world, r_stage * scale, world=W)
        cs = pose.sphere_contacts(inv[:3, :3] @ c_world + inv[:3, 3], r_stage * scale / scale)
        assert len(cs) > 0
        order_w, order_s = np.argsort(cw.triangle), np.argsort(cs.triangle)
        np.testing.assert_array_equal(cw.triangle[order_w], cs.triangle[order_s])
        np.testing.assert_allclose(cw.depth[order_w], cs.depth[order_s] * scale, rtol=1e-9, atol=1e-12 * scale)
        np.testing.assert_allclose(cw.point[order_w], cs.point[order_s] @ W[:3, :3].T + W[:3, 3],
                                   atol=1e-9 * scale * size + 1e-9 * 250)
        np.testing.assert_allclose(cw.normal[order_w], cs.normal[order_s] @ W[:3, :3].T / scale, atol=1e-9)
        np.testing.assert_allclose(cw.barycentric[order_w], cs.barycentric[order_s], atol=1e-12)
    # the part spheres placed in the world, and a Placement made once is reused as is
    place = Placement(W)
    ws = place.spheres(sph)
    np.testing.assert_allclose(ws[:, :3], sph[:, :3] @ W[:3, :3].T + W[:3, 3], atol=1e-9 * scale * size + 1e-9 * 250)
    np.testing.assert_allclose(ws[:, 3], sph[:, 3] * scale)
    assert Placement.of(place) is place
    np.testing.assert_array_equal(pose.raycast(o_world, d_world, world=place).distance, hw.distance)
    # tracked surface points and a contact patch's frame, in world space
    from colossus.runtime import SurfacePoints
    tri, bc = hs.triangle[h], hs.barycentric[h]
    ts = pose.track(tri, bc)
    np.testing.assert_allclose(pose.track(tri, bc, world=W), ts @ W[:3, :3].T + W[:3, 3],
                               atol=1e-9 * scale * size + 1e-9 * 250)
    np.testing.assert_allclose(pose.track(tri, bc, world=W), hw.point[h], atol=1e-6 * scale * size)
    sp = SurfacePoints(tri, bc)
    fs, fw = pose.surface_frame(sp).copy(), pose.surface_frame(sp, world=place)
    np.testing.assert_allclose(fw[:3], W[:3, :3] @ fs[:3] + W[:3, 3], atol=1e-9 * scale * size + 1e-9 * 250)
    np.testing.assert_allclose(fw[3:], W[:3, :3] @ fs[3:] / scale, atol=1e-9)
    assert abs(np.linalg.norm(fw[3:]) - 1.0) < 1e-9


@pytest.mark.parametrize("bad, match", [
    (np.diag([1.0, 2.0, 1.0, 1.0]), "non-uniform scale"),
    (np.diag([-1.0, 1.0, 1.0, 1.0]), "mirror"),
    (np.array([[1, 0.3, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]), "shear"),
    (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [5, 0, 0, 1.0]]), "row-vector"),
    (np.zeros((4, 4)), "affine"),
    (np.eye(3), "4, 4"),
    (np.full((4, 4), np.nan), "finite"),
])
def test_world_transform_validation(limb, bad, match):
    """What ``world=`` supports is checked: a similarity only, column-vector, with one clear line."""
    pose = limb.pose("bend", 3)
    with pytest.raises(ValueError, match=match):
        pose.raycast([0, 0, 5], [0, 0, -1], world=bad)
    with pytest.raises(ValueError, match=match):
        pose.sphere_contacts([0, 0, 0], 1.0, world=bad)


def test_readme_runtime_example_runs(imported):
    """The README's runtime snippet runs as written (on the imported creature): seconds into a
    clip, a world transform, and its world-space ray hits the creature's back where the ray says."""
    from paths import ROOT

    section = (ROOT / "README.md").read_text().split("## Runtime: using a collider in game code")[1]
    code = section.split("```python\n")[1].split("```")[0]
    code = code.replace('"out/creature.usda"', repr(str(imported("creature", "glb")[1])))
    ns = {}
    exec(compile(code, "README.md", "exec"), ns)
    hits, cs, world = ns["hits"], ns["cs"], ns["world"]
    pose = ns["col"].pose("walk", 12.5)  # the pose the snippet queries (it goes on to other poses)
    assert hits.hit.all() and len(cs) > 0
    # the hit is the world ray's, and in stage space it is a point of the posed creature's surface
    np.testing.assert_allclose(hits.point[0], [11.5, 10 - hits.distance[0], -8], atol=1e-9)
    inv = np.linalg.inv(world)
    stage_point = inv[:3, :3] @ hits.point[0] + inv[:3, 3]
    np.testing.assert_allclose(stage_point, pose.track(hits.triangle[:1], hits.barycentric[:1])[0], atol=1e-6)
    assert np.abs(cs.depth).max() <= 0.3 + 1e-9


@pytest.mark.parametrize("name", ["odd", "odd_skel"])
def test_guide_spheres_bake_to_pose_spheres_under_prim_transforms(name, odd_path, odd_skel_path):
    """The independent fixture's guide spheres, with a transformed (x1.5) SkelRoot and a
    geomBindTransform on the mesh, or a transformed (x0.8) Skeleton prim: UsdSkel.BakeSkinning of
    each clip variant puts them on the runtime's ``pose.spheres`` (and the mesh on ``pose.points``)
    within 1e-6 x size on every frame."""
    from usdskel_bake import bake_every_variant

    b = bake_every_variant(odd_path if name == "odd" else odd_skel_path)
    assert sorted(b["variants"]) == ["bend", "twist"] and b["guides"] == 3
    assert b["spheres"] <= 1e-6 * b["size"] and b["mesh"] <= 1e-6 * b["size"], (b["spheres"], b["mesh"], b["size"])
