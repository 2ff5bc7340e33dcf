"""COL4xx parts: every triangle in a part, and every part's sphere holding its vertices on
every frame (the frame proof, :mod:`validators.frameproof`)."""

from __future__ import annotations

import numpy as np

from .. import frameproof as fp
from .. import tolerances as tol
from ..registry import hit, rule


@rule("COL401", "faces-in-parts", "error", "Every triangle belongs to at least one part.", needs=("parts",))
def faces_in_parts(asset, ctx):
    """What: every face index appears in `colossus:parts:faces`.
    Why: the broad phase only tests triangles of parts whose sphere is hit: a triangle in no
    part can never be hit.
    Example: the cap triangles left out of every part."""
    covered = np.zeros(len(asset.tris), bool)
    covered[asset.part_faces] = True
    bad = np.nonzero(~covered)[0]
    if len(bad):
        yield hit(f"{len(bad)} triangles are in no part, first face {int(bad[0])}", face=int(bad[0]), count=len(bad))


@rule("COL402", "holds-in-bind-pose", "error",
      "Every part sphere contains its vertices in the bind pose.", needs=("spheres",))
def holds_in_bind_pose(asset, ctx):
    """What: with every joint at its bind transform, each vertex of each part's triangles lies in
    the part's sphere (centre moved by the joint's bind transform and the skeleton's
    transform, radius scaled by its largest axis scale).
    Why: the cheapest proof that the spheres belong to this mesh at all.
    Example: sphere centres written in skeleton space instead of joint space."""
    poff, pverts = asset.part_vertices
    joint_world = asset.skel_world @ asset.bind[None]
    sk = fp.skinning_transforms(asset.bind, asset.inv_bind, asset.geom_bind, asset.skel_world)
    wc, wr, _ = fp.world_spheres(joint_world, asset.part_joint_ids, asset.part_centers, asset.part_radii)
    d, v = fp.part_farthest(asset.points, asset.jidx, asset.jw, sk, poff, pverts, wc)
    excess = d[0] - wr[0]
    limit = tol.CONTAIN_RELATIVE * asset.model_size + tol.CONTAIN_RADIUS * wr[0]
    for p in np.nonzero(excess > limit)[0]:
        yield hit(f"part {p} (joint {asset.part_joints[p]!r}): vertex {int(v[0, p])} is {excess[p]:.4g} outside "
                  f"its sphere in the bind pose ({excess[p] / wr[0, p]:.2%} of radius {wr[0, p]:.4g})",
                  part=int(p), joint=asset.part_joints[p], vertex=int(v[0, p]), excess=float(excess[p]),
                  fraction=float(excess[p] / wr[0, p]), sort_key=excess[p])


@rule("COL403", "holds-on-all-frames", "error",
      "On every frame of every clip, every skinned vertex of every part lies inside the part's moving sphere.",
      needs=("proof",))
def holds_on_all_frames(asset, ctx):
    """What: the frame proof.  For every clip and every frame (plus `--subframes K` in-between
    times), every vertex is skinned (UsdSkel linear blend skinning) and tested against the
    sphere of every part it belongs to, moved by the part's joint at that time.  One finding per
    failing (clip, part) at its worst time, worst first: clip, time, frame, part, joint, vertex,
    excess in stage units and as a fraction of the radius, and how many times failed.
    Why: the runtime skips a part's triangles whenever the query misses its sphere; a vertex
    outside the sphere means missed hits, i.e. the player walks through the boss.
    Example: spheres fitted to the bind pose only, then the arm bends."""
    proof = ctx.proof()
    for r in proof.results:
        if r.failing_times:
            joint = asset.part_joints[r.part]
            yield hit(f"clip {r.clip!r} time {r.time:g} (frame {r.frame}): part {r.part} (joint {joint!r}) "
                      f"vertex {r.vertex} is {r.excess:.4g} outside its sphere ({r.fraction:.2%} of the radius); "
                      f"fails at {r.failing_times} checked time(s), first at {r.first_fail_time:g}",
                      clip=r.clip, time=r.time, frame=r.frame, part=r.part, joint=joint, vertex=r.vertex,
                      excess=r.excess, fraction=r.fraction, count=r.failing_times, sort_key=r.excess)


@rule("COL404", "slack-sphere", "warning",
      "A part sphere is much larger (> 1.5x by default) than the tightest one that holds on all frames.",
      needs=("proof",))
