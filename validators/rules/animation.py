"""COL5xx animation: the SkelAnimation clips."""

from __future__ import annotations

import numpy as np
from pxr import Usd

from .. import tolerances as tol
from ..registry import hit, rule


@rule("COL501", "clip-has-frames", "error", "Every clip has at least one time sample.", needs=("clips",))
def clip_has_frames(asset, ctx):
    """What: each SkelAnimation's translations/rotations/scales have at least one time sample.
    Why: a clip's frames are exactly its time samples; a clip without any is not a clip.
    Example: a SkelAnimation with only default values."""
    for c in asset.clips:
        if len(c.times) == 0:
            yield hit(f"clip {c.name!r} has no time samples", clip=c.name, prim=str(c.prim.GetPath()))


@rule("COL502", "time-code-rate", "error",
      "Clip samples sit on whole time codes, one per frame at timeCodesPerSecond, without gaps.", needs=("clips",))
def time_code_rate(asset, ctx):
    """What: every time sample of a clip is a whole number and consecutive samples are exactly
    1 apart (one sample per source frame at the stage's `timeCodesPerSecond`).
    Why: the runtime maps seconds to frames with `timeCodesPerSecond`; off-grid or missing
    samples play at the wrong speed or interpolate across a gap nobody checked.
    Example: samples at 0, 2.5, 5 (a 24 fps clip written on a 60 fps grid)."""
    for c in asset.clips:
        t = c.times
        if len(t) == 0:
            continue
        off = np.nonzero(np.abs(t - np.round(t)) > tol.TIME_CODE_EPS)[0]
        if len(off):
            i = int(off[0])
            yield hit(f"clip {c.name!r}: {len(off)} samples are not on whole time codes, first at {t[i]:g}",
                      clip=c.name, time=float(t[i]), frame=i, count=len(off))
            continue
        gaps = np.nonzero(np.abs(np.diff(t) - 1) > tol.TIME_CODE_EPS)[0]
        if len(gaps):
            i = int(gaps[0])
            yield hit(f"clip {c.name!r}: samples {t[i]:g} and {t[i + 1]:g} are not one frame apart "
                      f"({len(gaps)} irregular steps)", clip=c.name, time=float(t[i]), frame=i, count=len(gaps))


@rule("COL503", "finite-animation", "error",
      "No NaN or infinite translation, rotation or scale, and no zero-length rotation, on any frame.",
      needs=("clips",))
def finite_animation(asset, ctx):
    """What: at every time sample, every joint's translation, rotation (non-zero quaternion) and
    scale is finite, and so are the joints' transforms composed down the hierarchy (within 1e18).
    Why: one NaN joint transform throws its vertices and its part sphere to NaN.
    Example: a rotation `(nan, 0, 0, 0)` on frame 12 from a degenerate bake."""
    for c in asset.clips:
        for a, t, kind, joint in asset.clip_sample_issues[c.name]:
            if kind != "nonfinite":
                continue
            frame = int(np.searchsorted(c.times, t))
            what = (f"the transform of joint {joint!r}, composed down the hierarchy, overflows"
                    if a == "composed transforms" else f"{a} of joint {joint!r} is not finite (or a zero rotation)")
            yield hit(f"clip {c.name!r} time {t:g}: {what}",
                      clip=c.name, time=float(t), frame=frame, joint=joint)


@rule("COL504", "unique-clip-names", "error", "Clip names are unique.", needs=("root",))
def unique_clip_names(asset, ctx):
    """What: no two SkelAnimation prims on the stage share a name.
    Why: clips are looked up by name at run time.
    Example: `/Boss/walk` and `/Boss/Skeleton/walk`."""
    names = {}
    for p in asset.animations:
        names.setdefault(p.GetName(), []).append(str(p.GetPath()))
    for name, paths in names.items():
        if len(paths) > 1:
            yield hit(f"clip name {name!r} is used by {len(paths)} SkelAnimation prims: {', '.join(paths)}",
                      clip=name, count=len(paths))


