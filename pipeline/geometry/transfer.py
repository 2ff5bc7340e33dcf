"""Skin weights for new points (a proxy's vertices) by closest-point transfer on the full rest mesh:
:func:`transfer_weights`.

Each point takes the per-bone weights of its nearest point on its own shell of the full rest
surface (a rigid part or a second skin beside the body keeps its own joints), interpolated
barycentrically over that triangle's corners (weights of each bone are interpolated, joint
indices never); the strongest ``max_influences`` are kept and renormalised by
:func:`colossus.pipeline.stages.bind.limit_influences`, the same code ``bind`` uses.  This is
local at joints, where a cluster average would blend the weights of the whole (possibly large)
cluster.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..model import SkinnedMesh
from ..stages.bind import limit_influences
from .deviation import FULL_CANDIDATES
from .surface_distance import nearest_on_candidates


def transfer_weights(full: SkinnedMesh, points: np.ndarray, max_influences: int, point_shell=None, face_shell=None):
    """Skin weights at ``points`` (mesh space, rest) by closest-point transfer on the full rest
    mesh: per-bone weights interpolated barycentrically over the nearest triangle, strongest
    ``max_influences`` kept and renormalised.

    ``point_shell`` (n',) int and ``face_shell`` (m,) int, when given, keep each point to the
    triangles of its own shell: a rigid part (a helmet bound to the head with weight 1) or another
    skin merged into the one skeleton must not take the weights of a different shell that happens
    to lie nearer (a point of a shell with no triangle, ``-1``, looks at every triangle).

    Returns ``(joint_indices (n', max_influences) int32, joint_weights (n', max_influences)
    float32, distance (n',) float64, triangle (n',) int64, barycentric (n', 3) float64)``: the
    distance from each point to its full rest surface, and the nearest point it took (what
    :func:`transfer_shapes` interpolates the blend shapes' offsets at)."""
    rest = full.positions
    tri = full.triangles.astype(np.int64)
    pts = np.asarray(points, dtype=np.float32)
    n2 = len(pts)
    kk = int(min(FULL_CANDIDATES, len(tri)))
    centroids = rest.astype(np.float64)[tri].mean(axis=1)
    if point_shell is None or face_shell is None:
        cand = cKDTree(centroids).query(pts, k=kk)[1].reshape(n2, kk)
    else:
        point_shell = np.asarray(point_shell, dtype=np.int64)
        face_shell = np.asarray(face_shell, dtype=np.int64)
        cand = np.empty((n2, kk), np.int64)
        mine = np.isin(point_shell, face_shell)
        if not mine.all():
            cand[~mine] = cKDTree(centroids).query(pts[~mine], k=kk)[1].reshape(-1, kk)
        order = np.argsort(face_shell, kind="stable")
        shells, first, count = np.unique(face_shell[order], return_index=True, return_counts=True)
        for s, f0, c in zip(shells, first, count):
            rows = np.flatnonzero(point_shell == s)
            if not len(rows):
                continue
            faces = order[f0:f0 + c]
            k = int(min(kk, c))
            near = cKDTree(centroids[faces]).query(pts[rows], k=k)[1].reshape(len(rows), k)
            # a shell with fewer triangles than kk repeats its nearest one (a duplicate candidate)
            cand[rows] = faces[np.pad(near, ((0, 0), (0, kk - k)), mode="edge")]
    d, t, bary = nearest_on_candidates(pts, np.repeat(np.arange(n2)[:, None], 3, 1),
                                       np.tile([1.0, 0.0, 0.0], (n2, 1)), rest, tri, cand)
    corners = tri[t]                                       # (n', 3)
    k = full.joint_indices.shape[1]
    ji = full.joint_indices[corners].reshape(n2, 3 * k).astype(np.int64)
    jw = (full.joint_weights[corners].astype(np.float64) * bary[:, :, None]).reshape(n2, 3 * k)
    b = max(full.joint_count, 1)
    row = np.repeat(np.arange(n2), 3 * k)
    live = jw.ravel() > 0
    key = row[live] * b + ji.ravel()[live]
    uk, inv = np.unique(key, return_inverse=True)
    wsum = np.bincount(inv, weights=jw.ravel()[live])
    r, j = uk // b, uk % b
    cnt = np.bincount(r, minlength=n2)
    width = max(int(cnt.max()) if len(cnt) else 1, 1)
    start = np.r_[0, np.cumsum(cnt)[:-1]]
    col = np.arange(len(uk)) - start[r]
    J = np.zeros((n2, width), np.int64)
    W = np.zeros((n2, width))
    J[r, col], W[r, col] = j, wsum
    tot = W.sum(axis=1, keepdims=True)
    W = W / np.where(tot > 0, tot, 1.0)
    out_j, out_w, *_ = limit_influences(J, W, max_influences)
    return out_j, out_w.astype(np.float32), d, t, bary


def transfer_shapes(full: SkinnedMesh, triangle, barycentric) -> tuple:
    """The full mesh's blend shapes carried to new points by the same closest-point transfer as
    their weights (:func:`transfer_weights`' ``triangle`` and ``barycentric``): each offset, the
    primary one and every in-between's, interpolated barycentrically over that triangle's corners
    (the rest point moves with its nearest surface point's shape).  A shape's response stays
    piecewise linear in its weight with the same knots (the interpolation is linear in the
    offsets).  Each shape keeps the new points it moves (``pointIndices``)."""
    from ..model import BlendShape

    corners = full.triangles.astype(np.int64)[np.asarray(triangle, dtype=np.int64)]  # (n', 3)
    bary = np.asarray(barycentric, dtype=np.float64)
    n = full.vertex_count
    out = []
    for sh in full.blend_shapes:
        def carry(o, idx=np.asarray(sh.indices, dtype=np.int64)):
            dense = np.zeros((n, 3))
            dense[idx] = o
            return np.einsum("pc,pcx->px", bary, dense[corners])
        prim = carry(sh.offsets)
        ibs = [(w, carry(o)) for w, o in sh.inbetweens]
        moved = np.any(prim != 0, axis=1)
        for _, o in ibs:
            moved |= np.any(o != 0, axis=1)
        keep = np.flatnonzero(moved)
        out.append(BlendShape(sh.name, keep.astype(np.int32), prim[keep].astype(np.float32),
                              tuple((w, o[keep].astype(np.float32)) for w, o in ibs)))
    return tuple(out)
