"""Stage 7, ``write``: the USD collider asset, exactly as ``shared/CONTRACT.md`` lays it out.

Layout (``<Name>`` is the source file's stem made a valid identifier)::

    /<Name>                 SkelRoot (defaultPrim)
    /<Name>/Skeleton        Skeleton: joints, bindTransforms, restTransforms,
                            skel:animationSource -> the first clip
    /<Name>/Collider        Mesh: triangles, rightHanded, UsdSkelBindingAPI (jointIndices /
                            jointWeights, elementSize = max influences), PhysicsCollisionAPI,
                            PhysicsMeshCollisionAPI (approximation "none"), colossus:parts:*,
                            customData["colossus"] = provenance
    /<Name>/<clip>          SkelAnimation per clip, one time sample per source frame

The file is written to a temporary name in the output directory, re-opened with usd-core and
checked (:func:`_check_written`), and only then renamed into place: a failed import never leaves
a partial asset behind, and nothing usd-core cannot open is ever written.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from colossus.runtime import schema

from ..errors import OutputError
from ..model import SkinnedMesh
from ..xforms import compose_trs, decompose_trs
from . import StageReport

OUTPUT_EXTENSIONS = (".usda", ".usdc", ".usd")
RESERVED = (schema.SKELETON_NAME, schema.COLLIDER_NAME)


def _ident(name: str, taken: set) -> str:
    from pxr import Tf

    from ..readers.common import unique_name
    return unique_name(Tf.MakeValidIdentifier(str(name) or "_"), taken)


def joint_paths(names, parents) -> list:
    """UsdSkel joint paths (``"root/spine/neck"``) from joint names and parent indices."""
    paths, taken = [], {}
    for j, name in enumerate(names):
        p = parents[j]
        prefix = "" if p < 0 else paths[p] + "/"
        ident = _ident(name, taken.setdefault(prefix, set()))
        paths.append(prefix + ident)
    return paths


def check_output_path(out_path) -> str:
    """Raise :class:`OutputError` unless ``out_path`` can be written; return it as a str."""
    out = os.fspath(out_path)
    ext = os.path.splitext(out)[1].lower()
    if ext not in OUTPUT_EXTENSIONS:
        raise OutputError(f"{out}: output must end in {', '.join(OUTPUT_EXTENSIONS)}")
    folder = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(folder):
        raise OutputError(f"{out}: output directory {folder} does not exist")
    if os.path.isdir(out):
        raise OutputError(f"{out}: is a directory")
    try:  # probe for real: access() says yes to root even where writing fails
        fd, probe = tempfile.mkstemp(prefix=".colossus-", suffix=".probe", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise OutputError(f"{out}: output directory {folder} is not writable ({exc.strerror or exc})") from None
    return out


def root_scale(mesh: SkinnedMesh) -> float:
    """The uniform scale ``k`` the root joints carry (an armature object's scale, a unit
    conversion): the median of their axis scales in the bind pose, the rest pose and on every
    frame of every clip, or 1.0.  Dividing it out is exact; what remains of the roots' scales
    (1 where the roots carried only ``k``) goes into the animation.

    The writer moves it onto the Skeleton prim (``xformOp:scale``, double precision), out of the
    SkelAnimation's ``half3`` scales, where it would be rounded (``half(0.01) / 0.01 = 1 + 2.1e-4``).
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
    stored : (f, b, 4, 4) float64
        ``T R S`` of the rounded values (``write`` stores exactly these).
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
    return compose_trs(t, q, s), norms


def _storage_bound(norms: np.ndarray, joint_indices, joint_weights, dist, chunk: int = 64) -> float:
    """``max`` over frames and vertices of ``sum_k w_k ||D_jk||_2 |q_k - c_jk|`` (see
    :func:`_store_clip`); ``norms`` (f, b), ``dist`` (n, k)."""
    wd = np.where(joint_weights > 0, joint_weights, 0.0) * dist
    ji = np.clip(joint_indices, 0, norms.shape[1] - 1)
    out = 0.0
    for i in range(0, len(norms), chunk):
        out = max(out, float(np.max(np.einsum("fnk,nk->fn", norms[i:i + chunk][:, ji], wd), initial=0.0)))
    return out


