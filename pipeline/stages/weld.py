"""``weld``: merge vertices that share a position *and* the same skin influences.

After trimesh's ``grouping.merge_vertices``: :func:`weld_maps` returns ``(keep, inverse)`` index
maps that every per-vertex attribute goes through.  The weld key includes the skin influences:
two vertices at one position with different weights are genuinely different vertices (welding
them would change the animated shape), so they are kept apart and reported, since such a seam
tears open in animation.

Two vertices that share a triangle are never merged, however close: split copies of one vertex
never share a triangle, while a closed mesh may hold genuinely different vertices closer than the
tolerance, joined by a real edge (metaball-made meshes do); merging them would collapse that edge
and its faces.  (Bit-identical duplicates in one triangle are still merged: that triangle has no
area either way.)
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from colossus.pipeline.model import SkinnedMesh, Parts
from colossus.pipeline.stages import StageReport
from colossus.pipeline.tolerances import WELD_RELATIVE, WELD_WEIGHT, model_scale


def canonical_influences(joint_indices: np.ndarray, joint_weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Influences in a column-order independent form.

    Parameters
    ----------
    joint_indices : (n, k) int
    joint_weights : (n, k) float

    Returns
    -------
    joints : (n, k) int64
        Influences with weight > 0 sorted by joint index (then weight), then ``-1`` padding.
    weights : (n, k) float32
        Matching weights, ``0`` padding.
    """
    j = np.asarray(joint_indices, dtype=np.int64)
    w = np.asarray(joint_weights, dtype=np.float32)
    live = w > 0
    # per row: live influences first, by joint then weight (the last key of lexsort is the first)
    order = np.lexsort((w, np.where(live, j, np.iinfo(np.int64).max)), axis=-1)
    keep = np.take_along_axis(live, order, -1)
    cj = np.where(keep, np.take_along_axis(j, order, -1), -1)
    cw = np.where(keep, np.take_along_axis(w, order, -1), np.float32(0))
    return np.ascontiguousarray(cj), np.ascontiguousarray(cw, dtype=np.float32)


def _exact_groups(rows):
    """Label each row of ``rows`` (n, c) uint32 with the index of the first identical row.

    Rows are hashed to 64 bits (vectorised FNV-1a over the 32-bit words, then a splitmix
    finaliser) and grouped by sorting the hashes; every row is then compared with its group's
    first row, and should two different rows ever share a hash the rows themselves are sorted
    instead (O(n log n) either way)."""
    n, c = rows.shape
    if n == 0:
        return np.zeros(0, np.int64)
    with np.errstate(over="ignore"):
        h = np.full(n, 1469598103934665603, np.uint64)
        for t in range(c):
            h = (h ^ rows[:, t].astype(np.uint64)) * np.uint64(1099511628211)
        h ^= h >> np.uint64(31)
        h *= np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(29)
    _, first, inv = np.unique(h, return_index=True, return_inverse=True)
    label = first[inv]
    if not np.array_equal(rows[label], rows):  # a hash collision: group the rows exactly
        v = np.ascontiguousarray(rows).view(np.dtype((np.void, rows.dtype.itemsize * c))).ravel()
        _, first, inv = np.unique(v, return_index=True, return_inverse=True)
        label = first[inv]
    return label.astype(np.int64)


