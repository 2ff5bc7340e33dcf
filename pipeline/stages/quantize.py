"""Stage ``quantize``: the clips exactly as the asset stores them (float3 translations, quatf
rotations, half3 scales; the roots' common scale folded into the joints' translations), with the
bound of what that storage moves any vertex.  It runs before ``spheres`` so the spheres are proven
on the motion the asset really has; ``write`` stores its values as they are.  This is the one
place the roots' common scale is folded and a clip's quaternions are put in one hemisphere.

Before rounding, three exact changes of variables make the asset show the same in every UsdSkel
consumer, Blender's USD importer included (its armature's bones hold no scale, and its shape keys
clamp their values to [0, 1]): blend-shape weights are carried in [0, 1]
(:func:`unit_range_shapes`); a scale the skeleton carries in every frame relative to its bind is
folded into the points (:func:`point_scale`, :func:`fold_point_scale`; recorded as the
provenance's ``pointScale``, which ``validate --source`` divides out); and each joint's uniform
bind scale is divided out of its space (:func:`joint_scales`, :func:`fold_joint_scales`), so the
bind transforms are rigid wherever the source's were uniformly scaled.  The skinned points are the
same at every time (each function's docstring gives the identity).  The cost: a clip whose scales
differ from the bind's then stores ratios such as 0.01 that half precision rounds (the
lumberjack's one-frame A-pose: 2.4e-7 -> 5.8e-5 x size, stated in its ``storageErrorBoundRelative``
and within the 1e-4 fidelity tolerance).
"""

from __future__ import annotations

import numpy as np

from ..model import SkinnedMesh
from ..xforms import compose_trs, decompose_trs
from . import StageReport


def root_scale(mesh: SkinnedMesh) -> float:
    """The uniform scale ``k`` the root joints carry (an armature object's scale, a unit
    conversion): the median of their axis scales in the bind pose, the rest pose and on every
    frame of every clip, or 1.0.  Dividing it out is exact; what remains of the roots' scales
    (1 where the roots carried only ``k``) goes into the animation.

    :func:`fold_root_scale` folds it into the joints' translations, out of the SkelAnimation's
    ``half3`` scales, where it would be rounded (``half(0.01) / 0.01 = 1 + 2.1e-4``), and off the
    Skeleton prim (a unit scale there is composed by usd-core but applied to other objects by
    Blender's USD importer: the contract says no unit scale sits on the Skeleton prim).
    """
    roots = np.flatnonzero(mesh.parents < 0)
    if not len(roots):
        return 1.0
    mats = [mesh.bind_transforms[roots], mesh.rest_transforms[roots]] + [c.local[:, roots].reshape(-1, 4, 4)
                                                                         for c in mesh.clips]
    _, _, s = decompose_trs(np.concatenate(mats))
    k = float(np.median(s))
    # float32 sources give the "same" scale to ~1e-7: what is left after dividing by k then rounds
    # to exactly 1 in half precision
    if not (np.isfinite(k) and k > 0) or abs(k - 1.0) < 1e-12:
        return 1.0
    return k


def fold_root_scale(mesh: SkinnedMesh, k: float) -> SkinnedMesh:
    """``mesh`` with the roots' uniform scale ``k`` folded into the translations: the same skinned
    points at every frame, exactly, with no ``k`` anywhere in a joint's scale.

    With ``K = k I`` (uniform, so it commutes with rotations), a root's local transform is
    ``L_r = L'_r K`` (``L'_r``: its linear part divided by ``k``, translation kept) and for any
    affine ``L = [A | t]``, ``K L = [A | k t] K``.  Moving ``K`` down each chain, a joint's
    skeleton-space transform is ``W_j = W'_j K`` where ``W'_j`` composes ``L'_r`` and the
    descendants' locals with their translations times ``k``; the bind transforms likewise
    ``B_j = B'_j K``.  Skinning uses ``W_j B_j^-1 = W'_j K K^-1 B'_j^-1 = W'_j B'_j^-1``: unchanged,
    and the points stay where they are.  A joint's own space is ``k`` times larger (``q' = k q``),
    so the spheres, computed after this, are in it.
    """
    if k == 1.0:
        return mesh
    roots = mesh.parents < 0
    unscale = np.diag([1.0 / k, 1.0 / k, 1.0 / k, 1.0])

    def locals_(local):
        out = local.copy()
        out[..., roots, :3, :3] /= k
        out[..., ~roots, :3, 3] *= k
        return out

    clips = tuple(type(c)(c.name, c.times, locals_(c.local), c.shape_weights) for c in mesh.clips)
    return mesh.replace(bind_transforms=mesh.bind_transforms @ unscale,
                        rest_transforms=locals_(mesh.rest_transforms), clips=clips)


