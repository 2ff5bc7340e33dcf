"""Edge collapses applied with the topology checks a decimator lacks (used by ``simplify``).

`fast-simplification` chooses *which* edges to collapse and in which order (its quadric error
schedule); it has no link-condition test, so its own result can tear or pinch a closed shell
(upstream Fast-Quadric-Mesh-Simplification issue #41).  :func:`apply_collapses` replays its
history on the real positions and accepts a collapse ``(a, b)`` (``b`` merged into ``a``) only when
the mesh stays a two-manifold of the same topology:

1. both ends are *interior manifold* vertices of the input (:func:`interior_vertices`): a vertex on
   an open border, on a non-manifold edge or pinched (its fan not one cycle) never moves and is
   never merged, so open borders and the source's own defects stay exactly as they came;
2. ``a`` and ``b`` are joined by an edge of exactly two faces (earlier refusals can leave a later
   step of the history naming two vertices that are no longer neighbours);
3. the link condition (Dey, Edelsbrunner, Guha, Nekhayev 1999, "Topology preserving edge
   contraction"): the vertices adjacent to both ends are exactly the two opposite the edge.  On a
   two-manifold this is what makes a contraction keep the surface a two-manifold of the same
   topology: a closed shell stays closed, with the same Euler characteristic;
4. the shell keeps more than four vertices (a tetrahedron has no collapse left that keeps it);
5. no face around the edge turns over or degenerates when the merged vertex takes its place:
   each face's normal keeps a cosine of at least ``min_cos`` with its normal before.

Placement: the merged vertex goes to the minimiser of its cluster's area-weighted plane quadrics
(Garland-Heckbert), regularised towards the cluster's area-weighted centroid so a flat or creased
cluster stays put; a placement more than twice the cluster's radius (a running upper bound) from
that centroid falls back to the centroid.  A vertex nothing merged into keeps its exact position.

Collapses are looked at in history order until the live faces reach ``stop_faces`` or ``limit``
steps have been looked at; the outcome is deterministic in both, so a prefix search over ``limit``
(``--max-deviation``) sees a proxy that only gets coarser as ``limit`` grows.

Reference: ``tests/references/naive.py::apply_collapses`` (Python sets, the same rules).  The
replay is a numba kernel (``_apply``, in :mod:`pipeline.geometry._collapse_kernels`); this module
checks its inputs, precomputes what it needs and relabels what it returns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ._collapse_kernels import _apply

#: A collapse is refused when a face around it would turn by more than acos(FLIP_MIN_COS)
#: (~78 degrees; Fast-Quadric-Mesh-Simplification's own flip test uses the same 0.2).
FLIP_MIN_COS = 0.2
#: Outcome of each collapse of the history (:attr:`Collapsed.outcome`).
OUTCOMES = ("accepted", "locked end (open border or source defect)", "shell down to a tetrahedron",
            "ends not joined by a two-face edge", "link condition", "a face would turn over", "not reached")
#: Quadric placement is regularised towards the centroid by this times the quadric's mean
#: eigenvalue (keeps flat and creased clusters where their vertices were).
PLACEMENT_REGULARISATION = 1e-3


# ------------------------------------------------------------------------------ wrappers
def vertex_quadrics(positions: np.ndarray, triangles: np.ndarray):
    """Area-weighted plane quadrics per vertex (each face's area shared by its three corners).

    Parameters
    ----------
    positions : (n, 3) float, triangles : (m, 3) int

    Returns
    -------
    A : (n, 3, 3) float64, b : (n, 3) float64, w : (n,) float64
        ``sum over incident faces of area/3 * (n n^T, (n . p0) n, 1)``; the quadric's minimiser
        solves ``A x = b``.
    """
    p = np.asarray(positions, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    n = len(p)
    cr = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    area = 0.5 * np.linalg.norm(cr, axis=1)
    nrm = cr / np.where(area > 0, 2 * area, 1.0)[:, None]
    off = np.einsum("ij,ij->i", nrm, p[t[:, 0]])
    share = area / 3.0
    A = np.zeros((n, 9))
    b = np.zeros((n, 3))
    w = np.zeros(n)
    Af = (share[:, None, None] * nrm[:, :, None] * nrm[:, None, :]).reshape(-1, 9)
    bf = (share * off)[:, None] * nrm
    for k in range(3):
        np.add.at(A, t[:, k], Af)
        np.add.at(b, t[:, k], bf)
        np.add.at(w, t[:, k], share)
    return A.reshape(n, 3, 3), b, w


def interior_vertices(triangles: np.ndarray, n: int) -> np.ndarray:
    """``(n,)`` bool: vertices whose star is a closed disk: every incident edge is used by exactly
    two faces in opposite directions, and the faces around the vertex form one cycle.  Vertices of
    no face are False."""
    t = np.asarray(triangles, dtype=np.int64)
    out = np.zeros(n, bool)
    m = len(t)
    if m == 0:
        return out
    a, b, c = t.ravel(), t[:, [1, 2, 0]].ravel(), t[:, [2, 0, 1]].ravel()
    out[a] = True
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    _, inv, cnt = np.unique(lo * n + hi, return_inverse=True, return_counts=True)
    bal = np.bincount(inv, weights=np.where(a < b, 1, -1), minlength=len(cnt))
    bad = (cnt[inv] != 2) | (bal[inv] != 0)
    out[a[bad]] = False
    out[b[bad]] = False
    # fan: around corner a, the face links its directed edges (a, b) and (a, c)
    nodes, ninv = np.unique(np.concatenate([a * n + b, a * n + c]), return_inverse=True)
    g = coo_matrix((np.ones(3 * m), (ninv[:3 * m], ninv[3 * m:])), shape=(len(nodes), len(nodes)))
    _, lab = connected_components(g, directed=False)
    vl = np.unique(np.c_[nodes // n, lab], axis=0)
    fans = np.bincount(vl[:, 0], minlength=n)
    out[fans > 1] = False
    return out


@dataclass
class Collapsed:
    """The outcome of :func:`apply_collapses`.

    positions : (n', 3) float32, the proxy's vertices
    triangles : (m', 3) int64, the proxy's faces (orientation kept)
    vertex_map : (n,) int64, the proxy vertex each input vertex was merged into (-1: in no live face)
    accepted : (k,) bool, which collapses of the history were applied
    looked_at : int, collapses looked at (the rest of the history was not reached)
    outcome : (k,) int8, index into :data:`OUTCOMES` per collapse
    """

    positions: np.ndarray
    triangles: np.ndarray
    vertex_map: np.ndarray
    accepted: np.ndarray
    looked_at: int
    outcome: np.ndarray

    def refusals(self) -> dict:
        """``{reason: count}`` of the collapses looked at and refused."""
        c = np.bincount(self.outcome[:self.looked_at], minlength=len(OUTCOMES))
        return {OUTCOMES[i]: int(c[i]) for i in range(1, len(OUTCOMES) - 1) if c[i]}


def apply_collapses(positions, triangles, collapses, stop_faces: int = 0, limit: int | None = None,
                    quadrics=None, vertex_shell=None, min_cos: float = FLIP_MIN_COS) -> Collapsed:
    """Replay an edge-collapse history with topology checks (see the module docstring).

    Parameters
    ----------
    positions : (n, 3) float
    triangles : (m, 3) int
    collapses : (k, 2) int
        ``collapses[i] = (a, b)``: ``b`` merged into ``a`` (fast-simplification's
        ``return_collapses``); each vertex is merged away at most once.
    stop_faces : int
        Stop when at most this many faces are left.
    limit : int, optional
        Look at only the first ``limit`` collapses.
    quadrics : (A (n, 3, 3), b (n, 3), w (n,)), optional
        :func:`vertex_quadrics` of the input (computed when not given).
    vertex_shell : (n,) int, optional
        Shell of each vertex (any labelling that keeps the faces of one edge-connected component
        together); one shell for all when not given.

    Returns
    -------
    Collapsed
    """
    pos = np.ascontiguousarray(positions, dtype=np.float64)
    tri = np.ascontiguousarray(triangles, dtype=np.int64)
    col = np.ascontiguousarray(np.asarray(collapses, dtype=np.int64).reshape(-1, 2))
    n, m = len(pos), len(tri)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise ValueError(f"positions: expected shape (n, 3), got {pos.shape}")
    if tri.ndim != 2 or tri.shape[1] != 3 or (m and (tri.min() < 0 or tri.max() >= n)):
        raise ValueError(f"triangles: expected (m, 3) indices in [0, {n}), got shape {tri.shape}")
    if len(col) and (col.min() < 0 or col.max() >= n):
        raise ValueError(f"collapses: expected vertex indices in [0, {n}), got {col.min()}..{col.max()}")
    if len(np.unique(col[:, 1])) != len(col):
        raise ValueError("collapses: expected each vertex merged away at most once")
    A, b, w = quadrics if quadrics is not None else vertex_quadrics(pos, tri)
    if vertex_shell is None:
        vs = np.zeros(n, np.int64)
    else:
        vs = np.asarray(vertex_shell, dtype=np.int64)
        if vs.shape != (n,):
            raise ValueError(f"vertex_shell: expected shape ({n},), got {vs.shape}")
        vs = np.where(vs < 0, vs.max(initial=0) + 1, vs)
    used = np.zeros(n, bool)
    used[tri.ravel()] = True
    shell_verts = np.bincount(vs[used], minlength=int(vs.max(initial=0)) + 1).astype(np.int64)
    locked = ~interior_vertices(tri, n)
    k = len(col) if limit is None else int(max(0, min(limit, len(col))))
    out_pos = np.empty_like(pos)
    out_tri = np.empty_like(tri)
    alive = np.empty(m, np.bool_)
    outcome = np.full(len(col), len(OUTCOMES) - 1, np.int8)
    root = np.empty(n, np.int64)
    _, looked = _apply(pos, tri, col, locked, vs, shell_verts, np.ascontiguousarray(A, dtype=np.float64),
           np.ascontiguousarray(b, dtype=np.float64), np.ascontiguousarray(w, dtype=np.float64),
           int(stop_faces), k, float(min_cos), PLACEMENT_REGULARISATION, out_pos, out_tri, alive, outcome, root)
    # merge parents -> final cluster root
    while True:
        r2 = root[root]
        if np.array_equal(r2, root):
            break
        root = r2
    t = out_tri[alive]
    verts = np.unique(t)
    new = np.full(n, -1, np.int64)
    new[verts] = np.arange(len(verts))
    return Collapsed(out_pos[verts].astype(np.float32), new[t], new[root], outcome == 0, looked, outcome)
