"""Reading a collider asset with plain usd-core into numpy arrays (no per-element Python loops).

The layout is the contract's (``../shared/CONTRACT.md``): one ``SkelRoot`` (the default prim)
holding a ``Skeleton``, a triangle ``Mesh`` bound to it with UsdSkel influences and the
``colossus:parts:*`` attributes, and one ``SkelAnimation`` per clip (file order).  What the asset
holds for other USD tools is not read: the part spheres come from ``colossus:parts:*`` (the guide
``UsdGeom.Sphere`` prims under ``PartSpheres`` are not meshes, so never the collider), and every
clip is listed as a child of the SkelRoot whatever the ``clip`` variant selection binds.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from . import schema
from .schema import Clip
from .errors import ColliderError
from .kernels.bounds import BoundData, bound_data

PARTS = schema.PARTS_PREFIX


@dataclass
class ColliderData:
    """Everything the runtime needs, as arrays with documented shapes.

    rest_points (V, 3) float32, triangles (F, 3) int64, joint_indices (V, k) int32 (skeleton
    order), joint_weights (V, k) float32, bind / inv_bind / rest_local (J, 4, 4) float64,
    parents (J,) int64, topo_order (J,) int64 (parents first), geom_bind (4, 4),
    part_joint (P,) int64, part_centers (P, 3) float64, part_radii (P,) float64,
    face_offsets (P+1,) / faces: CSR faces of each part, vert_offsets (P+1,) / verts: CSR
    vertices of each part, face_part (F,) first part holding each face; each part's faces are
    ordered along a Morton curve and cut into chunks: chunk_offsets (C+1,) into ``faces``,
    part_chunks (P+1,) into the chunks, chunk_vert_offsets (C+1,) / chunk_verts: CSR of each
    chunk's distinct vertices (what its culling sphere is fitted to). ``bounds``: the per-part data of the sound bounds
    (:class:`runtime.kernels.bounds.BoundData`), for culling and certifying spheres without
    skinning (linear blend only: a dual-quaternion mesh, ``skinning_method``, is skinned).  Matrices are column-vector (``p' = M @ p``, :mod:`runtime.schema`), converted from
    USD's row-vector layout once, here.
    """

    path: str
    root_path: str
    skeleton_path: str
    mesh_path: str
    up_axis: str
    meters_per_unit: float
    time_codes_per_second: float
    joints: list
    parents: np.ndarray
    topo_order: np.ndarray
    bind: np.ndarray
    inv_bind: np.ndarray
    rest_local: np.ndarray
    geom_bind: np.ndarray
    rest_points: np.ndarray
    triangles: np.ndarray
    joint_indices: np.ndarray
    joint_weights: np.ndarray
    part_joint: np.ndarray
    part_centers: np.ndarray
    part_radii: np.ndarray
    face_offsets: np.ndarray
    faces: np.ndarray
    vert_offsets: np.ndarray
    verts: np.ndarray
    face_part: np.ndarray
    chunk_offsets: np.ndarray
    part_chunks: np.ndarray
    chunk_vert_offsets: np.ndarray
    chunk_verts: np.ndarray
    bounds: BoundData
    faces_shared: bool = False  # some face is in more than one part (--parts any)
    skinning_method: str = "classicLinear"  # or "dualQuaternion" (primvars:skel:skinningMethod)
    #: the mesh's UsdSkel blend shapes (:class:`runtime.kernels.skin.Shapes`, ``skel:blendShapes``
    #: order; empty when it binds none); each clip's ``tw`` / ``vw`` weights are in this order
    shapes: object = None
    clips: list = field(default_factory=list)
    static_local_to_world: np.ndarray | None = None
    stage: object = None  # kept open only when the skeleton's transform is animated


def _mats(value, what):
    a = schema.matrices_from_usd(value)
    if a is None or a.ndim != 3:
        raise ColliderError(f"{what} is missing or not an array of 4x4 matrices")
    return a


def _get(prim, name, what=None):
    attr = prim.GetAttribute(name)
    value = attr.Get() if attr and attr.HasAuthoredValue() else None
    if value is None:
        raise ColliderError(f"{prim.GetPath()} has no {what or name}")
    return value


def _find_prims(stage):
    from pxr import UsdSkel

    root = stage.GetDefaultPrim()
    if not root or not root.IsA(UsdSkel.Root):
        root = next((p for p in stage.Traverse() if p.IsA(UsdSkel.Root)), None)
    if root is None:
        raise ColliderError("no SkelRoot prim (the default prim should be one)")
    meshes = [p for p in root.GetChildren() if p.GetTypeName() == "Mesh"]
    meshes = meshes or [p for p in stage.Traverse() if p.GetTypeName() == "Mesh" and
                        str(p.GetPath()).startswith(str(root.GetPath()) + "/")]
    withparts = [m for m in meshes if m.GetAttribute(schema.PARTS_JOINTS)]
    if not withparts:
        raise ColliderError(f"no Mesh with {PARTS}* attributes under {root.GetPath()}")
    mesh = withparts[0]
    skel = None
    p = mesh
    while p and p.GetPath() != root.GetPath().GetParentPath() and skel is None:
        r = UsdSkel.BindingAPI(p).GetSkeletonRel()
        t = r.GetTargets() if r else []
        if t:
            skel = stage.GetPrimAtPath(t[0])
        p = p.GetParent()
    if skel is None or not skel.IsA(UsdSkel.Skeleton):
        skel = next((c for c in root.GetChildren() if c.IsA(UsdSkel.Skeleton)), None)
    if skel is None:
        raise ColliderError(f"no Skeleton bound to {mesh.GetPath()}")
    anims = [c for c in root.GetChildren() if c.IsA(UsdSkel.Animation)]
    return root, skel, mesh, anims


def _samples(attr, count, width, what):
    """(times (n,), values (n, count, width)) of an attribute; a default value is one sample."""
    times = list(attr.GetTimeSamples()) if attr else []
    if times:
        vals = [attr.Get(t) for t in times]
    else:
        v = attr.Get() if attr else None
        if v is None:
            raise ColliderError(f"{what} has no values")
        times, vals = [0.0], [v]
    try:
        arr = np.stack([np.asarray(v, dtype=np.float64) for v in vals])
    except ValueError:
        raise ColliderError(f"{what}: time samples have different lengths") from None
    if arr.shape[1:] != (count, width):
        raise ColliderError(f"{what}: expected {count} values of {width} per sample, got shape {arr.shape[1:]}")
    return np.asarray(times, dtype=np.float64), np.ascontiguousarray(arr)


def read_clip(prim, joint_index, shape_index=None) -> Clip:
    """One ``SkelAnimation`` prim as a :class:`runtime.schema.Clip` (raises :class:`ColliderError`).
    ``shape_index`` maps the mesh's blend-shape names to their order (``skel:blendShapes``): the
    animation's ``blendShapeWeights`` are read in that order (a shape it does not name is 0, one
    the mesh lacks is ignored: UsdSkel's mapper)."""
    from pxr import UsdSkel

    anim = UsdSkel.Animation(prim)
    where = str(prim.GetPath())
    ajoints = list(anim.GetJointsAttr().Get() or [])
    if not ajoints:
        raise ColliderError(f"clip {prim.GetName()!r} ({where}) has no joints")
    A = len(ajoints)
    tt, vt = _samples(anim.GetTranslationsAttr(), A, 3, f"{where}.translations")
    tr, vr = _samples(anim.GetRotationsAttr(), A, 4, f"{where}.rotations")
    ts, vs = _samples(anim.GetScalesAttr(), A, 3, f"{where}.scales")
    amap = np.array([joint_index.get(str(j), -1) for j in ajoints], dtype=np.int64)
    keep = amap >= 0  # animation joints the skeleton lacks are ignored (UsdSkel's AnimMapper)
    times = np.union1d(np.union1d(tt, tr), ts) if any(
        a.HasAuthoredValue() and a.GetNumTimeSamples() for a in
        (anim.GetTranslationsAttr(), anim.GetRotationsAttr(), anim.GetScalesAttr())) else np.zeros(0)
    aliases = []
    for value in (prim.GetCustomDataByKey(schema.CLIP_NAME_KEY),
                  (prim.GetCustomDataByKey(schema.CLIP_SOURCE_KEY) or {}).get("sourceName")):
        if isinstance(value, str) and value and value != prim.GetName() and value not in aliases:
            aliases.append(value)
    tw, vw = _shape_weights(anim, shape_index or {}, where)
    if len(tw):
        times = np.union1d(times, tw)
    return Clip(
        tw=tw, vw=vw,
        name=prim.GetName(), path=where,
        tt=tt, vt=np.ascontiguousarray(vt[:, keep]), tr=tr, vr=np.ascontiguousarray(vr[:, keep]),
        ts=ts, vs=np.ascontiguousarray(vs[:, keep]), anim_to_skel=amap[keep], times=times,
        source_names=tuple(aliases))


def _shape_weights(anim, shape_index, where):
    """``(times (nW,), weights (nW, S))`` of an animation's ``blendShapeWeights`` in the mesh's
    shape order (``shape_index``: name -> index)."""
    S = len(shape_index)
    names = list(anim.GetBlendShapesAttr().Get() or []) if anim.GetBlendShapesAttr() else []
    attr = anim.GetBlendShapeWeightsAttr()
    if not S or not names or not attr or not attr.HasAuthoredValue():
        return np.zeros(0), np.zeros((0, S))
    times = list(attr.GetTimeSamples())
    raw = [attr.Get(t) for t in times] if times else [attr.Get()]
    times = times or [0.0]  # a default value holds at every time: one sample
    if any(v is None or len(v) != len(names) for v in raw):
        raise ColliderError(f"{where}.blendShapeWeights: expected {len(names)} weights per sample (blendShapes)")
    times = np.asarray(times, dtype=np.float64)
    vals = np.array([np.asarray(v, dtype=np.float64) for v in raw]).reshape(len(times), len(names))
    if not np.isfinite(vals).all():
        raise ColliderError(f"{where}.blendShapeWeights: a weight is not finite")
    out = np.zeros((len(times), S))
    for a, n in enumerate(names):
        s = shape_index.get(str(n))
        if s is not None:
            out[:, s] = vals[:, a]
    return times, out


def read_shapes(mesh, point_count: int):
    """The mesh prim's UsdSkel blend shapes (``skel:blendShapes`` names, ``skel:blendShapeTargets``
    prims: ``offsets``, ``pointIndices``, ``inbetweens:*``) as :class:`runtime.kernels.skin.Shapes`
    (raises :class:`ColliderError` on a shape UsdSkel would not apply as written: counts that
    differ, an index out of range or repeated, a value that is not finite, an in-between at
    weight 0 or 1 or two at one weight)."""
    from pxr import UsdSkel

    from .kernels.skin import Shapes

    b = UsdSkel.BindingAPI(mesh)
    names = [str(n) for n in (b.GetBlendShapesAttr().Get() or [])] if b.GetBlendShapesAttr() else []
    targets = b.GetBlendShapeTargetsRel().GetTargets() if b.GetBlendShapeTargetsRel() else []
    where = mesh.GetPath()
    if not names and not targets:
        return Shapes.empty(point_count)
    if len(names) != len(targets):
        raise ColliderError(f"{where}: skel:blendShapes names {len(names)} shapes but skel:blendShapeTargets "
                            f"{len(targets)}")
    if len(set(names)) != len(names):
        raise ColliderError(f"{where}: skel:blendShapes repeats a name")
    idx_all, knots, offs = [], [], []
    stage = mesh.GetStage()
    for name, path in zip(names, targets):
        prim = stage.GetPrimAtPath(path)
        bs = UsdSkel.BlendShape(prim)
        if not prim or not prim.IsA(UsdSkel.BlendShape):
            raise ColliderError(f"{where}: blend shape target {path} is not a BlendShape prim")
        off = np.asarray(bs.GetOffsetsAttr().Get() or [], dtype=np.float64).reshape(-1, 3)
        pi = bs.GetPointIndicesAttr().Get() if bs.GetPointIndicesAttr().HasAuthoredValue() else None
        idx = np.arange(point_count) if pi is None else np.asarray(pi, dtype=np.int64)
        if len(off) != len(idx):
            raise ColliderError(f"{path}: {len(off)} offsets for {len(idx)} points")
        if idx.size and (idx.min() < 0 or idx.max() >= point_count or len(np.unique(idx)) != len(idx)):
            raise ColliderError(f"{path}.pointIndices: expected distinct indices in 0..{point_count - 1}")
        pts = [(0.0, np.zeros_like(off)), (1.0, off)]
        for ib in bs.GetInbetweens():
            w = ib.GetWeight()
            o = np.asarray(ib.GetOffsets() or [], dtype=np.float64).reshape(-1, 3)
            if w is None or len(o) != len(idx):
                raise ColliderError(f"{path}: in-between {ib.GetAttr().GetName()} has no weight or "
                                    f"{len(o)} offsets for {len(idx)} points")
            pts.append((float(w), o))
        pts.sort(key=lambda t: t[0])
        k = np.array([w for w, _ in pts])
        o = np.stack([x for _, x in pts])
        if not np.isfinite(k).all() or (np.diff(k) <= 0).any():
            raise ColliderError(f"{path}: in-between weights {sorted(k[1:-1].tolist())} (expected finite, distinct, "
                                "neither 0 nor 1)")
        if not np.isfinite(o).all():
            raise ColliderError(f"{path}: an offset is not finite")
        idx_all.append(idx)
        knots.append(k)
        offs.append(o)
    return Shapes(names, idx_all, knots, offs, point_count)


#: Faces per chunk: the second culling level under the part spheres.
CHUNK_FACES = 16


def _morton(q):
    """Interleave three 10-bit integer coordinates (n, 3) into Morton codes (n,)."""
    code = np.zeros(len(q), dtype=np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> bit) & 1) << (3 * bit + axis)
    return code


