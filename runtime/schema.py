"""The one description of the collider asset (``../shared/CONTRACT.md``) that the writer
(``pipeline.stages.write``) and both readers (``validators.asset``, ``runtime.asset``) use.

* the ``colossus:*`` attribute and customData names, with their USD value types;
* the parts CSR layout: part ``p``'s faces are ``faces[faceOffsets[p]:faceOffsets[p + 1]]``
  (parts may overlap; every face is in at least one part), and the derived CSR of each part's
  distinct vertices (:func:`part_vertex_csr`);
* joint ordering: UsdSkel joint paths, parents before children (:func:`parents_first`);
* the one matrix convention: numpy code works with **column-vector** ``float64`` 4x4 matrices
  (``p' = M @ p``, translation in the last column); USD's ``GfMatrix4d`` is row-vector (the
  transpose).  :func:`matrices_from_usd` / :func:`matrices_to_usd` are the only conversions
  (the runtime's arrays and kernels are column-vector too; :func:`row_vector` hands matrices to
  usd-core functions that take raw row-vector arrays, e.g. ``UsdSkel.SkinPointsLBS``).
* quaternions are ``(x, y, z, w)`` (scalar last), pxr's numpy order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Prefix of the per-part attributes on the collision mesh.
PARTS_PREFIX = "colossus:parts:"
PARTS_JOINTS = PARTS_PREFIX + "joints"
PARTS_CENTERS = PARTS_PREFIX + "centers"
PARTS_RADII = PARTS_PREFIX + "radii"
PARTS_FACE_OFFSETS = PARTS_PREFIX + "faceOffsets"
PARTS_FACES = PARTS_PREFIX + "faces"

#: attribute -> (field name in the readers, ``Sdf.ValueTypeNames`` member, numpy dtype, row width)
PARTS_ATTRIBUTES = {
    PARTS_JOINTS: ("joints", "TokenArray", None, 1),
    PARTS_CENTERS: ("centers", "Float3Array", np.float32, 3),
    PARTS_RADII: ("radii", "FloatArray", np.float32, 1),
    PARTS_FACE_OFFSETS: ("face_offsets", "IntArray", np.int64, 1),
    PARTS_FACES: ("faces", "IntArray", np.int64, 1),
}

#: The collision mesh's customData key holding the provenance dictionary.
PROVENANCE_KEY = "colossus"
#: A SkelAnimation's customData key with the clip's own name when it is not a valid prim name.
CLIP_NAME_KEY = "colossus:clipName"
#: customData key on a blend shape whose prim name differs from its source name
SHAPE_NAME_KEY = "colossus:shapeName"
#: A SkelAnimation's customData key describing how the clip was sampled from its source
#: (``sourceKeys``, ``interpolation``, ``sampling``, ``keysOnGrid``, ``errorBound`` stage units).
CLIP_SOURCE_KEY = "colossus:source"
#: Provenance keys of a simplified collision proxy (issue: collision proxy).  They are customData
#: *key paths* (``GetCustomDataByKey``): ``customData["colossus"]["proxy"]["sourceFaces"]`` etc.,
#: inside the provenance dictionary.  ``maxDeviation``: stage units, an upper bound of the
#: two-sided distance between the proxy and the full skinned mesh on the bind pose and every
#: frame of every clip; ``measuredDeviation``: the largest distance actually measured between
#: them (the bound is at most ``1 + DEVIATION_REFINE`` times it, plus a small resolution, where
#: the subdivision depth sufficed); the ``worst*`` keys say where that was measured.
PROXY_KEY = PROVENANCE_KEY + ":proxy"
PROXY_SOURCE_FACES = "colossus:proxy:sourceFaces"
PROXY_MAX_DEVIATION = "colossus:proxy:maxDeviation"
PROXY_MEASURED_DEVIATION = "colossus:proxy:measuredDeviation"
PROXY_WORST_CLIP = "colossus:proxy:worstClip"
PROXY_WORST_FRAME = "colossus:proxy:worstFrame"
PROXY_WORST_BONE = "colossus:proxy:worstBone"
PROXY_WORST_DIRECTION = "colossus:proxy:worstDirection"

#: The collision mesh's skinning method (UsdSkel's ``primvars:skel:skinningMethod``, a uniform
#: token; absent means ``classicLinear``) and the methods the runtime poses
#: (:mod:`runtime.kernels.skin`).
SKINNING_METHOD_ATTR = "primvars:skel:skinningMethod"
SKINNING_METHODS = ("classicLinear", "dualQuaternion")


def skinning_method(prim) -> str:
    """The authored ``primvars:skel:skinningMethod`` of ``prim`` as a str (``"classicLinear"``
    when not authored, UsdSkel's fallback); any other token is returned as is for the caller to
    refuse (the runtime) or report (the validator)."""
    attr = prim.GetAttribute(SKINNING_METHOD_ATTR)
    v = attr.Get() if attr and attr.HasAuthoredValue() else None
    return SKINNING_METHODS[0] if v is None else str(v)


#: Prim names under the SkelRoot.
SKELETON_NAME = "Skeleton"
COLLIDER_NAME = "Collider"
#: The ``Scope`` under the SkelRoot holding one guide-purpose ``UsdGeom.Sphere`` per part (in part
#: order; each rigidly bound to its part's joint, :func:`guide_bind_transform`): what every UsdSkel
#: consumer shows of the parts.  The ``colossus:parts:*`` attributes stay the truth.
GUIDES_NAME = "PartSpheres"
#: A guide sphere's customData key holding its part index.
GUIDE_PART_KEY = "colossus:part"
#: The variant set on the SkelRoot whose variants each bind one clip as the Skeleton's
#: ``skel:animationSource`` (variant name = the clip's prim name; the first clip is the default).
CLIP_VARIANT_SET = "clip"


def guide_bind_transform(bind, center) -> np.ndarray:
    """(4, 4) column-vector ``geomBindTransform`` of a part's guide sphere: ``bind @ T(center)``
    for its joint's bind transform ``bind`` (4, 4) and the part's joint-space ``center`` (3,).

    UsdSkel skins a rigidly bound prim by ``S_j(t) @ inv(bind_j) @ geomBind`` (column-vector), so
    the sphere's origin lands on ``S_j(t) @ center`` and its unit radius is scaled by ``S_j(t)``:
    the contract's part sphere at every time."""
    m = np.asarray(bind, dtype=np.float64).copy()
    c = np.asarray(center, dtype=np.float64).reshape(3)
    m[:3, 3] = m[:3, :3] @ c + m[:3, 3]
    return m


# ------------------------------------------------------------------------------ matrices
def matrices_from_usd(value) -> np.ndarray | None:
    """A ``GfMatrix4d`` or ``VtMatrix4dArray`` (row-vector) -> column-vector ``float64``
    ``(4, 4)`` or ``(b, 4, 4)``; None for None or anything that is not 4x4 matrices."""
    if value is None:
        return None
    a = np.array(value, dtype=np.float64)
    if a.shape[-2:] != (4, 4) or a.ndim not in (2, 3):
        return None
    return np.ascontiguousarray(np.swapaxes(a, -1, -2))


def matrices_to_usd(m: np.ndarray):
    """Column-vector ``(b, 4, 4)`` -> ``Vt.Matrix4dArray``; ``(4, 4)`` -> ``Gf.Matrix4d``."""
    from pxr import Gf, Vt

    m = np.asarray(m, dtype=np.float64)
    if m.ndim == 2:
        return Gf.Matrix4d(*m.T.reshape(-1).tolist())
    return Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(np.swapaxes(m, -1, -2)))


