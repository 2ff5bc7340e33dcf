"""COL1xx structure: the file's prims, stage metadata and the parts attributes."""

from __future__ import annotations

import numpy as np
from pxr import UsdGeom, UsdPhysics

from colossus.runtime import schema

from ..registry import hit, rule

_USD_VALIDATORS = None


def _usd_validation(asset):
    """UsdValidation (the successor of UsdUtils.ComplianceChecker) findings, run once per asset."""
    global _USD_VALIDATORS
    if "_usd_validation" not in asset.__dict__:
        from pxr import UsdValidation
        if _USD_VALIDATORS is None:
            reg = UsdValidation.ValidationRegistry()
            names = [m.name for m in reg.GetAllValidatorMetadata() if not m.isSuite]
            _USD_VALIDATORS = reg.GetOrLoadValidatorsByName(names)
        errors = UsdValidation.ValidationContext(_USD_VALIDATORS).Validate(asset.stage)
        out = []
        for e in errors:
            sites = []
            for s in e.GetSites():
                if s.IsPrim():
                    sites.append(str(s.GetPrim().GetPath()))
                elif s.IsProperty():
                    sites.append(str(s.GetProperty().GetPath()))
            out.append((e.GetType().name, e.GetIdentifier() or e.GetName(), e.GetMessage(), sites))
        asset.__dict__["_usd_validation"] = out
    return asset.__dict__["_usd_validation"]


@rule("COL101", "usd-validation-error", "error",
      "usd-core's own validators (UsdValidation, successor of UsdUtils.ComplianceChecker) report an error.")
def usd_validation_error(asset, ctx):
    """What: every error-type finding of usd-core's registered validators (UsdValidation: core,
    geom, skel, physics, shade, utils), passed through with the validator's identifier.
    Why: any UsdSkel consumer must read the asset the way the runtime does; usd-core's checks
    are the reference for what a well-formed stage is.
    Example: `SkelBindingAPI` applied to a prim outside any SkelRoot."""
    for kind, ident, msg, sites in _usd_validation(asset):
        if kind == "Error":
            yield hit(f"{ident}: {msg}", validator=ident, prim=sites[0] if sites else None)


@rule("COL102", "usd-validation-warning", "warning",
      "usd-core's own validators report a warning or note.")
def usd_validation_warning(asset, ctx):
    """What: warning- and info-type findings of usd-core's registered validators, passed through.
    Why: they usually point at something other tools will trip on.
    Example: a stage without `metersPerUnit`."""
    for kind, ident, msg, sites in _usd_validation(asset):
        if kind != "Error":
            yield hit(f"{ident}: {msg}", validator=ident, prim=sites[0] if sites else None)


@rule("COL103", "stage-metadata", "error",
      "upAxis, metersPerUnit and timeCodesPerSecond must be authored and truthful; defaultPrim is the SkelRoot.")
def stage_metadata(asset, ctx):
    """What: `upAxis` (Y or Z), `metersPerUnit` (> 0) and `timeCodesPerSecond` (> 0) are authored
    on the root layer, and `defaultPrim` names the SkelRoot.
    Why: the runtime scales, orients and times the collider from these; a default silently
    assumed is a collider that is 100x too big or plays at the wrong speed.
    Example: a stage written without `metersPerUnit`, or `defaultPrim = "Collider"`."""
    s = asset.stage
    for key in ("upAxis", "metersPerUnit", "timeCodesPerSecond"):
        if not s.HasAuthoredMetadata(key):
            yield hit(f"stage metadata {key} is not authored")
    if s.HasAuthoredMetadata("upAxis") and UsdGeom.GetStageUpAxis(s) not in ("Y", "Z"):
        yield hit(f"upAxis is {UsdGeom.GetStageUpAxis(s)!r}, expected 'Y' or 'Z'")
    mpu = UsdGeom.GetStageMetersPerUnit(s)
    if not (np.isfinite(mpu) and mpu > 0):
        yield hit(f"metersPerUnit is {mpu}, expected a positive number")
    tcps = s.GetTimeCodesPerSecond()
    if not (np.isfinite(tcps) and tcps > 0):
        yield hit(f"timeCodesPerSecond is {tcps}, expected a positive number")
    dp = s.GetDefaultPrim()
    if not dp:
        yield hit("defaultPrim is not set (expected the SkelRoot)")
    elif asset.root is None or dp.GetPath() != asset.root.GetPath():
        yield hit(f"defaultPrim {dp.GetPath()} is not the SkelRoot", prim=str(dp.GetPath()))