@rule("COL505", "clip-joints", "error", "Each clip animates the skeleton's joints, in the skeleton's order.",
      needs=("clips",))
def clip_joints(asset, ctx):
    """What: each clip's `joints` equals the Skeleton's `joints`, element for element.
    Why: the contract writes clips in skeleton order so consumers need no remapping; a
    missing joint silently stays at rest.
    Example: a clip listing `root/mid` before `root`."""
    for c in asset.clips:
        if c.joints != asset.joints:
            extra = [j for j in c.joints if j not in asset.joint_index]
            missing = [j for j in asset.joints if j not in c.joints]
            detail = (f"unknown {extra[:3]}" if extra else "") + (f" missing {missing[:3]}" if missing else "")
            yield hit(f"clip {c.name!r}: joints differ from the skeleton's ({detail.strip() or 'different order'})",
                      clip=c.name)
        for a, t, kind, n in asset.clip_sample_issues[c.name]:
            if kind == "length":  # on any sample, not only the first: AnimQuery would pose it at identity
                yield hit(f"clip {c.name!r}: {a} has {n} entries for {len(c.joints)} joints", clip=c.name, time=t)


@rule("COL506", "has-clips", "warning", "The SkelRoot holds at least one clip.", needs=("root",))
def has_clips(asset, ctx):
    """What: at least one SkelAnimation prim is a direct child of the SkelRoot.
    Why: a collider without animation cannot be proven on any frame; only the bind pose is checked.
    Example: an export with "bake animation" switched off."""
    if not asset.clips:
        yield hit(f"no SkelAnimation clips under {asset.root.GetPath()}: only the bind pose was checked")


@rule("COL507", "clip-location", "warning", "Every SkelAnimation is a direct child of the SkelRoot.",
      needs=("root",))
def clip_location(asset, ctx):
    """What: SkelAnimation prims sit directly under the SkelRoot, where the runtime looks for clips.
    Why: a clip elsewhere is not checked by the frame proof and not played by the runtime.
    Example: `/Boss/Skeleton/walk`."""
    clip_paths = {str(c.prim.GetPath()) for c in asset.clips}
    for p in asset.animations:
        if str(p.GetPath()) not in clip_paths:
            yield hit(f"SkelAnimation {p.GetPath()} is not a direct child of {asset.root.GetPath()} "
                      f"(not checked, not played)", prim=str(p.GetPath()), clip=p.GetName())


@rule("COL508", "animation-source", "warning",
      "The Skeleton's skel:animationSource targets the first clip.", needs=("clips",))
def animation_source(asset, ctx):
    """What: the Skeleton has `UsdSkelBindingAPI` with `skel:animationSource` targeting the first
    clip under the SkelRoot.
    Why: usdview and `UsdSkel.BakeSkinning` show the bound clip; the contract binds the first.
    Example: no animationSource, so other tools show the rest pose."""
    rel = asset.skeleton.GetRelationship("skel:animationSource")
    targets = [str(t) for t in rel.GetTargets()] if rel else []
    want = str(asset.clips[0].prim.GetPath())
    if targets != [want]:
        yield hit(f"skel:animationSource targets {targets}, expected [{want}]", prim=str(asset.skeleton.GetPath()))


@rule("COL509", "clip-variants", "warning",
      "The SkelRoot's variant set 'clip' binds each clip as skel:animationSource, the first clip the default selection.",
      needs=("clips",))
