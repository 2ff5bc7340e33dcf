"""COL3xx skin: joint influences, joint order and the bind pose."""

from __future__ import annotations

import numpy as np

from .. import tolerances as tol
from ..registry import hit, rule


@rule("COL301", "max-influences", "error",
      "At most N influences per vertex (--max-influences, default 4): the runtime skins a fixed number.",
      needs=("skin",))
def max_influences(asset, ctx):
    """What: `elementSize` of the skin primvars, and the number of non-zero weights of every
    vertex, are at most `--max-influences` (default 4).
    Why: the runtime's and most engines' skinning kernels take a fixed number of influences;
    extra ones are dropped and the shape changes.
    Example: `elementSize = 8` from an exporter that kept every bone."""
    N = ctx.max_influences
    if asset.k > N:
        nz = (asset.jw != 0).sum(1)
        worst = int(np.argmax(nz))
        yield hit(f"elementSize is {asset.k}, more than {N} influences; {int((nz > N).sum())} vertices use "
                  f"more than {N} (vertex {worst} uses {int(nz[worst])})", vertex=worst,
                  count=int((nz > N).sum()))


@rule("COL302", "negative-weights", "error", "Skin weights are non-negative.", needs=("skin",))
def negative_weights(asset, ctx):
    """What: every entry of `primvars:skel:jointWeights` is >= 0.
    Why: a negative weight pulls the vertex away from its bone, far outside any sphere.
    Example: `jointWeights = [1.2, -0.2, 0, 0]`."""
    neg = asset.jw < -tol.WEIGHT_NEGATIVE
    if np.any(neg):
        v = int(np.argmin(asset.jw.min(1)))
        yield hit(f"{int(neg.any(1).sum())} vertices have negative weights, worst vertex {v} "
                  f"({float(asset.jw[v].min()):.4g})", vertex=v, count=int(neg.any(1).sum()))


@rule("COL303", "weight-sum", "error", "Each weighted vertex's weights sum to 1 within 1e-4.", needs=("skin",))
def weight_sum(asset, ctx):
    """What: for every vertex with any weight, |sum of weights - 1| <= 1e-4.
    Why: UsdSkel does not renormalise; unnormalised weights scale the vertex towards the origin.
    Example: `jointWeights = [0.5, 0.3, 0, 0]`."""
    s = asset.jw.astype(np.float64).sum(1)
    err = np.abs(s - 1)
    bad = (err > tol.WEIGHT_SUM) & (np.abs(asset.jw).sum(1) > 0)
    if np.any(bad):
        v = int(np.argmax(np.where(bad, err, -1)))
        yield hit(f"{int(bad.sum())} vertices have weights not summing to 1, worst vertex {v} sums to "
                  f"{s[v]:.6g}", vertex=v, count=int(bad.sum()), sort_key=err[v])


@rule("COL304", "joint-indices", "error", "Skin joint indices name existing joints.", needs=("skin",))
def joint_indices(asset, ctx):
    """What: every entry of `primvars:skel:jointIndices` is in [0, joint count).
    Why: an out-of-range joint reads a random matrix at run time.
    Example: index 3 on a 3-joint skeleton."""
    b = len(asset.joints)
    bad = (asset.jidx < 0) | (asset.jidx >= b)
    if np.any(bad):
        v = int(np.argmax(bad.any(1)))
        yield hit(f"{int(bad.any(1).sum())} vertices have joint indices outside [0, {b}), first vertex {v} "
                  f"({asset.jidx[v].tolist()})", vertex=v, count=int(bad.any(1).sum()))


@rule("COL305", "unweighted-vertices", "error", "Every vertex has some skin weight.", needs=("skin",))
def unweighted_vertices(asset, ctx):
    """What: no vertex has all its weights zero.
    Why: an unweighted vertex collapses to the skeleton origin when skinned.
    Example: a vertex with `jointWeights = [0, 0, 0, 0]`."""
    bad = np.nonzero(np.all(asset.jw == 0, axis=1))[0]
    if len(bad):
        yield hit(f"{len(bad)} vertices have no weight, first vertex {int(bad[0])}", vertex=int(bad[0]),
                  count=len(bad))


@rule("COL306", "joint-order", "error",
      "Skeleton joints are valid paths ordered parents-first.", needs=("root",))
def joint_order(asset, ctx):
    """What: `UsdSkel.Topology(joints).Validate()` passes: every joint's parent path is an
    earlier joint (or it is a root).
    Why: skinning composes transforms in one pass in joint order; a child before its parent
    uses a stale parent transform.
    Example: `joints = ["root/mid", "root"]`."""
    if asset.skeleton is None or not asset.joints:
        return
    if asset.topology_error:
        yield hit(f"joint topology invalid: {asset.topology_error}", prim=str(asset.skeleton.GetPath()))
        return
    bad = np.nonzero(asset.parents >= np.arange(len(asset.parents)))[0]
    if len(bad):
        j = int(bad[0])
        yield hit(f"joint {asset.joints[j]!r} comes before its parent", joint=asset.joints[j])