def _posed_size(mesh: SkinnedMesh, local: np.ndarray) -> float:
    """The model size (:func:`pipeline.tolerances.model_scale`) of the vertices skinned by the
    joint-local transforms ``local`` (b, 4, 4): the model as a clip moves it (bind-space positions
    can be at another scale: lumberjack's mesh is authored in centimetres, bound by x100 binds,
    and moved in metres)."""
    from colossus.runtime.kernels.skin import skin_frames

    from ..model import skel_transforms
    from ..tolerances import model_scale

    mats = skel_transforms(local, mesh.parents) @ np.linalg.inv(mesh.bind_transforms) @ mesh.geom_bind
    return model_scale(skin_frames(mesh.positions, mesh.joint_indices, mesh.joint_weights, mats[None],
                                   dtype=np.float64)[0])


def stored_clips(mesh: SkinnedMesh) -> SkinnedMesh:
    """``mesh`` with every clip's joint-local transforms as the asset will store them.

    UsdSkel stores each joint's translation as ``float3``, rotation as ``quatf`` and scale as
    ``half3`` (the SkelAnimation schema's types).  The spheres must be computed on the motion the
    asset really has, so the pipeline rounds the clips the way :func:`_store_clip` does (the
    translations corrected for the rounded scales) before the ``spheres`` stage; ``write`` then
    stores exactly these values.  The roots' common scale (:func:`root_scale`) is taken out first,
    as the writer does, so it is not rounded.

    Each clip's ``clip_info`` entry (in ``mesh.source``) gets ``storage_error_relative``: the
    bound of :func:`_store_clip` on how far storage moves any vertex, over the model size (as the
    clip's first frame poses it, :func:`_posed_size`).
    """
    k = root_scale(mesh)
    roots = mesh.parents < 0
    centers, dist = _joint_local_points(mesh)
    clips, bounds = [], {}
    for c in mesh.clips:
        local = c.local.copy()
        local[:, roots, :3, :] /= k
        out, norms = _store_clip(local, mesh.parents, centers)
        out[:, roots, :3, :] *= k
        clips.append(type(c)(c.name, c.times, out))
        bounds[c.name] = (_storage_bound(norms, mesh.joint_indices, mesh.joint_weights, dist) * abs(k)
                          / _posed_size(mesh, c.local[0]))
    info = [dict(i, storage_error_relative=bounds[i["name"]]) if i.get("name") in bounds else i
            for i in mesh.source.get("clip_info", [])]
    return mesh.replace(clips=tuple(clips), source=dict(mesh.source, clip_info=info))