#: A joint whose bind transform's uniform scale differs from its parent's by more than this
#: (relatively) has it folded out by :func:`fold_joint_scales`; less is float noise, left alone.
JOINT_SCALE_STEP = 1e-5


def joint_scales(mesh: SkinnedMesh, k: float) -> np.ndarray:
    """(b,) the uniform scale ``s_j`` to divide out of each joint's space: ``k`` (:func:`root_scale`) at
    the roots (the root's own bind scale where it differs from ``k`` by more than
    :data:`JOINT_SCALE_STEP`: the bind is made rigid, and the animation keeps the ratio, rounded to half
    precision within the clip's stated storage bound), then down each chain the parent's, times the
    joint's own step where its bind transform's uniform scale (``|det|^(1/3)`` of its linear part)
    differs from its parent's by more than :data:`JOINT_SCALE_STEP` (a centimetre subtree under a metre
    root, an armature scaled below its root joint)."""
    lin = mesh.bind_transforms[:, :3, :3]
    u = np.cbrt(np.abs(np.linalg.det(lin)))
    s = np.ones(len(mesh.parents))
    from colossus.runtime.schema import parents_first
    for j in parents_first(mesh.parents):
        p = mesh.parents[j]
        if p < 0:  # k, or the root's own bind scale where that differs (its bind then rigid too)
            s[j] = k if u[j] > 0 and abs(u[j] / k - 1.0) <= JOINT_SCALE_STEP else (u[j] if u[j] > 0 else k)
            continue
        step = u[j] / u[p] if u[p] > 0 else 1.0
        s[j] = s[p] * step if np.isfinite(step) and step > 0 and abs(step - 1.0) > JOINT_SCALE_STEP else s[p]
    return s


def fold_joint_scales(mesh: SkinnedMesh, s: np.ndarray) -> SkinnedMesh:
    """:func:`fold_root_scale` for a uniform scale ``s_j`` per joint (:func:`joint_scales`): the same
    skinned points at every frame, exactly, with each joint's bind transform ``B_j / s_j`` (rigid
    where ``B_j``'s scale was uniform, as Blender's armature, whose bones hold no scale, needs it).

    Any constant ``C_j = s_j I`` per joint is a change of joint space: ``W'_j = W_j C_j^-1`` and
    ``B'_j = B_j C_j^-1`` skin alike (``W'_j B'_j^-1 = W_j B_j^-1``), and a joint's local transform
    becomes ``L'_j = C_p L_j C_j^-1``: for ``L = [A | t]``, ``[(s_p / s_j) A | s_p t]`` (``s_p = 1``
    at a root), still translation, rotation and scale since ``s_p / s_j`` is a scalar.  A joint's
    own space is ``s_j`` times larger, so the spheres, computed after this, are in it."""
    s = np.asarray(s, dtype=np.float64)
    if np.all(s == 1.0):
        return mesh
    sp = np.where(mesh.parents < 0, 1.0, s[np.maximum(mesh.parents, 0)])

    def locals_(local):
        out = local.copy()
        out[..., :3, :3] *= (sp / s)[:, None, None]
        out[..., :3, 3] *= sp[:, None]
        return out

    clips = tuple(type(c)(c.name, c.times, locals_(c.local), c.shape_weights) for c in mesh.clips)
    bind = mesh.bind_transforms.copy()
    bind[:, :3, :3] /= s[:, None, None]
    return mesh.replace(bind_transforms=bind, rest_transforms=locals_(mesh.rest_transforms), clips=clips)