def _not_invertible_affine(mats):
    """Indices of the (J, 4, 4) matrices whose 3x3 part has |det| <= the tolerance or whose last
    row is not (0, 0, 0, 1), and every matrix's determinant (COL307, COL318)."""
    det = np.linalg.det(mats[:, :3, :3])
    affine = np.all(np.abs(mats[:, 3] - [0, 0, 0, 1]) < 1e-9, axis=1)
    return np.nonzero((np.abs(det) <= tol.MIN_DETERMINANT) | ~affine)[0], det


@rule("COL307", "bind-invertible", "error",
      "Bind transforms and the geomBindTransform are invertible.", needs=("skeleton",))
def bind_invertible(asset, ctx):
    """What: every `bindTransforms` matrix and `primvars:skel:geomBindTransform` has a 3x3 part
    with |det| > 1e-12 and a last row (0, 0, 0, 1).
    Why: skinning uses the inverse bind transforms.
    Example: a bind matrix with a zero scale axis."""
    bad, det = _not_invertible_affine(asset.bind)
    for j in bad[:20]:
        yield hit(f"bind transform of joint {asset.joints[j]!r} is not an invertible affine matrix (det {det[j]:.3g})",
                  joint=asset.joints[j])
    g = asset.geom_bind
    if not np.all(np.isfinite(g)) or abs(np.linalg.det(g[:3, :3])) <= tol.MIN_DETERMINANT:
        yield hit("geomBindTransform is not invertible")


@rule("COL318", "rest-invertible", "error", "Rest transforms are invertible affine matrices.", needs=("skeleton",))
def rest_invertible(asset, ctx):
    """What: every `restTransforms` matrix has a 3x3 part with |det| > 1e-12 and a last row
    (0, 0, 0, 1).
    Why: a joint a clip leaves unanimated takes its rest transform, and the frame proof measures
    each part in its joint's space, the inverse of the joint's pose; a singular rest transform
    squashes the joint and everything under it to nothing.
    Example: a rest matrix with a zero scale axis, or a last row (0, 1, 0, 0)."""
    bad, det = _not_invertible_affine(asset.rest)
    for j in bad[:20]:
        yield hit(f"rest transform of joint {asset.joints[j]!r} is not an invertible affine matrix (det {det[j]:.3g})",
                  joint=asset.joints[j])


@rule("COL308", "bind-matches-rest", "warning",
      "Bind transforms equal the rest transforms composed down the hierarchy.", needs=("skeleton",))
def bind_matches_rest(asset, ctx):
    """What: composing `restTransforms` parents-first gives `bindTransforms` (within 1e-4
    relative; translations relative to the model size).
    Why: a Skeleton shown without animation (usdview, a clip that leaves a joint unanimated)
    should show the bind pose; a mismatch usually means the exporter mixed up local and world.
    Example: `restTransforms` authored in skeleton space instead of joint-local space."""
    comp = asset.skel_transforms(asset.rest[None])[0]
    d = np.abs(comp - asset.bind)
    d[:, :3, :3] /= 1 + np.abs(asset.bind[:, :3, :3])
    d[:, :3, 3] /= asset.model_size
    worst = d.reshape(len(d), -1).max(1)
    bad = np.nonzero(worst > tol.BIND_REST_RELATIVE)[0]
    for j in bad[:20]:
        yield hit(f"joint {asset.joints[j]!r}: composed rest transform differs from its bind transform "
                  f"(relative {worst[j]:.3g})", joint=asset.joints[j], sort_key=worst[j])


@rule("COL309", "skin-primvars", "error",
      "jointIndices / jointWeights are authored, vertex-interpolated, with elementSize k and n x k entries.",
      needs=("mesh_raw",))
def skin_primvars(asset, ctx):
    """What: `primvars:skel:jointIndices` and `primvars:skel:jointWeights` exist on the mesh,
    both with `interpolation = "vertex"`, the same `elementSize` k >= 1, n x k values each,
    and the mesh authors no `skel:joints` of its own.
    Why: the runtime reads them as dense (n, k) arrays.
    Example: `jointWeights` with `constant` interpolation."""
    if asset.skin_error:
        yield hit(asset.skin_error, prim=str(asset.mesh.GetPath()))


@rule("COL310", "weights-sorted", "warning", "Each vertex's influences are sorted strongest first.", needs=("skin",))
def weights_sorted(asset, ctx):
    """What: along each vertex's k influences, weights never increase.
    Why: the contract promises it, so consumers may truncate to fewer influences by slicing.
    Example: `jointWeights = [0.2, 0.8, 0, 0]`."""
    bad = np.nonzero(np.any(np.diff(asset.jw, axis=1) > tol.WEIGHT_NEGATIVE, axis=1))[0]
    if len(bad):
        yield hit(f"{len(bad)} vertices have weights not sorted strongest first, first vertex {int(bad[0])}",
                  vertex=int(bad[0]), count=len(bad))