def write(mesh: SkinnedMesh, out_path, provenance: dict | None = None):
    """Write ``mesh`` (baked, welded, oriented, bound, with parts and spheres) as a USD asset.

    Parameters
    ----------
    mesh : SkinnedMesh
        Must have ``parts`` with spheres and ``geom_bind`` may be any transform.
    out_path : str or PathLike
        ``.usda``, ``.usdc`` or ``.usd`` (binary crate).
    provenance : dict, optional
        Stored in the collider mesh's ``customData["colossus"]`` (source, sourceSha256,
        importer, settings).

    Returns
    -------
    (SkinnedMesh, StageReport)
    """
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdSkel, Vt

    out = check_output_path(out_path)
    if mesh.parts is None:
        raise ValueError("write needs a mesh with parts (run the parts and spheres stages)")
    tcps = float(mesh.time_codes_per_second)
    if not (np.isfinite(tcps) and tcps > 0):
        raise ValueError(f"write: timeCodesPerSecond must be a positive number, got {tcps}")
    ext = os.path.splitext(out)[1].lower()
    folder = os.path.dirname(os.path.abspath(out))
    from pxr import Tf

    tmp = os.path.join(folder, f".colossus-{os.getpid()}-{os.urandom(4).hex()}{ext}")
    try:
        stage = Usd.Stage.CreateNew(tmp)
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if mesh.up_axis == "Y" else UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(stage, float(mesh.meters_per_unit))
        stage.SetTimeCodesPerSecond(float(mesh.time_codes_per_second))
        stage.SetFramesPerSecond(float(mesh.time_codes_per_second))
        if mesh.clips:
            stage.SetStartTimeCode(float(min(c.times[0] for c in mesh.clips)))
            stage.SetEndTimeCode(float(max(c.times[-1] for c in mesh.clips)))

        stem = os.path.basename(str(mesh.source.get("file") or out)).split(".")[0]
        root_name = _ident(stem or "Collider", set())
        root_path = Sdf.Path("/" + root_name)
        root = UsdSkel.Root.Define(stage, root_path)
        stage.SetDefaultPrim(root.GetPrim())

        # -- skeleton ------------------------------------------------------------------------
        skel = UsdSkel.Skeleton.Define(stage, root_path.AppendChild(schema.SKELETON_NAME))
        jpaths = joint_paths(mesh.joint_names, mesh.parents)
        skel.CreateJointsAttr(Vt.TokenArray(jpaths))
        skel.CreateJointNamesAttr(Vt.TokenArray(list(mesh.joint_names)))
        # the roots' common scale goes onto the Skeleton prim in double precision (see root_scale)
        k = root_scale(mesh)
        roots = mesh.parents < 0
        unscale = np.diag([1.0 / k, 1.0 / k, 1.0 / k, 1.0])
        bind_k = unscale @ mesh.bind_transforms
        rest_k = mesh.rest_transforms.copy()
        rest_k[roots] = unscale @ rest_k[roots]
        if k != 1.0:
            UsdGeom.Xformable(skel.GetPrim()).AddScaleOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(k, k, k))
        skel.CreateBindTransformsAttr(schema.matrices_to_usd(bind_k))
        skel.CreateRestTransformsAttr(schema.matrices_to_usd(rest_k))

        # -- clips ---------------------------------------------------------------------------
        taken = set(RESERVED)
        clip_paths = []
        sampled = {c["name"]: c for c in mesh.source.get("clip_info", [])}
        for clip in mesh.clips:
            name = _ident(clip.name, taken)
            anim = UsdSkel.Animation.Define(stage, root_path.AppendChild(name))
            if name != clip.name:
                anim.GetPrim().SetCustomDataByKey(schema.CLIP_NAME_KEY, clip.name)
            if clip.name in sampled:
                anim.GetPrim().SetCustomDataByKey(schema.CLIP_SOURCE_KEY, _clip_source(sampled[clip.name], mesh))
            anim.CreateJointsAttr(Vt.TokenArray(jpaths))
            local = clip.local.copy()
            local[:, roots] = unscale @ local[:, roots]
            t, q, s = decompose_trs(local)
            # one hemisphere along time: consumers slerp consecutive samples in float (GfSlerp on
            # quatf), which is least exact for nearly opposite quaternions it has to flip
            flip = np.cumsum(np.einsum("fjk,fjk->fj", q[:-1], q[1:]) < 0, axis=0) % 2 == 1
            q[1:][flip] *= -1
            ta, ra, sa = anim.CreateTranslationsAttr(), anim.CreateRotationsAttr(), anim.CreateScalesAttr()
            qxyzw = np.ascontiguousarray(q, dtype=np.float32)
            for f, code in enumerate(clip.times):
                tc = Usd.TimeCode(float(code))
                ta.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(t[f], dtype=np.float32)), tc)
                ra.Set(Vt.QuatfArray.FromNumpy(qxyzw[f]), tc)
                sa.Set(Vt.Vec3hArray.FromNumpy(np.ascontiguousarray(s[f], dtype=np.float16)), tc)
            clip_paths.append(anim.GetPath())
        if clip_paths:
            UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([clip_paths[0]])

        # -- collision mesh ------------------------------------------------------------------
        geo = UsdGeom.Mesh.Define(stage, root_path.AppendChild(schema.COLLIDER_NAME))
        pts = np.ascontiguousarray(mesh.positions, dtype=np.float32)
        geo.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
        geo.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(mesh.face_count, 3, dtype=np.int32)))
        geo.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(mesh.triangles.reshape(-1).astype(np.int32)))
        geo.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
        geo.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        geo.CreateDoubleSidedAttr(False)
        if len(pts):
            geo.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, pts.min(0))), Gf.Vec3f(*map(float, pts.max(0)))]))
        binding = UsdSkel.BindingAPI.Apply(geo.GetPrim())
        binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
        k = mesh.joint_indices.shape[1]
        binding.CreateJointIndicesPrimvar(False, k).Set(Vt.IntArray.FromNumpy(mesh.joint_indices.reshape(-1).astype(np.int32)))
        binding.CreateJointWeightsPrimvar(False, k).Set(Vt.FloatArray.FromNumpy(mesh.joint_weights.reshape(-1).astype(np.float32)))
        geom_bind = unscale @ mesh.geom_bind  # points stay where they are; skeleton space is scaled by k
        if not np.allclose(geom_bind, np.eye(4), rtol=0, atol=1e-12):
            binding.CreateGeomBindTransformAttr(schema.matrices_to_usd(geom_bind))
        UsdPhysics.CollisionAPI.Apply(geo.GetPrim())
        UsdPhysics.MeshCollisionAPI.Apply(geo.GetPrim()).CreateApproximationAttr(UsdPhysics.Tokens.none)

        parts = mesh.parts
        prim = geo.GetPrim()
        schema.write_parts(prim, [jpaths[j] for j in parts.joints], parts.centers, parts.radii,
                           parts.face_offsets, parts.faces)
        if provenance:
            prim.SetCustomDataByKey(schema.PROVENANCE_KEY, _plain(provenance))
        stage.GetRootLayer().documentation = f"Collider asset written by colossus from {mesh.source.get('file', '?')}"
        stage.GetRootLayer().Save()
        del stage
        _check_written(tmp, out, root_path, tcps)
        os.replace(tmp, out)
    except OSError as exc:
        _unlink(tmp)
        raise OutputError(f"{out}: cannot write ({exc.strerror or exc})") from None
    except Tf.ErrorException as exc:
        _unlink(tmp)
        raise OutputError(f"{out}: cannot write ({' '.join(str(exc).split())[:200]})") from None
    except BaseException:
        _unlink(tmp)
        raise
    size = os.path.getsize(out)
    return mesh, StageReport("write", counts={"path": out, "bytes": size, "clips": len(mesh.clips),
                                              "joints": mesh.joint_count, "parts": len(parts)})