def point_scale(mesh: SkinnedMesh) -> float:
    """The uniform scale ``r`` the skeleton carries in every pose relative to its bind pose: the
    median, over the joints that skin a vertex and every frame of every clip (the rest pose without
    a clip), of ``a / b`` (``a``, ``b``: ``|det|^(1/3)`` of the joint's skeleton-space and bind
    transforms' linear parts), where every such ratio is within :data:`JOINT_SCALE_STEP` of it and
    it is not within that of 1 (a skeleton scaled after its skin was bound); else 1.0."""
    from ..model import skel_transforms

    used = np.unique(mesh.joint_indices[mesh.joint_weights > 0])
    if not len(used):
        return 1.0
    b = np.cbrt(np.abs(np.linalg.det(mesh.bind_transforms[used, :3, :3])))
    poses = [skel_transforms(c.local, mesh.parents) for c in mesh.clips]
    if not poses:  # the rest pose is what a clip-less asset shows (with clips, only joints no clip moves use it)
        poses = [skel_transforms(mesh.rest_transforms, mesh.parents)[None]]
    a = np.concatenate([np.cbrt(np.abs(np.linalg.det(k[:, used, :3, :3]))) for k in poses])
    with np.errstate(all="ignore"):
        ratio = a / b[None]
    if not np.all(np.isfinite(ratio)) or not np.all(ratio > 0):
        return 1.0
    r = float(np.median(ratio))
    if abs(r - 1.0) <= JOINT_SCALE_STEP or np.max(np.abs(ratio / r - 1.0)) > JOINT_SCALE_STEP:
        return 1.0
    return r


def fold_point_scale(mesh: SkinnedMesh, r: float) -> SkinnedMesh:
    """``mesh`` with its points (and blend-shape offsets, and the geomBindTransform's translation)
    ``r`` times larger and its bind transforms ``r`` times larger from the left (``B' = r B``): the
    same skinned points at every frame, exactly.  With ``D = r I``: ``M_j p = K_j B_j^-1 p = K_j
    (D B_j)^-1 (D p)``, and ``D G x = G' (r x)`` for ``G' = [A_G | r t_G]``.  Where the skeleton
    carries ``r`` in every pose relative to its bind (:func:`point_scale`), the bind transforms
    (and a rest pose that was the bind pose: its roots' rest locals times ``D``, so it stays the
    bind pose) then hold the skeleton's own scale, which :func:`fold_joint_scales` divides out of both: the
    asset's joints are rigid at bind and in every pose, as Blender's armature (bones hold no
    scale) shows them."""
    from dataclasses import replace as dc_replace

    if r == 1.0:
        return mesh
    from ..model import skel_transforms

    D = np.diag([r, r, r, 1.0])
    # a rest pose that is the bind pose stays the bind pose (its roots' rest locals times D): the
    # source's rest == bind relation is kept (COL308), and its rest then shows the skeleton's size
    rest = mesh.rest_transforms
    K = skel_transforms(rest, mesh.parents)
    tol = 1e-6 * max(1.0, float(np.abs(mesh.bind_transforms[:, :3, 3]).max(initial=0.0)))
    if np.allclose(K, mesh.bind_transforms, rtol=0.0, atol=tol):
        rest = rest.copy()
        roots = mesh.parents < 0
        rest[roots] = D @ rest[roots]
    G = mesh.geom_bind.copy()
    G[:3, 3] *= r
    shapes = tuple(dc_replace(b, offsets=(b.offsets.astype(np.float64) * r).astype(np.float32),
                              inbetweens=tuple((w, (o.astype(np.float64) * r).astype(np.float32))
                                               for w, o in b.inbetweens))
                   for b in mesh.blend_shapes)
    return mesh.replace(positions=(mesh.positions.astype(np.float64) * r).astype(np.float32),
                        geom_bind=G, bind_transforms=D @ mesh.bind_transforms, rest_transforms=rest,
                        blend_shapes=shapes)