def row_vector(m: np.ndarray) -> np.ndarray:
    """Column-vector matrices ``(..., 4, 4)`` in the row-vector layout (``[x y z 1] @ M``) the
    runtime's kernels loop over (contiguous copy)."""
    return np.ascontiguousarray(np.swapaxes(np.asarray(m, dtype=np.float64), -1, -2))


# ------------------------------------------------------------------------------ joints
def parents_first(parents) -> np.ndarray:
    """Joint indices ordered so every parent comes before its children.

    The given order is kept when it already is parents-first (UsdSkel's own rule); otherwise each
    joint is placed right after its not-yet-placed ancestors, the original order kept otherwise.
    Raises ``ValueError`` on a cycle.
    """
    parents = np.asarray(parents, dtype=np.int64)
    b = len(parents)
    if b == 0 or np.all(parents < np.arange(b)):
        return np.arange(b)
    placed = np.zeros(b, dtype=bool)
    order = []
    for j in range(b):
        chain, k = [], j
        while k >= 0 and not placed[k]:
            if k in chain:
                raise ValueError("joint hierarchy has a cycle")
            chain.append(k)
            k = int(parents[k])
        for c in reversed(chain):
            placed[c] = True
            order.append(c)
    return np.array(order, dtype=np.int64)


# ------------------------------------------------------------------------------ parts
def read_parts(prim):
    """The ``colossus:parts:*`` attributes of the collision mesh ``prim``.

    Returns ``(values, errors)``: ``values[field]`` for each field of :data:`PARTS_ATTRIBUTES`
    (``joints`` a list of str, ``centers`` (P, 3) float32, ``radii`` (P,) float32,
    ``face_offsets`` (P + 1,) int64, ``faces`` (sum,) int64), None where unusable; ``errors`` maps
    each unusable attribute's name to why ("missing", or its wrong type).  Never raises for a
    malformed asset: the validators report, the runtime refuses.
    """
    from pxr import Sdf

    values, errors = {}, {}
    for name, (fld, typ, dtype, width) in PARTS_ATTRIBUTES.items():
        values[fld] = None
        attr = prim.GetAttribute(name)
        if not attr or not attr.HasAuthoredValue():
            errors[name] = "missing"
            continue
        want = getattr(Sdf.ValueTypeNames, typ)
        if attr.GetTypeName() != want:
            errors[name] = f"type {attr.GetTypeName()} (expected {want})"
            continue
        v = attr.Get()
        if dtype is None:
            values[fld] = [str(t) for t in v]
        else:
            a = np.array(v, dtype=dtype)
            values[fld] = a.reshape(-1, width) if width > 1 else a.reshape(-1)
    return values, errors