def _clip_source(info: dict, mesh: SkinnedMesh) -> dict:
    """How a clip was sampled from its source, for its SkelAnimation's customData."""
    out = {"sourceName": str(info.get("source_name") or ""), "sourceKeys": int(info["source_keys"]),
           "interpolation": str(info["interpolation"]), "sampling": str(info["sampling"]),
           "keysOnGrid": bool(info["keys_on_grid"])}
    if "error_bound_relative" in info:
        from ..tolerances import model_scale
        out["errorBound"] = float(info["error_bound_relative"] * model_scale(mesh.positions))
        out["errorBoundRelative"] = float(info["error_bound_relative"])
    if "storage_error_relative" in info:
        out["storageErrorBoundRelative"] = float(info["storage_error_relative"])
    return out


def _check_written(tmp, out, root_path, tcps) -> None:
    """Re-open the file just written with usd-core and check what every consumer relies on
    first (it opens; frame rates positive; the default prim is the SkelRoot), raising
    :class:`OutputError` before the rename otherwise.

    A text layer is re-read up to its metadata only (where an invalid value such as
    ``framesPerSecond = -1`` makes usd-core refuse the whole file; parsing 100k points again
    would double the stage's time); a crate layer opens lazily, so it is opened whole."""
    from pxr import Sdf, Tf

    text = os.path.splitext(tmp)[1].lower() == ".usda"
    try:
        layer = Sdf.Layer.OpenAsAnonymous(tmp, text)
    except Tf.ErrorException as exc:
        raise OutputError(f"{out}: usd-core cannot re-open the asset just written ({' '.join(str(exc).split())[:200]})") from None
    if layer is None:
        raise OutputError(f"{out}: usd-core cannot re-open the asset just written")
    problems = []
    for key in ("timeCodesPerSecond", "framesPerSecond"):
        v = layer.pseudoRoot.GetInfo(key) if layer.pseudoRoot.HasInfo(key) else None
        if v is None or not (float(v) > 0) or abs(float(v) - tcps) > 1e-9 * tcps:
            problems.append(f"{key} is {v}, expected {tcps:g}")
    if layer.defaultPrim != root_path.name:
        problems.append(f"defaultPrim is {layer.defaultPrim!r}, expected {root_path.name!r}")
    elif not text:
        spec = layer.GetPrimAtPath(root_path)
        if spec is None or spec.typeName != "SkelRoot":
            problems.append("the default prim is not a SkelRoot")
    if problems:
        raise OutputError(f"{out}: the asset just written is not valid USD ({'; '.join(problems)}); nothing written")


def _plain(d):
    """Provenance made of types USD dictionaries hold (str, float, int, bool, nested dicts)."""
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out[str(k)] = _plain(v)
        elif isinstance(v, (bool, int, float, str)):
            out[str(k)] = v
        elif v is None:
            out[str(k)] = ""
        elif isinstance(v, (list, tuple)):
            out[str(k)] = ", ".join(str(x) for x in v)
        else:
            out[str(k)] = str(v)
    return out


def _unlink(p):
    try:
        os.unlink(p)
    except OSError:
        pass
