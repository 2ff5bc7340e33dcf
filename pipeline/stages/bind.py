"""Stage 4, ``bind``: map vertices to bones.

Keeps each vertex's strongest influences up to ``max_influences``, drops negligible weights,
renormalises to sum 1 and orders joints parents-first.  A vertex with no weight at all is an
error by default; ``unweighted="nearest-bone"`` gives it to the nearest bone instead.
"""

from __future__ import annotations

import numpy as np

from colossus.runtime.schema import parents_first

from .. import notcarried
from ..errors import InputError
from ..model import Clip, SkinnedMesh
from ..tolerances import NEGLIGIBLE_WEIGHT
from . import StageReport

UNWEIGHTED_POLICIES = ("error", "nearest-bone")


def nearest_bone(points: np.ndarray, bind: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """Index of the bone nearest to each point.

    A bone is the segment from a joint's origin to each of its children's origins (a leaf joint
    is its origin point); distances are measured in the bind pose.

    Parameters
    ----------
    points : (n, 3)
    bind : (b, 4, 4) joint-to-skeleton bind transforms
    parents : (b,) int

    Returns
    -------
    (n,) int64 joint index
    """
    heads = bind[:, :3, 3]
    seg_joint, a, b = [], [], []
    for j in range(len(parents)):
        kids = np.nonzero(parents == j)[0]
        for k in kids if len(kids) else [j]:
            seg_joint.append(j)
            a.append(heads[j])
            b.append(heads[k])
    a, b, seg_joint = np.array(a), np.array(b), np.array(seg_joint)
    p = np.asarray(points, dtype=np.float64)
    best = np.full(len(p), np.inf)
    out = np.zeros(len(p), dtype=np.int64)
    for s in range(len(a)):
        d = b[s] - a[s]
        dd = float(d @ d)
        t = np.clip(((p - a[s]) @ d) / dd, 0, 1) if dd > 0 else np.zeros(len(p))
        dist = np.linalg.norm(p - (a[s] + t[:, None] * d), axis=1)
        better = dist < best
        best[better] = dist[better]
        out[better] = seg_joint[s]
    return out


def limit_influences(joint_indices: np.ndarray, weights: np.ndarray, max_influences: int):
    """The strongest ``max_influences`` influences of each vertex, negligible ones dropped,
    renormalised (the one place this is done: ``bind`` and ``simplify`` use it).

    Parameters
    ----------
    joint_indices : (n, s) int
    weights : (n, s) float, >= 0, each row summing to 1 (any column order)
    max_influences : int, >= 1

    Returns
    -------
    out_j : (n, max_influences) int32
        Strongest first; padding entries joint 0.
    out_w : (n, max_influences) float64
        Matching weights, summing to 1; padding 0.
    over : (n, s) bool
        Influences dropped for being beyond the strongest ``max_influences`` (input column order
        after sorting strongest first).
    negligible : (n, s) bool
        Influences dropped for being below :data:`~pipeline.tolerances.NEGLIGIBLE_WEIGHT`.
    dropped_weight : (n,) float64
        Total weight dropped from each vertex.
    """
    norm = np.asarray(weights, dtype=np.float64)
    ji = np.asarray(joint_indices, dtype=np.int64)
    n = len(norm)
    srt = np.argsort(-norm, axis=1, kind="stable")
    norm = np.take_along_axis(norm, srt, axis=1)
    ji = np.take_along_axis(ji, srt, axis=1)
    present = norm > 0
    negligible = present & (norm < NEGLIGIBLE_WEIGHT)
    negligible[:, 0] = False  # never drop a vertex's strongest influence
    keep = present & ~negligible
    rank = np.cumsum(keep, axis=1)
    over = keep & (rank > max_influences)
    keep &= ~over
    dropped_weight = np.where(over | negligible, norm, 0.0).sum(axis=1)
    kk = max(max_influences, 1)
    out_j = np.zeros((n, kk), dtype=np.int32)
    out_w = np.zeros((n, kk), dtype=np.float64)
    src_k = ji.shape[1]
    # kept entries are already sorted strongest first; compact them to the left
    pos = np.cumsum(keep, axis=1) - 1
    rows = np.broadcast_to(np.arange(n)[:, None], (n, src_k))
    out_j[rows[keep], pos[keep]] = ji[keep]
    out_w[rows[keep], pos[keep]] = norm[keep]
    out_w /= out_w.sum(axis=1, keepdims=True)
    return out_j, out_w, over, negligible, dropped_weight


#: A trim of skin weights (influences beyond ``max_influences``, negligible ones) that moves a vertex
#: more than this x the model size is a ``skin_influences`` not-carried record (the fidelity
#: tolerance of ``validate --source``, :data:`validators.tolerances.SOURCE_MOTION_RELATIVE`).
TRIM_RELATIVE = 1e-4


def _trim_moves(mesh: SkinnedMesh, ji_full, jw_full, ji_kept, jw_kept, rows, poses=None) -> float:
    """Largest distance, at the bind pose and at every frame of every clip, between the vertices
    ``rows`` skinned with every influence they had (``ji_full``, ``jw_full``, normalised) and with
    the kept ones: the mesh's own method, its blend shapes at each clip's weights (UsdSkel's
    order), in skeleton space.  Exact at those poses (the one kernel, float64)."""
    from colossus.runtime.kernels import skin as SK

    from ..model import kernel_shapes

    inv_bind = np.linalg.inv(mesh.bind_transforms)
    ks = kernel_shapes(mesh.blend_shapes, mesh.vertex_count) if mesh.blend_shapes else None
    a_j, a_w = np.ascontiguousarray(ji_full[rows], np.int32), np.ascontiguousarray(jw_full[rows], np.float32)
    b_j, b_w = np.ascontiguousarray(ji_kept[rows], np.int32), np.ascontiguousarray(jw_kept[rows], np.float32)
    poses = _poses(mesh) if poses is None else poses
    step = max(1, min(64, 2_000_000 // max(1, mesh.vertex_count if ks is not None else len(rows))))
    worst = 0.0
    for skel, W in poses:
        for f0 in range(0, len(skel), step):
            s = skel[f0:f0 + step]
            if ks is not None and W is not None and W.shape[1] and np.any(W[f0:f0 + step]):
                pts = SK.shape_points(mesh.positions, ks, W[f0:f0 + step])[:, rows]
            else:
                pts = mesh.positions[rows]
            mats = SK.fold_method(mesh.skinning_method, s @ inv_bind, mesh.geom_bind)
            d = SK.skin_frames(pts, a_j, a_w, mats, dtype=np.float64) - SK.skin_frames(pts, b_j, b_w, mats,
                                                                                     dtype=np.float64)
            worst = max(worst, float(np.sqrt(np.einsum("fvi,fvi->fv", d, d).max(initial=0.0))))
    return worst


def _trim_cheap(mesh: SkinnedMesh, rows, dropped, poses=None) -> np.ndarray | None:
    """A cheap upper bound, per vertex of ``rows``, of what dropping weight ``dropped`` moves it
    (linear blend only; None otherwise): with ``d`` the dropped weight and the kept weights scaled
    by ``1 / (1 - d)``, ``x_full - x_kept = sum_dropped w_j (M_j p - x_kept)``, and every skinned
    point is within ``L |p| + T`` of the origin (``L``, ``T``: the largest linear-part norm and
    translation of any skinning transform at the bind pose or a frame; ``|p|`` with every blend
    shape's largest displacement over the weights its clips reach added), so ``|x_full - x_kept| <=
    2 d (L |p| + T)``. Lets :func:`_trim_moves` skin exactly only the vertices that could reach the
    record's line."""
    if mesh.skinning_method != "classicLinear":
        return None
    inv_bind = np.linalg.inv(mesh.bind_transforms)
    L = T = 0.0
    for skel, _ in (_poses(mesh) if poses is None else poses):
        m = skel @ inv_bind @ mesh.geom_bind
        L = max(L, float(np.linalg.norm(m[..., :3, :3], ord=2, axis=(-2, -1)).max(initial=0.0)))
        T = max(T, float(np.linalg.norm(m[..., :3, 3], axis=-1).max(initial=0.0)))
    p = np.linalg.norm(mesh.positions[rows].astype(np.float64), axis=1)
    if mesh.blend_shapes and mesh.clips:
        # a shape's displacement is piecewise linear in its weight: its largest over the weights a
        # clip reaches is at the range's ends or at a knot inside it
        from ..model import kernel_shapes
        ks = kernel_shapes(mesh.blend_shapes, mesh.vertex_count)
        reach = np.zeros(mesh.vertex_count)
        for s in range(len(ks)):
            w = np.concatenate([c.shape_weights[:, s] for c in mesh.clips])
            lo, hi = float(w.min(initial=0.0)), float(w.max(initial=0.0))
            k = ks.knots[s]
            at = np.r_[lo, hi, k[(k >= lo) & (k <= hi)]]
            reach[ks.indices[s]] += np.linalg.norm(ks.displacement(s, at), axis=2).max(axis=0)
        p = p + reach[rows]
    return 2.0 * np.asarray(dropped, dtype=np.float64) * (L * p + T) * (1 + 1e-9)


def _posed_size(mesh: SkinnedMesh) -> float:
    """The posed model size (the contract's: the mesh as its first clip's first frame poses it; the
    bind pose without a clip), that tolerances are relative to (:func:`.quantize.posed_size`)."""
    from ..model import skel_transforms
    from .quantize import posed_size

    skel = skel_transforms(mesh.clips[0].local[0], mesh.parents) if mesh.clips else mesh.bind_transforms
    return posed_size(mesh, skel) or 1.0


def _poses(mesh: SkinnedMesh) -> list:
    """``[(skel (f, b, 4, 4), shape weights (f, S) or None)]``: the bind pose, then every clip's
    frames (what :func:`_trim_cheap` and :func:`_trim_moves` both read, computed once)."""
    from ..model import skel_transforms

    return [(mesh.bind_transforms[None], None)] + [(skel_transforms(c.local, mesh.parents), c.shape_weights)
                                                   for c in mesh.clips]

def bind(mesh: SkinnedMesh, max_influences: int = 4, unweighted: str = "error"):
    """Limit, clean and normalise skin weights; order joints parents-first.

    Parameters
    ----------
    mesh : SkinnedMesh
    max_influences : int
        Influences kept per vertex (also the output's ``k``, the USD ``elementSize``).
    unweighted : {"error", "nearest-bone"}

    Returns
    -------
    (SkinnedMesh, StageReport)
        ``joint_indices``/``joint_weights`` are ``(n, max_influences)``, strongest first,
        summing to 1; padding entries have joint 0 and weight 0.
    """
    if max_influences < 1:
        raise ValueError(f"max_influences must be >= 1, got {max_influences}")
    if unweighted not in UNWEIGHTED_POLICIES:
        raise ValueError(f"unweighted must be one of {UNWEIGHTED_POLICIES}, got {unweighted!r}")
    n = mesh.vertex_count
    # -- joints parents-first -------------------------------------------------------------
    order = parents_first(mesh.parents)
    reordered = not np.array_equal(order, np.arange(len(order)))
    new_of_old = np.empty_like(order)
    new_of_old[order] = np.arange(len(order))
    parents = np.where(mesh.parents[order] < 0, -1, new_of_old[np.maximum(mesh.parents[order], 0)])
    ji = new_of_old[mesh.joint_indices].astype(np.int64)
    jw = mesh.joint_weights.astype(np.float64)
    jw = np.where(jw > 0, jw, 0.0)

    # -- unweighted vertices --------------------------------------------------------------
    total = jw.sum(axis=1)
    empty = np.nonzero(total <= 0)[0]
    assigned = 0
    if len(empty):
        if unweighted == "error":
            path = mesh.source.get("path") or mesh.source.get("file")
            raise InputError(path, f"{len(empty)} of {n} vertices have no skin weight (first: vertex {int(empty[0])}); "
                             "use --unweighted nearest-bone to give them to the nearest bone")
        bones = nearest_bone(mesh.positions[empty] @ mesh.geom_bind[:3, :3].T + mesh.geom_bind[:3, 3],
                             mesh.bind_transforms[order], parents)
        ji[empty] = 0
        jw[empty] = 0
        ji[empty, 0] = bones
        jw[empty, 0] = 1.0
        assigned = len(empty)
        total = jw.sum(axis=1)

    # -- strongest first, drop negligible and excess, renormalise -------------------------
    out_j, out_w, over, negligible, dropped_weight = limit_influences(ji, jw / total[:, None], max_influences)

    clips = tuple(Clip(c.name, c.times, c.local[:, order], c.shape_weights) for c in mesh.clips)
    out = mesh.replace(
        joint_indices=out_j, joint_weights=out_w.astype(np.float32),
        joint_names=tuple(mesh.joint_names[i] for i in order), parents=parents,
        bind_transforms=mesh.bind_transforms[order], rest_transforms=mesh.rest_transforms[order],
        clips=clips,
    )
    counts = {
        "joints": len(order), "max_influences": int(max_influences),
        "source_max_influences": int(np.max(np.count_nonzero(mesh.joint_weights > 0, axis=1))) if n else 0,
        "influences_dropped": int(np.count_nonzero(over)), "negligible_dropped": int(np.count_nonzero(negligible)),
        "vertices_trimmed": int(np.count_nonzero(over.any(axis=1))),
        "max_weight_dropped": round(float(dropped_weight.max()) if n else 0.0, 6),
        "unweighted_assigned": assigned, "joints_reordered": bool(reordered),
    }
    warnings = []
    rows = np.flatnonzero(over.any(axis=1) | negligible.any(axis=1))
    moved, size = 0.0, 1.0
    if len(rows):
        size = _posed_size(out)
        poses = _poses(out)
        cheap = _trim_cheap(out, rows, dropped_weight[rows], poses)
        exact = rows if cheap is None else rows[cheap > 0.5 * TRIM_RELATIVE * size]
        moved = _trim_moves(out, ji, jw / np.where(total > 0, total, 1.0)[:, None], out_j, out_w, exact, poses) \
            if len(exact) else 0.0
        if cheap is not None and len(exact) < len(rows):  # the rest: their cheap bound (sound, below half the line)
            moved = max(moved, float(cheap[cheap <= 0.5 * TRIM_RELATIVE * size].max(initial=0.0)))
    counts["trim_moves_relative"] = moved / size
    if counts["influences_dropped"] and moved <= TRIM_RELATIVE * size:
        warnings.append(f"{counts['influences_dropped']} influences beyond the strongest {max_influences} dropped "
                        f"on {counts['vertices_trimmed']} vertices (largest weight lost "
                        f"{counts['max_weight_dropped']:.4f}; moves vertices up to {moved / size:.2g} x the model size)")
    if moved > TRIM_RELATIVE * size:  # fail closed: named with its bound (--strict refuses)
        item = notcarried.item(
            "skin_influences", [f"{counts['vertices_trimmed']} vertices"],
            f"{counts['influences_dropped']} influences beyond the strongest {max_influences} and "
            f"{counts['negligible_dropped']} below {NEGLIGIBLE_WEIGHT:g} dropped (largest weight lost "
            f"{counts['max_weight_dropped']:.4f}; import and validate with --max-influences "
            f"{counts['source_max_influences']} to carry them) (bound: at the bind pose and every frame of every clip)",
            moved / size)
        out = out.replace(source=dict(out.source, **{notcarried.SOURCE_KEY:
                                                      list(out.source.get(notcarried.SOURCE_KEY) or []) + [item]}))
        warnings.append(notcarried.warning_line(item))
    if assigned:
        warnings.append(f"{assigned} unweighted vertices given to their nearest bone")
    return out, StageReport("bind", counts=counts, warnings=warnings)