def write_parts(prim, joint_paths, centers, radii, face_offsets, faces) -> None:
    """Author the parts on the collision mesh ``prim`` with the contract's names and types.

    joint_paths : list of P UsdSkel joint paths; centers (P, 3) joint-space sphere centres;
    radii (P,); face_offsets (P + 1,) and faces: the CSR face lists."""
    from pxr import Sdf, Vt

    T = Sdf.ValueTypeNames
    prim.CreateAttribute(PARTS_JOINTS, T.TokenArray).Set(Vt.TokenArray(list(joint_paths)))
    prim.CreateAttribute(PARTS_CENTERS, T.Float3Array).Set(
        Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(centers, dtype=np.float32).reshape(-1, 3)))
    prim.CreateAttribute(PARTS_RADII, T.FloatArray).Set(
        Vt.FloatArray.FromNumpy(np.ascontiguousarray(radii, dtype=np.float32)))
    prim.CreateAttribute(PARTS_FACE_OFFSETS, T.IntArray).Set(
        Vt.IntArray.FromNumpy(np.ascontiguousarray(face_offsets, dtype=np.int32)))
    prim.CreateAttribute(PARTS_FACES, T.IntArray).Set(
        Vt.IntArray.FromNumpy(np.ascontiguousarray(faces, dtype=np.int32)))