@rule("COL104", "one-skel-root", "error", "Exactly one SkelRoot holds the collider.")
def one_skel_root(asset, ctx):
    """What: the stage has exactly one `SkelRoot` prim.
    Why: the runtime and every UsdSkel consumer find the rig through its SkelRoot; two are ambiguous,
    none means nothing is skinned.
    Example: a stage whose top prim is an `Xform` instead of a `SkelRoot`."""
    n = len(asset.skel_roots)
    if n != 1:
        yield hit(f"found {n} SkelRoot prims, expected 1",
                  prim=", ".join(str(p.GetPath()) for p in asset.skel_roots) or None, count=n)


@rule("COL105", "one-skeleton", "error",
      "Exactly one Skeleton under the SkelRoot, with joints, bindTransforms and restTransforms, one per joint.",
      needs=("root",))
def one_skeleton(asset, ctx):
    """What: one `Skeleton` prim under the SkelRoot; its `joints` is non-empty and
    `bindTransforms` / `restTransforms` have one finite matrix per joint.
    Why: parts, spheres and skinning all index this one joint list.
    Example: `bindTransforms` with 2 matrices for 3 joints."""
    skels = [p for p in asset.skeletons if p.GetPath().HasPrefix(asset.root.GetPath())]
    if len(skels) != 1:
        yield hit(f"found {len(skels)} Skeleton prims under {asset.root.GetPath()}, expected 1", count=len(skels))
    if asset.skeleton is None:
        return
    prim = str(asset.skeleton.GetPath())
    b = len(asset.joints or [])
    if b == 0:
        yield hit("the Skeleton has no joints", prim=prim)
        return
    for name, m in (("bindTransforms", asset.bind), ("restTransforms", asset.rest)):
        if m is None:
            yield hit(f"{name} is missing", prim=prim)
        elif len(m) != b:
            yield hit(f"{name} has {len(m)} matrices for {b} joints", prim=prim)
        elif not np.all(np.isfinite(m)):
            yield hit(f"{name} has non-finite entries", prim=prim)


@rule("COL106", "collision-mesh", "error",
      "Exactly one collision Mesh under the SkelRoot, bound to the Skeleton, with the physics collision APIs.",
      needs=("root",))
def collision_mesh(asset, ctx):
    """What: one `Mesh` under the SkelRoot, with `UsdSkelBindingAPI` and `skel:skeleton` targeting
    the Skeleton, `PhysicsCollisionAPI` and `PhysicsMeshCollisionAPI` (approximation `none`), and
    `orientation = rightHanded`.
    Why: physics engines only treat the mesh as an exact triangle collider with these, and a
    mesh not bound to the skeleton does not move.
    Example: the mesh's `physics:approximation` is `convexHull`."""
    meshes = [p for p in asset.meshes if p.GetPath().HasPrefix(asset.root.GetPath())]
    if len(meshes) != 1:
        yield hit(f"found {len(meshes)} Mesh prims under {asset.root.GetPath()}, expected 1", count=len(meshes))
    if asset.mesh is None:
        return
    prim = str(asset.mesh.GetPath())
    if asset.skeleton is not None and asset.mesh_skeleton_targets != [str(asset.skeleton.GetPath())]:
        yield hit(f"skel:skeleton targets {asset.mesh_skeleton_targets}, expected [{asset.skeleton.GetPath()}]",
                  prim=prim)
    schemas = asset.mesh.GetAppliedSchemas()
    for api in ("SkelBindingAPI", "PhysicsCollisionAPI", "PhysicsMeshCollisionAPI"):
        if api not in schemas:
            yield hit(f"{api} is not applied", prim=prim)
    if "PhysicsMeshCollisionAPI" in schemas:
        approx = UsdPhysics.MeshCollisionAPI(asset.mesh).GetApproximationAttr().Get()
        if approx != "none":
            yield hit(f"physics:approximation is {approx!r}, expected 'none'", prim=prim)
    if asset.orientation != UsdGeom.Tokens.rightHanded:
        yield hit(f"orientation is {asset.orientation!r}, expected 'rightHanded'", prim=prim)