def slack_sphere(asset, ctx):
    """What: radius / (largest joint-space distance from the stored centre to any of the part's
    skinned vertices over every checked time) exceeds `slack_ratio` (default 1.5).
    Why: an oversized sphere makes the broad phase useless: its triangles are tested on every query.
    Example: every radius multiplied by 3 "to be safe"."""
    proof = ctx.proof()
    for p, (r, t) in enumerate(zip(asset.part_radii, fp.tightest(asset, proof, ctx.slack_ratio))):
        ratio = float(r / t) if t > 0 else float("inf")
        if ratio > ctx.slack_ratio:
            yield hit(f"part {p} (joint {asset.part_joints[p]!r}): radius {r:.4g} is {ratio:.2f}x the tightest "
                      f"radius {t:.4g} that holds on all checked frames", part=p, joint=asset.part_joints[p],
                      ratio=ratio, sort_key=ratio)


@rule("COL407", "holds-between-frames", "error",
      "At every time between consecutive frames of every clip, as UsdSkel interpolates the joints, every skinned "
      "vertex of every part lies inside the part's moving sphere.", needs=("proof",))
def holds_between_frames(asset, ctx):
    """What: the continuous certificate (`runtime.certify.continuous`).  For every clip and every
    interval between consecutive frames, under UsdSkel's interpolation (translations and scales
    lerped, rotations slerped along the shortest arc), a sound bound on how far each vertex strays
    from the chord between its positions at the two frames proves the vertex stays inside its
    part's sphere; where the bound is too loose the interval is halved (up to 256 sub-steps) and
    the ends skinned exactly.  One finding per (clip, part, interval) that is not certified:
    `interval` [t0, t1], the worst time found in it, part, joint, vertex and excess (sampled at 16
    sub-steps), or, when no sub-step fails but the bound still cannot decide, the bound's excess.
    Intervals next to a frame that fails COL403 are left to COL403.
    Why: a game samples animation at its own rate (60 Hz over 30 fps clips, blended, time-scaled):
    in-between poses are what it queries; a vertex outside its sphere there is a missed hit.
    Example: spheres fitted to the frames only, on a clip whose joints swing far between frames."""
    proof = ctx.proof()
    for f in proof.between:
        p = f["part"]
        joint = asset.part_joints[p]
        what = (f"vertex {f['vertex']} is {f['excess']:.4g} outside its sphere at time {f['time']:g} "
                f"({f['excess'] / f['radius']:.2%} of the radius)" if f["definite"] else
                f"the bound cannot certify it (up to {f['bound']:.4g} from the centre in joint space; "
                f"worst sampled excess {f['excess']:.4g} at time {f['time']:g})")
        yield hit(f"clip {f['clip']!r} between times {f['t0']:g} and {f['t1']:g}: part {p} (joint {joint!r}) "
                  f"{what}", clip=f["clip"], interval=[f["t0"], f["t1"]], time=f["time"], part=p, joint=joint,
                  vertex=f["vertex"], excess=f["excess"], fraction=f["excess"] / f["radius"],
                  sort_key=f["excess"] if f["definite"] else f["bound"])


@rule("COL405", "sphere-values", "error", "Sphere centres are finite and radii positive and finite.", needs=("parts",))
def sphere_values(asset, ctx):
    """What: every `colossus:parts:centers` entry is finite and every `radii` entry is > 0 and finite.
    Why: a NaN centre or zero radius makes the part unhittable.
    Example: `radii = [0.5, 0, 0.4]`."""
    c_bad = ~np.all(np.isfinite(asset.part_centers), axis=1)
    r_bad = ~(np.isfinite(asset.part_radii) & (asset.part_radii > 0))
    for p in np.nonzero(c_bad | r_bad)[0]:
        yield hit(f"part {p}: centre {asset.part_centers[p].tolist()} radius {float(asset.part_radii[p])}",
                  part=int(p), joint=asset.part_joints[p])


@rule("COL406", "empty-part", "warning", "Every part has at least one triangle.", needs=("parts",))
def empty_part(asset, ctx):
    """What: `faceOffsets[p] < faceOffsets[p + 1]` for every part.
    Why: an empty part costs a sphere test per query and hits nothing.
    Example: a part for a twist bone that owns no triangles."""
    for p in np.nonzero(np.diff(asset.part_offsets) == 0)[0]:
        yield hit(f"part {p} (joint {asset.part_joints[p]!r}) has no triangles", part=int(p),
                  joint=asset.part_joints[p])


@rule("COL408", "guide-spheres", "warning",
      "Each part has one guide-purpose UsdGeom.Sphere, rigidly bound to its joint, that UsdSkel moves exactly as the part's sphere.",
      needs=("spheres",))