def part_vertex_csr(triangles, face_offsets, faces, vertex_count: int | None = None):
    """CSR of the distinct vertices of each part's faces.

    Parameters
    ----------
    triangles : (F, 3) int; face_offsets : (P + 1,) int; faces : (sum,) int (valid indices)
    vertex_count : int, optional (default ``triangles.max() + 1``)

    Returns
    -------
    offsets : (P + 1,) int64, vertices : (sum,) int64
        Part ``p``'s vertices, sorted, are ``vertices[offsets[p]:offsets[p + 1]]``.
    """
    triangles = np.asarray(triangles, dtype=np.int64)
    face_offsets = np.asarray(face_offsets, dtype=np.int64)
    faces = np.asarray(faces, dtype=np.int64)
    P = len(face_offsets) - 1
    n = max(int(vertex_count if vertex_count is not None else (triangles.max() + 1 if triangles.size else 0)), 1)
    part_of = np.repeat(np.arange(P, dtype=np.int64), np.diff(face_offsets))
    key = np.unique(np.repeat(part_of, 3) * n + triangles[faces].ravel())
    offsets = np.searchsorted(key // n, np.arange(P + 1)).astype(np.int64)
    return offsets, (key % n).astype(np.int64)


def face_owner(face_count: int, face_offsets, faces) -> np.ndarray:
    """(F,) int64 the first part holding each face, -1 for a face in no part."""
    face_offsets = np.asarray(face_offsets, dtype=np.int64)
    faces = np.asarray(faces, dtype=np.int64)
    owner = np.full(face_count, -1, dtype=np.int64)
    part_of = np.repeat(np.arange(len(face_offsets) - 1), np.diff(face_offsets))
    owner[faces[::-1]] = part_of[::-1]  # the first part wins
    return owner


# ------------------------------------------------------------------------------ triangles
#: A triangle whose bind-pose area is at most ``(ZERO_AREA_RELATIVE x model size)^2`` has zero area
#: (the model size: the diagonal of the bind-pose bounding box of all the collider's points).  The
#: validator's COL204 flags it; the importer's ``degenerate`` stage drops it (with a margin,
#: ``pipeline.tolerances.DEGENERATE_MARGIN``) so that no asset it writes can trip the rule.
ZERO_AREA_RELATIVE = 1e-7


def bind_model_size(bind_points) -> float:
    """The model size of the tolerances: the diagonal of the bounding box of the finite rows of
    ``bind_points`` (n, 3); 1.0 when there are none or the box is degenerate."""
    p = np.asarray(bind_points, dtype=np.float64)
    p = p[np.all(np.isfinite(p), axis=1)] if len(p) else p
    if len(p) == 0:
        return 1.0
    d = float(np.linalg.norm(p.max(0) - p.min(0)))
    return d if d > 0 and np.isfinite(d) else 1.0


def zero_area_faces(points, triangles, linear, model_size: float,
                    relative: float = ZERO_AREA_RELATIVE) -> np.ndarray:
    """(m,) bool: the triangles whose bind-pose area is at most ``(relative x model_size)^2``, the
    one test of COL204 (repeated vertex indices included: their area is exactly 0).

    The area is ``|L e1 x L e2| / 2`` for the edge vectors ``e1 = p1 - p0``, ``e2 = p2 - p0`` of the
    points as stored (``points`` (n, 3), float32 in an asset) taken in float64, and ``L`` (3, 3)
    the linear part of the map to the bind pose (skeleton world @ geomBindTransform): the translation
    cancels in the edges, so the importer (before the roots' scale moves onto the Skeleton) and the
    validator (after) compute it from the same stored numbers.  A non-finite area is not flagged
    (COL203 reports non-finite points)."""
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(t) == 0:
        return np.zeros(0, bool)
    p = np.asarray(points, dtype=np.float64)
    L = np.asarray(linear, dtype=np.float64)[:3, :3]
    with np.errstate(all="ignore"):
        e1 = (p[t[:, 1]] - p[t[:, 0]]) @ L.T
        e2 = (p[t[:, 2]] - p[t[:, 0]]) @ L.T
        area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
        area = np.where(np.isfinite(area), area, np.inf)
        return area <= (float(relative) * float(model_size)) ** 2


@dataclass
class Clip:
    """One clip, as UsdSkel stores it and as every part of colossus reads it: the one clip record
    the importer's ``quantize`` stage makes, the writer writes, and the runtime's and the
    validator's readers return (a ``SkelAnimation``).

    Per-attribute sample times and values, all float64 (the values exactly as stored: float32
    translations and rotations, half-precision scales, when they come from an asset or from the
    ``quantize`` stage): ``tt/vt`` translations (nT,), (nT, A, 3); ``tr/vr`` rotations (nR,),
    (nR, A, 4) as ``(x, y, z, w)``; ``ts/vs`` scales (nS,), (nS, A, 3).  ``anim_to_skel`` (A,)
    int64 maps the animation's joints to the skeleton's.  ``times`` is the union of sample times
    (the clip's frames).  ``name`` is the clip's name, ``path`` its prim path (or its name where
    it has no prim yet).  Matrices are made from it only by the pose kernels
    (:func:`runtime.kernels.pose.locals_at`).
    """

    name: str
    path: str
    tt: np.ndarray
    vt: np.ndarray
    tr: np.ndarray
    vr: np.ndarray
    ts: np.ndarray
    vs: np.ndarray
    anim_to_skel: np.ndarray
    times: np.ndarray
    #: the names the clip had in its source where the asset's differs (a prim name is a USD
    #: identifier: ``Take 001`` becomes ``Take_001``), from the animation's customData
    source_names: tuple = ()
    #: blend-shape weights (UsdSkel's ``blendShapeWeights``): sample times (nW,) and values
    #: (nW, S) float64 in the **mesh's** shape order (``skel:blendShapes``; a shape the
    #: animation does not name is 0, UsdSkel's mapper), linearly interpolated between samples
    #: and held beyond the ends; none: every shape at 0
    tw: np.ndarray = field(default_factory=lambda: np.zeros(0))
    vw: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    def shape_weights(self, times, shape_count: int) -> np.ndarray:
        """(T, S) float64 blend-shape weights at ``times`` (T,) as UsdSkel interpolates the
        ``blendShapeWeights`` samples: linear between samples, held before the first and after
        the last (float32 arithmetic in usd-core: within 1e-7 relative of these)."""
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        out = np.zeros((len(times), shape_count))
        if len(self.tw) == 0 or shape_count == 0:
            return out
        for s in range(min(shape_count, self.vw.shape[1])):
            out[:, s] = np.interp(times, self.tw, self.vw[:, s])
        return out

    @classmethod
    def on_grid(cls, name: str, times, t, q, s, path: str | None = None, weights=None) -> "Clip":
        """A clip whose three attributes share the frames ``times`` (f,) and that animates every
        joint of the skeleton in order: ``t`` (f, J, 3), ``q`` (f, J, 4), ``s`` (f, J, 3); and
        every blend shape of the mesh in order, ``weights`` (f, S) (none: no shape)."""
        times = np.ascontiguousarray(times, dtype=np.float64)
        f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)
        w = np.zeros((len(times), 0)) if weights is None else f64(weights)
        tw = times if w.shape[1] else np.zeros(0)
        return cls(name, name if path is None else path, times, f64(t), times, f64(q), times, f64(s),
                   np.arange(np.shape(t)[1], dtype=np.int64), times, tw=tw,
                   vw=w if w.shape[1] else np.zeros((0, 0)))


