"""Stage 7, ``write``: the USD collider asset, exactly as ``shared/CONTRACT.md`` lays it out.

Layout (``<Name>`` is the source file's stem made a valid identifier)::

    /<Name>                 SkelRoot (defaultPrim)
    /<Name>                 variant set "clip": variant <clip> binds /<Name>/<clip> as the
                            Skeleton's skel:animationSource (default selection: the first clip)
    /<Name>/Skeleton        Skeleton: joints, bindTransforms, restTransforms (its
                            skel:animationSource is authored in the "clip" variants only)
    /<Name>/Collider        Mesh: triangles, rightHanded, UsdSkelBindingAPI (jointIndices /
                            jointWeights, elementSize = max influences; skinningMethod
                            "dualQuaternion" where the source skins so), PhysicsCollisionAPI,
                            PhysicsMeshCollisionAPI (approximation "none"), colossus:parts:*,
                            customData["colossus"] = provenance
    /<Name>/<clip>          SkelAnimation per clip, one time sample per source frame
    /<Name>/PartSpheres     Scope (purpose guide): per part p a Sphere ``p<p>_<joint>``, purpose
                            guide, radius = the part's, rigidly bound to the part's joint
                            (constant jointIndices / jointWeights of one, geomBindTransform =
                            bind_j @ T(centre), the same as its xform), customData colossus:part = p

The file is written to a temporary name in the output directory, re-opened with usd-core and
checked (:func:`_check_written`), then handed to the caller's ``check`` (the command line runs the
validator's error rules on it: the pipeline, a floor below the validators, cannot import them), and
only then renamed into place: a failed import never leaves a partial asset behind, nothing usd-core
cannot open is ever written, and nothing the caller's check refuses either.
"""

from __future__ import annotations

import os
import time

import numpy as np

from colossus.runtime import schema

from ..errors import InputError, OutputError
from ..tempfiles import clean_stale, temp_path
from ..model import SkinnedMesh
from . import StageReport

OUTPUT_EXTENSIONS = (".usda", ".usdc", ".usd")
RESERVED = (schema.SKELETON_NAME, schema.COLLIDER_NAME, schema.GUIDES_NAME)


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
        probe = temp_path(folder, ".probe")
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        os.unlink(probe)
    except OSError as exc:
        raise OutputError(f"{out}: output directory {folder} is not writable ({exc.strerror or exc})") from None
    return out