def unit_range_shapes(mesh: SkinnedMesh):
    """``mesh`` with every blend shape that has no in-betweens weighted in [0, 1] in every clip, the
    same points at every time; and the number of shapes changed.

    Blender's USD importer turns blend shapes into shape keys whose values it clamps to [0, 1]: a
    weight of -0.06 (Blender's own barbarian) or 1.3 plays differently there than in usd-core.
    Without in-betweens a shape moves its points by ``w o``, linear in ``w``, so with ``w = w+ -
    w-`` (``w+ = max(w, 0)``, ``w- = max(-w, 0)``) a negative range becomes a second shape
    ``<name>_neg`` with offsets ``-o`` and weights ``w-`` (UsdSkel lerps weights between frames, and
    ``lerp(w+) - lerp(w-) = lerp(w)``: exact there too), and a range up to ``m > 1`` becomes offsets
    ``m o`` and weights ``w / m`` (float32 rounding only).  The proof's bound ``sum |w| |o|`` is
    unchanged.  Shapes with in-betweens (a piecewise-linear response) keep their weights."""
    from dataclasses import replace as dc_replace

    if not mesh.blend_shapes or not mesh.clips:
        return mesh, 0
    W = [c.shape_weights.astype(np.float64) for c in mesh.clips]
    names = {b.name for b in mesh.blend_shapes}
    shapes, cols, changed = [], [[] for _ in W], 0
    for si, b in enumerate(mesh.blend_shapes):
        w = [x[:, si] for x in W]
        lo = min(float(x.min(initial=0.0)) for x in w)
        hi = max(float(x.max(initial=0.0)) for x in w)
        if b.inbetweens or (lo >= 0.0 and hi <= 1.0):
            shapes.append(b)
            for c, x in zip(cols, w):
                c.append(x)
            continue
        changed += 1
        o = b.offsets.astype(np.float64)
        mp = max(hi, 1.0)
        shapes.append(dc_replace(b, offsets=(o * mp).astype(np.float32)))
        for c, x in zip(cols, w):
            c.append(np.maximum(x, 0.0) / mp)
        if lo < 0.0:
            mn = max(-lo, 1.0)
            name = f"{b.name}_neg"
            while name in names:
                name += "_"
            names.add(name)
            shapes.append(dc_replace(b, name=name, offsets=(-o * mn).astype(np.float32)))
            for c, x in zip(cols, w):
                c.append(np.maximum(-x, 0.0) / mn)
    if not changed:
        return mesh, 0
    clips = tuple(type(c)(c.name, c.times, c.local, np.stack(col, axis=1)) for c, col in zip(mesh.clips, cols))
    return mesh.replace(blend_shapes=tuple(shapes), clips=clips), changed


def _joint_local_points(mesh: SkinnedMesh):
    """Where each joint holds the vertices it moves.

    Returns
    -------
    centers : (b, 3) float64
        Per joint, the weight-averaged joint-local (bind) position ``inv(bind_j) @ geom_bind @ v``
        of the vertices with a nonzero weight on it (0 for joints that move no vertex).
    dist : (n, k) float64
        Per vertex and influence, the distance of the vertex's joint-local position from that
        joint's centre (0 for padding influences).
    """
    b = len(mesh.parents)
    v = mesh.positions.astype(np.float64) @ mesh.geom_bind[:3, :3].T + mesh.geom_bind[:3, 3]
    inv = np.linalg.inv(mesh.bind_transforms)
    ji = np.clip(mesh.joint_indices, 0, max(b - 1, 0))
    w = np.where(mesh.joint_weights > 0, mesh.joint_weights, 0.0).astype(np.float64)
    q = np.einsum("nkab,nb->nka", inv[ji, :3, :3], v) + inv[ji, :3, 3]          # (n, k, 3)
    wsum = np.bincount(ji.ravel(), weights=w.ravel(), minlength=b)
    centers = np.stack([np.bincount(ji.ravel(), weights=(w * q[..., a]).ravel(), minlength=b)
                        for a in range(3)], axis=1) / np.where(wsum > 0, wsum, 1.0)[:, None]
    dist = np.where(w > 0, np.linalg.norm(q - centers[ji], axis=-1), 0.0)
    return centers, dist


