"""The kernels of the two-sided surface distance and their checking wrappers (numba behind
validating public functions: :func:`sample_distances`, :func:`nearest_on_candidates`,
:func:`piece_bounds`, :func:`triangle_bounds`, :func:`cover_radius`, :func:`vertex_triangles`).
The two bounds and why they hold, and the refinement driver that calls these, are in
:mod:`pipeline.geometry.surface_distance` (where the rest of the project imports them from).

Kernels (private, ``_``-prefixed; readable references in ``tests/references/naive.py``)
--------------------------------------------------------------------------
``_sample_distances``: for (pose, sample) pairs, the distance to the nearest of a candidate row;
``_piece_bounds``: for (pose, piece) pairs, the smaller of the two bounds (Lipschitz, convexity);
``_all_triangle_bounds``: the same for every source triangle on every pose of a chunk (each
vertex's distance to its home triangle computed once per pose).  Ericson's
closest point on a triangle is the runtime's (:func:`runtime.kernels.triangle.closest_on_triangle`),
the one copy of it.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from colossus.runtime.kernels.config import FASTMATH_OFF
from colossus.runtime.kernels.triangle import closest_on_triangle

#: Pairs per task of the parallel kernels (the scratch buffer is allocated once per task).
BLOCK = 512


# ------------------------------------------------------------------------------ kernels
@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
def _cover(ax, ay, az, bx, by, bz, cx, cy, cz):
    """Covering radius of triangle abc by its corners (see :func:`cover_radius`)."""
    la = (bx - cx) ** 2 + (by - cy) ** 2 + (bz - cz) ** 2  # squared side opposite a
    lb = (cx - ax) ** 2 + (cy - ay) ** 2 + (cz - az) ** 2
    lc = (ax - bx) ** 2 + (ay - by) ** 2 + (az - bz) ** 2
    if lc >= la and lc >= lb:
        big, p, q = lc, la, lb
    elif lb >= la:
        big, p, q = lb, lc, la
    else:
        big, p, q = la, lb, lc
    if big <= 0.0:
        return 0.0
    L = np.sqrt(big)
    if big >= p + q:  # right or obtuse: the bisectors of the short sides cross the long one
        r1 = p * L / (p + big - q) if p > 0.0 else 0.0
        r2 = q * L / (q + big - p) if q > 0.0 else 0.0
        return max(r1, r2, 0.5 * L) if (p == 0.0 or q == 0.0) else max(r1, r2)
    ux, uy, uz = bx - ax, by - ay, bz - az
    vx, vy, vz = cx - ax, cy - ay, cz - az
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    twice_area = np.sqrt(nx * nx + ny * ny + nz * nz)
    return np.sqrt(la * lb * lc) / (2.0 * twice_area)




@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
def _sample_xyz(v, f, s_idx, s_bary, s):
    """Sample ``s`` (a barycentric combination of three source vertices) at pose ``f``."""
    i0, i1, i2 = s_idx[s, 0], s_idx[s, 1], s_idx[s, 2]
    b0, b1, b2 = s_bary[s, 0], s_bary[s, 1], s_bary[s, 2]
    x = b0 * np.float64(v[f, i0, 0]) + b1 * np.float64(v[f, i1, 0]) + b2 * np.float64(v[f, i2, 0])
    y = b0 * np.float64(v[f, i0, 1]) + b1 * np.float64(v[f, i1, 1]) + b2 * np.float64(v[f, i2, 1])
    z = b0 * np.float64(v[f, i0, 2]) + b1 * np.float64(v[f, i1, 2]) + b2 * np.float64(v[f, i2, 2])
    return x, y, z


@njit(cache=True, fastmath=FASTMATH_OFF)
def _dist2(px, py, pz, tv, tri, j, tmp):
    """Squared distance from p to target triangle ``j`` of the pose ``tv`` (n, 3).  Not inlined:
    the runtime's closest-point routine is inlined once here, not at every call site (compile
    time)."""
    closest_on_triangle(px, py, pz, tv, tri[j, 0], tri[j, 1], tri[j, 2], tmp)
    return (tmp[0] - px) ** 2 + (tmp[1] - py) ** 2 + (tmp[2] - pz) ** 2


@njit(cache=True, parallel=True, fastmath=FASTMATH_OFF)
def _sample_distances(sv, tv, pf, ps, s_idx, s_bary, tri, cand, crow, vt_off, vt_tri, walk, out_d, out_t, out_b):
    """For each pair ``p``: the distance from sample ``ps[p]`` at pose ``pf[p]`` of ``sv``
    (F, n, 3) to the nearest target triangle of ``cand[crow[p]]`` (-1 ends a row) at the same
    pose of ``tv``, that triangle and the barycentrics of the nearest point; ``inf`` / -1 for an
    empty row.  With ``walk > 0``, the search then moves up to ``walk`` times to a nearer
    triangle sharing a corner with the current one (CSR ``vt_off`` / ``vt_tri``: the triangles
    of each target vertex), which finds the nearest triangle when the pose moved it off the
    candidates (stopping where a nearest point is inside its triangle would miss folds)."""
    P = pf.shape[0]
    for blk in prange((P + BLOCK - 1) // BLOCK):
        tmp = np.empty(6)
        for p in range(blk * BLOCK, min(P, (blk + 1) * BLOCK)):
            f = pf[p]
            x, y, z = _sample_xyz(sv, f, s_idx, s_bary, ps[p])
            t = tv[f]
            best = np.inf
            bt = -1
            bu, bv, bw = 1.0, 0.0, 0.0
            r = crow[p]
            for c in range(cand.shape[1]):
                j = cand[r, c]
                if j < 0:
                    break
                d2 = _dist2(x, y, z, t, tri, j, tmp)
                if d2 < best:
                    best = d2
                    bt = j
                    bu, bv, bw = tmp[3], tmp[4], tmp[5]
            for _ in range(walk):
                if bt < 0:
                    break
                cur = bt
                for k in range(3):
                    v = tri[cur, k]
                    for e in range(vt_off[v], vt_off[v + 1]):
                        j = vt_tri[e]
                        if j == cur:
                            continue
                        d2 = _dist2(x, y, z, t, tri, j, tmp)
                        if d2 < best:
                            best = d2
                            bt = j
                            bu, bv, bw = tmp[3], tmp[4], tmp[5]
                if bt == cur:
                    break
            out_d[p] = np.sqrt(best)
            out_t[p] = bt
            out_b[p, 0], out_b[p, 1], out_b[p, 2] = bu, bv, bw


@njit(cache=True, parallel=True, fastmath=FASTMATH_OFF)
def _piece_bounds(sv, tv, pf, pt, ub, given, corners, s_idx, s_bary, near, home, tri, thr, out, out_cover):
    """For each pair ``p`` (pose ``pf[p]``, piece ``pt[p]`` with sample corners
    ``corners[pt[p]]``): ``min(max(u) + cover, max over corners of d(corner, home))`` where the
    corner bounds ``u`` are ``ub[p]`` when ``given``, else each corner's distance to its own
    ``near`` triangle; the second term is computed only when the first is above ``thr`` (either
    is an upper bound).  ``out_cover``: the piece's cover radius at that pose."""
    P = pf.shape[0]
    for blk in prange((P + BLOCK - 1) // BLOCK):
        tmp = np.empty(6)
        for p in range(blk * BLOCK, min(P, (blk + 1) * BLOCK)):
            f = pf[p]
            q = pt[p]
            c0, c1, c2 = corners[q, 0], corners[q, 1], corners[q, 2]
            ax, ay, az = _sample_xyz(sv, f, s_idx, s_bary, c0)
            bx, by, bz = _sample_xyz(sv, f, s_idx, s_bary, c1)
            cx, cy, cz = _sample_xyz(sv, f, s_idx, s_bary, c2)
            t = tv[f]
            if given:
                u = max(ub[p, 0], ub[p, 1], ub[p, 2])
            else:
                u = np.sqrt(max(_dist2(ax, ay, az, t, tri, near[c0], tmp), _dist2(bx, by, bz, t, tri, near[c1], tmp),
                                _dist2(cx, cy, cz, t, tri, near[c2], tmp)))
            r = _cover(ax, ay, az, bx, by, bz, cx, cy, cz)
            out_cover[p] = r
            b = u + r
            h = home[q]
            if b > thr and h >= 0:
                d = max(_dist2(ax, ay, az, t, tri, h, tmp), _dist2(bx, by, bz, t, tri, h, tmp),
                        _dist2(cx, cy, cz, t, tri, h, tmp))
                b = min(b, np.sqrt(d))
            out[p] = b


@njit(cache=True, parallel=True, fastmath=FASTMATH_OFF)
def _all_triangle_bounds(sv, tv, stri, near, home, ttri, thr, ub, out, out_cover):
    """Every source triangle ``stri`` on every pose of ``sv`` (F, n, 3): first ``ub`` (F, n), each
    vertex's distance to its ``near`` target triangle, then ``out`` (F, m), the smaller of the
    Lipschitz bound (largest corner ``ub`` + cover) and, where that is above ``thr``, the
    convexity bound on the triangle's ``home``; ``out_cover`` (F, m) the cover radii."""
    F, n = ub.shape
    m = stri.shape[0]
    nb = (n + BLOCK - 1) // BLOCK
    for task in prange(F * nb):
        f = task // nb
        lo = (task - f * nb) * BLOCK
        tmp = np.empty(6)
        t = tv[f]
        for v in range(lo, min(n, lo + BLOCK)):
            j = near[v]
            if j < 0:
                ub[f, v] = 0.0
            else:
                ub[f, v] = np.sqrt(_dist2(np.float64(sv[f, v, 0]), np.float64(sv[f, v, 1]), np.float64(sv[f, v, 2]),
                                          t, ttri, j, tmp))
    mb = (m + BLOCK - 1) // BLOCK
    for task in prange(F * mb):
        f = task // mb
        lo = (task - f * mb) * BLOCK
        tmp = np.empty(6)
        t = tv[f]
        for q in range(lo, min(m, lo + BLOCK)):
            a, b, c = stri[q, 0], stri[q, 1], stri[q, 2]
            ax, ay, az = np.float64(sv[f, a, 0]), np.float64(sv[f, a, 1]), np.float64(sv[f, a, 2])
            bx, by, bz = np.float64(sv[f, b, 0]), np.float64(sv[f, b, 1]), np.float64(sv[f, b, 2])
            cx, cy, cz = np.float64(sv[f, c, 0]), np.float64(sv[f, c, 1]), np.float64(sv[f, c, 2])
            r = _cover(ax, ay, az, bx, by, bz, cx, cy, cz)
            bnd = max(ub[f, a], ub[f, b], ub[f, c]) + r
            h = home[q]
            if bnd > thr and h >= 0:
                d = max(_dist2(ax, ay, az, t, ttri, h, tmp), _dist2(bx, by, bz, t, ttri, h, tmp),
                        _dist2(cx, cy, cz, t, ttri, h, tmp))
                bnd = min(bnd, np.sqrt(d))
            out[f, q] = bnd
            out_cover[f, q] = r


@njit(cache=True, fastmath=FASTMATH_OFF)
def _cover_many(v_all, tri, out):
    m = tri.shape[0]
    for ft in range(v_all.shape[0] * m):
        f = ft // m
        t = ft - f * m
        v = v_all[f]
        a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
        out[f, t] = _cover(np.float64(v[a, 0]), np.float64(v[a, 1]), np.float64(v[a, 2]),
                           np.float64(v[b, 0]), np.float64(v[b, 1]), np.float64(v[b, 2]),
                           np.float64(v[c, 0]), np.float64(v[c, 1]), np.float64(v[c, 2]))


# ------------------------------------------------------------------------------ wrappers
def _pose_array(v, name: str) -> np.ndarray:
    v = np.ascontiguousarray(v, dtype=np.float32)
    if v.ndim == 2:
        v = v[None]
    if v.ndim != 3 or v.shape[2] != 3:
        raise ValueError(f"{name}: expected shape (n, 3) or (F, n, 3), got {v.shape}")
    return v


def _index_array(a, name: str, width: int, upper: int) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.int64)
    if a.ndim != 2 or a.shape[1] != width:
        raise ValueError(f"{name}: expected shape (n, {width}), got {a.shape}")
    if a.size and (a.min() < -1 or a.max() >= upper):
        raise ValueError(f"{name}: expected indices below {upper}, got {a.min()}..{a.max()}")
    return a