@rule("COL311", "no-blend-shapes", "error",
      "Retired: blend shapes are carried, posed and proven (COL313, COL314 check them).",
      needs=("mesh_raw",), removed=True)
def no_blend_shapes(asset, ctx):
    """What: (retired) the mesh bound no UsdSkel blend shapes.
    Why: the runtime, the frame proof and the continuous certificate now apply blend shapes before
    skinning exactly as UsdSkel does (runtime.certify_shapes); the code stays reserved.
    Example: a face mesh with `skel:blendShapes = ["smile"]` bound to `/Rig/Shapes/smile`."""
    return iter(())


@rule("COL312", "skinning-method", "error",
      "The collision mesh's primvars:skel:skinningMethod is one the runtime poses (classicLinear or dualQuaternion).",
      needs=("mesh_raw",))
def skinning_method(asset, ctx):
    """What: `primvars:skel:skinningMethod` on the collision mesh is absent (UsdSkel's fallback,
    `classicLinear`), `classicLinear` or `dualQuaternion`.
    Why: the runtime, the frame proof and the continuous certificate pose the mesh with one of
    those two methods exactly as UsdSkel does; any other token is one no UsdSkel consumer skins
    (usd-core refuses it), so neither the shape a player meets nor the proof would exist.  The
    proof is not run on such an asset.
    Example: `uniform token primvars:skel:skinningMethod = "blended"` (Maya's per-vertex blend
    has no UsdSkel token)."""
    from colossus.runtime import schema

    m = asset.skinning_method
    if m not in schema.SKINNING_METHODS:
        yield hit(f"primvars:skel:skinningMethod is {m!r}: the runtime poses {' and '.join(schema.SKINNING_METHODS)} "
                  "only (nothing is proven for this mesh)", prim=str(asset.mesh.GetPath()))


@rule("COL313", "blend-shapes-valid", "error",
      "The collision mesh's UsdSkel blend shapes are well formed and finite (names, targets, offsets, "
      "point indices, in-betweens).", needs=("mesh_raw",))
def blend_shapes_valid(asset, ctx):
    """What: `skel:blendShapes` and `skel:blendShapeTargets` name the same number of distinct
    shapes, each target a `BlendShape` prim whose `offsets` are finite and one per point index
    (every point when it has no `pointIndices`), its indices distinct and in range, its
    in-betweens at finite weights other than 0 and 1, no two at one weight, with as many finite
    offsets.
    Why: the runtime and the proof apply the shapes before skinning as UsdSkel does; a shape they
    cannot apply as written (NaN offsets, counts that differ, which usd-core skips with a warning)
    would leave the posed surface and the proof's to disagree, so the proof is not run.
    Example: `offsets = [(nan, 0, 0)]` on `/Root/Collider/smile`."""
    if asset.shapes_error:
        yield hit(f"blend shapes cannot be posed: {asset.shapes_error}", prim=str(asset.mesh.GetPath()))


@rule("COL314", "blend-shape-weights", "error",
      "Each clip's blend-shape weights are finite, one per name of its blendShapes.", needs=("clips",))
def blend_shape_weights(asset, ctx):
    """What: in every SkelAnimation, `blendShapeWeights` has one finite weight per `blendShapes`
    name at every time sample.
    Why: the proof holds for any finite weights, linearly interpolated between their samples
    (UsdSkel's interpolation, extrapolated in-betweens included: runtime.certify_shapes); a NaN or
    infinite weight, or a count that differs from the names, is outside what it assumes, and the
    runtime refuses the clip.
    Example: `float[] blendShapeWeights.timeSamples = {0: [nan]}`."""
    from pxr import UsdSkel

    for c in asset.clips:
        a = UsdSkel.Animation(c.prim)
        names = list(a.GetBlendShapesAttr().Get() or []) if a.GetBlendShapesAttr() else []
        attr = a.GetBlendShapeWeightsAttr()
        if not attr or not attr.HasAuthoredValue():
            continue
        times = list(attr.GetTimeSamples()) or [None]
        for t in times:
            v = attr.Get() if t is None else attr.Get(t)
            w = np.asarray(v if v is not None else [], dtype=np.float64)
            where = "its default" if t is None else f"time {t:g}"
            if len(w) != len(names):
                yield hit(f"clip {c.name!r}: blendShapeWeights at {where} has {len(w)} weights for {len(names)} "
                          "blendShapes names", prim=str(c.prim.GetPath()))
                break
            if not np.isfinite(w).all():
                yield hit(f"clip {c.name!r}: blendShapeWeights at {where} has a weight that is not finite "
                          f"({names[int(np.flatnonzero(~np.isfinite(w))[0])]!r})", prim=str(c.prim.GetPath()))
                break
