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

Reference: ``tests/references/naive.py::apply_collapses`` (Python sets, the same rules).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

#: A collapse is refused when a face around it would turn by more than acos(FLIP_MIN_COS)
#: (~78 degrees; Fast-Quadric-Mesh-Simplification's own flip test uses the same 0.2).
FLIP_MIN_COS = 0.2
#: Outcome of each collapse of the history (:attr:`Collapsed.outcome`).
OUTCOMES = ("accepted", "locked end (open border or source defect)", "shell down to a tetrahedron",
            "ends not joined by a two-face edge", "link condition", "a face would turn over", "not reached")
#: Quadric placement is regularised towards the centroid by this times the quadric's mean
#: eigenvalue (keeps flat and creased clusters where their vertices were).
PLACEMENT_REGULARISATION = 1e-3


# ------------------------------------------------------------------------------ kernel
@njit(cache=True, inline="always")
def _corner(P, v, a, b, px, py, pz, moved):
    if moved and (v == a or v == b):
        return px, py, pz
    return P[v, 0], P[v, 1], P[v, 2]


@njit(cache=True, inline="always")
def _normal(P, T, f, a, b, px, py, pz, moved):
    """Normal (not normalised) of face ``f`` with vertices ``a``/``b`` put at ``p`` when ``moved``."""
    x0, y0, z0 = _corner(P, T[f, 0], a, b, px, py, pz, moved)
    x1, y1, z1 = _corner(P, T[f, 1], a, b, px, py, pz, moved)
    x2, y2, z2 = _corner(P, T[f, 2], a, b, px, py, pz, moved)
    ux, uy, uz = x1 - x0, y1 - y0, z1 - z0
    vx, vy, vz = x2 - x0, y2 - y0, z2 - z0
    return uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx


