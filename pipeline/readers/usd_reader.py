"""Reader for USD (``.usd``, ``.usda``, ``.usdc``, ``.usdz``) skinned meshes, through usd-core's UsdSkel.

* Skeleton space is stage (world) space: the Skeleton prim's local-to-world transform is folded
  into the root joints (per frame, so an animated SkelRoot is kept) and into the bind and
  geom-bind transforms.
* Every ``SkelAnimation`` prim in the file bound to (or written for) the chosen skeleton is one
  clip, sampled at its own joint-transform time samples.  Blender's USD export writes only the
  active action, so its files have one clip.
* Units and axes come from the stage's ``metersPerUnit`` and ``upAxis``.
* Rest transforms are the bind pose made joint-local (the file's ``restTransforms`` are not
  used): joints a clip does not animate hold their bind pose.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import InputError
from ..model import Clip, SkinnedMesh
from .common import AllocationBudget, check_finite, check_input_file, clip_name


def _m44(values) -> np.ndarray:
    """Gf.Matrix4d or VtMatrix4dArray (row-vector) -> column-vector float64 (..., 4, 4)."""
    a = np.array(values, dtype=np.float64)
    return np.swapaxes(a.reshape(-1, 4, 4), -1, -2) if a.ndim != 2 else a.T


def _open(path):
    from pxr import Tf, Usd
    try:
        stage = Usd.Stage.Open(path, Usd.Stage.LoadAll)
    except Tf.ErrorException as exc:
        msg = " ".join(str(exc).split())
        if len(msg) > 200:
            msg = msg[:200] + "..."
        raise InputError(path, f"not a readable USD file: {msg}") from None
    if stage is None:
        raise InputError(path, "not a readable USD file")
    return stage


def _triangulate(counts: np.ndarray, indices: np.ndarray, path, name) -> np.ndarray:
    """Fan-triangulate polygons given face vertex counts and indices -> (m, 3)."""
    if len(counts) == 0:
        return np.zeros((0, 3), dtype=np.int64)
    if counts.min() < 3:
        raise InputError(path, f"mesh {name}: a face has fewer than 3 vertices")
    if int(counts.sum()) != len(indices):
        raise InputError(path, f"mesh {name}: faceVertexCounts sum to {int(counts.sum())} but there are {len(indices)} faceVertexIndices")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    ntri = counts - 2
    face = np.repeat(np.arange(len(counts)), ntri)
    k = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    s = starts[face]
    return np.stack([indices[s], indices[s + k + 1], indices[s + k + 2]], axis=1)


def read_usd(path, meshes=None, fps=None) -> SkinnedMesh:
    """Read a UsdSkel skinned mesh and every SkelAnimation of its skeleton.

    Parameters
    ----------
    path : str or PathLike
    meshes : list of str, optional
        Names (prim names or paths) of the meshes to take; default every mesh bound to the
        skeleton, merged.
    fps : float, optional
        Override of the stage's ``timeCodesPerSecond`` (time codes are kept as they are).
    """
    from pxr import Usd, UsdGeom, UsdSkel

    path = os.fspath(path)
    size = check_input_file(path)
    budget = AllocationBudget(path, size)
    stage = _open(path)
    up = UsdGeom.GetStageUpAxis(stage)
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    tcps = float(stage.GetTimeCodesPerSecond())
    early = Usd.TimeCode.EarliestTime()

    cache = UsdSkel.Cache()
    bindings = []
    for prim in stage.Traverse():
        if prim.IsA(UsdSkel.Root):
            root = UsdSkel.Root(prim)
            cache.Populate(root, Usd.PrimDefaultPredicate)
            bindings.extend(cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate))
    targets = []
    for b in bindings:
        for q in b.GetSkinningTargets():
            p = q.GetPrim()
            if not p.IsA(UsdGeom.Mesh) or not q.HasJointInfluences():
                continue
            if meshes and p.GetName() not in meshes and str(p.GetPath()) not in meshes:
                continue
            targets.append((b.GetSkeleton(), q))
    if meshes:
        found = {t[1].GetPrim().GetName() for t in targets} | {str(t[1].GetPrim().GetPath()) for t in targets}
        missing = [m for m in meshes if m not in found]
        if missing:
            avail = sorted(str(p.GetPath()) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
            raise InputError(path, f"no skinned mesh named {missing[0]!r} (meshes: {', '.join(avail) or 'none'})")
    if not targets:
        if not any(p.IsA(UsdGeom.Mesh) for p in stage.Traverse()):
            raise InputError(path, "the stage has no mesh")
        raise InputError(path, "no skinned mesh: no Mesh is bound to a Skeleton with joint influences inside a SkelRoot (a mesh with no skin cannot be animated)")
    skels = {str(s.GetPrim().GetPath()) for s, _ in targets}
    if len(skels) > 1:
        raise InputError(path, f"meshes are bound to {len(skels)} different skeletons ({', '.join(sorted(skels))}); choose meshes of one with --mesh")
    skel = targets[0][0]
    skel_query = cache.GetSkelQuery(skel)
    if not skel_query:
        raise InputError(path, f"skeleton {skel.GetPrim().GetPath()} is invalid (check its joints)")
    joints = [str(j) for j in skel_query.GetJointOrder()]
    if not joints:
        raise InputError(path, f"skeleton {skel.GetPrim().GetPath()} has no joints")
    topo = skel_query.GetTopology()
    ok, why = topo.Validate()
    if not ok:
        raise InputError(path, f"skeleton joints are not a valid hierarchy: {why}")
    parents = np.array(topo.GetParentIndices(), dtype=np.int32)
    nj = len(joints)
    bind_attr = skel.GetBindTransformsAttr().Get()
    if bind_attr is None or len(bind_attr) != nj:
        raise InputError(path, f"skeleton has {0 if bind_attr is None else len(bind_attr)} bindTransforms for {nj} joints")
    bind = _m44(bind_attr)
    check_finite(path, "bind transforms", bind.reshape(nj, -1))
    # The rest pose is the bind pose expressed joint-local, as for every other format (Blender's
    # USD export writes restTransforms that do not compose to its bindTransforms).
    rest_local = np.empty_like(bind)
    for k, p in enumerate(parents):
        rest_local[k] = bind[k] if p < 0 else np.linalg.solve(bind[p], bind[k])
    xf_cache = UsdGeom.XformCache(early)
    skel_w0 = _m44(xf_cache.GetLocalToWorldTransform(skel.GetPrim()))

    # ---- geometry ---------------------------------------------------------------------------
    pos_list, tri_list, vj, jj, ww = [], [], [], [], []
    geom_bind = None
    base = 0
    names = []
    for _, q in targets:
        prim = q.GetPrim()
        mesh = UsdGeom.Mesh(prim)
        name = str(prim.GetPath())
        names.append(prim.GetName())
        pts = mesh.GetPointsAttr().Get(early)
        if pts is None or len(pts) == 0:
            raise InputError(path, f"mesh {name} has no points")
        nv = len(pts)
        budget.claim(nv * 200, f"mesh {name} ({nv} points)")
        p = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
        check_finite(path, f"mesh {name} points", p)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
        idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
        budget.claim(len(idx) * 40, f"mesh {name} faces")
        tri = _triangulate(counts, idx, path, name)
        if len(tri) and (tri.max() >= nv or tri.min() < 0):
            raise InputError(path, f"mesh {name}: face vertex index out of range for {nv} points")
        if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
            tri = tri[:, ::-1]
        g = skel_w0 @ _m44(q.GetGeomBindTransform(early))
        if geom_bind is None:
            geom_bind = g
        rel = np.linalg.solve(geom_bind, g)
        if not np.allclose(rel, np.eye(4), atol=1e-9):
            p = p @ rel[:3, :3].T + rel[:3, 3]
        inf = q.ComputeJointInfluences(early)
        if not inf:
            raise InputError(path, f"mesh {name}: joint influences cannot be read")
        ji_flat, jw_flat = inf
        k = q.GetNumInfluencesPerComponent()
        ji = np.asarray(ji_flat, dtype=np.int64)
        jw = np.asarray(jw_flat, dtype=np.float64)
        if q.GetInterpolation() == UsdGeom.Tokens.constant:
            ji = np.tile(ji, nv)
            jw = np.tile(jw, nv)
        if len(ji) != nv * k or len(jw) != nv * k:
            raise InputError(path, f"mesh {name}: {len(ji)} joint indices / {len(jw)} weights for {nv} points x {k} influences")
        mapper = q.GetJointMapper()
        if mapper and not mapper.IsIdentity():
            local_joints = [str(j) for j in q.GetJointOrder()]
            lut = np.array([joints.index(j) if j in joints else -1 for j in local_joints], dtype=np.int64)
            if len(ji) and (ji.max() >= len(lut) or ji.min() < 0):
                raise InputError(path, f"mesh {name}: joint index out of range for its {len(lut)} skel:joints")
            ji = lut[ji]
        if len(ji) and (ji.max() >= nj or ji.min() < 0):
            raise InputError(path, f"mesh {name}: joint index {int(ji.max()) if ji.max() >= nj else int(ji.min())} out of range for {nj} joints")
        check_finite(path, f"mesh {name} joint weights", jw[:, None])
        pos_list.append(p)
        tri_list.append(tri + base)
        vj.append(np.repeat(np.arange(nv) + base, k))
        jj.append(ji)
        ww.append(jw)
        base += nv
    from .common import pack_influences
    ji, jw = pack_influences(base, np.concatenate(vj), np.concatenate(jj), np.concatenate(ww))

    # ---- clips ------------------------------------------------------------------------------
    anim_prims = []
    src = skel_query.GetAnimQuery()
    if src:
        anim_prims.append(src.GetPrim())
    for prim in stage.Traverse():
        if prim.IsA(UsdSkel.Animation) and all(prim != a for a in anim_prims):
            anim_prims.append(prim)
    clips, taken = [], set()
    for prim in anim_prims:
        aq = cache.GetAnimQuery(UsdSkel.Animation(prim))
        if not aq:
            continue
        times = sorted(aq.GetJointTransformTimeSamples())
        if not times:
            continue  # a static pose, not a clip
        anim_joints = [str(j) for j in aq.GetJointOrder()]
        unknown = [j for j in anim_joints if j not in joints]
        if len(unknown) == len(anim_joints):
            continue  # animation of another skeleton
        budget.claim(len(times) * nj * 16 * 8 * 3, f"animation {prim.GetName()!r} ({len(times)} frames)")
        lut = np.array([joints.index(j) if j in joints else -1 for j in anim_joints])
        local = np.broadcast_to(rest_local, (len(times), nj, 4, 4)).copy()
        for f, t in enumerate(times):
            xf = aq.ComputeJointLocalTransforms(Usd.TimeCode(t))
            if xf is None or len(xf) != len(anim_joints):
                raise InputError(path, f"animation {prim.GetPath()}: cannot compute joint transforms at time {t}")
            m = _m44(xf)
            local[f, lut[lut >= 0]] = m[lut >= 0]
            w = _m44(UsdGeom.XformCache(Usd.TimeCode(t)).GetLocalToWorldTransform(skel.GetPrim()))
            local[f, parents < 0] = w @ local[f, parents < 0]
        check_finite(path, f"animation {prim.GetName()!r} joint transforms", local.reshape(len(times), -1))
        clips.append(Clip(clip_name(prim.GetName(), taken), np.array(times, dtype=np.float64), local))

    jnames = [j.split("/")[-1] for j in joints]
    rest_world = rest_local.copy()  # skeleton space is world space: roots carry the skeleton's transform
    rest_world[parents < 0] = skel_w0 @ rest_local[parents < 0]
    return SkinnedMesh(
        positions=np.concatenate(pos_list).astype(np.float32), triangles=np.concatenate(tri_list),
        joint_indices=ji, joint_weights=jw, joint_names=jnames, parents=parents,
        bind_transforms=skel_w0 @ bind, rest_transforms=rest_world, geom_bind=geom_bind,
        clips=tuple(clips), up_axis=str(up), meters_per_unit=mpu,
        time_codes_per_second=float(fps) if fps else tcps,
        source={"file": os.path.basename(path), "format": os.path.splitext(path)[1].lstrip(".").lower(),
                "reader": "usd", "meshes": names,
                "frame": f"USD stage: upAxis={up}, metersPerUnit={mpu:g}"},
    )