@rule("COL107", "parts-attributes", "error",
      "The colossus:parts:* attributes are all present with their contract types.", needs=("mesh_raw",))
def parts_attributes(asset, ctx):
    """What: `colossus:parts:joints` token[], `centers` float3[], `radii` float[], `faceOffsets`
    int[], `faces` int[] are authored on the collision mesh.
    Why: without them the runtime has no parts and no broad phase.
    Example: `colossus:parts:radii` authored as `double[]`."""
    for name, why in asset.parts_attr_errors.items():
        yield hit(f"{name}: {why}", prim=str(asset.mesh.GetPath()))


@rule("COL108", "parts-lengths", "error",
      "Parts attributes have consistent lengths: P joints, centres, radii; P+1 non-decreasing offsets ending at len(faces).",
      needs=("mesh_raw",))
def parts_lengths(asset, ctx):
    """What: with P = len(joints): len(centers) = len(radii) = P, len(faceOffsets) = P + 1,
    offsets start at 0, never decrease, and end at len(faces).
    Why: the CSR layout is read without bounds checks at run time.
    Example: 3 joints but 2 radii; offsets `[0, 5, 4, 9]`."""
    if asset.parts_attr_errors:
        return
    P = len(asset.part_joints)
    for name, arr, want in (("centers", asset.part_centers, P), ("radii", asset.part_radii, P),
                            ("faceOffsets", asset.part_offsets, P + 1)):
        if len(arr) != want:
            yield hit(f"colossus:parts:{name} has {len(arr)} entries, expected {want} ({P} parts)")
    o = asset.part_offsets
    if len(o) and (o[0] != 0 or o[-1] != len(asset.part_faces) or np.any(np.diff(o) < 0)):
        bad = int(np.argmax(np.diff(o) < 0)) if np.any(np.diff(o) < 0) else None
        yield hit(f"faceOffsets must rise from 0 to len(faces) = {len(asset.part_faces)}; "
                  f"got first {o[0]}, last {o[-1]}" + (f", decreasing at part {bad}" if bad is not None else ""),
                  part=bad)


@rule("COL109", "parts-indices", "error",
      "Part faces index existing triangles and part joints name existing skeleton joints.",
      needs=("mesh", "skeleton"))
def parts_indices(asset, ctx):
    """What: every entry of `colossus:parts:faces` is in [0, face count) and every entry of
    `colossus:parts:joints` is one of the Skeleton's `joints`.
    Why: an out-of-range index crashes or silently corrupts the runtime.
    Example: a part naming joint `root/spine` when the skeleton calls it `root/Spine`."""
    if asset.parts_attr_errors:
        return
    F = len(asset.tris)
    f = asset.part_faces
    bad = np.nonzero((f < 0) | (f >= F))[0]
    if len(bad):
        yield hit(f"{len(bad)} part face entries out of range [0, {F}), first {int(f[bad[0]])} at "
                  f"position {int(bad[0])}", face=int(f[bad[0]]), count=len(bad))
    for p, j in enumerate(asset.part_joints):
        if j not in asset.joint_index:
            yield hit(f"part {p} names joint {j!r}, which the Skeleton does not have", part=p, joint=j)


@rule("COL110", "provenance", "warning",
      "The mesh's customData records where the asset came from (source, sourceSha256, importer, settings).",
      needs=("mesh_raw",))
def provenance(asset, ctx):
    """What: `customData["colossus"]` on the collision mesh is a dictionary with `source`,
    `sourceSha256`, `importer` and `settings`.
    Why: a failing asset must be traceable to the export and the importer version that made it.
    Example: an asset edited by hand with its customData stripped."""
    data = asset.mesh.GetCustomDataByKey(schema.PROVENANCE_KEY)
    if not isinstance(data, dict):
        yield hit("customData has no 'colossus' provenance dictionary", prim=str(asset.mesh.GetPath()))
        return
    missing = [k for k in ("source", "sourceSha256", "importer", "settings") if k not in data]
    if missing:
        yield hit(f"provenance lacks {', '.join(missing)}", prim=str(asset.mesh.GetPath()))