def write(mesh: SkinnedMesh, out_path, provenance: dict | None = None, check=None):
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
    check : callable, optional
        ``check(path) -> None | str`` run on the temporary file, fully written and re-opened,
        before the rename: a string is the one-line reason to refuse the asset (the command line
        passes the validator's error rules: ``"COL204: 2 triangles have zero area ..."``), raised as
        :class:`InputError` naming the source, with nothing written.

    Returns
    -------
    (SkinnedMesh, StageReport)
    """
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, UsdSkel, Vt

    out = check_output_path(out_path)
    if mesh.parts is None:
        raise ValueError("write needs a mesh with parts (run the parts and spheres stages)")
    if len(mesh.stored_clips) != len(mesh.clips):
        raise ValueError("write needs the clips as stored (run the quantize stage)")
    tcps = float(mesh.time_codes_per_second)
    if not (np.isfinite(tcps) and tcps > 0):
        raise ValueError(f"write: timeCodesPerSecond must be a positive number, got {tcps}")
    ext = os.path.splitext(out)[1].lower()
    folder = os.path.dirname(os.path.abspath(out))
    from pxr import Tf

    clean_stale(folder)  # what a killed write left here
    tmp = temp_path(folder, ext)
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
        # no unit scale on the Skeleton prim: quantize folded the roots' common scale into the
        # translations (quantize.fold_root_scale)
        if mesh.root_scale != 1.0:
            raise ValueError("write: the roots' scale is not folded (run the quantize stage first)")
        skel.CreateBindTransformsAttr(schema.matrices_to_usd(mesh.bind_transforms))
        skel.CreateRestTransformsAttr(schema.matrices_to_usd(mesh.rest_transforms))

        # -- clips ---------------------------------------------------------------------------
        taken = set(RESERVED)
        shape_names = _shape_names(mesh)
        clip_paths = []
        sampled = {c["name"]: c for c in mesh.source.get("clip_info", [])}
        for clip, stored in zip(mesh.clips, mesh.stored_clips, strict=True):
            name = _ident(clip.name, taken)
            anim = UsdSkel.Animation.Define(stage, root_path.AppendChild(name))
            if name != clip.name:
                anim.GetPrim().SetCustomDataByKey(schema.CLIP_NAME_KEY, clip.name)
            if clip.name in sampled:
                anim.GetPrim().SetCustomDataByKey(schema.CLIP_SOURCE_KEY, _clip_source(sampled[clip.name], mesh))
            anim.CreateJointsAttr(Vt.TokenArray(jpaths))
            t, q, s = stored.vt, stored.vr, stored.vs
            ta, ra, sa = anim.CreateTranslationsAttr(), anim.CreateRotationsAttr(), anim.CreateScalesAttr()
            qxyzw = np.ascontiguousarray(q, dtype=np.float32)
            for f, code in enumerate(clip.times):
                tc = Usd.TimeCode(float(code))
                ta.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(t[f], dtype=np.float32)), tc)
                ra.Set(Vt.QuatfArray.FromNumpy(qxyzw[f]), tc)
                sa.Set(Vt.Vec3hArray.FromNumpy(np.ascontiguousarray(s[f], dtype=np.float16)), tc)
            _write_shape_weights(anim, clip, stored, shape_names)
            clip_paths.append(anim.GetPath())
        _clip_variants(stage, root, skel, clip_paths)

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
        if mesh.skinning_method != UsdSkel.Tokens.classicLinear:  # UsdSkel's default is linear
            binding.CreateSkinningMethodAttr().Set(mesh.skinning_method)
        if not np.allclose(mesh.geom_bind, np.eye(4), rtol=0, atol=1e-12):
            binding.CreateGeomBindTransformAttr(schema.matrices_to_usd(mesh.geom_bind))
        _write_blend_shapes(stage, geo, mesh, shape_names)
        UsdPhysics.CollisionAPI.Apply(geo.GetPrim())
        UsdPhysics.MeshCollisionAPI.Apply(geo.GetPrim()).CreateApproximationAttr(UsdPhysics.Tokens.none)

        parts = mesh.parts
        prim = geo.GetPrim()
        schema.write_parts(prim, [jpaths[j] for j in parts.joints], parts.centers, parts.radii,
                           parts.face_offsets, parts.faces)
        _guide_spheres(stage, root_path, skel, mesh)
        if provenance:
            prim.SetCustomDataByKey(schema.PROVENANCE_KEY, _plain(provenance))
        stage.GetRootLayer().documentation = f"Collider asset written by colossus from {mesh.source.get('file', '?')}"
        stage.GetRootLayer().Save()
        del stage
        _check_written(tmp, out, root_path, tcps)
        checked = None
        if check is not None:
            t_check = time.perf_counter()
            refusal = check(tmp)
            checked = time.perf_counter() - t_check
            if refusal:
                raise InputError(mesh.source.get("path") or mesh.source.get("file") or out, refusal)
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
    counts = {"path": out, "bytes": size, "clips": len(mesh.clips), "joints": mesh.joint_count, "parts": len(parts),
              "skinning_method": mesh.skinning_method, "blend_shapes": len(mesh.blend_shapes)}
    if checked is not None:
        counts["check_seconds"] = checked
    return mesh, StageReport("write", counts=counts)


def _shape_names(mesh: SkinnedMesh) -> list:
    """The blend shapes' prim names under the collision mesh, also their ``skel:blendShapes``
    tokens and the clips' ``blendShapes`` (valid identifiers, unique)."""
    taken = set()
    return [_ident(s.name, taken) for s in mesh.blend_shapes]


def _write_blend_shapes(stage, geo, mesh: SkinnedMesh, names) -> None:
    """One ``UsdSkel.BlendShape`` per shape under the collision mesh (``offsets``,
    ``pointIndices``, ``inbetweens:*`` with their weights), named by ``skel:blendShapes`` and
    targeted by ``skel:blendShapeTargets`` in that order (shared/CONTRACT.md)."""
    from pxr import Vt, UsdSkel

    if not mesh.blend_shapes:
        return
    binding = UsdSkel.BindingAPI(geo.GetPrim())
    paths = []
    for shape, name in zip(mesh.blend_shapes, names, strict=True):
        bs = UsdSkel.BlendShape.Define(stage, geo.GetPath().AppendChild(name))
        bs.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(shape.offsets, dtype=np.float32)))
        bs.CreatePointIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(shape.indices, dtype=np.int32)))
        for k, (w, off) in enumerate(shape.inbetweens):
            ib = bs.CreateInbetween(f"inbetween{k}")
            ib.SetWeight(float(w))
            ib.SetOffsets(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(off, dtype=np.float32)))
        if name != shape.name:
            bs.GetPrim().SetCustomDataByKey(schema.SHAPE_NAME_KEY, shape.name)
        paths.append(bs.GetPath())
    binding.CreateBlendShapesAttr(Vt.TokenArray(list(names)))
    binding.CreateBlendShapeTargetsRel().SetTargets(paths)