def _chunk_parts(points, triangles, face_offsets, faces, size=CHUNK_FACES):
    """Reorder each part's faces along a Morton curve of their rest centroids and cut them into
    chunks of ``size``: returns (faces reordered, chunk_offsets (C+1,), part_chunks (P+1,))."""
    cent = points[triangles].mean(1)
    out = np.empty_like(faces)
    chunk_offsets = [0]
    part_chunks = [0]
    for p in range(len(face_offsets) - 1):
        a, b = face_offsets[p], face_offsets[p + 1]
        f = faces[a:b]
        if len(f):
            c = cent[f]
            lo, hi = c.min(0), c.max(0)
            q = ((c - lo) / np.maximum(hi - lo, 1e-30) * 1023).astype(np.int64)
            f = f[np.argsort(_morton(q), kind="stable")]
        out[a:b] = f
        chunk_offsets.extend(range(a + size, b, size))
        if b > a:
            chunk_offsets.append(b)
        part_chunks.append(len(chunk_offsets) - 1)
    return out, np.array(chunk_offsets, dtype=np.int64), np.array(part_chunks, dtype=np.int64)


def _chunk_vertices(triangles, faces, chunk_offsets):
    """CSR of each chunk's distinct vertices: (chunk_vert_offsets (C+1,) int64, chunk_verts
    int64), each chunk's vertices ascending."""
    C = len(chunk_offsets) - 1
    chunk = np.repeat(np.arange(C, dtype=np.int64), np.diff(chunk_offsets))
    corners = triangles[faces[:chunk_offsets[-1]]]  # (n, 3)
    V = int(triangles.max()) + 1 if triangles.size else 1
    key = np.unique(np.repeat(chunk, 3) * V + corners.reshape(-1))
    offsets = np.searchsorted(key // V, np.arange(C + 1), side="left").astype(np.int64)
    return offsets, key % V


def blend_shapes(mesh) -> str:
    """What blend shapes a mesh prim binds (``skel:blendShapes`` / ``skel:blendShapeTargets``),
    as a short description, or "" when it has none."""
    from pxr import UsdSkel

    b = UsdSkel.BindingAPI(mesh)
    names = b.GetBlendShapesAttr().Get() if b.GetBlendShapesAttr() else None
    targets = b.GetBlendShapeTargetsRel().GetTargets() if b.GetBlendShapeTargetsRel() else []
    if names:
        return f"skel:blendShapes = {list(names)[:3]}{'...' if len(names) > 3 else ''}"
    if targets:
        return f"skel:blendShapeTargets -> {str(targets[0])}"
    return ""


def _static_local_to_world(prim):
    from pxr import Usd, UsdGeom

    p = prim
    while p and not p.IsPseudoRoot():
        x = UsdGeom.Xformable(p)
        if x and x.TransformMightBeTimeVarying():
            return None
        p = p.GetParent()
    return schema.matrices_from_usd(UsdGeom.Imageable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()))