def _row_groups(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group identical rows of a 2-D uint32 array: ``(first index of each group (increasing),
    group of each row)``."""
    label = _exact_groups(np.ascontiguousarray(rows, dtype=np.uint32))
    is_first = label == np.arange(len(label))
    first = np.flatnonzero(is_first)
    group = (np.cumsum(is_first) - 1)[label]
    return first, group


def weld_maps(positions: np.ndarray, joint_indices: np.ndarray, joint_weights: np.ndarray,
              tolerance: float, triangles: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Index maps that merge vertices closer than ``tolerance`` with the same skin influences.

    Two vertices are merged when they are within ``tolerance`` (Euclidean) of each other and
    carry the same influences: the same set of joints with weight > 0 (in any column order),
    each weight equal within :data:`~pipeline.tolerances.WELD_WEIGHT`.  Merging is transitive
    (connected components of that relation, like trimesh).  O(n log n): exact duplicates are
    grouped by sorting, the rest found with a k-d tree.

    Parameters
    ----------
    positions : (n, 3) float
    joint_indices : (n, k) int
    joint_weights : (n, k) float
    tolerance : float, >= 0
    triangles : (m, 3) int, optional
        When given, two vertices of one triangle never end up merged (unless bit-identical).

    Returns
    -------
    keep : (u,) int64
        Index of the vertex kept for each output vertex: the lowest original index of its group;
        increasing, so kept vertices stay in their original relative order.
    inverse : (n,) int64
        Output vertex of each input vertex: ``positions[keep][inverse]`` is each vertex's
        representative.
    conflicts : int
        Number of **output** vertices lying within ``tolerance`` of another output vertex whose
        influences differ (a seam kept open because the skin weights disagree).
    """
    p = np.asarray(positions)
    n = len(p)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"weld positions: expected shape (n, 3), got {p.shape}")
    ji = np.asarray(joint_indices)
    jw = np.asarray(joint_weights)
    if ji.ndim != 2 or ji.shape[0] != n:
        raise ValueError(f"weld joint_indices: expected shape ({n}, k), got {ji.shape}")
    if jw.shape != ji.shape:
        raise ValueError(f"weld joint_weights: expected shape {ji.shape}, got {jw.shape}")
    tolerance = float(tolerance)
    if not np.isfinite(tolerance) or tolerance < 0:
        raise ValueError(f"weld tolerance: expected a finite number >= 0, got {tolerance}")
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), 0

    cj, cw = canonical_influences(ji, jw)
    # 1. exact duplicates (position bits + canonical influences): "classes"
    pos32 = np.ascontiguousarray(p, dtype=np.float32) + np.float32(0.0)  # -0.0 -> +0.0
    rows = np.concatenate([pos32.view(np.uint32), cj.astype(np.int32).view(np.uint32),
                           cw.view(np.uint32)], axis=1)
    cls_first, cls_of = _row_groups(rows)
    nc = len(cls_first)

    # 2. near classes (k-d tree on class representatives), split by influence equality
    tree = cKDTree(pos32[cls_first].astype(np.float64))
    pairs = tree.query_pairs(r=tolerance, output_type="ndarray")
    a, b = cls_first[pairs[:, 0]], cls_first[pairs[:, 1]]
    same = np.all(cj[a] == cj[b], axis=1) & np.all(np.abs(cw[a] - cw[b]) <= WELD_WEIGHT, axis=1)
    good = pairs[same]
    edges = None
    if triangles is not None and len(good):
        edges = _class_edges(np.asarray(triangles, dtype=np.int64), cls_of, nc)
        good = good[~np.isin(good[:, 0] * nc + good[:, 1], edges)]  # pairs are (lo, hi)
    graph = coo_matrix((np.ones(len(good), np.int8), (good[:, 0], good[:, 1])), shape=(nc, nc))
    ncomp, comp_of_cls = connected_components(graph, directed=False)
    if edges is not None and len(edges):
        lo, hi = edges // nc, edges % nc
        if np.any(comp_of_cls[lo] == comp_of_cls[hi]):  # merged through a chain of near vertices
            ncomp, comp_of_cls = _greedy_components(nc, good, lo, hi)
    comp = comp_of_cls[cls_of]

    # 3. lowest original index per group, groups in original order (classes are numbered in
    #    order of their first vertex, so a group's first class holds its lowest vertex)
    first = np.full(ncomp, nc, dtype=np.int64)
    np.minimum.at(first, comp_of_cls, np.arange(nc, dtype=np.int64))
    order = np.argsort(first, kind="stable")
    keep = cls_first[first[order]]
    rank = np.empty(ncomp, np.int64)
    rank[order] = np.arange(ncomp)
    inverse = rank[comp]

    bad = pairs[~same]
    ra, rb = rank[comp_of_cls[bad[:, 0]]], rank[comp_of_cls[bad[:, 1]]]
    apart = ra != rb
    conflicts = int(len(np.unique(np.concatenate([ra[apart], rb[apart]]))))
    return keep, inverse, conflicts


def _class_edges(triangles, cls_of, nc):
    """Sorted unique ``lo * nc + hi`` keys of the class pairs joined by a triangle edge."""
    c = cls_of[triangles]
    e = np.concatenate([c[:, [0, 1]], c[:, [1, 2]], c[:, [0, 2]]])
    e = e[e[:, 0] != e[:, 1]]
    e.sort(axis=1)
    return np.unique(e[:, 0] * nc + e[:, 1])