def _write_shape_weights(anim, clip, stored, names) -> None:
    """The clip's blend-shape weights in its SkelAnimation (``blendShapes``,
    ``blendShapeWeights``, one float32 sample per frame: the values ``quantize`` stored)."""
    from pxr import Usd, Vt

    if not names:
        return
    w = stored.shape_weights(clip.times, len(names))
    anim.CreateBlendShapesAttr(Vt.TokenArray(list(names)))
    attr = anim.CreateBlendShapeWeightsAttr()
    for f, code in enumerate(clip.times):
        attr.Set(Vt.FloatArray.FromNumpy(np.ascontiguousarray(w[f], dtype=np.float32)), Usd.TimeCode(float(code)))


def _clip_variants(stage, root, skel, clip_paths) -> None:
    """The SkelRoot's variant set ``clip``: one variant per clip (named as its prim), binding it
    as the Skeleton's ``skel:animationSource``; the first clip is the default selection.  The
    relationship lives in the variants only (a local opinion would be stronger than any variant),
    so every USD tool reaches every clip by switching the variant; the ``SkelAnimation`` prims
    themselves stay plain children of the SkelRoot, which our readers list directly."""
    from pxr import UsdSkel

    if not clip_paths:
        return
    UsdSkel.BindingAPI.Apply(skel.GetPrim())
    vset = root.GetPrim().GetVariantSets().AddVariantSet(schema.CLIP_VARIANT_SET)
    for path in clip_paths:
        vset.AddVariant(path.name)
        vset.SetVariantSelection(path.name)
        with vset.GetVariantEditContext():
            UsdSkel.BindingAPI(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([path])
    vset.SetVariantSelection(clip_paths[0].name)


def _guide_spheres(stage, root_path, skel, mesh: SkinnedMesh) -> None:
    """Per part a guide-purpose ``UsdGeom.Sphere`` under ``<root>/PartSpheres``, rigidly bound to
    the part's joint (UsdSkel's constant-interpolation joint binding, one influence of weight 1)
    so that every UsdSkel consumer moves it with the body: ``geomBindTransform`` (and the
    sphere's own transform, what a viewer that does not skin shows) is ``bind_j @ T(centre)``
    (:func:`runtime.schema.guide_bind_transform`) with the centre and radius exactly as stored
    in ``colossus:parts:*`` (float32), which stay the truth (the validator's COL408 checks the two
    agree)."""
    from pxr import Gf, UsdGeom, UsdSkel, Vt

    parts = mesh.parts
    if parts is None or len(parts) == 0:
        return
    scope = UsdGeom.Scope.Define(stage, root_path.AppendChild(schema.GUIDES_NAME))
    scope.CreatePurposeAttr(UsdGeom.Tokens.guide)
    centers = np.asarray(parts.centers, dtype=np.float32).astype(np.float64).reshape(-1, 3)
    radii = np.asarray(parts.radii, dtype=np.float32).astype(np.float64).reshape(-1)
    taken = set()
    for p, j in enumerate(np.asarray(parts.joints, dtype=np.int64)):
        name = _ident(f"p{p}_{mesh.joint_names[j]}", taken)
        sphere = UsdGeom.Sphere.Define(stage, scope.GetPath().AppendChild(name))
        r = float(radii[p])
        sphere.CreateRadiusAttr(r)
        sphere.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-r, -r, -r), Gf.Vec3f(r, r, r)]))
        sphere.CreatePurposeAttr(UsdGeom.Tokens.guide)
        gb = schema.guide_bind_transform(mesh.bind_transforms[j], centers[p])
        sphere.AddTransformOp().Set(schema.matrices_to_usd(gb))
        binding = UsdSkel.BindingAPI.Apply(sphere.GetPrim())
        binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
        binding.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([int(j)]))
        binding.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
        binding.CreateGeomBindTransformAttr(schema.matrices_to_usd(gb))
        sphere.GetPrim().SetCustomDataByKey(schema.GUIDE_PART_KEY, int(p))


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