def guide_spheres(asset, ctx):
    """What: the `UsdGeom.Sphere` prims under the SkelRoot (the contract's guide spheres, one per
    part, `customData` `colossus:part` = its part index) agree with `colossus:parts:*`, which stay
    the truth: purpose `guide`; `UsdSkelBindingAPI` with `skel:skeleton` targeting the Skeleton and
    constant-interpolation `primvars:skel:jointIndices` = [the part's joint] / `jointWeights` = [1];
    radius = the part's radius; and UsdSkel's rigid skinning of the sphere
    (`S_j(t) @ inv(bind_j) @ geomBindTransform`) puts its centre on the part's joint-space centre
    with no rotation or scale of its own (within 1e-6 x model size, 1e-6 x radius), so at every
    time it is the runtime's `pose.spheres[p]`.  A part without its sphere, a sphere naming no
    part, or two for one part are reported too.
    Why: usdview, Blender and Omniverse users see what the validator proved only through these
    spheres; one that disagrees shows a wrong sphere (the runtime and the proof read the attributes).
    Example: a part's radius grown in `colossus:parts:radii` but not on its guide sphere."""
    from pxr import Usd, UsdGeom, UsdSkel

    from colossus.runtime import schema

    size = asset.model_size
    P = len(asset.part_joints)
    seen = {}
    skel_path = str(asset.skeleton.GetPath())
    for prim in Usd.PrimRange(asset.root):
        if not prim.IsA(UsdGeom.Sphere):
            continue
        where = str(prim.GetPath())
        p = prim.GetCustomDataByKey(schema.GUIDE_PART_KEY)
        if not isinstance(p, int) or isinstance(p, bool) or not 0 <= p < P:
            yield hit(f"sphere {where} names no part (customData {schema.GUIDE_PART_KEY} = {p!r}; {P} parts)",
                      prim=where)
            continue
        if p in seen:
            yield hit(f"part {p} has two guide spheres: {seen[p]} and {where}", prim=where, part=p)
            continue
        seen[p] = where
        joint = asset.part_joints[p]
        j = int(asset.part_joint_ids[p])
        problems = []
        purpose = UsdGeom.Imageable(prim).ComputePurpose()
        if purpose != UsdGeom.Tokens.guide:
            problems.append(f"purpose is {purpose!r}, not 'guide'")
        b = UsdSkel.BindingAPI(prim)
        rel = b.GetSkeletonRel()
        targets = [str(t) for t in rel.GetTargets()] if rel else []
        if "SkelBindingAPI" not in prim.GetAppliedSchemas() or targets != [skel_path]:
            problems.append(f"not bound to {skel_path} (SkelBindingAPI, skel:skeleton targets {targets})")
        ip, wp = b.GetJointIndicesPrimvar(), b.GetJointWeightsPrimvar()
        ji = list(ip.Get()) if ip and ip.HasAuthoredValue() else None
        jw = list(wp.Get()) if wp and wp.HasAuthoredValue() else None
        if (ji != [j] or jw is None or len(jw) != 1 or abs(float(jw[0]) - 1.0) > 1e-6
                or ip.GetInterpolation() != UsdGeom.Tokens.constant or wp.GetInterpolation() != UsdGeom.Tokens.constant):
            problems.append(f"not rigidly bound to joint {joint!r} (index {j}): constant jointIndices {ji}, "
                            f"jointWeights {jw}")
        r = UsdGeom.Sphere(prim).GetRadiusAttr().Get()
        want_r = float(asset.part_radii[p])
        if r is None or not abs(float(r) - want_r) <= tol.GUIDE_RELATIVE * want_r:
            problems.append(f"radius {r} != the part's {want_r:.9g}")
        gba = b.GetGeomBindTransformAttr()
        gb = schema.matrices_from_usd(gba.Get()) if gba and gba.HasAuthoredValue() else np.eye(4)
        # the sphere in joint space: inv(bind_j) @ geomBind maps its origin to its centre
        with np.errstate(all="ignore"):
            m = asset.inv_bind[j] @ gb
        c = m[:3, 3]
        off = float(np.linalg.norm(c - asset.part_centers[p].astype(np.float64)))
        if not off <= tol.GUIDE_RELATIVE * size:
            problems.append(f"UsdSkel puts its centre {off:.4g} from the part's centre {asset.part_centers[p].tolist()} "
                            f"(joint space)")
        elif not np.abs(m[:3, :3] - np.eye(3)).max() <= tol.GUIDE_RELATIVE:
            problems.append("its geomBindTransform turns or scales it in its joint's space (inv(bind) @ geomBind "
                            "is not a translation)")
        if problems:
            yield hit(f"part {p} (joint {joint!r}): guide sphere {where}: " + "; ".join(problems),
                      prim=where, part=p, joint=joint)
    missing = [p for p in range(P) if p not in seen]
    if missing:
        yield hit(f"{len(missing)} of {P} parts have no guide sphere (a UsdGeom.Sphere under the SkelRoot with "
                  f"customData {schema.GUIDE_PART_KEY}), first part {missing[0]} (joint "
                  f"{asset.part_joints[missing[0]]!r}): other USD tools cannot show it",
                  part=missing[0], joint=asset.part_joints[missing[0]], count=len(missing))
