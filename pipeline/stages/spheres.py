"""``spheres``: one bounding sphere per part, fixed in its joint's space, valid on every frame.

For a part of joint ``j`` the sphere must contain the part's vertices (the vertices of its
triangles) in the bind pose and on every frame of every clip, expressed in joint ``j``'s space::

    q[f, v] = sum_k w[v, k] * inv(S_j(f)) @ S_{i_k}(f) @ inv(B_{i_k}) @ geom_bind @ p[v]

with ``S = skel_transforms(clip.local, parents)`` (``S = bind_transforms`` for the bind pose).
The points of one part over all poses are skinned by the project's one skinning kernel
(:mod:`runtime.kernels.skin`) into a ``(F, nv, 3)`` float64 array (one part at a time), and the
sphere is their exact minimal enclosing sphere (:func:`pipeline.geometry.min_sphere`).

After the centre is rounded to float32, the radius is re-derived from the float64 distance of the
float64 skinned points to that centre, so containment holds exactly at every sampled pose.

Where a pose shears the joint's transform (a parent's non-uniform scale under a rotated child),
the radius is multiplied by the largest ratio, over the poses, of that transform's largest
singular value to its largest axis scale: the contract moves a sphere by the joint transform and
scales its radius by the largest axis scale, which alone would not cover the sheared ball.

**Between frames.** The asset's guarantee covers every time in ``[first, last]`` of every clip as
UsdSkel interpolates it, which ``colossus validate`` certifies with
:func:`runtime.certify.continuous`. The same certificate runs here on the clips exactly as the
writer will store them (translations and rotations float32, scales float16) in ``growth`` mode,
holding each interval to the padded minimal radius (``r (1 + SPHERE_PAD_RADIUS) +
SPHERE_PAD_RELATIVE * model size``) times the interval's scale ratio (``s_lo / s_hi`` of the joint's
transform, below 1 where a non-uniform scale on its path makes the certificate conservative, exactly
as the validator holds a radius): wherever it cannot, it subdivides, down to 2^6 sub-steps, and the
part's radius becomes the largest bound it reached over that ratio (``growth`` in the report, beyond
the padded radius; 0 for most parts). Where it reaches no finite bound (a dual-quaternion skin
outside every bound it has: a mirrored skinning transform, negative weights) no radius would pass
the validator: the import fails closed with an :class:`InputError` naming the clip, interval, part
and reason, and nothing is written. The validator's adaptive subdivision stops at or before every
node this one stopped at (its radius is at least the bound there), so the written spheres pass it.
Finally the radius is rounded up to float32.

``slack_ratio`` compares the sphere with the tightest possible per-pose sphere: the radius over the
largest per-pose minimal sphere radius of the part's points, computed exactly on the bind pose and
on up to :data:`SLACK_FRAMES_PER_CLIP` evenly spaced frames of each clip (all frames of shorter
clips; a subset can only over-state the slack).  It is >= 1; large values mean the part changes
shape a lot in its joint's space (it is skinned to several joints that move apart).
"""

from __future__ import annotations

import numpy as np

from colossus.pipeline.errors import InputError
from colossus.pipeline.geometry.minsphere import KERNEL_MIN, largest_min_sphere, min_sphere
from colossus.pipeline.model import SkinnedMesh, Parts, kernel_shapes, skel_transforms
from colossus.pipeline.stages import StageReport
from colossus.pipeline.tolerances import SPHERE_PAD_RADIUS, SPHERE_PAD_RELATIVE, model_scale
from colossus.runtime import certify, certify_shapes
from colossus.runtime.kernels import skin as SK
from colossus.runtime.schema import part_vertex_csr

#: ``slack_ratio`` uses exact per-pose minimal spheres on the bind pose and on at most this many
#: evenly spaced frames of each clip (first and last included): enough to characterise the slack,
#: and it keeps the per-pose work bounded on long clips.  The containing sphere itself always
#: covers every frame.
SLACK_FRAMES_PER_CLIP = 32
#: ``tight_radius`` is the largest per-pose minimal radius to within this (relative, below): the
#: poses of a near-rigid part, whose spheres differ only by rounding, are then solved once.
TIGHT_REL = 1e-7


def pose_transforms(mesh: SkinnedMesh) -> tuple[np.ndarray, list]:
    """Skeleton transforms of every pose the spheres must cover: the bind pose, then every frame
    of every clip.  Returns ``(F, b, 4, 4)`` float64 and a label per pose."""
    poses = [mesh.bind_transforms[None]]
    labels = ["bind"]
    for c in mesh.clips:
        poses.append(skel_transforms(c.local, mesh.parents))
        labels += [f"{c.name}[{i}]" for i in range(c.frame_count)]
    return np.concatenate(poses), labels