def _store_clip(local: np.ndarray, parents: np.ndarray, centers: np.ndarray):
    """Round one clip's joint-local transforms to the asset's storage types, correcting each
    joint's translation for what its parents' and its own rounding moved.

    UsdSkel stores a joint's local scale as ``half3`` (11 significant bits: an animated stretch
    of 1.03 moves by up to 2**-11 of itself), rotation as ``quatf`` and translation as
    ``float3``.  Rounding each value on its own lets the errors add up down a chain (a thigh's
    rounded stretch moves the knee, the shin and the foot).  Instead, parents first, each joint
    keeps its rounded rotation and scale, and its translation is chosen in full float precision
    so that, with the parent's *stored* world transform ``W'_p = [M | o]``, the affine error
    ``e(q) = W'_p L'_j q - W_j q`` (``W_j`` the exact world transform, ``q`` a joint-local point)
    vanishes at the centre ``c_j`` of the joint's own vertices: ``t'_j = M^-1 (w_j - o - D_j c_j)``
    with ``D_j = M R'_j S'_j - A_j`` (``A_j`` the linear part of ``W_j``).  Then
    ``e(q) = D_j (q - c_j)``, so ``|e(q)| <= ||D_j||_2 |q - c_j|``, and a vertex skinned by
    weights ``w_k`` to joints ``j_k`` errs at most ``sum_k w_k ||D_jk||_2 |q_k - c_jk|`` (LBS is a
    weighted sum of the joints' transforms; float32 rounding of ``t'`` adds ~1e-7 of it).  Joint
    positions down the chain stay exact up to ``D_j c_j``, which the children absorb.

    Parameters
    ----------
    local : (f, b, 4, 4) float64
        Exact joint-local transforms per frame.
    parents : (b,) int
    centers : (b, 3) float64
        From :func:`_joint_local_points`.

    Returns
    -------
    t, q, s : (f, b, 3), (f, b, 4), (f, b, 3) float64
        The rounded values: translations float32, rotations float32 (``(x, y, z, w)``, as
        :func:`~colossus.pipeline.xforms.decompose_trs` gives them), scales half precision.
    norms : (f, b) float64
        ``||D_j||_2`` per frame and joint.
    """
    from colossus.runtime.schema import parents_first

    from ..xforms import quat_to_matrix

    f, b = local.shape[:2]
    t_own, q, s = decompose_trs(local)
    q = q.astype(np.float32).astype(np.float64)
    s = s.astype(np.float16).astype(np.float64)
    lin = quat_to_matrix(q) * s[..., None, :]                      # stored local linear parts
    t = np.zeros((f, b, 3))
    world = np.empty_like(local)                                    # exact, parents first
    sw_lin, sw_off = np.empty((f, b, 3, 3)), np.empty((f, b, 3))    # stored world
    norms = np.zeros((f, b))
    for j in parents_first(parents):
        p = parents[j]
        if p < 0:
            world[:, j] = local[:, j]
            m, o = np.broadcast_to(np.eye(3), (f, 3, 3)), np.zeros((f, 3))
        else:
            world[:, j] = world[:, p] @ local[:, j]
            m, o = sw_lin[:, p], sw_off[:, p]
        stored_lin = m @ lin[:, j]
        d = stored_lin - world[:, j, :3, :3]
        rhs = world[:, j, :3, 3] - o - d @ centers[j]
        # a parent whose stored linear part is singular (a zero scale) cannot be corrected for:
        # those frames keep the joint's own rounded translation
        with np.errstate(invalid="ignore", over="ignore"):
            regular = np.abs(np.linalg.det(m)) > 1e-300
            tj = t_own[:, j].copy()
            if regular.any():
                tj[regular] = np.linalg.solve(m[regular], rhs[regular][..., None])[..., 0]
        tj = tj.astype(np.float32).astype(np.float64)
        t[:, j] = tj
        sw_lin[:, j] = stored_lin
        sw_off[:, j] = (m @ tj[..., None])[..., 0] + o
        norms[:, j] = np.linalg.norm(d, ord=2, axis=(-2, -1))
    return t, q, s, norms


def _storage_bound(norms: np.ndarray, joint_indices, joint_weights, dist, chunk: int = 64) -> float:
    """``max`` over frames and vertices of ``sum_k w_k ||D_jk||_2 |q_k - c_jk|`` (see
    :func:`_store_clip`); ``norms`` (f, b), ``dist`` (n, k)."""
    wd = np.where(joint_weights > 0, joint_weights, 0.0) * dist
    ji = np.clip(joint_indices, 0, norms.shape[1] - 1)
    out = 0.0
    for i in range(0, len(norms), chunk):
        out = max(out, float(np.max(np.einsum("fnk,nk->fn", norms[i:i + chunk][:, ji], wd), initial=0.0)))
    return out


def posed_size(mesh: SkinnedMesh, skel: np.ndarray) -> float:
    """The model size (:func:`pipeline.tolerances.model_scale`) of the vertices skinned by the
    skeleton-space joint transforms ``skel`` (b, 4, 4), the mesh's own method, float64: the
    contract's posed size when ``skel`` is a clip's first frame (bind-space positions can be at
    another scale: lumberjack's mesh is authored in centimetres, bound by x100 binds, and moved in
    metres)."""
    from colossus.runtime.kernels.skin import fold_method, skin_frames

    from ..tolerances import model_scale

    mats = fold_method(mesh.skinning_method, skel[None] @ np.linalg.inv(mesh.bind_transforms), mesh.geom_bind)
    return model_scale(skin_frames(mesh.positions, mesh.joint_indices, mesh.joint_weights, mats,
                                   dtype=np.float64)[0])


def _posed_size(mesh: SkinnedMesh, local: np.ndarray) -> float:
    """:func:`posed_size` at the joint-local transforms ``local`` (b, 4, 4)."""
    from ..model import skel_transforms

    return posed_size(mesh, skel_transforms(local, mesh.parents))