def clip_variants(asset, ctx):
    """What: the SkelRoot has a variant set `clip` with one variant per clip, named as the clip,
    whose opinion on the Skeleton is `skel:animationSource` = that clip; its selection is the first
    clip; and no opinion outside the variants binds a clip (a local `skel:animationSource` on the
    Skeleton is stronger than every variant: switching would change nothing).  Read from the
    asset's layer (the variants' specs), so the stage checked is never edited.
    Why: UsdSkel binds one animation; the variants are how usdview, Blender and Omniverse users reach
    every other clip (the runtime and the proof read every SkelAnimation directly).
    Example: an asset written before the variant set existed: other tools show one clip of ten."""
    from colossus.runtime import schema

    root = asset.root
    where = str(root.GetPath())
    clip_paths = {c.name: str(c.prim.GetPath()) for c in asset.clips}
    vset = root.GetVariantSets().GetVariantSet(schema.CLIP_VARIANT_SET) if root.GetVariantSets().HasVariantSet(
        schema.CLIP_VARIANT_SET) else None
    if vset is None:
        yield hit(f"{where} has no variant set {schema.CLIP_VARIANT_SET!r}: other USD tools reach only the bound "
                  f"clip of {len(clip_paths)}", prim=where)
        return
    names = set(vset.GetVariantNames())
    missing = [c for c in clip_paths if c not in names]
    if missing:
        yield hit(f"{len(missing)} clip(s) have no variant in {schema.CLIP_VARIANT_SET!r}, first {missing[0]!r}: "
                  "other USD tools cannot reach them", prim=where, clip=missing[0], count=len(missing))
    sel = vset.GetVariantSelection()
    first = asset.clips[0].name
    if sel != first:
        yield hit(f"the {schema.CLIP_VARIANT_SET!r} variant selection is {sel!r}, expected the first clip {first!r}",
                  prim=where, clip=first)
    skel_rel = f"{asset.skeleton.GetPath().name}"
    rel_name = "skel:animationSource"

    def targets(prim_spec):
        """The skeleton's authored animationSource targets in ``prim_spec`` (the root's spec or a
        variant's), or None where it has no opinion."""
        if prim_spec is None or asset.skeleton.GetPath().GetParentPath() != root.GetPath():
            return None
        child = prim_spec.nameChildren.get(skel_rel) if prim_spec.nameChildren else None
        rel = child.relationships.get(rel_name) if child is not None and child.relationships else None
        if rel is None:
            return None
        items = rel.targetPathList
        return [str(p) for p in (items.explicitItems if items.isExplicit else
                                 list(items.prependedItems) + list(items.appendedItems) + list(items.addedItems))]

    layer = asset.stage.GetRootLayer()
    spec = layer.GetPrimAtPath(root.GetPath())
    local = targets(spec)
    if local:
        yield hit(f"{asset.skeleton.GetPath()} binds {local} outside the {schema.CLIP_VARIANT_SET!r} variants: that "
                  "opinion is stronger than every variant, so switching them changes nothing",
                  prim=str(asset.skeleton.GetPath()))
    vspecs = spec.variantSets.get(schema.CLIP_VARIANT_SET) if spec is not None and spec.variantSets else None
    for name in sorted(names & set(clip_paths)):
        v = vspecs.variants.get(name) if vspecs is not None else None
        got = targets(v.primSpec) if v is not None else None
        if got != [clip_paths[name]]:
            yield hit(f"variant {name!r} binds {got} as the Skeleton's {rel_name}, expected [{clip_paths[name]}]",
                      prim=where, clip=name)


@rule("COL518", "invertible-poses", "error",
      "Every joint's transform is invertible on every frame and between frames: no zero scale, no scale "
      "changing sign between samples.", needs=("clips",))
def invertible_poses(asset, ctx):
    """What: on every frame of every clip, every joint's transform composed down the hierarchy is
    an affine matrix whose 3x3 part has |det| > 1e-12; no animated scale is below 2^-22 on an
    axis, and none changes sign between two samples (UsdSkel lerps scales, so it would pass
    through 0 in between).
    Why: the frame proof measures each part in its joint's space, the inverse of the joint's
    pose, and a joint squashed to nothing has none; a zero scale is not a pose a collider can be
    proven (or a ball moved) in.
    Example: a scale of `(0, 0, 0)` on frame 4, or `(1, 1, 1)` then `(-1, 1, 1)` on the next frame."""
    for c in asset.clips:
        for a, t, kind, detail in asset.clip_sample_issues[c.name]:
            if kind != "singular":
                continue
            joint, why = detail
            yield hit(f"clip {c.name!r} time {t:g}: joint {joint!r} {why}",
                      clip=c.name, time=float(t), frame=int(np.searchsorted(c.times, t)), joint=joint)
