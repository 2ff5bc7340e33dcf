"""``spheres``: one bounding sphere per part, fixed in its joint's space, valid on every frame.

For a part of joint ``j`` the sphere must contain the part's vertices (the vertices of its
triangles) in the bind pose and on every frame of every clip, expressed in joint ``j``'s space::

    q[f, v] = sum_k w[v, k] * inv(S_j(f)) @ S_{i_k}(f) @ inv(B_{i_k}) @ geom_bind @ p[v]

with ``S = skel_transforms(clip.local, parents)`` (``S = bind_transforms`` for the bind pose).
The points of one part over all poses are skinned by a numba kernel into a ``(F, nv, 3)``
float32 array (one part at a time), and the sphere is their exact minimal enclosing sphere
(:func:`pipeline.geometry.min_sphere`), padded by
``SPHERE_PAD_RELATIVE * model size + SPHERE_PAD_RADIUS * radius``.

Where a pose shears the joint's transform (a parent's non-uniform scale under a rotated child),
the radius is multiplied by the largest ratio, over the poses, of that transform's largest
singular value to its largest axis scale: the contract moves a sphere by the joint transform and
scales its radius by the largest axis scale, which alone would not cover the sheared ball.

After the centre is rounded to float32, the radius is re-derived from the float64 distance of the
float64 skinned points (recomputed by a second kernel, not the float32 copies) to that centre, so
containment holds exactly for the stored values before the pad is added.

``slack_ratio`` compares the sphere with the tightest possible per-pose sphere: the radius over the
largest per-pose minimal sphere radius of the part's points, computed exactly on the bind pose and
on up to :data:`SLACK_FRAMES_PER_CLIP` evenly spaced frames of each clip (all frames of shorter
clips; a subset can only over-state the slack).  It is >= 1; large values mean the part changes
shape a lot in its joint's space (it is skinned to several joints that move apart).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from pipeline.geometry.minsphere import min_sphere, min_spheres
from pipeline.model import SkinnedMesh, Parts, skel_transforms
from pipeline.stages import StageReport
from pipeline.tolerances import SPHERE_PAD_RADIUS, SPHERE_PAD_RELATIVE, model_scale

#: ``slack_ratio`` uses exact per-pose minimal spheres on the bind pose and on at most this many
#: evenly spaced frames of each clip (first and last included): enough to characterise the slack,
#: and it keeps the per-pose work bounded on long clips.  The containing sphere itself always
#: covers every frame.
SLACK_FRAMES_PER_CLIP = 32


@njit(cache=True, inline="always")
def _skin_one(pos, jidx, w, mats, f, v):
    """Skinned position of vertex ``v`` in pose ``f`` (float64)."""
    x = np.float64(pos[v, 0])
    y = np.float64(pos[v, 1])
    z = np.float64(pos[v, 2])
    ax = 0.0
    ay = 0.0
    az = 0.0
    for c in range(jidx.shape[1]):
        wt = np.float64(w[v, c])
        if wt == 0.0:
            continue
        j = jidx[v, c]
        ax += wt * (mats[f, j, 0, 0] * x + mats[f, j, 0, 1] * y + mats[f, j, 0, 2] * z + mats[f, j, 0, 3])
        ay += wt * (mats[f, j, 1, 0] * x + mats[f, j, 1, 1] * y + mats[f, j, 1, 2] * z + mats[f, j, 1, 3])
        az += wt * (mats[f, j, 2, 0] * x + mats[f, j, 2, 1] * y + mats[f, j, 2, 2] * z + mats[f, j, 2, 3])
    return ax, ay, az


@njit(cache=True)
def _skin_frame(pos, jidx, w, mats, f, out):
    for v in range(pos.shape[0]):
        out[f, v, 0], out[f, v, 1], out[f, v, 2] = _skin_one(pos, jidx, w, mats, f, v)


@njit(cache=True)
def _frame_max_d2(pos, jidx, w, mats, f, cx, cy, cz):
    best = 0.0
    for v in range(pos.shape[0]):
        ax, ay, az = _skin_one(pos, jidx, w, mats, f, v)
        d = (ax - cx) ** 2 + (ay - cy) ** 2 + (az - cz) ** 2
        if d > best:
            best = d
    return best


@njit(parallel=True, cache=True)
def _skin_points(pos, jidx, w, mats, out):
    """Linear-blend skinning of ``pos`` (n, 3) float32 for every pose.

    ``jidx`` (n, k) int32, ``w`` (n, k) float32, ``mats`` (F, b, 3, 4) float64 per-pose skinning
    matrices (already including the change to the target space), ``out`` (F, n, 3) float32.
    """
    for f in prange(mats.shape[0]):
        _skin_frame(pos, jidx, w, mats, f, out)


@njit(parallel=True, cache=True)
def _max_distance(pos, jidx, w, mats, cx, cy, cz):
    """Largest float64 distance from ``(cx, cy, cz)`` to a skinned point over every pose
    (same arguments as :func:`_skin_points`, nothing stored)."""
    F = mats.shape[0]
    best = np.zeros(F)
    for f in prange(F):
        best[f] = _frame_max_d2(pos, jidx, w, mats, f, cx, cy, cz)
    return np.sqrt(best.max())


def _check_skin_args(positions, joint_indices, joint_weights, mats):
    pos = np.ascontiguousarray(positions, dtype=np.float32)
    ji = np.ascontiguousarray(joint_indices, dtype=np.int32)
    jw = np.ascontiguousarray(joint_weights, dtype=np.float32)
    mats = np.ascontiguousarray(mats, dtype=np.float64)
    n = len(pos)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise ValueError(f"skin positions: expected shape (n, 3), got {pos.shape}")
    if ji.ndim != 2 or ji.shape[0] != n or jw.shape != ji.shape:
        raise ValueError(f"skin joint_indices/joint_weights: expected shape ({n}, k) each, got {ji.shape} and {jw.shape}")
    if mats.ndim != 4 or mats.shape[2:] != (3, 4):
        raise ValueError(f"skin matrices: expected shape (F, b, 3, 4), got {mats.shape}")
    b = mats.shape[1]
    bad = ((ji < 0) | (ji >= b)) & (jw != 0)
    if bad.any():
        raise ValueError(f"skin joint_indices: expected values in [0, {b}) where weight != 0, got {ji[bad][0]}")
    ji = np.where((ji < 0) | (ji >= b), 0, ji).astype(np.int32)  # zero-weight padding only
    return pos, ji, jw, mats


def skin_points(positions: np.ndarray, joint_indices: np.ndarray, joint_weights: np.ndarray,
                mats: np.ndarray) -> np.ndarray:
    """Linear-blend skinning for every pose (numba; reference: :func:`pipeline.model.skin_points`).

    Parameters
    ----------
    positions : (n, 3) float32
    joint_indices : (n, k) int
    joint_weights : (n, k) float32
    mats : (F, b, 3, 4) or (F, b, 4, 4) float64
        Per-pose matrix of each joint, applied to homogeneous positions, e.g.
        ``skel @ inv(bind) @ geom_bind`` (skeleton space) or ``inv(skel[j]) @ skel @ inv(bind) @
        geom_bind`` (joint ``j``'s space).

    Returns
    -------
    (F, n, 3) float32
    """
    mats = np.asarray(mats, dtype=np.float64)[..., :3, :]
    pos, ji, jw, mats = _check_skin_args(positions, joint_indices, joint_weights, mats)
    out = np.empty((mats.shape[0], len(pos), 3), np.float32)
    _skin_points(pos, ji, jw, mats, out)
    return out


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


def _round_up_f32(x: float) -> np.float32:
    r = np.float32(x)
    if float(r) < x:
        r = np.nextafter(r, np.float32(np.inf))
    return r


def spheres(mesh: SkinnedMesh) -> tuple[SkinnedMesh, StageReport]:
    """Bounding sphere of each part in its joint's space, valid in every pose.

    Parameters
    ----------
    mesh : SkinnedMesh with ``parts``.

    Returns
    -------
    (SkinnedMesh, StageReport)
        ``parts`` with float32 ``centers`` and ``radii``.  Report counts: ``parts``,
        ``max_radius``, ``max_slack_ratio``, ``poses``, ``slack_poses``, ``pad``; details:
        ``parts`` (a list of ``{"part", "joint", "radius", "center", "slack_ratio",
        "tight_radius", "vertices"}``), ``slack_poses`` (labels of the poses the tight radius was
        computed on) and ``slack_note``.
    """
    if mesh.parts is None:
        raise ValueError("spheres: expected a mesh with parts (run the parts stage first), got parts=None")
    parts_in = mesh.parts
    S, labels = pose_transforms(mesh)
    to_skel = S @ np.linalg.inv(mesh.bind_transforms)[None] @ mesh.geom_bind  # (F, b, 4, 4)
    inv_S = np.linalg.inv(S)
    G = mesh.geom_bind
    rest = mesh.positions.astype(np.float64) @ G[:3, :3].T + G[:3, 3]
    abs_pad = SPHERE_PAD_RELATIVE * model_scale(rest)
    _, ji_all, jw_all, _ = _check_skin_args(mesh.positions, mesh.joint_indices, mesh.joint_weights,
                                            to_skel[:1, :, :3, :])

    # A joint-space ball moved by a sheared joint transform (a parent's non-uniform stretch under a
    # rotated child) is an ellipsoid whose longest axis is the transform's largest singular
    # value, more than its largest axis scale, the radius multiplier of the contract: the radius
    # is widened by the largest ratio of the two over the poses (1 where no pose shears).
    lin = S[..., :3, :3]
    shear = np.maximum(np.linalg.norm(lin, ord=2, axis=(-2, -1)) / np.linalg.norm(lin, axis=-2).max(-1), 1.0)
    shear = shear.max(axis=0) * (1.0 + 1e-12)  # (b,)

    slack_idx = slack_pose_indices(mesh)
    P = len(parts_in)
    centers = np.zeros((P, 3), np.float32)
    radii = np.zeros(P, np.float32)
    details = []
    for p in range(P):
        j = int(parts_in.joints[p])
        verts = np.unique(mesh.triangles[parts_in.part_faces(p)].ravel())
        pos, ji, jw = mesh.positions[verts], ji_all[verts], jw_all[verts]
        mats = np.ascontiguousarray((inv_S[:, j, None] @ to_skel)[:, :, :3, :])
        pts = np.empty((len(S), len(verts), 3), np.float32)
        _skin_points(pos, ji, jw, mats, pts)
        center, r = min_sphere(pts.reshape(-1, 3))
        _, frame_r = min_spheres(pts if len(slack_idx) == len(S) else pts[slack_idx])
        del pts
        c32 = center.astype(np.float32)
        c64 = c32.astype(np.float64)
        dmax = _max_distance(pos, ji, jw, mats, c64[0], c64[1], c64[2])
        radius = max(r, dmax) * (shear[j] if shear[j] > 1.0 + 1e-9 else 1.0) + abs_pad + SPHERE_PAD_RADIUS * r
        r32 = _round_up_f32(radius)
        centers[p], radii[p] = c32, r32
        tight = float(frame_r.max())
        details.append({
            "part": p,
            "joint": mesh.joint_names[j],
            "radius": float(r32),
            "center": [float(x) for x in c32],
            "tight_radius": tight,
            "slack_ratio": float(r32) / tight if tight > 0 else None,
            "vertices": int(len(verts)),
        })

    slacks = [d["slack_ratio"] for d in details if d["slack_ratio"] is not None]
    report = StageReport("spheres")
    report.counts = {
        "parts": P,
        "max_radius": float(radii.max()) if P else 0.0,
        "max_slack_ratio": float(max(slacks)) if slacks else None,
        "poses": len(S),
        "slack_poses": int(len(slack_idx)),
        "pad": float(abs_pad),
    }
    report.details = {
        "parts": details,
        "slack_poses": [labels[i] for i in slack_idx],
        "slack_note": (f"tight radius = largest exact per-pose minimal sphere over the bind pose and up to "
                       f"{SLACK_FRAMES_PER_CLIP} evenly spaced frames per clip"),
    }
    new_parts = Parts(parts_in.joints, parts_in.face_offsets, parts_in.faces, centers, radii)
    return mesh.replace(parts=new_parts), report
