"""Small but real contract-conforming collider assets, authored directly with pxr.

``write_test_asset(path, **options)`` writes one; ``build_test_stage(**options)`` returns it as an
in-memory stage; ``open_copy(path)`` opens an in-memory copy of any asset to break with pxr.

The asset: a closed, capped tube along Y (``rings x segments + 2`` vertices, default 402),
skinned smoothly to a 3-joint chain ``root``, ``root/mid``, ``root/mid/tip`` (bones 1 unit
long), ``elementSize`` 4, two clips: ``bend`` (24 frames, time codes 0..23: mid and tip bend
about Z) and ``twist`` (12 frames, time codes 100..111: the root twists about Y and slides in
X).  Parts: one per joint, each triangle to the joint with the largest summed weight.  Spheres:
centre = middle of the joint-space bounding box of the part's vertices over the bind pose and
all frames, radius = farthest such vertex x (1 + pad) + 1e-3; each part's guide sphere (a
``UsdGeom.Sphere`` under ``PartSpheres``) and the ``clip`` variant set binding each clip, as the
contract says.  Everything here is computed in plain numpy, independently of ``validators``.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np
from scipy.spatial.transform import Rotation
from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdSkel, Vt

JOINTS = ["root", "root/mid", "root/mid/tip"]
PARENTS = np.array([-1, 0, 1])


# ------------------------------------------------------------------------- small helpers
def trs(t, q, s):
    """Translation (..., 3), (x, y, z, w) quaternion (..., 4), scale (..., 3) -> (..., 4, 4) T R S."""
    t = np.asarray(t, dtype=np.float64)
    m = np.zeros(t.shape[:-1] + (4, 4))
    q = np.asarray(q, dtype=np.float64)
    rot = Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(q.shape[:-1] + (3, 3))
    m[..., :3, :3] = rot * np.asarray(s, dtype=np.float64)[..., None, :]
    m[..., :3, 3] = t
    m[..., 3, 3] = 1
    return m


def axis_quat(axis, angle):
    """(..., 4) (x, y, z, w) quaternions of rotations by ``angle`` (...) about unit ``axis``."""
    angle = np.asarray(angle, dtype=np.float64)
    rv = angle.reshape(-1, 1) * np.asarray(axis, dtype=np.float64)
    return Rotation.from_rotvec(rv).as_quat().reshape(angle.shape + (4,))


def compose(local, parents=PARENTS):
    """(f, b, 4, 4) local -> skeleton space (parents listed first)."""
    out = np.empty_like(local)
    for j, p in enumerate(parents):
        out[:, j] = local[:, j] if p < 0 else out[:, p] @ local[:, j]
    return out


def naive_skin(points, jidx, jw, skel, inv_bind, geom_bind=np.eye(4), world=np.eye(4)):
    """Readable numpy linear-blend skinning: (f, n, 3) float64 stage-space points."""
    p = np.c_[np.asarray(points, np.float64), np.ones(len(points))] @ geom_bind.T
    out = np.zeros((len(skel), len(points), 3))
    for f in range(len(skel)):
        m = world @ skel[f] @ inv_bind
        for k in range(jidx.shape[1]):
            out[f] += jw[:, k, None].astype(np.float64) * np.einsum("nij,nj->ni", m[jidx[:, k]][:, :3], p)
    return out


def _m4(m):
    """column-vector 4x4 -> Gf.Matrix4d (row-vector)."""
    return Gf.Matrix4d(np.asarray(m, dtype=np.float64).T.tolist())


# ------------------------------------------------------------------------------ geometry
def tube(rings=20, segments=20, length=3.0, radius=0.3):
    """Closed capped tube along +Y: (points (n, 3) float32, triangles (m, 3) int32), outward CCW."""
    ys = np.linspace(0.0, length, rings)
    th = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(th), np.zeros_like(th), radius * np.sin(th)], -1)
    pts = (ring[None] + ys[:, None, None] * np.array([0, 1, 0])).reshape(-1, 3)
    bottom, top = len(pts), len(pts) + 1
    pts = np.vstack([pts, [[0, 0, 0], [0, length, 0]]])
    tris = []
    for i in range(rings - 1):
        for j in range(segments):
            a, b = i * segments + j, i * segments + (j + 1) % segments
            c, d = a + segments, b + segments
            tris += [[a, c, b], [b, c, d]]
    for j in range(segments):
        a, b = j, (j + 1) % segments
        tris.append([bottom, a, b])
        top_a, top_b = (rings - 1) * segments + a, (rings - 1) * segments + b
        tris.append([top, top_b, top_a])
    tris = np.array(tris, dtype=np.int32)
    v = pts[tris]
    vol = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6
    if vol < 0:
        tris = tris[:, ::-1].copy()
    return pts.astype(np.float32), tris


def smooth_weights(y, k=4, joints=3):
    """(n, k) indices and weights, hat functions around bone midpoints, strongest first."""
    centers = np.arange(joints) + 0.5
    w = np.maximum(0.0, 1.0 - np.abs(y[:, None] - centers[None]))
    w[y <= 0.5, 0] = np.maximum(w[y <= 0.5, 0], 1.0)
    w[y >= joints - 0.5, joints - 1] = np.maximum(w[y >= joints - 0.5, joints - 1], 1.0)
    w /= w.sum(1, keepdims=True)
    order = np.argsort(-w, axis=1, kind="stable")
    ws = np.take_along_axis(w, order, 1)
    idx = order.astype(np.int32)
    ji = np.zeros((len(y), k), np.int32)
    jw = np.zeros((len(y), k), np.float32)
    m = min(k, joints)
    ji[:, :m], jw[:, :m] = idx[:, :m], ws[:, :m]
    jw /= jw.sum(1, keepdims=True)
    ji[jw == 0] = 0
    return ji, jw


def clip_locals(name, frames):
    """(f, 3) times and (t, q, s) per joint: arrays (f, 3, 3), (f, 3, 4), (f, 3, 3)."""
    f = np.arange(frames, dtype=np.float64)
    t = np.zeros((frames, 3, 3))
    t[:, 1:, 1] = 1.0
    s = np.ones((frames, 3, 3))
    q = np.zeros((frames, 3, 4))
    q[..., 3] = 1
    if name == "bend":
        a = 0.8 * np.sin(np.pi * f / max(frames - 1, 1))
        q[:, 1] = axis_quat([0, 0, 1], a)
        q[:, 2] = axis_quat([0, 0, 1], a)
        times = f
    elif name == "twist":
        b = 1.2 * f / max(frames - 1, 1)
        q[:, 0] = axis_quat([0, 1, 0], b)
        q[:, 1] = axis_quat([1, 0, 0], 0.3 * b)
        t[:, 0, 0] = 0.1 * f / max(frames - 1, 1)
        times = f + 100.0
    elif name == "swing":  # mid and tip swing from +0.9 to -0.9 rad in one frame: straight in between
        a = 0.9 * (1 - 2 * (f % 2))
        q[:, 1] = axis_quat([0, 0, 1], a)
        q[:, 2] = axis_quat([0, 0, 1], a)
        times = f
    else:
        a = 0.5 * np.sin(2 * np.pi * f / max(frames, 1))
        q[:, 2] = axis_quat([1, 0, 0], a)
        times = f
    return times, t, q, s


# ------------------------------------------------------------------------------ authoring
def build_test_stage(*, name="Tube", rings=20, segments=20, max_influences=4,
                     clips=(("bend", 24), ("twist", 12)), pad=0.02, radius_scale=1.0,
                     geom_bind=None, up_axis="Y", time_codes_per_second=24.0, path=None) -> Usd.Stage:
    """Author the asset; in memory unless ``path`` is given (then also saved there).

    Options: ``rings``/``segments`` (tube resolution), ``max_influences`` (elementSize),
    ``clips`` ((name, frames) pairs; known names ``bend``, ``twist``, ``swing`` (+-0.9 rad on
    alternate frames), others wiggle the tip),
    ``pad`` (sphere padding fraction), ``radius_scale`` (multiplies every radius after padding:
    < 1 breaks containment, > 1.5 makes slack spheres), ``geom_bind`` (4x4 column-vector; the
    points are authored so that geom_bind @ p is the tube).
    """
    stage = Usd.Stage.CreateNew(path) if path else Usd.Stage.CreateInMemory()
    pts, tris = tube(rings, segments)
    gb = np.eye(4) if geom_bind is None else np.asarray(geom_bind, dtype=np.float64)
    mesh_pts = ((np.c_[pts.astype(np.float64), np.ones(len(pts))] @ np.linalg.inv(gb).T)[:, :3]).astype(np.float32)
    ji, jw = smooth_weights(pts[:, 1].astype(np.float64), max_influences)

    bind = np.repeat(np.eye(4)[None], 3, 0)
    bind[:, 1, 3] = np.arange(3)
    rest = np.repeat(np.eye(4)[None], 3, 0)
    rest[1:, 1, 3] = 1.0
    inv_bind = np.linalg.inv(bind)

    # -- clips, and joint-space vertex positions for the spheres
    clip_data = []
    poses = [bind[None]]
    for cname, frames in clips:
        times, t, q, s = clip_locals(cname, frames)
        clip_data.append((cname, times, t, q, s))
        poses.append(compose(trs(t, q, s)))
    skel_all = np.concatenate(poses)  # (F, 3, 4, 4) including bind
    skinned = naive_skin(mesh_pts, ji, jw, skel_all, inv_bind, gb)

    # -- parts: each triangle to the joint with the largest summed weight
    dense = np.zeros((len(pts), 3))
    np.add.at(dense, (np.repeat(np.arange(len(pts)), max_influences), ji.ravel()), jw.ravel())
    owner = dense[tris].sum(1).argmax(1)
    faces = np.argsort(owner, kind="stable")
    offsets = np.searchsorted(owner[faces], np.arange(4))
    centers = np.zeros((3, 3))
    radii = np.zeros(3)
    for p in range(3):
        vs = np.unique(tris[owner == p])
        inv = np.linalg.inv(skel_all[:, p])  # (F, 4, 4)
        qj = np.einsum("fij,fvj->fvi", inv[:, :3, :3], skinned[:, vs]) + inv[:, None, :3, 3]
        qj = qj.reshape(-1, 3)
        c = (qj.min(0) + qj.max(0)) / 2
        centers[p] = c
        radii[p] = (np.linalg.norm(qj - c, axis=1).max() * (1 + pad) + 1e-3) * radius_scale

    # -- stage
    first = clips[0][1] if clips else 0
    all_times = np.concatenate([d[1] for d in clip_data]) if clip_data else np.zeros(1)
    stage.SetStartTimeCode(float(all_times.min()))
    stage.SetEndTimeCode(float(all_times.max()))
    stage.SetTimeCodesPerSecond(time_codes_per_second)
    stage.SetFramesPerSecond(time_codes_per_second)
    UsdGeom.SetStageUpAxis(stage, up_axis)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdSkel.Root.Define(stage, f"/{name}")
    stage.SetDefaultPrim(root.GetPrim())

    skel = UsdSkel.Skeleton.Define(stage, f"/{name}/Skeleton")
    skel.CreateJointsAttr(JOINTS)
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray([_m4(m) for m in bind]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray([_m4(m) for m in rest]))
    UsdSkel.BindingAPI.Apply(skel.GetPrim())
    if clips:  # the contract's variant set "clip": each variant binds one clip, the first the default
        vset = root.GetPrim().GetVariantSets().AddVariantSet("clip")
        for cname, _ in clips:
            vset.AddVariant(cname)
            vset.SetVariantSelection(cname)
            with vset.GetVariantEditContext():
                UsdSkel.BindingAPI(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([Sdf.Path(f"/{name}/{cname}")])
        vset.SetVariantSelection(clips[0][0])

    mesh = UsdGeom.Mesh.Define(stage, f"/{name}/Collider")
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(mesh_pts))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(tris)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(tris.ravel().astype(np.int32)))
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    ext = skinned.reshape(-1, 3)
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*ext.min(0)), Gf.Vec3f(*ext.max(0))]))
    mb = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    mb.CreateSkeletonRel().SetTargets([skel.GetPath()])
    mb.CreateJointIndicesPrimvar(False, max_influences).Set(Vt.IntArray.FromNumpy(ji.ravel()))
    mb.CreateJointWeightsPrimvar(False, max_influences).Set(Vt.FloatArray.FromNumpy(jw.ravel()))
    if geom_bind is not None:
        mb.CreateGeomBindTransformAttr(_m4(gb))
    UsdPhysics.CollisionAPI.Apply(mesh.GetPrim())
    UsdPhysics.MeshCollisionAPI.Apply(mesh.GetPrim()).CreateApproximationAttr("none")
    prim = mesh.GetPrim()
    prim.CreateAttribute("colossus:parts:joints", Sdf.ValueTypeNames.TokenArray).Set(JOINTS)
    prim.CreateAttribute("colossus:parts:centers", Sdf.ValueTypeNames.Float3Array).Set(
        Vt.Vec3fArray.FromNumpy(centers.astype(np.float32)))
    prim.CreateAttribute("colossus:parts:radii", Sdf.ValueTypeNames.FloatArray).Set(
        Vt.FloatArray.FromNumpy(radii.astype(np.float32)))
    prim.CreateAttribute("colossus:parts:faceOffsets", Sdf.ValueTypeNames.IntArray).Set(
        Vt.IntArray.FromNumpy(offsets.astype(np.int32)))
    prim.CreateAttribute("colossus:parts:faces", Sdf.ValueTypeNames.IntArray).Set(
        Vt.IntArray.FromNumpy(faces.astype(np.int32)))
    prim.SetCustomDataByKey("colossus", {
        "source": "tube.blend", "sourceSha256": hashlib.sha256(b"tube").hexdigest(),
        "importer": "usd_fixture", "settings": {"max_influences": max_influences}})
    # the contract's guide spheres: one per part, guide purpose, rigidly bound to its joint; the
    # origin of the sphere's space is the centre: geomBind = bind_j @ T(centre)
    UsdGeom.Scope.Define(stage, f"/{name}/PartSpheres")
    for p, jname in enumerate(JOINTS):
        c32 = centers[p].astype(np.float32).astype(np.float64)
        r32 = float(np.float32(radii[p]))
        gbm = bind[p] @ np.block([[np.eye(3), c32[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])
        sph = UsdGeom.Sphere.Define(stage, f"/{name}/PartSpheres/part{p}")
        sph.CreateRadiusAttr(r32)
        sph.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-r32, -r32, -r32), Gf.Vec3f(r32, r32, r32)]))
        sph.CreatePurposeAttr(UsdGeom.Tokens.guide)
        sph.AddTransformOp().Set(_m4(gbm))
        sbind = UsdSkel.BindingAPI.Apply(sph.GetPrim())
        sbind.CreateSkeletonRel().SetTargets([skel.GetPath()])
        sbind.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([p]))
        sbind.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
        sbind.CreateGeomBindTransformAttr(_m4(gbm))
        sph.GetPrim().SetCustomDataByKey("colossus:part", p)

    for cname, times, t, q, s in clip_data:
        anim = UsdSkel.Animation.Define(stage, f"/{name}/{cname}")
        anim.CreateJointsAttr(JOINTS)
        ta, ra, sa = anim.CreateTranslationsAttr(), anim.CreateRotationsAttr(), anim.CreateScalesAttr()
        for i, tc in enumerate(times):
            ta.Set(Vt.Vec3fArray.FromNumpy(t[i].astype(np.float32)), tc)
            ra.Set(Vt.QuatfArray.FromNumpy(np.ascontiguousarray(q[i], dtype=np.float32)), tc)
            sa.Set(Vt.Vec3hArray([Gf.Vec3h(*map(float, v)) for v in s[i]]), tc)
    if path:
        stage.GetRootLayer().Save()
    return stage


def write_test_asset(path, **options) -> str:
    """Write the test asset to ``path`` (``.usda``, ``.usdc`` or ``.usd``); returns ``str(path)``."""
    path = str(path)
    stage = build_test_stage(**options)
    stage.GetRootLayer().Export(path)
    return path


def open_copy(path_or_stage) -> Usd.Stage:
    """An in-memory copy of an asset (file path or stage), safe to edit in a test."""
    if isinstance(path_or_stage, Usd.Stage):
        src = path_or_stage.GetRootLayer()
    else:
        src = Sdf.Layer.FindOrOpen(str(path_or_stage))
    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().TransferContent(src)
    return stage


def clip_skel(name, frames):
    """(times, (f, 3, 4, 4) skeleton-space transforms) of a fixture clip, from numpy alone."""
    times, t, q, s = clip_locals(name, frames)
    return times, compose(trs(t, q, s))
