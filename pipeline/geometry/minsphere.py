"""Exact minimal enclosing sphere of a 3-D point set.

Method (an iterative core-set scheme, after Gärtner's "Fast and robust smallest enclosing balls"
and the usual Welzl nested loop):

1. the core set starts as the extreme points of the input along 7 directions (14 points;
   with the parallel passes, those of every chunk);
2. the exact minimal sphere of the core set is solved with Welzl's algorithm in its iterative
   nested-loop form on a deterministically shuffled copy (support sets of 1..4 points; collinear
   and coplanar support sets fall back to the smallest sphere enclosing them);
3. one pass over all points finds, per chunk, the farthest point; those outside
   ``radius * (1 + 1e-9)`` join the core set and we go back to 2;
4. when no point is outside, the returned radius is the exact (float64) largest distance from the
   centre to any input point, so containment holds even when the tolerance let a point slip.

Step 3 touches every point once per iteration (typically 2-5 iterations), so the cost is a few
linear passes: about a second for 10 million points on two cores.

The private ``_``-prefixed functions are numba kernels; :func:`min_sphere` and
:func:`min_spheres` validate their input and call them.  ``tests/naive.py`` holds a brute-force
reference (every support set of up to 4 points).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

#: Initial core-set directions (see :func:`_extremes_range`; both ends of each are used).
_NDIRS = 7
#: Points per block of the blocked linear passes.  The block scans use only the nnan/ninf/nsz
#: fast-math flags (inputs are checked finite): no contraction or reassociation, so a distance
#: computed in a block scan is bit-identical to the rescan's and no point can slip through.
_BLOCK = 512

#: Welzl's "point is outside" test: squared distance above ``r2 * (1 + _INSIDE_REL)``.
_INSIDE_REL = 1e-11
#: The core-set loop stops once every point lies within ``radius * (1 + CONTAIN_REL)``.
CONTAIN_REL = 1e-9
#: A triangle is collinear when ``|u x v|^2 <= _COLLINEAR * |u|^2 |v|^2`` (sin^2 of its angle).
_COLLINEAR = 1e-14
#: A tetrahedron is coplanar when ``|det(u, v, t)| <= _COPLANAR * |u| |v| |t|``.
_COPLANAR = 1e-10
#: Farthest-point chunks per pass (each may add one point to the core set).
_CHUNKS = 16
#: Inputs at least this large use the multi-threaded passes.
_PARALLEL_MIN = 100_000
#: Safety cap on core-set iterations (each adds at least one new point, so it is never reached
#: in practice; if it were, containment still holds, only minimality would suffer).
_MAX_ITER = 200


# -- support-set spheres (scalars only: these run in the innermost loops) --------------------

@njit(cache=True)
def _d2(S, i, cx, cy, cz):
    dx = S[i, 0] - cx
    dy = S[i, 1] - cy
    dz = S[i, 2] - cz
    return dx * dx + dy * dy + dz * dz


@njit(cache=True)
def _ball2(S, i, j):
    cx = 0.5 * (S[i, 0] + S[j, 0])
    cy = 0.5 * (S[i, 1] + S[j, 1])
    cz = 0.5 * (S[i, 2] + S[j, 2])
    return cx, cy, cz, max(_d2(S, i, cx, cy, cz), _d2(S, j, cx, cy, cz))


@njit(cache=True)
def _enclose3(S, i, j, k):
    """Smallest sphere of 3 (nearly) collinear points: the diameter ball of the farthest pair."""
    dij = _d2(S, i, S[j, 0], S[j, 1], S[j, 2])
    dik = _d2(S, i, S[k, 0], S[k, 1], S[k, 2])
    djk = _d2(S, j, S[k, 0], S[k, 1], S[k, 2])
    if dij >= dik and dij >= djk:
        cx, cy, cz, r2 = _ball2(S, i, j)
    elif dik >= djk:
        cx, cy, cz, r2 = _ball2(S, i, k)
    else:
        cx, cy, cz, r2 = _ball2(S, j, k)
    return cx, cy, cz, max(r2, _d2(S, i, cx, cy, cz), _d2(S, j, cx, cy, cz), _d2(S, k, cx, cy, cz))


@njit(cache=True)
def _ball3(S, i, j, k):
    """Sphere through 3 points centred in their plane (their circumcircle)."""
    ax, ay, az = S[i, 0], S[i, 1], S[i, 2]
    ux, uy, uz = S[j, 0] - ax, S[j, 1] - ay, S[j, 2] - az
    vx, vy, vz = S[k, 0] - ax, S[k, 1] - ay, S[k, 2] - az
    wx = uy * vz - uz * vy
    wy = uz * vx - ux * vz
    wz = ux * vy - uy * vx
    uu = ux * ux + uy * uy + uz * uz
    vv = vx * vx + vy * vy + vz * vz
    ww = wx * wx + wy * wy + wz * wz
    if ww <= _COLLINEAR * uu * vv or ww == 0.0:
        return _enclose3(S, i, j, k)
    # centre = a + ((|u|^2 v - |v|^2 u) x w) / (2 |w|^2)
    px, py, pz = uu * vx - vv * ux, uu * vy - vv * uy, uu * vz - vv * uz
    s = 0.5 / ww
    cx = ax + (py * wz - pz * wy) * s
    cy = ay + (pz * wx - px * wz) * s
    cz = az + (px * wy - py * wx) * s
    r2 = max(_d2(S, i, cx, cy, cz), _d2(S, j, cx, cy, cz), _d2(S, k, cx, cy, cz))
    return cx, cy, cz, r2


@njit(cache=True)
def _contains4(S, i, j, k, m, cx, cy, cz, r2):
    lim = r2 * (1.0 + 1e-9) + 1e-300
    return (_d2(S, i, cx, cy, cz) <= lim and _d2(S, j, cx, cy, cz) <= lim
            and _d2(S, k, cx, cy, cz) <= lim and _d2(S, m, cx, cy, cz) <= lim)


@njit(cache=True)
def _enclose4(S, i, j, k, m):
    """Smallest sphere of 4 (nearly) coplanar points: best pair or triple sphere holding all."""
    ids = (i, j, k, m)
    best = (0.0, 0.0, 0.0, np.inf)
    for a in range(4):
        for b in range(a + 1, 4):
            cx, cy, cz, r2 = _ball2(S, ids[a], ids[b])
            if r2 < best[3] and _contains4(S, i, j, k, m, cx, cy, cz, r2):
                best = (cx, cy, cz, r2)
            for c in range(b + 1, 4):
                cx, cy, cz, r2 = _ball3(S, ids[a], ids[b], ids[c])
                if r2 < best[3] and _contains4(S, i, j, k, m, cx, cy, cz, r2):
                    best = (cx, cy, cz, r2)
    if best[3] == np.inf:  # numerically nothing fits: centroid and farthest corner
        cx = 0.25 * (S[i, 0] + S[j, 0] + S[k, 0] + S[m, 0])
        cy = 0.25 * (S[i, 1] + S[j, 1] + S[k, 1] + S[m, 1])
        cz = 0.25 * (S[i, 2] + S[j, 2] + S[k, 2] + S[m, 2])
        r2 = max(_d2(S, i, cx, cy, cz), _d2(S, j, cx, cy, cz), _d2(S, k, cx, cy, cz), _d2(S, m, cx, cy, cz))
        best = (cx, cy, cz, r2)
    return best


@njit(cache=True)
def _ball4(S, i, j, k, m):
    """Circumsphere of 4 points."""
    ax, ay, az = S[i, 0], S[i, 1], S[i, 2]
    ux, uy, uz = S[j, 0] - ax, S[j, 1] - ay, S[j, 2] - az
    vx, vy, vz = S[k, 0] - ax, S[k, 1] - ay, S[k, 2] - az
    tx, ty, tz = S[m, 0] - ax, S[m, 1] - ay, S[m, 2] - az
    # v x t, t x u, u x v
    vtx, vty, vtz = vy * tz - vz * ty, vz * tx - vx * tz, vx * ty - vy * tx
    tux, tuy, tuz = ty * uz - tz * uy, tz * ux - tx * uz, tx * uy - ty * ux
    uvx, uvy, uvz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    det = ux * vtx + uy * vty + uz * vtz
    uu = ux * ux + uy * uy + uz * uz
    vv = vx * vx + vy * vy + vz * vz
    tt = tx * tx + ty * ty + tz * tz
    if abs(det) <= _COPLANAR * np.sqrt(uu * vv * tt) or det == 0.0:
        return _enclose4(S, i, j, k, m)
    s = 0.5 / det
    cx = ax + (uu * vtx + vv * tux + tt * uvx) * s
    cy = ay + (uu * vty + vv * tuy + tt * uvy) * s
    cz = az + (uu * vtz + vv * tuz + tt * uvz) * s
    r2 = max(_d2(S, i, cx, cy, cz), _d2(S, j, cx, cy, cz), _d2(S, k, cx, cy, cz), _d2(S, m, cx, cy, cz))
    return cx, cy, cz, r2


@njit(cache=True)
def _outside(S, i, cx, cy, cz, r2):
    return _d2(S, i, cx, cy, cz) > r2 * (1.0 + _INSIDE_REL)


@njit(cache=True)
def _welzl(S):
    """Minimal sphere of the rows of ``S`` (c, 3) float64: Welzl's nested-loop form.

    Expected linear time for a random order (the caller shuffles).  Returns ``cx, cy, cz, r2``.
    """
    n = S.shape[0]
    cx, cy, cz, r2 = S[0, 0], S[0, 1], S[0, 2], 0.0
    for i in range(1, n):
        if not _outside(S, i, cx, cy, cz, r2):
            continue
        cx, cy, cz, r2 = S[i, 0], S[i, 1], S[i, 2], 0.0
        for j in range(i):
            if not _outside(S, j, cx, cy, cz, r2):
                continue
            cx, cy, cz, r2 = _ball2(S, i, j)
            for k in range(j):
                if not _outside(S, k, cx, cy, cz, r2):
                    continue
                cx, cy, cz, r2 = _ball3(S, i, j, k)
                for m in range(k):
                    if _outside(S, m, cx, cy, cz, r2):
                        cx, cy, cz, r2 = _ball4(S, i, j, k, m)
    return cx, cy, cz, r2


# -- linear passes over all points ---------------------------------------------------------

@njit(cache=True, fastmath={"nnan", "ninf", "nsz"})
def _block_range(P, start, stop):
    """Smallest and largest of x, y, z, x+y+z, x+y-z, x-y+z, -x+y+z over ``P[start:stop]``
    (no indices, so the loop vectorises)."""
    lo0 = lo1 = lo2 = lo3 = lo4 = lo5 = lo6 = np.inf
    hi0 = hi1 = hi2 = hi3 = hi4 = hi5 = hi6 = -np.inf
    for i in range(start, stop):
        x = np.float64(P[i, 0])
        y = np.float64(P[i, 1])
        z = np.float64(P[i, 2])
        lo0, hi0 = min(lo0, x), max(hi0, x)
        lo1, hi1 = min(lo1, y), max(hi1, y)
        lo2, hi2 = min(lo2, z), max(hi2, z)
        lo3, hi3 = min(lo3, x + y + z), max(hi3, x + y + z)
        lo4, hi4 = min(lo4, x + y - z), max(hi4, x + y - z)
        lo5, hi5 = min(lo5, x - y + z), max(hi5, x - y + z)
        lo6, hi6 = min(lo6, y + z - x), max(hi6, y + z - x)
    return (lo0, lo1, lo2, lo3, lo4, lo5, lo6), (hi0, hi1, hi2, hi3, hi4, hi5, hi6)


@njit(cache=True)
def _extremes_range(P, start, stop, imin, imax):
    """Indices of the smallest and largest projections of ``P[start:stop]`` on the 7 directions
    x, y, z, x+y+z, x+y-z, x-y+z, -x+y+z.  Blocks whose extremes cannot improve the current
    ones are skipped after one vectorised scan."""
    lo0 = lo1 = lo2 = lo3 = lo4 = lo5 = lo6 = np.inf
    hi0 = hi1 = hi2 = hi3 = hi4 = hi5 = hi6 = -np.inf
    a0 = a1 = a2 = a3 = a4 = a5 = a6 = start
    b0 = b1 = b2 = b3 = b4 = b5 = b6 = start
    for bs in range(start, stop, _BLOCK):
        be = min(bs + _BLOCK, stop)
        blo, bhi = _block_range(P, bs, be)
        if not (blo[0] < lo0 or blo[1] < lo1 or blo[2] < lo2 or blo[3] < lo3 or blo[4] < lo4
                or blo[5] < lo5 or blo[6] < lo6 or bhi[0] > hi0 or bhi[1] > hi1 or bhi[2] > hi2
                or bhi[3] > hi3 or bhi[4] > hi4 or bhi[5] > hi5 or bhi[6] > hi6):
            continue
        for i in range(bs, be):
            x = np.float64(P[i, 0])
            y = np.float64(P[i, 1])
            z = np.float64(P[i, 2])
            s3 = x + y + z
            s4 = x + y - z
            s5 = x - y + z
            s6 = y + z - x
            if x < lo0:
                lo0, a0 = x, i
            if x > hi0:
                hi0, b0 = x, i
            if y < lo1:
                lo1, a1 = y, i
            if y > hi1:
                hi1, b1 = y, i
            if z < lo2:
                lo2, a2 = z, i
            if z > hi2:
                hi2, b2 = z, i
            if s3 < lo3:
                lo3, a3 = s3, i
            if s3 > hi3:
                hi3, b3 = s3, i
            if s4 < lo4:
                lo4, a4 = s4, i
            if s4 > hi4:
                hi4, b4 = s4, i
            if s5 < lo5:
                lo5, a5 = s5, i
            if s5 > hi5:
                hi5, b5 = s5, i
            if s6 < lo6:
                lo6, a6 = s6, i
            if s6 > hi6:
                hi6, b6 = s6, i
    imin[0], imin[1], imin[2], imin[3], imin[4], imin[5], imin[6] = a0, a1, a2, a3, a4, a5, a6
    imax[0], imax[1], imax[2], imax[3], imax[4], imax[5], imax[6] = b0, b1, b2, b3, b4, b5, b6


@njit(cache=True, fastmath={"nnan", "ninf", "nsz"})
def _block_farthest(P, start, stop, cx, cy, cz):
    m = 0.0
    for i in range(start, stop):
        dx = np.float64(P[i, 0]) - cx
        dy = np.float64(P[i, 1]) - cy
        dz = np.float64(P[i, 2]) - cz
        m = max(m, dx * dx + dy * dy + dz * dz)
    return m


@njit(cache=True)
def _farthest_range(P, start, stop, cx, cy, cz):
    """Index and squared distance of the point of ``P[start:stop]`` farthest from the centre
    (a vectorised block maximum first; only blocks that beat the best so far are rescanned)."""
    best = -1.0
    bi = start
    for bs in range(start, stop, _BLOCK):
        be = min(bs + _BLOCK, stop)
        if _block_farthest(P, bs, be, cx, cy, cz) <= best:
            continue
        for i in range(bs, be):
            dx = np.float64(P[i, 0]) - cx
            dy = np.float64(P[i, 1]) - cy
            dz = np.float64(P[i, 2]) - cz
            d = dx * dx + dy * dy + dz * dz
            if d > best:
                best = d
                bi = i
    return bi, best


@njit(parallel=True, cache=True)
def _extremes_par(P, nch):
    n = P.shape[0]
    idx = np.empty((nch, 2 * _NDIRS), np.int64)
    for c in prange(nch):
        _extremes_range(P, c * n // nch, (c + 1) * n // nch, idx[c, :_NDIRS], idx[c, _NDIRS:])
    return idx.ravel()


@njit(parallel=True, cache=True)
def _farthest_par(P, cx, cy, cz, nch):
    n = P.shape[0]
    idx = np.empty(nch, np.int64)
    d2 = np.empty(nch)
    for c in prange(nch):
        idx[c], d2[c] = _farthest_range(P, c * n // nch, (c + 1) * n // nch, cx, cy, cz)
    return idx, d2


@njit(cache=True)
def _extremes_ser(P):
    idx = np.empty(2 * _NDIRS, np.int64)
    _extremes_range(P, 0, P.shape[0], idx[:_NDIRS], idx[_NDIRS:])
    return idx


@njit(cache=True)
def _farthest_ser(P, cx, cy, cz, nch):
    n = P.shape[0]
    idx = np.empty(nch, np.int64)
    d2 = np.empty(nch)
    for c in range(nch):
        idx[c], d2[c] = _farthest_range(P, c * n // nch, (c + 1) * n // nch, cx, cy, cz)
    return idx, d2


# -- the core-set driver ---------------------------------------------------------------------

@njit(cache=True)
def _min_sphere_core(P, parallel):
    """Minimal sphere of ``P`` (n >= 1, 3) float32/float64 -> ``cx, cy, cz, r`` (float64).

    ``parallel`` selects the multi-threaded linear passes (never inside another prange).
    """
    n = P.shape[0]
    nch = min(_CHUNKS, n)
    if parallel:
        ext = _extremes_par(P, nch)
    else:
        ext = _extremes_ser(P)
    cap = ext.shape[0] + _CHUNKS * 8
    core = np.empty(cap, np.int64)
    nc = 0
    for t in range(ext.shape[0]):
        dup = False
        for s in range(nc):
            if core[s] == ext[t]:
                dup = True
                break
        if not dup:
            core[nc] = ext[t]
            nc += 1
    ox = np.float64(P[core[0], 0])
    oy = np.float64(P[core[0], 1])
    oz = np.float64(P[core[0], 2])
    seed = 12345
    cx, cy, cz, r2 = ox, oy, oz, 0.0
    maxd2 = 0.0
    for _ in range(_MAX_ITER):
        # exact sphere of the core set, relative to the first core point for precision
        S = np.empty((nc, 3))
        for s in range(nc):
            S[s, 0] = np.float64(P[core[s], 0]) - ox
            S[s, 1] = np.float64(P[core[s], 1]) - oy
            S[s, 2] = np.float64(P[core[s], 2]) - oz
        for s in range(nc - 1, 0, -1):  # deterministic Fisher-Yates shuffle (LCG)
            seed = (seed * 1103515245 + 12345) % 2147483648
            t = seed % (s + 1)
            for a in range(3):
                S[s, a], S[t, a] = S[t, a], S[s, a]
        sx, sy, sz, r2 = _welzl(S)
        cx, cy, cz = sx + ox, sy + oy, sz + oz
        if parallel:
            fidx, fd2 = _farthest_par(P, cx, cy, cz, nch)
        else:
            fidx, fd2 = _farthest_ser(P, cx, cy, cz, nch)
        maxd2 = fd2.max()
        lim = r2 * (1.0 + CONTAIN_REL) * (1.0 + CONTAIN_REL)
        if maxd2 <= lim:
            break
        added = 0
        for c in range(nch):
            if fd2[c] <= lim:
                continue
            dup = False
            for s in range(nc):
                if core[s] == fidx[c]:
                    dup = True
                    break
            if dup:
                continue
            if nc == core.shape[0]:
                bigger = np.empty(2 * nc, np.int64)
                bigger[:nc] = core
                core = bigger
            core[nc] = fidx[c]
            nc += 1
            added += 1
        if added == 0:  # numerically stuck: the radius below still covers every point
            break
    return cx, cy, cz, np.sqrt(max(r2, maxd2))


@njit(parallel=True, cache=True)
def _min_spheres_batch(P):
    """Minimal sphere of each ``P[f]`` for ``P`` (F, n >= 1, 3): one frame per thread."""
    F = P.shape[0]
    centers = np.empty((F, 3))
    radii = np.empty(F)
    for f in prange(F):
        cx, cy, cz, r = _min_sphere_core(P[f], False)
        centers[f, 0] = cx
        centers[f, 1] = cy
        centers[f, 2] = cz
        radii[f] = r
    return centers, radii


# -- public wrappers -------------------------------------------------------------------------

def _as_points(points, ndim: int, what: str) -> np.ndarray:
    p = np.asarray(points)
    if p.dtype != np.float32:
        p = p.astype(np.float64, copy=False)
    p = np.ascontiguousarray(p)
    want = "(n, 3)" if ndim == 2 else "(F, n, 3)"
    if p.ndim != ndim or p.shape[-1] != 3:
        raise ValueError(f"{what}: expected shape {want}, got {p.shape}")
    if p.shape[-2] == 0:
        raise ValueError(f"{what}: expected at least one point, got {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError(f"{what}: expected finite coordinates, got NaN or inf")
    return p


def min_sphere(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Minimal enclosing sphere of a point set.

    Parameters
    ----------
    points : (n, 3) float32 or float64, n >= 1, finite.

    Returns
    -------
    center : (3,) float64
    radius : float
        The largest float64 distance from ``center`` to a point, so every point is contained;
        it exceeds the exact minimal radius by at most about ``1e-9`` relative.
    """
    p = _as_points(points, 2, "min_sphere points")
    cx, cy, cz, r = _min_sphere_core(p, len(p) >= _PARALLEL_MIN)
    return np.array([cx, cy, cz]), float(r)


def min_spheres(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Minimal enclosing sphere of each of ``F`` point sets of the same size (e.g. frames).

    Parameters
    ----------
    points : (F, n, 3) float32 or float64, n >= 1, finite.

    Returns
    -------
    centers : (F, 3) float64
    radii : (F,) float64
    """
    p = _as_points(points, 3, "min_spheres points")
    if len(p) == 0:
        return np.zeros((0, 3)), np.zeros(0)
    return _min_spheres_batch(p)