def _one_hemisphere(q: np.ndarray) -> np.ndarray:
    """``q`` (f, b, 4) with each joint's quaternions kept in one hemisphere along time (a sign
    change never changes a rotation): consumers slerp consecutive samples in float (GfSlerp on
    quatf), which is least exact for nearly opposite quaternions it has to flip."""
    q = q.copy()
    flip = np.cumsum(np.einsum("fjk,fjk->fj", q[:-1], q[1:]) < 0, axis=0) % 2 == 1
    q[1:][flip] *= -1
    return q


def _as_stored(t, q, s):
    """The values exactly as the asset holds them (float64 arrays of float32 / half values):
    rotations normalised in double before their float32 rounding (the rotation the rounded
    matrices of :func:`_store_clip` carry; a rounded quaternion's norm is 1 only to ~6e-8), then
    put in one hemisphere."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    f32 = lambda a: a.astype(np.float32).astype(np.float64)
    # (+ 0.0: no negative zero in the file)
    return f32(t) + 0.0, _one_hemisphere(f32(q)) + 0.0, s.astype(np.float16).astype(np.float64) + 0.0


def quantize(mesh: SkinnedMesh):
    """Stage ``quantize``: every clip exactly as the asset will store it.

    UsdSkel stores each joint's translation as ``float3``, rotation as ``quatf`` and scale as
    ``half3`` (the SkelAnimation schema's types).  The spheres must be computed on the motion the
    asset really has, so this stage rounds the clips the way :func:`_store_clip` does (the
    translations corrected for the rounded scales) before the ``spheres`` stage; ``write`` then
    stores exactly these values.  The roots' common scale (:func:`root_scale`) is folded into the
    translations first, once (:func:`fold_root_scale`: exact), so it is never rounded.

    Returns the mesh with
    * bind, rest and clip transforms with the roots' scale folded;
    * ``clips``: the rounded joint-local transforms, for the stages that pose matrices;
    * ``stored_clips``: one :class:`runtime.schema.Clip` per clip, the TRS values the writer stores
      (quaternions in one hemisphere), which the spheres' certificate and the writer read;
    * ``root_scale``: 1 (the scale is folded; the report's ``root_scale`` says what was folded);
    * each clip's ``clip_info`` entry (in ``mesh.source``) with ``storage_error_relative``: the
      bound of :func:`_store_clip` on how far storage moves any vertex, over the model size (as
      the clip's first frame poses it, :func:`_posed_size`);
    and a :class:`StageReport`.
    """
    from colossus.runtime.schema import Clip

    mesh, reshaped = unit_range_shapes(mesh)
    r = point_scale(mesh)
    mesh = fold_point_scale(mesh, r)
    k = root_scale(mesh)
    js = joint_scales(mesh, k)
    mesh = fold_root_scale(mesh, k) if np.all(js == k) else fold_joint_scales(mesh, js)
    centers, dist = _joint_local_points(mesh)
    clips, stored, bounds = [], [], {}
    for c in mesh.clips:
        t, q, s, norms = _store_clip(c.local, mesh.parents, centers)
        # blend-shape weights are stored as float32 (UsdSkel's blendShapeWeights): rounded here
        w = c.shape_weights.astype(np.float32).astype(np.float64)
        clips.append(type(c)(c.name, c.times, compose_trs(t, q, s), w))
        stored.append(Clip.on_grid(c.name, c.times, *_as_stored(t, q, s), weights=w))
        bounds[c.name] = (_storage_bound(norms, mesh.joint_indices, mesh.joint_weights, dist)
                          / _posed_size(mesh, c.local[0]))
    info = [dict(i, storage_error_relative=bounds[i["name"]]) if i.get("name") in bounds else i
            for i in mesh.source.get("clip_info", [])]
    src = dict(mesh.source, clip_info=info)
    if r != 1.0:
        src["point_scale"] = r
    out = mesh.replace(clips=tuple(clips), stored_clips=tuple(stored), root_scale=1.0, source=src)
    rep = StageReport("quantize", counts={"clips": len(clips), "root_scale": k, "point_scale": r,
                                          "shapes_to_unit_range": reshaped,
                                          "joint_scales_folded": int(np.count_nonzero(
                                              js != np.where(mesh.parents < 0, js, js[np.maximum(mesh.parents, 0)]))),
                                          "storage_error_relative": max(bounds.values(), default=0.0)})
    return out, rep