#: An animated scale whose magnitude on an axis is below this counts as zero: between two
#: samples UsdSkel lerps scales in half precision, which can round such a scale to exactly 0
#: (a few of half's smallest subnormal steps, 2^-24).
MIN_SCALE = 2.0 ** -22


def scale_singularity(clip: Clip, min_scale: float = MIN_SCALE):
    """Where the clip's scales leave a joint without an inverse pose, at a sample or between two
    (UsdSkel lerps scales, so one that changes sign passes through 0): ``(time, animation joint
    index, why)`` of the first such place, else None.  The frame proofs (the importer's and the
    validator's) measure each part in its joint's space, the inverse of the joint's pose."""
    vs = np.asarray(clip.vs, dtype=np.float64)
    if not vs.size:
        return None
    with np.errstate(invalid="ignore"):
        tiny = np.abs(vs) < min_scale
        flips = (np.sign(vs[1:]) * np.sign(vs[:-1])) < 0
    if tiny.any():
        i, j, _ = np.argwhere(tiny)[0]
        v = float(vs[i, j][np.argmax(tiny[i, j])])
        return float(clip.ts[i]), int(j), f"has a scale of {v:g} on an axis: no inverse (a scale below 2^-22 counts as 0)"
    if flips.any():
        i, j, _ = np.argwhere(flips)[0]
        return (float(clip.ts[i]), int(j), f"has a scale that changes sign between times {clip.ts[i]:g} and "
                                           f"{clip.ts[i + 1]:g} (UsdSkel interpolates it through 0)")
    return None