def cover_radius(v: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Covering radius of each triangle by its three corners: the largest distance from a point
    of the triangle to its nearest corner.

    Parameters
    ----------
    v : (n, 3) or (F, n, 3) float32 (F poses of the same triangles)
    tri : (m, 3) int

    Returns
    -------
    (m,) or (F, m) float64
        The circumradius for a non-obtuse triangle; for an obtuse one (long side ``L``, short
        sides ``p``, ``q``) ``max(p**2 L / (p**2 + L**2 - q**2), q**2 L / (q**2 + L**2 - p**2))``.
    """
    single = np.ndim(v) == 2
    v = _pose_array(v, "vertices")
    tri = _index_array(tri, "triangles", 3, v.shape[1])
    if tri.size and tri.min() < 0:
        raise ValueError("triangles: expected indices >= 0")
    out = np.empty((len(v), len(tri)))
    _cover_many(v, tri, out)
    return out[0] if single else out


def vertex_triangles(triangles, n: int):
    """CSR of the triangles around each vertex: ``(offsets (n + 1,) int64, triangles (3m,) int64)``."""
    t = np.asarray(triangles, dtype=np.int64)
    order = np.argsort(t.ravel(), kind="stable")
    off = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(t.ravel(), minlength=n), out=off[1:])
    return off, (order // 3).astype(np.int64)


def sample_distances(src_v, sample_idx, sample_bary, target_v, target_tri, candidates, pose=None, sample=None,
                     row=None, walk: int = 0, fans=None):
    """Exact distance from samples to the nearest of their candidate target triangles.

    Parameters
    ----------
    src_v : (n, 3) or (F, n, 3) float32
        Vertices the samples are made of (F poses).
    sample_idx : (N, 3) int, sample_bary : (N, 3) float
        Each sample is ``sum_k bary[k] * src_v[idx[k]]`` (a vertex sample repeats one index).
    target_v : (n_t, 3) or (F, n_t, 3) float32, target_tri : (m_t, 3) int
    candidates : (R, k) int
        Rows of target triangles to try; -1 ends a row early.
    pose, sample, row : (P,) int, optional
        The pairs to evaluate: pose index, sample index and candidate row of each (default:
        every sample on pose 0, row = sample).
    walk : int
        After the candidates, move up to this many times to a nearer triangle sharing a vertex
        around the corners the nearest point so far touches (``fans``: :func:`vertex_triangles`
        of the target, computed when not given).

    Returns
    -------
    distance : (P,) float64
        An upper bound of the distance to the whole target (exact when the nearest triangle is
        in the row); ``inf`` for an empty row.
    triangle : (P,) int64, the nearest candidate (-1 for an empty row).
    barycentric : (P, 3) float64, the nearest point on it.
    """
    sv, tv = _pose_array(src_v, "source vertices"), _pose_array(target_v, "target vertices")
    if sv.shape[0] != tv.shape[0]:
        raise ValueError(f"poses: expected as many target poses as source poses ({sv.shape[0]}), got {tv.shape[0]}")
    s_idx = _index_array(sample_idx, "sample_idx", 3, sv.shape[1])
    s_bary = np.ascontiguousarray(sample_bary, dtype=np.float64)
    if s_bary.shape != s_idx.shape or (s_idx.size and s_idx.min() < 0):
        raise ValueError(f"samples: expected (N, 3) indices >= 0 and barycentrics, got {s_idx.shape} and "
                         f"{s_bary.shape}")
    tri = _index_array(target_tri, "target_tri", 3, tv.shape[1])
    cand = np.ascontiguousarray(candidates, dtype=np.int64)
    if cand.ndim != 2 or (cand.size and cand.max() >= len(tri)):
        raise ValueError(f"candidates: expected (R, k) indices below {len(tri)}, got shape {cand.shape}")
    N = len(s_idx)
    ps = np.arange(N) if sample is None else np.ascontiguousarray(sample, dtype=np.int64)
    pf = np.zeros(len(ps), np.int64) if pose is None else np.ascontiguousarray(pose, dtype=np.int64)
    cr = ps if row is None else np.ascontiguousarray(row, dtype=np.int64)
    if not (len(pf) == len(ps) == len(cr)):
        raise ValueError(f"pairs: expected equal lengths, got {len(pf)}, {len(ps)}, {len(cr)}")
    if len(ps) and (ps.min() < 0 or ps.max() >= N or pf.min() < 0 or pf.max() >= len(sv)
                    or cr.min() < 0 or cr.max() >= len(cand)):
        raise ValueError("pairs: pose, sample or row out of range")
    if walk and fans is None:
        fans = vertex_triangles(tri, tv.shape[1])
    off, vt = fans if walk else (np.zeros(1, np.int64), np.zeros(0, np.int64))
    d = np.empty(len(ps))
    t = np.empty(len(ps), np.int64)
    b = np.empty((len(ps), 3))
    _sample_distances(sv, tv, pf, ps, s_idx, s_bary, tri, cand, cr, np.ascontiguousarray(off, dtype=np.int64),
                      np.ascontiguousarray(vt, dtype=np.int64), int(walk), d, t, b)
    return d, t, b


def nearest_on_candidates(src_v, sample_idx, sample_bary, target_v, target_tri, candidates):
    """:func:`sample_distances` of every sample on one pose (row = sample)."""
    return sample_distances(src_v, sample_idx, sample_bary, target_v, target_tri, candidates)


def piece_bounds(src_v, sample_idx, sample_bary, target_v, target_tri, corners, near, home, pose, piece,
                 corner_bounds=None, threshold: float = -np.inf, cover=False):
    """Upper bound of the distance to the target over source pieces (triangles of samples).

    Parameters
    ----------
    src_v, sample_idx, sample_bary, target_v, target_tri : as :func:`sample_distances`
    corners : (Q, 3) int, the three samples of each piece
    near : (N,) int, a target triangle per sample (its distance bounds the sample's)
    home : (Q,) int, a target triangle per piece (-1: none)
    pose, piece : (P,) int, the pairs
    corner_bounds : (P, 3) float64, optional
        Upper bounds of the distance at the corners of each pair's piece (default: each corner's
        distance to its ``near`` triangle).
    threshold : float
        The convexity bound is computed only where the Lipschitz bound is above this.

    cover : bool
        Also return each pair's cover radius.

    Returns
    -------
    (P,) float64: ``min(max(corner bounds) + cover, max over corners of d(corner, home))``
    (and ``(P,)`` float64 cover radii with ``cover``).
    """
    sv, tv = _pose_array(src_v, "source vertices"), _pose_array(target_v, "target vertices")
    s_idx = _index_array(sample_idx, "sample_idx", 3, sv.shape[1])
    s_bary = np.ascontiguousarray(sample_bary, dtype=np.float64)
    tri = _index_array(target_tri, "target_tri", 3, tv.shape[1])
    c = _index_array(corners, "corners", 3, len(s_idx))
    nr = np.ascontiguousarray(near, dtype=np.int64)
    h = np.ascontiguousarray(home, dtype=np.int64)
    pf = np.ascontiguousarray(pose, dtype=np.int64)
    pt = np.ascontiguousarray(piece, dtype=np.int64)
    given = corner_bounds is not None
    ub = np.ascontiguousarray(corner_bounds, dtype=np.float64) if given else np.zeros((0, 3))
    if nr.shape != (len(s_idx),) or (nr.size and (nr.min() < 0 or nr.max() >= len(tri))):
        raise ValueError(f"near: expected ({len(s_idx)},) target triangles, got {nr.shape}")
    if h.shape != (len(c),) or (h.size and h.max() >= len(tri)):
        raise ValueError(f"home: expected ({len(c)},) target triangles, got {h.shape}")
    if pf.shape != pt.shape or (given and ub.shape != (len(pt), 3)):
        raise ValueError(f"pairs: expected pose, piece (P,) and corner_bounds (P, 3), got {pf.shape}, {pt.shape}, "
                         f"{ub.shape}")
    if len(pt) and (pt.min() < 0 or pt.max() >= len(c) or pf.min() < 0 or pf.max() >= len(sv)):
        raise ValueError("pairs: pose or piece out of range")
    out = np.empty(len(pt))
    rad = np.empty(len(pt))
    _piece_bounds(sv, tv, pf, pt, ub, given, c, s_idx, s_bary, nr, h, tri, float(threshold), out, rad)
    return (out, rad) if cover else out


def triangle_bounds(src_v, src_tri, target_v, target_tri, near, home, threshold: float = -np.inf):
    """:func:`piece_bounds` of every source triangle on every pose, the corner bounds being each
    vertex's distance to its ``near`` target triangle.

    Parameters
    ----------
    src_v : (F, n, 3) float32, src_tri : (m, 3) int
    target_v : (F, n_t, 3) float32, target_tri : (m_t, 3) int
    near : (n,) int, a target triangle per source vertex (-1: none, bound 0: a vertex of no triangle)
    home : (m,) int, a target triangle per source triangle (-1: none)
    threshold : float, the convexity bound is computed only where the Lipschitz bound is above it

    Returns
    -------
    bound : (F, m) float64, cover : (F, m) float64, vertex_bound : (F, n) float64
    """
    sv, tv = _pose_array(src_v, "source vertices"), _pose_array(target_v, "target vertices")
    if sv.shape[0] != tv.shape[0]:
        raise ValueError(f"poses: expected as many target poses as source poses ({sv.shape[0]}), got {tv.shape[0]}")
    stri = _index_array(src_tri, "src_tri", 3, sv.shape[1])
    ttri = _index_array(target_tri, "target_tri", 3, tv.shape[1])
    nr = np.ascontiguousarray(near, dtype=np.int64)
    h = np.ascontiguousarray(home, dtype=np.int64)
    if nr.shape != (sv.shape[1],) or (nr.size and nr.max() >= len(ttri)):
        raise ValueError(f"near: expected ({sv.shape[1]},) target triangles, got {nr.shape}")
    if h.shape != (len(stri),) or (h.size and h.max() >= len(ttri)):
        raise ValueError(f"home: expected ({len(stri)},) target triangles, got {h.shape}")
    if (stri.size and stri.min() < 0) or (ttri.size and ttri.min() < 0):
        raise ValueError("triangles: expected indices >= 0")
    F = sv.shape[0]
    ub = np.empty((F, sv.shape[1]))
    out = np.empty((F, len(stri)))
    rad = np.empty((F, len(stri)))
    _all_triangle_bounds(sv, tv, stri, nr, h, ttri, float(threshold), ub, out, rad)
    return out, rad, ub