def slack_pose_indices(mesh: SkinnedMesh, per_clip: int = SLACK_FRAMES_PER_CLIP) -> np.ndarray:
    """Indices into :func:`pose_transforms` of the poses used for ``slack_ratio``: the bind pose
    and at most ``per_clip`` evenly spaced frames of each clip (first and last included)."""
    idx = [np.zeros(1, np.int64)]
    start = 1
    for c in mesh.clips:
        n = c.frame_count
        pick = np.arange(n) if n <= per_clip else np.unique(np.round(np.linspace(0, n - 1, per_clip)).astype(np.int64))
        idx.append(start + pick)
        start += n
    return np.concatenate(idx)


#: Subdivision depth of the growth run (the validator allows more: runtime.certify.MAX_DEPTH).
GROWTH_DEPTH = 6


def _round_up_f32(x: float) -> np.float32:
    r = np.float32(x)
    if float(r) < x:
        r = np.nextafter(r, np.float32(np.inf))
    return r


def spheres(mesh: SkinnedMesh) -> tuple[SkinnedMesh, StageReport]:
    """Bounding sphere of each part in its joint's space, valid in every pose and between frames.

    Parameters
    ----------
    mesh : SkinnedMesh with ``parts``, after ``quantize`` (its ``stored_clips`` are what the
        certificate between frames runs on, as the validator will read them from the asset).

    Returns
    -------
    (SkinnedMesh, StageReport)
        ``parts`` with float32 ``centers`` and ``radii``.  Report counts: ``parts``,
        ``max_radius``, ``max_slack_ratio``, ``poses``, ``slack_poses``, ``pad``, ``grown`` (parts
        grown for the times between frames), ``max_growth``; details: ``parts`` (a list of
        ``{"part", "joint", "radius", "center", "slack_ratio", "tight_radius", "vertices",
        "growth"}``, growth in joint-space units), ``slack_poses`` (labels of the poses the tight
        radius was computed on) and ``slack_note``.
    """
    if mesh.parts is None:
        raise ValueError("spheres: expected a mesh with parts (run the parts stage first), got parts=None")
    if len(mesh.stored_clips) != len(mesh.clips):
        raise ValueError("spheres: expected the clips as stored (run the quantize stage first), "
                         f"got {len(mesh.stored_clips)} stored of {len(mesh.clips)} clips")
    parts_in = mesh.parts
    S, labels = pose_transforms(mesh)
    # A joint-space ball moved by a sheared joint transform (a parent's non-uniform stretch under a
    # rotated child) is an ellipsoid whose longest axis is the transform's largest singular
    # value, more than its largest axis scale, the radius multiplier of the contract: radii (and
    # the per-pose bounds) are widened by the largest ratio of the two over the poses (1 where no
    # pose shears).
    lin = S[..., :3, :3]
    shear = np.maximum(np.linalg.norm(lin, ord=2, axis=(-2, -1)) / np.linalg.norm(lin, axis=-2).max(-1), 1.0)
    shear = shear.max(axis=0) * (1.0 + 1e-12)  # (b,)
    to_skel = S @ np.linalg.inv(mesh.bind_transforms)[None] @ mesh.geom_bind  # (F, b, 4, 4)
    inv_S = np.linalg.inv(S)
    skin_skel = S @ np.linalg.inv(mesh.bind_transforms)[None]  # the dual-quaternion layout's skinning transforms
    G = mesh.geom_bind
    rest = mesh.positions.astype(np.float64) @ G[:3, :3].T + G[:3, 3]
    abs_pad = SPHERE_PAD_RELATIVE * model_scale(rest)
    pos_all, ji_all, jw_all = SK.check_skin_inputs(mesh.positions, mesh.joint_indices, mesh.joint_weights,
                                                   mesh.joint_count)

    if mesh.blend_shapes:  # every pose's points displaced by its shape weights (the bind pose: none)
        W = np.concatenate([np.zeros((1, len(mesh.blend_shapes)))] + [c.shape_weights for c in mesh.clips])
        pos_all = SK.shape_points(mesh.positions, kernel_shapes(mesh.blend_shapes, mesh.vertex_count), W)
    slack_idx = slack_pose_indices(mesh)
    P = len(parts_in)
    centers = np.zeros((P, 3), np.float32)
    r_min = np.zeros(P)
    pose_far = np.zeros((len(S), P))  # joint-space farthest vertex at each pose (exact, float64)
    details = []
    # the minimal spheres run compiled when the stage's points over every pose make it worth the
    # compile (minsphere.KERNEL_MIN; both forms give bit-identical spheres)
    part_verts = [np.unique(mesh.triangles[parts_in.part_faces(p)].ravel()) for p in range(P)]
    compiled = len(S) * sum(len(v) for v in part_verts) >= KERNEL_MIN
    for p in range(P):
        j = int(parts_in.joints[p])
        verts = part_verts[p]
        pos, ji, jw = pos_all[..., verts, :], ji_all[verts], jw_all[verts]
        mats = (SK.fold(inv_S[:, j, None] @ to_skel) if mesh.skinning_method == SK.CLASSIC_LINEAR else
                SK.fold_method(mesh.skinning_method, skin_skel, G, world=inv_S[:, j]))
        pts = SK.skin_frames(pos, ji, jw, mats, dtype=np.float64)  # (F, nv, 3) joint space
        center, r = min_sphere(pts.reshape(-1, 3), compiled)
        tight = largest_min_sphere(pts if len(slack_idx) == len(S) else pts[slack_idx], center, rel=TIGHT_REL,
                                   compiled=compiled)
        c32 = center.astype(np.float32)
        pts -= c32.astype(np.float64)
        d = np.sqrt(np.einsum("fvi,fvi->fv", pts, pts).max(1))
        del pts
        widen = shear[j] if shear[j] > 1.0 + 1e-9 else 1.0
        pose_far[:, p] = d * widen
        centers[p], r_min[p] = c32, max(r, float(d.max())) * widen
        details.append({"part": p, "joint": mesh.joint_names[j], "tight_radius": tight, "vertices": int(len(verts))})

    target = r_min * (1.0 + SPHERE_PAD_RADIUS) + abs_pad  # the padded minimal sphere of the samples
    need = _between_frames(mesh, parts_in, centers, target, pose_far)
    growth = np.maximum(need - target, 0.0)
    radii = np.zeros(P, np.float32)
    for p in range(P):
        radii[p] = _round_up_f32(max(target[p], need[p]))
        tight = details[p]["tight_radius"]
        details[p].update({"radius": float(radii[p]), "center": [float(x) for x in centers[p]],
                           "slack_ratio": float(radii[p]) / tight if tight > 0 else None,
                           "growth": float(growth[p])})

    slacks = [d["slack_ratio"] for d in details if d["slack_ratio"] is not None]
    report = StageReport("spheres")
    report.counts = {
        "parts": P,
        "max_radius": float(radii.max()) if P else 0.0,
        "max_slack_ratio": float(max(slacks)) if slacks else None,
        "poses": len(S),
        "slack_poses": int(len(slack_idx)),
        "pad": float(abs_pad),
        "grown": int((growth > 0).sum()),
        "max_growth": float(growth.max()) if P else 0.0,
    }
    report.details = {
        "parts": details,
        "slack_poses": [labels[i] for i in slack_idx],
        "slack_note": (f"tight radius = largest exact per-pose minimal sphere over the bind pose and up to "
                       f"{SLACK_FRAMES_PER_CLIP} evenly spaced frames per clip"),
    }
    new_parts = Parts(parts_in.joints, parts_in.face_offsets, parts_in.faces, centers, radii)
    return mesh.replace(parts=new_parts), report


