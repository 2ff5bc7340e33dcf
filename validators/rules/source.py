"""COL6xx source: the asset against the export it was made from (``colossus validate --source FILE``).

These rules run only when a source is given (``check_asset(..., source=FILE)``); the comparison
itself is :func:`validators.source.compare_source`, run once per asset and shared.
"""

from __future__ import annotations

from .. import tolerances as tol
from ..registry import hit, rule


def _check(asset, ctx):
    return ctx.source_check() if ctx.source else None


@rule("COL601", "source-motion", "error",
      "With --source: the asset's motion matches the source's within 1e-4 x model size on every frame.",
      needs=("skin_ok", "clips"))
def source_motion(asset, ctx):
    """What: every vertex of the asset, skinned by its own UsdSkel data on every frame of every
    clip, lies within 1e-4 x the model size of the same vertex of the source (read again by the
    importer with the settings in the asset's provenance) at that time; the model size is the
    asset's as the clip's first frame poses it, and a clip whose animated scales UsdSkel stores in
    half precision is allowed the storage bound it states on top (its `colossus:source`
    customData, `storageErrorBoundRelative`).  The source's skin weights are limited as the
    import's settings limit them (`--max-influences`, negligible weights dropped): the import
    states what that moves (a `skin_influences` not-carried record with its bound, `--strict`
    refuses it), so this rule judges everything else exactly.
    Why: a CI gate for stale colliders: an export re-made with other motion must be re-imported.
    Example: the animator re-keyed `walk`; the collider still has the old walk."""
    c = _check(asset, ctx)
    if c is None or c.error:
        return
    for name, (err, frame, time, vertex) in c.clip_motion.items():
        size = c.clip_size.get(name, c.size)
        allowed = tol.SOURCE_MOTION_RELATIVE + c.clip_storage.get(name, 0.0)
        limit = allowed * size
        if err > limit:
            yield hit(f"clip {name!r}: vertex {vertex} is {err:.4g} away from the source at time {time:g} "
                      f"({err / size:.2g} x model size, more than {allowed:.2g})",
                      sort_key=-err, clip=name, frame=frame, time=time, vertex=vertex, excess=err - limit)


@rule("COL602", "source-sha256", "warning",
      "With --source: the source's sha256 is the one recorded in the asset's provenance.", needs=("mesh_raw",))
def source_sha256(asset, ctx):
    """What: the sha256 of the `--source` file equals the provenance's `sourceSha256`.
    Why: a different file may still hold the same rig (re-exports differ byte-wise), so this alone
    is a warning; COL601, COL603 and COL604 say whether the collider is really stale.
    Example: `boss.glb` re-exported from Blender without changes."""
    c = _check(asset, ctx)
    if c is None or c.error:
        return
    if not c.recorded_sha256:
        yield hit(f"the asset records no sourceSha256; the source's is {c.sha256}")
    elif c.recorded_sha256 != c.sha256:
        yield hit(f"the source's sha256 {c.sha256[:16]}... differs from the one recorded at import "
                  f"({c.recorded_sha256[:16]}...)")


@rule("COL603", "source-clips", "error",
      "With --source: the asset and the source have the same clips on the same frames.", needs=("clips",))
def source_clips(asset, ctx):
    """What: every clip of the source is in the asset and every clip of the asset is in the source,
    with the same frames (time codes).
    Why: a clip added, removed or retimed in the source since the import leaves the collider stale.
    Example: the source gained a `jump` clip; the asset has only `walk`."""
    c = _check(asset, ctx)
    if c is None or c.error:
        return
    for name, msg in c.clip_problems:
        yield hit(msg, clip=name)


@rule("COL604", "source-geometry", "error",
      "With --source: every source vertex has an asset vertex at its bind position, and back.", needs=("skin_ok",))
def source_geometry(asset, ctx):
    """What: each vertex of the source's moving meshes has an asset vertex within 1e-5 x model size
    at the bind pose, and each asset vertex has a source vertex there.
    Why: a mesh added to (or removed from) the character since the import is missing from (or
    extra in) the collider.
    Example: a helmet mesh parented to the head joint was added to the export."""
    c = _check(asset, ctx)
    if c is None or c.error:
        return
    if c.unmatched_source:
        yield hit(f"{c.unmatched_source} source vertices have no asset vertex at their bind position",
                  count=c.unmatched_source)
    if len(c.unmatched_asset):
        yield hit(f"{len(c.unmatched_asset)} asset vertices have no source vertex at their bind position "
                  f"(first: vertex {int(c.unmatched_asset[0])})", vertex=int(c.unmatched_asset[0]),
                  count=len(c.unmatched_asset))


@rule("COL605", "source-readable", "error",
      "With --source: the source file can be read by the importer.", needs=("root",))
def source_readable(asset, ctx):
    """What: the `--source` file exists and the importer's reader accepts it.
    Why: a gate that cannot read the source proves nothing about the collider.
    Example: `--source boss.glb` names a truncated file."""
    c = _check(asset, ctx)
    if c is not None and c.error:
        yield hit(f"the source cannot be read: {c.error}")