def read_collider(path) -> ColliderData:
    """Read one asset into :class:`ColliderData`; :class:`ColliderError` with one line if it
    cannot be read or does not follow the layout."""
    return read_collider_stage(path)[0]


def read_collider_stage(path):
    """:func:`read_collider`, and the ``Usd.Stage`` it read (so a verifier can check the same
    stage instead of reading the file again)."""
    try:
        return _read(path)
    except ColliderError as e:
        raise ColliderError(f"{path}: {e}") from None
    except Exception as e:  # pxr raises Tf errors of its own types
        msg = " ".join(str(e).split()) or type(e).__name__
        raise ColliderError(f"{path}: cannot read asset: {msg[:300]}") from None


def _read(path):
    """``(ColliderData, stage)``."""
    from pxr import Sdf, Usd, UsdGeom, UsdSkel

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ColliderError("no such file")
    try:
        layer = Sdf.Layer.FindOrOpen(path)
    except Exception as e:
        raise ColliderError(f"not a readable USD file ({' '.join(str(e).split())[:200]})") from None
    if layer is None:
        raise ColliderError("not a readable USD file")
    from .references import layer_references
    try:
        refs = layer_references(path)
    except Exception as e:  # never composed: usd-core follows what it parsed of a broken layer
        raise ColliderError(f"not a readable USD file ({' '.join(str(e).split())[:200]})") from None
    if refs:  # a collider is one self-contained layer: nothing it names is opened
        raise ColliderError(f"names other files (a collider has no composition arcs), not read: {refs[0]!r}"
                            + (f" and {len(refs) - 1} more" if len(refs) > 1 else ""))
    stage = Usd.Stage.Open(layer, load=Usd.Stage.LoadAll)
    if stage is None:
        raise ColliderError("not a readable USD stage")
    root, skel_prim, mesh, anims = _find_prims(stage)
    skel = UsdSkel.Skeleton(skel_prim)

    joints = [str(j) for j in (skel.GetJointsAttr().Get() or [])]
    J = len(joints)
    if J == 0:
        raise ColliderError(f"{skel_prim.GetPath()} has no joints")
    joint_index = {j: i for i, j in enumerate(joints)}
    if len(joint_index) != J:
        raise ColliderError(f"{skel_prim.GetPath()} has duplicate joint paths")
    topo = UsdSkel.Topology(joints)
    ok, why = topo.Validate()
    if not ok:
        raise ColliderError(f"{skel_prim.GetPath()} joint topology is invalid: {why}")
    parents = np.asarray(topo.GetParentIndices(), dtype=np.int64)
    topo_order = schema.parents_first(parents)

    bind = _mats(skel.GetBindTransformsAttr().Get(), f"{skel_prim.GetPath()}.bindTransforms")
    rest = _mats(skel.GetRestTransformsAttr().Get(), f"{skel_prim.GetPath()}.restTransforms")
    if len(bind) != J or len(rest) != J:
        raise ColliderError(f"{skel_prim.GetPath()}: {J} joints but {len(bind)} bindTransforms and "
                            f"{len(rest)} restTransforms")
    for name, m in (("bindTransforms", bind), ("restTransforms", rest)):
        bad = np.flatnonzero(~np.isfinite(m).all(axis=(1, 2)))
        if len(bad):
            raise ColliderError(f"{skel_prim.GetPath()}.{name}: joint {joints[bad[0]]!r} is not finite")
    try:
        with np.errstate(all="ignore"):
            inv_bind = np.linalg.inv(bind)
    except np.linalg.LinAlgError:
        raise ColliderError(f"{skel_prim.GetPath()}: a bind transform is singular") from None
    if not np.isfinite(inv_bind).all():
        raise ColliderError(f"{skel_prim.GetPath()}: a bind transform is singular")

    # -- mesh
    counts = np.asarray(_get(mesh, "faceVertexCounts"), dtype=np.int64)
    if counts.size and (counts != 3).any():
        raise ColliderError(f"{mesh.GetPath()} is not all triangles ({int((counts != 3).sum())} faces are not)")
    fvi = np.asarray(_get(mesh, "faceVertexIndices"), dtype=np.int64)
    if fvi.size != 3 * counts.size:
        raise ColliderError(f"{mesh.GetPath()}: {counts.size} triangles but {fvi.size} face vertex indices")
    tris = np.ascontiguousarray(fvi.reshape(-1, 3))
    pts = np.ascontiguousarray(np.asarray(_get(mesh, "points"), dtype=np.float32))
    V = len(pts)
    if pts.ndim != 2 or pts.shape[1] != 3 or V == 0:
        raise ColliderError(f"{mesh.GetPath()} has no points")
    if tris.size and (tris.min() < 0 or tris.max() >= V):
        raise ColliderError(f"{mesh.GetPath()}: face vertex index out of range 0..{V - 1}")
    if not np.isfinite(pts).all():
        raise ColliderError(f"{mesh.GetPath()}: points are not finite")

    binding = UsdSkel.BindingAPI(mesh)
    ji_pv, jw_pv = binding.GetJointIndicesPrimvar(), binding.GetJointWeightsPrimvar()
    if not ji_pv or not jw_pv or ji_pv.Get() is None or jw_pv.Get() is None:
        raise ColliderError(f"{mesh.GetPath()} has no primvars:skel:jointIndices/jointWeights")
    k = ji_pv.GetElementSize()
    if k < 1 or jw_pv.GetElementSize() != k:
        raise ColliderError(f"{mesh.GetPath()}: jointIndices/jointWeights elementSize differ")
    ji = np.asarray(ji_pv.Get(), dtype=np.int32)
    jw = np.asarray(jw_pv.Get(), dtype=np.float32)
    if ji_pv.GetInterpolation() == "constant":  # rigid binding: one influence set for all points
        ji, jw = np.tile(ji, V), np.tile(jw, V)
    if ji.size != V * k or jw.size != V * k:
        raise ColliderError(f"{mesh.GetPath()}: {V} points x {k} influences expected, "
                            f"got {ji.size} joint indices and {jw.size} weights")
    ji = ji.reshape(V, k)
    jw = jw.reshape(V, k)
    # strongest first (the contract's order; enforced here because the skinning kernel stops at
    # a vertex's first zero weight)
    order = np.argsort(-jw, axis=1, kind="stable")
    ji = np.ascontiguousarray(np.take_along_axis(ji, order, 1))
    jw = np.ascontiguousarray(np.take_along_axis(jw, order, 1))
    used = (jw != 0).any(0)  # influence slots no vertex uses (zero weights are never read)
    if not used.all() and used.any():  # one pass over the skin is memory-bound: read less
        ji, jw = np.ascontiguousarray(ji[:, used]), np.ascontiguousarray(jw[:, used])
    mesh_joints = binding.GetJointsAttr().Get() if binding.GetJointsAttr() else None
    if mesh_joints:  # skel:joints on the mesh: indices refer to that ordering
        remap = np.array([joint_index.get(str(j), -1) for j in mesh_joints], dtype=np.int32)
        if (remap < 0).any():
            raise ColliderError(f"{mesh.GetPath()}: skel:joints names joints not in the skeleton")
        if ji.size and (ji.min() < 0 or ji.max() >= len(remap)):
            raise ColliderError(f"{mesh.GetPath()}: joint index out of range")
        ji = np.ascontiguousarray(remap[ji])
    elif ji.size and (ji.min() < 0 or ji.max() >= J):
        raise ColliderError(f"{mesh.GetPath()}: joint index out of range 0..{J - 1}")
    gb_attr = binding.GetGeomBindTransformAttr()
    gb = gb_attr.Get() if gb_attr and gb_attr.HasAuthoredValue() else None
    geom_bind = schema.matrices_from_usd(gb) if gb is not None else np.eye(4)
    if not np.isfinite(geom_bind).all():
        raise ColliderError(f"{mesh.GetPath()}: primvars:skel:geomBindTransform is not finite")
    method = schema.skinning_method(mesh)
    if method not in schema.SKINNING_METHODS:
        raise ColliderError(f"{mesh.GetPath()}.{schema.SKINNING_METHOD_ATTR} is {method!r}: the runtime poses "
                            f"{' and '.join(schema.SKINNING_METHODS)} only")
    shapes = read_shapes(mesh, V)

    # -- parts
    where = f"{mesh.GetPath()}.{PARTS}"
    values, errors = schema.read_parts(mesh)
    if errors:
        name, why = next(iter(errors.items()))
        raise ColliderError(f"{mesh.GetPath()}.{name} is {why}")
    pj = values["joints"]
    P = len(pj)
    missing = [j for j in pj if j not in joint_index]
    if missing:
        raise ColliderError(f"{where}joints names {missing[0]!r}, not a skeleton joint")
    part_joint = np.array([joint_index[j] for j in pj], dtype=np.int64)
    centers = values["centers"].astype(np.float64)
    radii = values["radii"].astype(np.float64)
    offs, faces = values["face_offsets"], values["faces"]
    if len(centers) != P or len(radii) != P or len(offs) != P + 1:
        raise ColliderError(f"{where}*: {P} joints but {len(centers)} centers, {len(radii)} radii, "
                            f"{len(offs)} faceOffsets (want {P + 1})")
    bad = np.flatnonzero(~(np.isfinite(radii) & (radii >= 0)))
    if len(bad):
        raise ColliderError(f"{where}radii: part {int(bad[0])} radius is {float(radii[bad[0]])!r} (a radius is a finite "
                            "number >= 0)")
    bad = np.flatnonzero(~np.isfinite(centers).all(axis=1))
    if len(bad):
        raise ColliderError(f"{where}centers: part {int(bad[0])} centre is not finite")
    if offs[0] != 0 or (np.diff(offs) < 0).any() or offs[-1] != len(faces):
        raise ColliderError(f"{where}faceOffsets is not a CSR offset array into {len(faces)} faces")
    F = len(tris)
    if faces.size and (faces.min() < 0 or faces.max() >= F):
        raise ColliderError(f"{where}faces: face index out of range 0..{F - 1}")
    face_part = schema.face_owner(F, offs, faces)
    if (face_part < 0).any():
        raise ColliderError(f"{where}faces: {int((face_part < 0).sum())} faces are in no part")
    vert_offsets, verts = schema.part_vertex_csr(tris, offs, faces, V)
    faces, chunk_offsets, part_chunks = _chunk_parts(pts.astype(np.float64), tris, offs, faces)
    chunk_vert_offsets, chunk_verts = _chunk_vertices(tris, faces, chunk_offsets)
    bounds = bound_data(pts, ji, jw, geom_bind, bind, part_joint, centers, radii, vert_offsets, verts)

    shape_index = {n: i for i, n in enumerate(shapes.names)}
    clips = [read_clip(a, joint_index, shape_index) for a in anims]
    names = [c.name for c in clips]
    if len(set(names)) != len(names):
        raise ColliderError("duplicate clip names")

    l2w = _static_local_to_world(skel_prim)
    return ColliderData(
        path=path, root_path=str(root.GetPath()), skeleton_path=str(skel_prim.GetPath()),
        mesh_path=str(mesh.GetPath()),
        up_axis=str(UsdGeom.GetStageUpAxis(stage)),
        meters_per_unit=float(UsdGeom.GetStageMetersPerUnit(stage)),
        time_codes_per_second=float(stage.GetTimeCodesPerSecond()),
        joints=joints, parents=parents, topo_order=topo_order,
        bind=bind, inv_bind=inv_bind,
        rest_local=np.ascontiguousarray(rest), geom_bind=np.ascontiguousarray(geom_bind),
        rest_points=pts, triangles=tris, joint_indices=ji, joint_weights=jw,
        part_joint=part_joint, part_centers=np.ascontiguousarray(centers), part_radii=radii,
        face_offsets=offs, faces=faces, vert_offsets=vert_offsets, verts=verts,
        face_part=face_part, chunk_offsets=chunk_offsets, part_chunks=part_chunks,
        chunk_vert_offsets=chunk_vert_offsets, chunk_verts=chunk_verts, faces_shared=bool(len(faces) > F),
        bounds=bounds, clips=clips, static_local_to_world=l2w, skinning_method=method, shapes=shapes,
        stage=stage if l2w is None else None,
    ), stage