def _between_frames(mesh, parts_in, centers, target, pose_far) -> np.ndarray:
    """(P,) the radius each part needs between frames: at most ``target`` where the continuous
    certificate (:func:`runtime.certify.continuous` in growth mode, on the clips as written)
    holds every interval to it (times the interval's scale ratio, as the validator holds a radius),
    else the largest bound it reached at :data:`GROWTH_DEPTH` over that ratio."""
    P = len(parts_in)
    need = np.zeros(P)
    if not mesh.clips or P == 0:
        return need
    voff, verts = part_vertex_csr(mesh.triangles, parts_in.face_offsets, parts_in.faces, mesh.vertex_count)
    # the rig exactly as the writer lays it out (the roots' scale folded by quantize)
    rig = certify.Rig(mesh.positions, mesh.joint_indices, mesh.joint_weights, mesh.geom_bind,
                      mesh.bind_transforms, mesh.rest_transforms, mesh.parents, np.asarray(parts_in.joints),
                      centers.astype(np.float64), target, voff, verts, skinning_method=mesh.skinning_method,
                      shapes=kernel_shapes(mesh.blend_shapes, mesh.vertex_count) if mesh.blend_shapes else None)
    start = 1  # pose 0 is the bind pose
    for clip, stored in zip(mesh.clips, mesh.stored_clips, strict=True):
        n = clip.frame_count
        far = pose_far[start:start + n]
        start += n
        if n < 2:
            continue
        c = certify_shapes.certificate(rig, stored, clip.times, far,
                               np.ones_like(far, bool), 0.0, 0.0, rho=target, growth=True,
                               max_depth=GROWTH_DEPTH, frame_bound_space="joint")
        # a J-space bound U certifies a radius r where U <= r * ratio (non-uniform scales on the
        # joint's path): the radius each interval needs is U / ratio
        need_c = c.bound / c.ratio
        if not np.isfinite(need_c).all():  # fail closed: no radius would pass the validator
            i, p = (int(x) for x in np.argwhere(~np.isfinite(need_c))[0])
            why = next((f["reason"].removesuffix(": not certified") for f in c.failures
                        if (f["interval"], f["part"]) == (i, p) and "reason" in f),
                       "the certificate reached no finite bound")
            raise InputError(mesh.source.get("path") or mesh.source.get("file"),
                             f"not written (validate would reject it): no between-frames bound on "
                             f"{int((~np.isfinite(need_c)).sum())} interval(s), first clip '{clip.name}' "
                             f"{clip.times[i]:g}-{clip.times[i + 1]:g} part {p} "
                             f"'{mesh.joint_names[int(parts_in.joints[p])]}': {why}")
        need = np.maximum(need, np.max(need_c, axis=0))
    return need
