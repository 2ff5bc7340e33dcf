"""Two-sided distance between two animated triangle surfaces, as a sound upper bound on every pose
(used by ``simplify`` to bound how far a collision proxy strays from the full skinned mesh).

The two bounds (after Metro's sampling and libigl's ``hausdorff`` lower/upper bounds)
------------------------------------------------------------------------------------
For a source surface ``S`` and a target surface ``T`` at one pose, the one-sided distance is
``h(S, T) = max over x in S of d(x, T)``.  Every bound below uses only distances to *some*
triangles of ``T`` (``d(x, T) <= d(x, T_j)`` for any target triangle ``T_j``), so a candidate
list that misses the nearest triangle can over-state the distance, never under-state it.
For a triangle ``tau`` of the source (or a piece of one) with corners ``x_0, x_1, x_2``:

* **Lipschitz**: ``d(., T)`` is 1-Lipschitz, and every point of ``tau`` is within
  ``cover(tau)`` (:func:`cover_radius`, the exact covering radius of a triangle by its corners)
  of a corner, so ``max over tau of d(x, T) <= max_i u_i + cover(tau)`` for any upper bounds
  ``u_i >= d(x_i, T)``.
* **Convexity**: the distance to one triangle ``T_h`` (a convex set) is a convex function, so
  its maximum over ``tau`` is at a corner: ``max over tau of d(x, T) <= max_i d(x_i, T_h)``.
  This one is exact where the two surfaces coincide (a proxy triangle the decimation left as it
  was, a full triangle lying on one proxy triangle), where the Lipschitz bound would need samples
  finer than the distance itself.

A piece's bound is the smaller of the two.  Pieces whose bound is more than ``refine`` above the
largest distance sampled so far (``L``, over both directions and every pose) are split into four
(midpoints of the sides: the cover radius halves) *at the poses where they are above*, up to
``max_depth`` times; a piece at ``max_depth`` keeps its bound, which stays an upper bound.  So the
result is an upper bound of the two-sided distance at every pose, and where the depth suffices it
is at most ``L (1 + refine) + resolution`` with ``L`` a distance actually found.

Work shared across poses
------------------------
Candidate triangles (the ``k`` nearest target triangles by centroid) and each sample's nearest
target triangle ("home") are chosen once, on the setup pose (pose 0, the bind pose).  On every
other pose a sample is first bounded by its exact distance to its home triangle alone (one
point-triangle test); only samples of pieces still above the threshold get the exact distance to
all their candidates.  Both directions share one skinning per pose chunk (``frames``).

Kernels (private, ``_``-prefixed; readable references in ``tests/references/naive.py``)
--------------------------------------------------------------------------
``_sample_distances``: for (pose, sample) pairs, the distance to the nearest of a candidate row;
``_piece_bounds``: for (pose, piece) pairs, the smaller of the two bounds above;
``_all_triangle_bounds``: the same for every source triangle on every pose of a chunk (each
vertex's distance to its home triangle computed once per pose).  Ericson's
closest point on a triangle is the runtime's (:func:`runtime.kernels.triangle.closest_on_triangle`),
the one copy of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange
from scipy.spatial import cKDTree

from colossus.runtime.kernels.triangle import closest_on_triangle

#: Pairs per task of the parallel kernels (the scratch buffer is allocated once per task).
BLOCK = 512
#: Exact distances on poses other than the setup pose walk at most this many steps to nearer
#: neighbouring triangles after the candidates.
WALK_STEPS = 8
#: A source triangle's home is chosen among its corners' nearest triangles and the first three
#: target triangles in the first this many candidates of all three corners.
HOME_CANDIDATES = 8
#: Candidate searches widen up to this many nearest centroids.
MAX_CANDIDATE_SEARCH = 32
#: Integer barycentric resolution of the pieces: 2**MAX_DEPTH_LIMIT subdivisions per side at most.
MAX_DEPTH_LIMIT = 10
_D = 1 << MAX_DEPTH_LIMIT


# ------------------------------------------------------------------------------ kernels
@njit(cache=True, inline="always")
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




@njit(cache=True, inline="always")
def _sample_xyz(v, f, s_idx, s_bary, s):
    """Sample ``s`` (a barycentric combination of three source vertices) at pose ``f``."""
    i0, i1, i2 = s_idx[s, 0], s_idx[s, 1], s_idx[s, 2]
    b0, b1, b2 = s_bary[s, 0], s_bary[s, 1], s_bary[s, 2]
    x = b0 * np.float64(v[f, i0, 0]) + b1 * np.float64(v[f, i1, 0]) + b2 * np.float64(v[f, i2, 0])
    y = b0 * np.float64(v[f, i0, 1]) + b1 * np.float64(v[f, i1, 1]) + b2 * np.float64(v[f, i2, 1])
    z = b0 * np.float64(v[f, i0, 2]) + b1 * np.float64(v[f, i1, 2]) + b2 * np.float64(v[f, i2, 2])
    return x, y, z


@njit(cache=True)
def _dist2(px, py, pz, tv, tri, j, tmp):
    """Squared distance from p to target triangle ``j`` of the pose ``tv`` (n, 3).  Not inlined:
    the runtime's closest-point routine is inlined once here, not at every call site (compile
    time)."""
    closest_on_triangle(px, py, pz, tv, tri[j, 0], tri[j, 1], tri[j, 2], tmp)
    return (tmp[0] - px) ** 2 + (tmp[1] - py) ** 2 + (tmp[2] - pz) ** 2


@njit(cache=True, parallel=True)
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


@njit(cache=True, parallel=True)
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


@njit(cache=True, parallel=True)
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


@njit(cache=True)
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


# ------------------------------------------------------------------------------ the bound
@dataclass
class OneSided:
    """Upper bound of ``max over x in source of d(x, target)`` on every pose (one direction).

    bound : float, the largest over the poses
    pose_bound : (F,) float64, an upper bound at each pose
    worst_pose : int, worst_triangle : int (the source triangle where ``bound`` is reached)
    sampled : float, the largest distance sampled in this direction (exact distance to the
        candidate triangles: the truth, unless the candidates missed the nearest triangle)
    pose_sampled : (F,) float64, the largest distance sampled at each pose (0 where none was)
    sampled_pose : int, sampled_vertex : int (a source vertex of the sample where ``sampled`` was
        found)
    samples : int, sample points made (vertices, then piece corners)
    pieces : int, pieces made (source triangles and their subdivisions)
    evaluations : int, (pose, piece) pairs bounded
    depth : int, the deepest subdivision used
    exceeded : bool, the search stopped at a distance above ``limit`` (``decide``): ``bound`` and
        ``pose_bound`` are then not bounds, only ``bound >= sampled > limit`` is known
    """

    bound: float
    pose_bound: np.ndarray
    worst_pose: int
    worst_triangle: int
    sampled: float
    pose_sampled: np.ndarray
    sampled_pose: int
    sampled_vertex: int
    samples: int
    pieces: int
    evaluations: int
    depth: int
    exceeded: bool = False


@dataclass
class _Shared:
    """What both directions share: the largest sampled distance and the threshold from it.

    With a ``limit`` the threshold never exceeds it (the bound then stays within the limit
    wherever the depth allows); ``decide`` only asks whether the bound is within the limit: the
    threshold is the limit itself, and the work stops as soon as a distance above it is found."""

    sampled: float
    refine: float
    resolution: float
    limit: float = np.inf
    decide: bool = False

    def threshold(self) -> float:
        if self.decide:
            return self.limit
        return min(self.sampled * (1.0 + self.refine) + self.resolution, self.limit)

    @property
    def exceeded(self) -> bool:
        return self.decide and self.sampled > self.limit


_CORNER_UV = np.array([[_D, 0], [0, _D], [0, 0]], np.int64)


class _Targets:
    """Candidate target triangles for points on the setup pose: the ``k`` nearest by centroid,
    widened (k x 4, up to ``MAX_CANDIDATE_SEARCH``) until the nearest triangle is certainly among
    them (no other centroid is close enough: ``k-th centroid distance - largest triangle radius >=
    the best distance found``); each row keeps the ``k`` most promising (smallest lower bound
    ``|x - centroid| - radius``), the nearest first."""

    def __init__(self, t0: np.ndarray, tri: np.ndarray):
        v = t0.astype(np.float64)[tri]
        self.tri = tri
        self.t0 = t0
        self.c = v.mean(axis=1)
        self.r = np.linalg.norm(v - self.c[:, None], axis=2).max(axis=1)
        self.rmax = float(self.r.max()) if len(self.r) else 0.0
        self.tree = cKDTree(self.c)

    def query(self, points: np.ndarray, k: int):
        """``(candidates (N, k) int64, nearest (N,) int64)`` for ``points`` (N, 3) float64."""
        m = len(self.tri)
        k = int(min(k, m))
        N = len(points)
        cand = np.empty((N, k), np.int64)
        near = np.empty(N, np.int64)
        todo = np.arange(N)
        kk = k
        pts32 = np.ascontiguousarray(points, dtype=np.float32)
        while len(todo):
            dd, jj = self.tree.query(points[todo], k=kk, workers=-1)
            dd, jj = dd.reshape(len(todo), kk), jj.reshape(len(todo), kk).astype(np.int64)
            n = len(todo)
            d, t, _ = sample_distances(pts32[todo], np.repeat(np.arange(n)[:, None], 3, 1),
                                       np.tile(np.array([1.0, 0.0, 0.0]), (n, 1)), self.t0, self.tri, jj)
            last = kk >= min(m, MAX_CANDIDATE_SEARCH)
            sure = (dd[:, -1] - self.rmax >= d) | last
            i = np.flatnonzero(sure)
            lb = dd[i] - self.r[jj[i]]
            lb[jj[i] == t[i, None]] = -np.inf       # the nearest first
            order = np.argsort(lb, axis=1, kind="stable")[:, :k]
            cand[todo[i]] = np.take_along_axis(jj[i], order, axis=1)
            near[todo[i]] = t[i]
            todo = todo[~sure]
            kk = min(m, kk * 4, MAX_CANDIDATE_SEARCH)
        return cand, near


class _Side:
    """One direction (source -> target): its samples, pieces, and the bound so far."""

    def __init__(self, src_tri, tgt_tri, s0, t0, k: int, count: int, max_depth: int):
        self.tri = np.ascontiguousarray(src_tri, dtype=np.int64)
        self.ttri = np.ascontiguousarray(tgt_tri, dtype=np.int64)
        self.s0, self.t0 = s0, t0          # (1, n, 3) float32 setup pose
        self.max_depth = int(max_depth)
        n, m = s0.shape[1], len(self.tri)
        self.targets = _Targets(t0[0], self.ttri)
        self.fans = vertex_triangles(self.ttri, t0.shape[1])
        self.k = int(k)
        self.s_idx = np.repeat(np.arange(n, dtype=np.int64)[:, None], 3, axis=1)
        self.s_bary = np.tile(np.array([1.0, 0.0, 0.0]), (n, 1))
        self.cand, self.near = self.targets.query(s0[0].astype(np.float64), self.k)
        d = sample_distances(s0, self.s_idx, self.s_bary, t0, self.ttri, self.near[:, None])[0]
        used = np.zeros(n, bool)
        used[self.tri.ravel()] = True
        self.used = np.flatnonzero(used)
        self.sampled = 0.0
        self.sampled_at = (0, 0)
        self.pose_sampled = np.zeros(count)
        self.saw(np.zeros(len(self.used), np.int64), self.used, d[self.used])
        self.corners = self.tri.copy()
        self.src = np.arange(m, dtype=np.int64)
        self.uv = np.broadcast_to(_CORNER_UV, (m, 3, 2)).copy()
        self.depth = np.zeros(m, np.int64)
        self.home = self._homes(self.corners, None)
        self.pose_bound = np.zeros(count)
        self.best = (-1.0, 0, 0)
        self.evaluations = 0
        self.deepest = 0
        self.pending = []

    def saw(self, poses, samples, d) -> None:
        """Exact sampled distances ``d`` of ``samples`` at global ``poses``: the largest found."""
        if not len(d):
            return
        np.maximum.at(self.pose_sampled, poses, d)
        i = int(np.argmax(d))
        if d[i] > self.sampled:
            self.sampled = float(d[i])
            self.sampled_at = (int(poses[i]), int(samples[i]))

    def _homes(self, corners, parent) -> np.ndarray:
        """Per piece, the target triangle with the smallest largest corner distance on the setup
        pose, among its corners' nearest triangles and either the first three triangles in all
        three corners' candidate rows (source triangles, ``parent`` None: where the surfaces
        coincide, the triangle under the piece is one of them) or the ``parent``'s home."""
        if parent is None:
            h = min(HOME_CANDIDATES, self.cand.shape[1])
            r0, r1, r2 = (self.cand[corners[:, i], :h] for i in range(3))
            common = (r0[:, :, None] == r1[:, None, :]).any(2) & (r0[:, :, None] == r2[:, None, :]).any(2)
            pick = np.argsort(~common, axis=1, kind="stable")[:, :3]           # the first three in common
            both = np.take_along_axis(common, pick, 1)
            C = np.c_[self.near[corners], np.where(both, np.take_along_axis(r0, pick, 1), self.near[corners[:, :1]])]
        else:
            C = np.c_[self.near[corners], parent]
        Q, c = C.shape
        sample = np.repeat(corners, c, axis=1).ravel()           # (q, corner, candidate)
        rows = np.tile(C, (1, 3)).reshape(-1, 1)
        d, _, _ = sample_distances(self.s0, self.s_idx, self.s_bary, self.t0, self.ttri, rows,
                                   sample=sample, row=np.arange(len(sample)))
        worst = d.reshape(Q, 3, c).max(axis=1)
        return C[np.arange(Q), np.argmin(worst, axis=1)]

    def split(self, q: np.ndarray) -> np.ndarray:
        """Four children (midpoint subdivision) of each piece ``q`` (U,); returns (U, 4) ids."""
        c, uv, src = self.corners[q], self.uv[q], self.src[q]
        mid_uv = np.stack([(uv[:, 0] + uv[:, 1]) // 2, (uv[:, 1] + uv[:, 2]) // 2, (uv[:, 2] + uv[:, 0]) // 2], 1)
        base = (_D + 1) ** 2
        keys = src[:, None] * base + mid_uv[..., 0] * (_D + 1) + mid_uv[..., 1]
        uk, inv = np.unique(keys.ravel(), return_inverse=True)
        st, u, v = uk // base, (uk % base) // (_D + 1), uk % (_D + 1)
        idx = self.tri[st]
        bary = np.stack([u, v, _D - u - v], axis=1) / _D
        pts = np.einsum("nk,nkd->nd", bary, self.s0[0].astype(np.float64)[idx])
        first = len(self.s_idx)
        cand, near = self.targets.query(pts, self.k)
        self.s_idx = np.concatenate([self.s_idx, idx])
        self.s_bary = np.concatenate([self.s_bary, bary])
        self.cand = np.concatenate([self.cand, cand])
        self.near = np.concatenate([self.near, near])
        m = (first + inv).reshape(-1, 3)                      # m01, m12, m20
        kids = np.stack([np.c_[c[:, 0], m[:, 0], m[:, 2]], np.c_[m[:, 0], c[:, 1], m[:, 1]],
                         np.c_[m[:, 2], m[:, 1], c[:, 2]], np.c_[m[:, 0], m[:, 1], m[:, 2]]], axis=1)
        kuv = np.stack([np.stack([uv[:, 0], mid_uv[:, 0], mid_uv[:, 2]], 1),
                        np.stack([mid_uv[:, 0], uv[:, 1], mid_uv[:, 1]], 1),
                        np.stack([mid_uv[:, 2], mid_uv[:, 1], uv[:, 2]], 1),
                        np.stack([mid_uv[:, 0], mid_uv[:, 1], mid_uv[:, 2]], 1)], axis=1)
        U = len(q)
        ids = len(self.corners) + np.arange(4 * U).reshape(U, 4)
        kc = kids.reshape(-1, 3)
        self.corners = np.concatenate([self.corners, kc])
        self.uv = np.concatenate([self.uv, kuv.reshape(-1, 3, 2)])
        self.src = np.concatenate([self.src, np.repeat(src, 4)])
        self.depth = np.concatenate([self.depth, np.repeat(self.depth[q] + 1, 4)])
        self.home = np.concatenate([self.home, self._homes(kc, np.repeat(self.home[q], 4))])
        return ids

    def evaluate(self, sv, tv, ch, lf, q, shared: _Shared):
        """Bound the pairs (local pose ``lf`` into ``sv``/``tv``, whose global poses are ``ch``,
        piece ``q``); record the resolved ones, keep the others pending (see the module
        docstring)."""
        if not len(q):
            return
        gf = ch[lf]
        self.evaluations += len(q)
        thr = shared.threshold()
        B, rad = piece_bounds(sv, self.s_idx, self.s_bary, tv, self.ttri, self.corners, self.near, self.home, lf, q,
                              threshold=thr, cover=True)
        # exact corner distances can only lower the Lipschitz term to (corner bounds) + cover: not
        # worth it for a piece whose cover alone is above the threshold (it is split anyway)
        hot = np.flatnonzero((B > thr) & (rad < thr))
        if len(hot):
            # the corners of the pieces above: exact distance to all their candidates, each once
            N = len(self.s_idx)
            uk, inv = np.unique((lf[hot, None] * N + self.corners[q[hot]]).ravel(), return_inverse=True)
            ef, es = uk // N, uk % N
            ex = sample_distances(sv, self.s_idx, self.s_bary, tv, self.ttri, self.cand, pose=ef, sample=es, row=es,
                                  walk=WALK_STEPS, fans=self.fans)[0]
            self.saw(ch[ef], es, ex)
            shared.sampled = max(shared.sampled, self.sampled)
            thr = shared.threshold()
            B[hot] = piece_bounds(sv, self.s_idx, self.s_bary, tv, self.ttri, self.corners, self.near, self.home,
                                  lf[hot], q[hot], corner_bounds=ex[inv].reshape(-1, 3), threshold=thr)
        done = (B <= thr) | (self.depth[q] >= self.max_depth)
        self._record(gf[done], q[done], B[done])
        keep = ~done
        if keep.any():
            self.pending.append((gf[keep], q[keep], B[keep]))

    def evaluate_all(self, sv, tv, ch, shared: _Shared):
        """Round 0: every source triangle on every pose of the chunk (global poses ``ch``), with
        the dense kernel; records the resolved ones, keeps the others pending."""
        F, m, n = sv.shape[0], len(self.tri), sv.shape[1]
        self.evaluations += F * m
        thr = shared.threshold()
        B, rad, _ = triangle_bounds(sv, self.tri, tv, self.ttri, self.near[:n], self.home[:m], threshold=thr)
        fh, th = np.nonzero((B > thr) & (rad < thr))
        if len(fh):
            key = (fh[:, None] * n + self.tri[th]).ravel()
            mark = np.zeros(F * n, bool)
            mark[key] = True
            uk = np.flatnonzero(mark)
            inv = (np.cumsum(mark) - 1)[key]
            ef, es = uk // n, uk % n
            ex = sample_distances(sv, self.s_idx, self.s_bary, tv, self.ttri, self.cand, pose=ef, sample=es, row=es,
                                  walk=WALK_STEPS, fans=self.fans)[0]
            self.saw(ch[ef], es, ex)
            shared.sampled = max(shared.sampled, self.sampled)
            thr = shared.threshold()
            B[fh, th] = piece_bounds(sv, self.s_idx, self.s_bary, tv, self.ttri, self.corners, self.near, self.home,
                                     fh, th, corner_bounds=ex[inv].reshape(-1, 3), threshold=thr)
        done = B <= thr if self.max_depth > 0 else np.ones_like(B, bool)
        low = np.where(done, B, -np.inf)
        top = low.max(axis=1)
        self.pose_bound[ch] = np.maximum(self.pose_bound[ch], top)
        f = int(np.argmax(top))
        if top[f] > self.best[0]:
            self.best = (float(top[f]), int(ch[f]), int(np.argmax(low[f])))
        pf, pq = np.nonzero(~done)
        if len(pf):
            self.pending.append((ch[pf], pq, B[pf, pq]))

    def _record(self, gf, q, B):
        if not len(B):
            return
        np.maximum.at(self.pose_bound, gf, B)
        i = int(np.argmax(B))
        if B[i] > self.best[0]:
            self.best = (float(B[i]), int(gf[i]), int(self.src[q[i]]))
        self.deepest = max(self.deepest, int(self.depth[q].max()))

    def _take_pending(self):
        p, self.pending = self.pending, []
        if not p:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        return tuple(np.concatenate(x) for x in zip(*p))

    def next_round(self, shared: _Shared):
        """Pending pairs still above the threshold, split: returns (pose, child piece) pairs."""
        gf, q, B = self._take_pending()
        ok = B <= shared.threshold()
        self._record(gf[ok], q[ok], B[ok])
        gf, q = gf[~ok], q[~ok]
        if not len(q):
            return gf, q
        uq, inv = np.unique(q, return_inverse=True)
        kids = self.split(uq)
        return np.repeat(gf, 4), kids[inv].ravel()

    def result(self, exceeded: bool = False) -> OneSided:
        if exceeded:  # stopped early: nothing below the measured distance is known
            self.best = (max(self.best[0], self.sampled), self.sampled_at[0], self.best[2])
        return OneSided(exceeded=exceeded, bound=max(self.best[0], 0.0), pose_bound=self.pose_bound,
                        worst_pose=self.best[1], worst_triangle=self.best[2], sampled=self.sampled,
                        pose_sampled=self.pose_sampled,
                        sampled_pose=self.sampled_at[0], sampled_vertex=int(self.s_idx[self.sampled_at[1], 0]),
                        samples=len(self.s_idx), pieces=len(self.corners), evaluations=self.evaluations,
                        depth=self.deepest)


def _pose_chunks(poses: np.ndarray, vertices: int, budget: int):
    step = max(1, int(budget // max(1, 12 * vertices)))
    return [poses[i:i + step] for i in range(0, len(poses), step)]


def deviation_bound(frames, count: int, tri_a, tri_b, refine: float, resolution: float,
                    candidates=(8, 16), max_depth: int = 6, probes: int = 8, limit: float | None = None,
                    decide: bool = False, frame_bytes: int = 128 * 2 ** 20, pair_budget: int = 1_000_000):
    """Upper bounds of both one-sided distances between two animated surfaces on every pose.

    Parameters
    ----------
    frames : callable
        ``frames(poses)`` ((p,) int) returns ``(a, b)``: ``(p, n_a, 3)`` and ``(p, n_b, 3)``
        float32 vertex positions of the two surfaces at those poses.  Pose 0 is the setup pose
        (candidates and home triangles are chosen on it).
    count : int, the number of poses
    tri_a, tri_b : (m_a, 3), (m_b, 3) int, the two surfaces' triangles
    refine : float
        Pieces are subdivided while their bound is more than this fraction above the largest
        sampled distance (over both directions and every pose) ...
    resolution : float
        ... plus this length.
    candidates : (k_ab, k_ba)
        Candidate target triangles per sample for a -> b and for b -> a.
    max_depth : int, at most ``MAX_DEPTH_LIMIT``
        Subdivisions at most (a piece at this depth keeps its bound).
    probes : int
        Poses (evenly spaced) on which every vertex is measured exactly before the sweep, to
        start the threshold near the truth.
    limit : float, optional
        Subdivide at least until the bound is within ``limit`` (where the depth allows).
    decide : bool
        Only decide whether the bound is within ``limit``: subdivide only down to the limit, and
        stop as soon as a distance above it is measured (the results then say ``exceeded``).

    Returns
    -------
    (OneSided a -> b, OneSided b -> a)
    """
    if not 0 <= max_depth <= MAX_DEPTH_LIMIT:
        raise ValueError(f"max_depth: expected 0..{MAX_DEPTH_LIMIT}, got {max_depth}")
    a0, b0 = frames(np.array([0]))
    a0, b0 = _pose_array(a0, "frames a"), _pose_array(b0, "frames b")
    sides = (_Side(tri_a, tri_b, a0, b0, candidates[0], count, max_depth),
             _Side(tri_b, tri_a, b0, a0, candidates[1], count, max_depth))
    shared = _Shared(max(s.sampled for s in sides), float(refine), float(resolution),
                     np.inf if limit is None else float(limit), bool(decide and limit is not None))

    def done():
        return [s.result(shared.exceeded) for s in sides]

    if shared.exceeded:
        return done()
    nv = a0.shape[1] + b0.shape[1]
    # probes: exact distances of every vertex on a few poses
    pp = np.unique(np.linspace(0, count - 1, min(count, max(probes, 1))).astype(np.int64))
    for ch in _pose_chunks(pp, nv, frame_bytes):
        va, vb = frames(ch)
        for s, sv, tv in ((sides[0], va, vb), (sides[1], vb, va)):
            step = max(1, pair_budget // max(len(s.used), 1))
            for i in range(0, len(ch), step):
                f = np.repeat(np.arange(i, min(len(ch), i + step)), len(s.used))
                u = np.tile(s.used, len(f) // max(len(s.used), 1))
                d = sample_distances(sv, s.s_idx, s.s_bary, tv, s.ttri, s.cand, pose=f, sample=u, row=u,
                                     walk=WALK_STEPS, fans=s.fans)[0]
                s.saw(ch[f], u, d)
        shared.sampled = max(shared.sampled, *(s.sampled for s in sides))
        if shared.exceeded:
            return done()
    # round 0: every piece (source triangle) on every pose
    per = max(len(sides[0].tri), len(sides[1].tri), 1)
    step = max(1, min(4 * pair_budget // per, int(frame_bytes // max(1, 12 * nv))))
    for lo in range(0, count, step):
        ch = np.arange(lo, min(count, lo + step))
        va, vb = frames(ch)
        for s, sv, tv in ((sides[0], va, vb), (sides[1], vb, va)):
            s.evaluate_all(sv, tv, ch, shared)
        if shared.exceeded:
            return done()
    # refinement rounds: the pending pairs split, on the poses where they are above
    for _ in range(max_depth):
        todo = []
        for s in sides:
            gf, q = s.next_round(shared)
            order = np.argsort(gf, kind="stable")
            todo.append((gf[order], q[order]))
        if not any(len(q) for _, q in todo):
            break
        poses = np.unique(np.concatenate([gf for gf, _ in todo]))
        for ch in _pose_chunks(poses, nv, frame_bytes):
            va, vb = frames(ch)
            for (gf, q), s, sv, tv in zip(todo, sides, (va, vb), (vb, va)):
                i0, i1 = np.searchsorted(gf, ch[0]), np.searchsorted(gf, ch[-1], side="right")
                for i in range(i0, i1, pair_budget):
                    j = min(i1, i + pair_budget)
                    s.evaluate(sv, tv, ch, np.searchsorted(ch, gf[i:j]), q[i:j], shared)
            if shared.exceeded:
                return done()
    for s in sides:  # pairs left at the last round keep their bound
        gf, q, B = s._take_pending()
        s._record(gf, q, B)
    return done()
