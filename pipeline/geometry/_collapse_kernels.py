"""The kernel of :func:`pipeline.geometry.collapse.apply_collapses`: the edge-collapse replay
with its topology checks (``_apply``; the rules, the placement and why they keep a closed shell a
two-manifold of the same topology are in :mod:`pipeline.geometry.collapse`'s docstring, the
outcome codes in its ``OUTCOMES``).  Reference: ``tests/references/naive.py::apply_collapses``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from colossus.runtime.kernels.config import FASTMATH_OFF


@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
def _corner(P, v, a, b, px, py, pz, moved):
    if moved and (v == a or v == b):
        return px, py, pz
    return P[v, 0], P[v, 1], P[v, 2]


@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
def _normal(P, T, f, a, b, px, py, pz, moved):
    """Normal (not normalised) of face ``f`` with vertices ``a``/``b`` put at ``p`` when ``moved``."""
    x0, y0, z0 = _corner(P, T[f, 0], a, b, px, py, pz, moved)
    x1, y1, z1 = _corner(P, T[f, 1], a, b, px, py, pz, moved)
    x2, y2, z2 = _corner(P, T[f, 2], a, b, px, py, pz, moved)
    ux, uy, uz = x1 - x0, y1 - y0, z1 - z0
    vx, vy, vz = x2 - x0, y2 - y0, z2 - z0
    return uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx


@njit(cache=True, fastmath=FASTMATH_OFF)
def _apply(pos, tris, col, locked, vshell, shell_verts, qa, qb, qw, stop_faces, limit, min_cos, reg,
           out_pos, out_tris, alive, reason, root):
    """Replay ``col[:limit]`` on ``pos``/``tris`` (see :mod:`pipeline.geometry.collapse`).  Writes
    the final positions of every vertex (``out_pos``), the relabelled triangles (``out_tris``), the
    live faces (``alive``), each collapse's outcome (``reason``: see
    :data:`~pipeline.geometry.collapse.OUTCOMES`) and each vertex's merge parent (``root``);
    returns ``(live faces, collapses looked at)``."""
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
