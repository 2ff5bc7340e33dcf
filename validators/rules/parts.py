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