def _greedy_components(nc, pairs, lo, hi):
    """Union-find over ``pairs`` (in order) that refuses a union joining two classes of one
    triangle edge (``lo[i]``, ``hi[i]``); only reached when a chain of near vertices would do so."""
    parent = np.arange(nc)
    adj = {}
    for x, y in zip(lo.tolist(), hi.tolist()):
        adj.setdefault(x, set()).add(y)
        adj.setdefault(y, set()).add(x)

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    members = {}
    for x, y in pairs.tolist():
        rx, ry = find(x), find(y)
        if rx == ry:
            continue
        mx, my = members.get(rx, [rx]), members.get(ry, [ry])
        if len(mx) < len(my):
            rx, ry, mx, my = ry, rx, my, mx
        ny = set(my)
        if any(adj.get(v, set()) & ny for v in mx):
            continue
        parent[ry] = rx
        members[rx] = mx + my
        members.pop(ry, None)
    roots = np.array([find(x) for x in range(nc)])
    _, comp = np.unique(roots, return_inverse=True)
    return int(comp.max()) + 1 if nc else 0, comp


def weld(mesh: SkinnedMesh, tolerance: float | None = None) -> tuple[SkinnedMesh, StageReport]:
    """Merge coincident vertices with equal skin influences; drop faces that collapse.

    Parameters
    ----------
    mesh : SkinnedMesh
    tolerance : float, optional
        Absolute weld distance in mesh units; default
        :data:`~pipeline.tolerances.WELD_RELATIVE` times the model size.

    Returns
    -------
    (SkinnedMesh, StageReport)
        Report counts: ``vertices_in``, ``vertices_out``, ``merged``, ``weight_conflicts``,
        ``degenerate_faces_removed``, ``faces_out``, ``tolerance``.
    """
    if tolerance is None:
        tolerance = WELD_RELATIVE * model_scale(mesh.positions)
    keep, inverse, conflicts = weld_maps(mesh.positions, mesh.joint_indices, mesh.joint_weights, tolerance,
                                         mesh.triangles)
    shape_split = 0
    if mesh.blend_shapes:  # two vertices merge only if every shape moves them alike too
        keep, inverse, shape_split = _split_by_shapes(keep, inverse, mesh.blend_shapes, mesh.vertex_count)
    tris = inverse[mesh.triangles]
    degenerate = (tris[:, 0] == tris[:, 1]) | (tris[:, 1] == tris[:, 2]) | (tris[:, 0] == tris[:, 2])
    kept_faces = ~degenerate
    changes = dict(
        positions=mesh.positions[keep],
        triangles=tris[kept_faces].astype(np.int32),
        joint_indices=mesh.joint_indices[keep],
        joint_weights=mesh.joint_weights[keep],
    )
    if mesh.blend_shapes:
        from ..model import remap_shapes
        changes["blend_shapes"] = remap_shapes(mesh.blend_shapes, inverse, len(keep))
    if mesh.parts is not None:
        changes["parts"] = _drop_faces(mesh.parts, kept_faces)
    out = mesh.replace(**changes)

    report = StageReport("weld")
    report.counts = {
        "vertices_in": int(mesh.vertex_count),
        "vertices_out": int(len(keep)),
        "merged": int(mesh.vertex_count - len(keep)),
        "weight_conflicts": int(conflicts),
        "degenerate_faces_removed": int(degenerate.sum()),
        "faces_out": int(kept_faces.sum()),
        "tolerance": float(tolerance),
        "kept_apart_by_shapes": int(shape_split),
    }
    if conflicts:
        report.warnings.append(
            f"{conflicts} same-position vertices have different skin weights and were kept apart "
            "(they would tear open in animation)")
    return out, report


def _split_by_shapes(keep, inverse, shapes, n):
    """The weld's classes split where their vertices' blend-shape offsets differ
    (:func:`model.shape_table`, exact float32 equality): ``(keep, inverse, extra classes)``; the
    classes stay in the order of their first vertex."""
    from ..model import shape_table

    table = shape_table(shapes, n)
    _, row = np.unique(table, axis=0, return_inverse=True)
    key = np.asarray(inverse, dtype=np.int64) * (int(row.max()) + 1) + row.reshape(-1)
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    new_inverse = rank[inv.reshape(-1)]
    new_keep = first[order]
    if len(new_keep) == len(keep):  # nothing split: the weld's own choice of vertex stands
        return keep, inverse, 0
    return new_keep, new_inverse, len(new_keep) - len(keep)


def _drop_faces(parts: Parts, kept_faces: np.ndarray) -> Parts:
    """Parts with removed faces dropped and the remaining faces renumbered."""
    new_index = np.cumsum(kept_faces) - 1
    part_of = np.repeat(np.arange(len(parts)), np.diff(parts.face_offsets))
    alive = kept_faces[parts.faces]
    counts = np.bincount(part_of[alive], minlength=len(parts))
    return Parts(parts.joints, np.concatenate([[0], np.cumsum(counts)]), new_index[parts.faces[alive]],
                 parts.centers, parts.radii)
