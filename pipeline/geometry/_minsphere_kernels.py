"""The kernel of the minimal enclosing sphere's core-set loop (numba behind
:func:`pipeline.geometry.minsphere.min_sphere` and friends, where the method and its constants
are documented).

``_core_loop`` is steps 2-4 of :mod:`pipeline.geometry.minsphere` (Welzl's nested loop on the
shuffled core set, the farthest point of each chunk, the next core set) operation for operation
as the plain-Python form it replaced: the same IEEE float64 operations in the same order, no
fast-math flag (so no contraction into fused multiply-adds), the same deterministic shuffle.
Its spheres are therefore bit-identical to the Python form's.  Why compiled: the spheres stage
solves one sphere per part and per sampled pose (about 3,800 on the 200,000-triangle benchmark,
several core-set rounds each); in Python and numpy that was ~14 s of that import, mostly
interpreter overhead on small core sets and numpy calls on a few thousand points.  One kernel
(and its small helpers) compiles in a couple of seconds once per machine (``cache=True``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from colossus.runtime.kernels.config import FASTMATH_OFF

# The constants are minsphere's (repeated here: numba freezes module globals at compile time;
# tests/pipeline/test_stages_geometry.py checks that the two agree).
_INSIDE_REL = 1e-11
CONTAIN_REL = 1e-9
_COLLINEAR = 1e-14
_COPLANAR = 1e-10
_CHUNKS = 16
_MAX_ITER = 200


@njit(cache=True, fastmath=FASTMATH_OFF)
def _d2(a, c):
    dx, dy, dz = a[0] - c[0], a[1] - c[1], a[2] - c[2]
    return dx * dx + dy * dy + dz * dz


@njit(cache=True, fastmath=FASTMATH_OFF)
def _ball2(a, b):
    c = (0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2]))
    return c, max(_d2(a, c), _d2(b, c))


@njit(cache=True, fastmath=FASTMATH_OFF)
def _enclose3(a, b, c):
    dab, dac, dbc = _d2(a, b), _d2(a, c), _d2(b, c)
    if dab >= dac and dab >= dbc:
        ctr, r2 = _ball2(a, b)
    elif dac >= dbc:
        ctr, r2 = _ball2(a, c)
    else:
        ctr, r2 = _ball2(b, c)
    return ctr, max(max(r2, _d2(a, ctr)), max(_d2(b, ctr), _d2(c, ctr)))


@njit(cache=True, fastmath=FASTMATH_OFF)
def _ball3(a, b, c):
    ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    vx, vy, vz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    wx, wy, wz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    uu = ux * ux + uy * uy + uz * uz
    vv = vx * vx + vy * vy + vz * vz
    ww = wx * wx + wy * wy + wz * wz
    if ww <= _COLLINEAR * uu * vv or ww == 0.0:
        return _enclose3(a, b, c)
    px, py, pz = uu * vx - vv * ux, uu * vy - vv * uy, uu * vz - vv * uz
    s = 0.5 / ww
    ctr = (a[0] + (py * wz - pz * wy) * s, a[1] + (pz * wx - px * wz) * s, a[2] + (px * wy - py * wx) * s)
    return ctr, max(max(_d2(a, ctr), _d2(b, ctr)), _d2(c, ctr))


@njit(cache=True, fastmath=FASTMATH_OFF)
def _fits(q, ctr, lim):
    return _d2(q[0], ctr) <= lim and _d2(q[1], ctr) <= lim and _d2(q[2], ctr) <= lim and _d2(q[3], ctr) <= lim


@njit(cache=True, fastmath=FASTMATH_OFF)
def _enclose4(q):
    """Smallest sphere of 4 (nearly) coplanar points ``q`` (a 4-tuple of points)."""
    found = False
    best_c, best_r2 = q[0], 0.0
    for i in range(4):
        for j in range(i + 1, 4):
            for k in range(j, 4):  # k == j: the pair's ball, then the triples (j < k)
                if k == j:
                    ctr, r2 = _ball2(q[i], q[j])
                else:
                    ctr, r2 = _ball3(q[i], q[j], q[k])
                lim = r2 * (1.0 + 1e-9) + 1e-300
                if (not found or r2 < best_r2) and _fits(q, ctr, lim):
                    found, best_c, best_r2 = True, ctr, r2
    if not found:  # numerically nothing fits: centroid and farthest corner
        ctr = (0.25 * (((q[0][0] + q[1][0]) + q[2][0]) + q[3][0]), 0.25 * (((q[0][1] + q[1][1]) + q[2][1]) + q[3][1]),
               0.25 * (((q[0][2] + q[1][2]) + q[2][2]) + q[3][2]))
        r2 = _d2(q[0], ctr)
        for t in range(1, 4):
            r2 = max(r2, _d2(q[t], ctr))
        best_c, best_r2 = ctr, r2
    return best_c, best_r2


@njit(cache=True, fastmath=FASTMATH_OFF)
def _ball4(a, b, c, d):
    ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    vx, vy, vz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    tx, ty, tz = d[0] - a[0], d[1] - a[1], d[2] - a[2]
    vtx, vty, vtz = vy * tz - vz * ty, vz * tx - vx * tz, vx * ty - vy * tx
    tux, tuy, tuz = ty * uz - tz * uy, tz * ux - tx * uz, tx * uy - ty * ux
    uvx, uvy, uvz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    det = ux * vtx + uy * vty + uz * vtz
    uu = ux * ux + uy * uy + uz * uz
    vv = vx * vx + vy * vy + vz * vz
    tt = tx * tx + ty * ty + tz * tz
    if abs(det) <= _COPLANAR * math.sqrt(uu * vv * tt) or det == 0.0:
        return _enclose4((a, b, c, d))
    s = 0.5 / det
    ctr = (a[0] + (uu * vtx + vv * tux + tt * uvx) * s, a[1] + (uu * vty + vv * tuy + tt * uvy) * s,
           a[2] + (uu * vtz + vv * tuz + tt * uvz) * s)
    return ctr, max(max(max(_d2(a, ctr), _d2(b, ctr)), _d2(c, ctr)), _d2(d, ctr))


@njit(cache=True, fastmath=FASTMATH_OFF)
def _pt(S, i):
    return (S[i, 0], S[i, 1], S[i, 2])


@njit(cache=True, fastmath=FASTMATH_OFF)
def _welzl(S):
    """Minimal sphere of the rows of ``S`` (m, 3) float64 (nested-loop Welzl): ``(centre, r2)``."""
    grow = 1.0 + _INSIDE_REL
    ctr, r2 = _pt(S, 0), 0.0
    for i in range(1, S.shape[0]):
        if not _d2(_pt(S, i), ctr) > r2 * grow:
            continue
        ctr, r2 = _pt(S, i), 0.0
        for j in range(i):
            if not _d2(_pt(S, j), ctr) > r2 * grow:
                continue
            ctr, r2 = _ball2(_pt(S, i), _pt(S, j))
            for k in range(j):
                if not _d2(_pt(S, k), ctr) > r2 * grow:
                    continue
                ctr, r2 = _ball3(_pt(S, i), _pt(S, j), _pt(S, k))
                for m in range(k):
                    if _d2(_pt(S, m), ctr) > r2 * grow:
                        ctr, r2 = _ball4(_pt(S, i), _pt(S, j), _pt(S, k), _pt(S, m))
    return ctr, r2


@njit(cache=True, fastmath=FASTMATH_OFF)
def _boundary(P, core, nc, o, c, r2, out):
    """Write the core points on the boundary of ``(c, r2)`` (relative to ``o``) to ``out``;
    returns their count."""
    lim = r2 * (1.0 - 1e-7)
    m = 0
    for t in range(nc):
        i = core[t]
        q = (np.float64(P[i, 0]) - o[0], np.float64(P[i, 1]) - o[1], np.float64(P[i, 2]) - o[2])
        if _d2(q, c) >= lim:
            out[m] = i
            m += 1
    return m


@njit(cache=True, fastmath=FASTMATH_OFF)
def _first_core(P, hint):
    """Step 1: the ``hint`` indices, then the points of ``P`` (n, 3) with the smallest and the
    largest projection on each of minsphere's 7 directions (the first such point in index
    order), without repeats, in that order (int64 array).

    The directions' components are 0 and +-1, so each projection ``(d0 x + d1 y) + d2 z`` is
    exact but for the two additions, summed in the order a matrix product sums them
    (minsphere's Python form computes the projections with BLAS; a test checks the cores agree)."""
    n = P.shape[0]
    lo_v = np.empty(7)
    hi_v = np.empty(7)
    for k in range(7):
        lo_v[k], hi_v[k] = np.inf, -np.inf
    lo_i = np.zeros(7, np.int64)
    hi_i = np.zeros(7, np.int64)
    for i in range(n):
        x, y, z = np.float64(P[i, 0]), np.float64(P[i, 1]), np.float64(P[i, 2])
        for k in range(7):
            if k == 0:
                v = x
            elif k == 1:
                v = y
            elif k == 2:
                v = z
            elif k == 3:
                v = (x + y) + z
            elif k == 4:
                v = (x + y) - z
            elif k == 5:
                v = (x - y) + z
            else:
                v = (y - x) + z
            if v < lo_v[k]:
                lo_v[k], lo_i[k] = v, i
            if v > hi_v[k]:
                hi_v[k], hi_i[k] = v, i
    out = np.empty(len(hint) + 14, np.int64)
    m = 0
    for t in range(len(hint) + 14):
        if t < len(hint):
            i = hint[t]
        elif t < len(hint) + 7:
            i = lo_i[t - len(hint)]
        else:
            i = hi_i[t - len(hint) - 7]
        seen = False
        for u in range(m):
            if out[u] == i:
                seen = True
                break
        if not seen:
            out[m] = i
            m += 1
    return out[:m]


@njit(cache=True, fastmath=FASTMATH_OFF)
def _farthest2(P, c):
    """Largest squared distance ``(dx^2 + dy^2) + dz^2`` (float64) from ``c`` (3,) to a row of ``P``."""
    best = 0.0
    for i in range(P.shape[0]):
        dx = np.float64(P[i, 0]) - c[0]
        dy = np.float64(P[i, 1]) - c[1]
        dz = np.float64(P[i, 2]) - c[2]
        d = dx * dx + dy * dy + dz * dz
        if d > best:
            best = d
    return best


@njit(cache=True, fastmath=FASTMATH_OFF)
def _core_sphere(P, hint):
    """Minimal sphere of ``P`` (n, 3): minsphere's steps 1-4, starting from the ``hint`` indices
    (int64, distinct).  Returns ``(centre (3,) float64, radius, boundary indices)``."""
    return _core_loop(P, _first_core(P, hint))


@njit(cache=True, fastmath=FASTMATH_OFF)
def _core_loop(P, core0):
    """Steps 2-4 of minsphere's method from the first core set ``core0`` (int64, distinct
    indices into ``P`` (n, 3)).  Returns ``(centre (3,) float64, radius, boundary indices)``."""
    n = P.shape[0]
    cap = len(core0) + _CHUNKS * (_MAX_ITER + 1)
    core = np.empty(cap, np.int64)
    nc = len(core0)
    for t in range(nc):  # element loops, not slice assignments: those compile a shape-error path (~2 s)
        core[t] = core0[t]
    on = np.empty(cap, np.int64)
    o = (np.float64(P[core[0], 0]), np.float64(P[core[0], 1]), np.float64(P[core[0], 2]))
    nch = min(_CHUNKS, n)
    far = np.empty(nch, np.int64)
    S = np.empty((cap, 3))
    d2 = np.empty(n)
    seed = 12345
    ctr = o
    c = (0.0, 0.0, 0.0)
    r2, maxd2 = 0.0, 0.0
    lim_c = (1.0 + CONTAIN_REL)
    for _ in range(_MAX_ITER):
        for t in range(nc):
            i = core[t]
            S[t, 0] = np.float64(P[i, 0]) - o[0]
            S[t, 1] = np.float64(P[i, 1]) - o[1]
            S[t, 2] = np.float64(P[i, 2]) - o[2]
        for s in range(nc - 1, 0, -1):  # deterministic Fisher-Yates shuffle (LCG)
            seed = (seed * 1103515245 + 12345) % 2147483648
            t = seed % (s + 1)
            for a in range(3):
                S[s, a], S[t, a] = S[t, a], S[s, a]
        c, r2 = _welzl(S[:nc])
        ctr = (c[0] + o[0], c[1] + o[1], c[2] + o[2])
        for i in range(n):
            dx = np.float64(P[i, 0]) - ctr[0]
            dy = np.float64(P[i, 1]) - ctr[1]
            dz = np.float64(P[i, 2]) - ctr[2]
            d2[i] = dx * dx + dy * dy + dz * dz
        maxd2 = -1.0
        for ch in range(nch):
            lo, hi = ch * n // nch, (ch + 1) * n // nch
            best = lo
            for i in range(lo + 1, hi):
                if d2[i] > d2[best]:
                    best = i
            far[ch] = best
            if d2[best] > maxd2:
                maxd2 = d2[best]
        lim = r2 * lim_c * lim_c
        if maxd2 <= lim:
            break
        m = _boundary(P, core, nc, o, c, r2, on)
        added = 0
        for ch in range(nch):
            i = far[ch]
            if d2[i] > lim:
                known = False
                for t in range(m):
                    if on[t] == i:
                        known = True
                        break
                if not known:
                    on[m + added] = i
                    added += 1
        if added == 0:  # numerically stuck: the radius below still covers every point
            break
        nc = m + added
        for t in range(nc):
            core[t] = on[t]
    m = _boundary(P, core, nc, o, c, r2, on)
    return np.array([ctr[0], ctr[1], ctr[2]]), math.sqrt(max(r2, maxd2)), on[:m].copy()