@njit(cache=True)
def _apply(pos, tris, col, locked, vshell, shell_verts, qa, qb, qw, stop_faces, limit, min_cos, reg,
           out_pos, out_tris, alive, reason, root):
    """Replay ``col[:limit]`` on ``pos``/``tris`` (see the module docstring).  Writes the final
    positions of every vertex (``out_pos``), the relabelled triangles (``out_tris``), the live
    faces (``alive``), each collapse's outcome (``reason``: see :data:`OUTCOMES`) and each vertex's
    merge parent (``root``); returns ``(live faces, collapses looked at)``."""
    n = pos.shape[0]
    m = tris.shape[0]
    # vertex -> incident corner entries (3 f + k), singly linked; merging appends b's list to a's
    head = np.full(n, -1, np.int64)
    tail = np.full(n, -1, np.int64)
    nxt = np.full(3 * m, -1, np.int64)
    for f in range(m):
        for k in range(3):
            e = 3 * f + k
            v = tris[f, k]
            if head[v] < 0:
                head[v] = e
            else:
                nxt[tail[v]] = e
            tail[v] = e
    for v in range(n):
        root[v] = v
        for k in range(3):
            out_pos[v, k] = pos[v, k]
    for f in range(m):
        alive[f] = True
        for k in range(3):
            out_tris[f, k] = tris[f, k]
    P, T = out_pos, out_tris
    A = qa.copy()
    B = qb.copy()
    W = qw.copy()
    WC = np.empty((n, 3))
    for v in range(n):
        for k in range(3):
            WC[v, k] = qw[v] * pos[v, k]
    R = np.zeros(n)
    sv = shell_verts.copy()
    mark = np.zeros(n, np.int64)
    stamp = 0
    fa = np.empty(m, np.int64)
    fb = np.empty(m, np.int64)
    Ax = np.empty((3, 3))
    rhs = np.empty(3)
    live = m
    looked = 0
    for i in range(min(limit, col.shape[0])):
        if live <= stop_faces:
            break
        looked = i + 1
        a, b = col[i, 0], col[i, 1]
        if a == b or locked[a] or locked[b]:
            reason[i] = 1
            continue
        if sv[vshell[a]] <= 4:
            reason[i] = 2
            continue
        na = 0
        e = head[a]
        while e >= 0:
            f = e // 3
            if alive[f]:
                fa[na] = f
                na += 1
            e = nxt[e]
        nb = 0
        e = head[b]
        while e >= 0:
            f = e // 3
            if alive[f]:
                fb[nb] = f
                nb += 1
            e = nxt[e]
        # neighbours of a
        stamp += 1
        for s in range(na):
            for k in range(3):
                mark[T[fa[s], k]] = stamp
        shared = 0
        for s in range(nb):
            f = fb[s]
            if T[f, 0] == a or T[f, 1] == a or T[f, 2] == a:
                shared += 1
        if shared != 2:
            reason[i] = 3
            continue
        # link condition: common neighbours (other than a and b themselves) are the two opposite
        common = 0
        stamp += 1
        for s in range(nb):
            for k in range(3):
                v = T[fb[s], k]
                if v != a and v != b and mark[v] == stamp - 1:
                    mark[v] = stamp  # counted once
                    common += 1
        if common != 2:
            reason[i] = 4
            continue
        # placement
        w = W[a] + W[b]
        tr = A[a, 0, 0] + A[b, 0, 0] + A[a, 1, 1] + A[b, 1, 1] + A[a, 2, 2] + A[b, 2, 2]
        lam = reg * tr / 3.0 + 1e-300
        cx = (WC[a, 0] + WC[b, 0]) / w
        cy = (WC[a, 1] + WC[b, 1]) / w
        cz = (WC[a, 2] + WC[b, 2]) / w
        for r in range(3):
            for q in range(3):
                Ax[r, q] = A[a, r, q] + A[b, r, q] + (lam if r == q else 0.0)
        rhs[0] = B[a, 0] + B[b, 0] + lam * cx
        rhs[1] = B[a, 1] + B[b, 1] + lam * cy
        rhs[2] = B[a, 2] + B[b, 2] + lam * cz
        det = (Ax[0, 0] * (Ax[1, 1] * Ax[2, 2] - Ax[1, 2] * Ax[2, 1])
               - Ax[0, 1] * (Ax[1, 0] * Ax[2, 2] - Ax[1, 2] * Ax[2, 0])
               + Ax[0, 2] * (Ax[1, 0] * Ax[2, 1] - Ax[1, 1] * Ax[2, 0]))
        ra = R[a] + np.sqrt((cx - WC[a, 0] / W[a]) ** 2 + (cy - WC[a, 1] / W[a]) ** 2 + (cz - WC[a, 2] / W[a]) ** 2) \
            if W[a] > 0 else R[a]
        rb = R[b] + np.sqrt((cx - WC[b, 0] / W[b]) ** 2 + (cy - WC[b, 1] / W[b]) ** 2 + (cz - WC[b, 2] / W[b]) ** 2) \
            if W[b] > 0 else R[b]
        # the centroid bound of a cluster also covers its members' own positions
        ra = max(ra, np.sqrt((cx - pos[a, 0]) ** 2 + (cy - pos[a, 1]) ** 2 + (cz - pos[a, 2]) ** 2))
        rb = max(rb, np.sqrt((cx - pos[b, 0]) ** 2 + (cy - pos[b, 1]) ** 2 + (cz - pos[b, 2]) ** 2))
        rad = max(ra, rb)
        px, py, pz = cx, cy, cz
        if det != 0.0 and np.isfinite(det):
            sx = (rhs[0] * (Ax[1, 1] * Ax[2, 2] - Ax[1, 2] * Ax[2, 1])
                  - Ax[0, 1] * (rhs[1] * Ax[2, 2] - Ax[1, 2] * rhs[2])
                  + Ax[0, 2] * (rhs[1] * Ax[2, 1] - Ax[1, 1] * rhs[2])) / det
            sy = (Ax[0, 0] * (rhs[1] * Ax[2, 2] - Ax[1, 2] * rhs[2])
                  - rhs[0] * (Ax[1, 0] * Ax[2, 2] - Ax[1, 2] * Ax[2, 0])
                  + Ax[0, 2] * (Ax[1, 0] * rhs[2] - rhs[1] * Ax[2, 0])) / det
            sz = (Ax[0, 0] * (Ax[1, 1] * rhs[2] - rhs[1] * Ax[2, 1])
                  - Ax[0, 1] * (Ax[1, 0] * rhs[2] - rhs[1] * Ax[2, 0])
                  + rhs[0] * (Ax[1, 0] * Ax[2, 1] - Ax[1, 1] * Ax[2, 0])) / det
            if np.sqrt((sx - cx) ** 2 + (sy - cy) ** 2 + (sz - cz) ** 2) <= 2.0 * rad + 1e-12 * (1.0 + rad):
                px, py, pz = sx, sy, sz
        # no face around the edge turns over or degenerates
        ok = True
        for side in range(2):
            cnt = na if side == 0 else nb
            for s in range(cnt):
                f = fa[s] if side == 0 else fb[s]
                hasa = T[f, 0] == a or T[f, 1] == a or T[f, 2] == a
                hasb = T[f, 0] == b or T[f, 1] == b or T[f, 2] == b
                if hasa and hasb:
                    continue
                ox, oy, oz = _normal(P, T, f, a, b, px, py, pz, False)
                nx, ny, nz = _normal(P, T, f, a, b, px, py, pz, True)
                lo = np.sqrt(ox * ox + oy * oy + oz * oz)
                ln = np.sqrt(nx * nx + ny * ny + nz * nz)
                if not (ln > 0.0) or ox * nx + oy * ny + oz * nz < min_cos * lo * ln:
                    ok = False
                    break
            if not ok:
                break
        if not ok:
            reason[i] = 5
            continue
        # accept
        for s in range(nb):
            f = fb[s]
            hasa = T[f, 0] == a or T[f, 1] == a or T[f, 2] == a
            if hasa:
                alive[f] = False
            else:
                for k in range(3):
                    if T[f, k] == b:
                        T[f, k] = a
        if head[b] >= 0:
            if head[a] < 0:
                head[a] = head[b]
            else:
                nxt[tail[a]] = head[b]
            tail[a] = tail[b]
            head[b] = -1
        P[a, 0], P[a, 1], P[a, 2] = px, py, pz
        for r in range(3):
            for q in range(3):
                A[a, r, q] += A[b, r, q]
            B[a, r] += B[b, r]
            WC[a, r] += WC[b, r]
        W[a] = w
        R[a] = rad
        sv[vshell[a]] -= 1
        root[b] = a
        reason[i] = 0
        live -= 2
    return live, looked


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
