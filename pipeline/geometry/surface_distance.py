"""Distances between triangle surfaces, as sound upper bounds (used by ``simplify``).

The bound (after Metro and libigl's ``hausdorff`` lower/upper bounds)
----------------------------------------------------------------------
For a source surface ``S`` and a target surface ``T``, the one-sided distance is
``h(S, T) = max over x in S of d(x, T)``.  ``d(., T)`` is 1-Lipschitz, so for a source triangle
``t`` covered by sample points ``s_i`` within radius ``r`` (every point of ``t`` within ``r`` of
some sample)::

    max over x in t of d(x, T)  <=  max_i d(s_i, T) + r

and ``d(s_i, T) <= d(s_i, P)`` for any patch ``P`` of ``T`` (a subset of its triangles), so the
exact distance from a sample to a few candidate triangles is an upper bound too.  The samples of
a triangle are its corners and the points of a barycentric grid of level ``s`` (``s**2`` similar
sub-triangles); the covering radius of the grid is ``cover_radius(t) / s``, where
:func:`cover_radius` is the exact covering radius of a triangle by its three corners (the
circumradius for a non-obtuse triangle; for an obtuse one the largest distance along the long
side to the nearer corner, where a perpendicular bisector of a short side crosses it).

Everything is evaluated on the skinned triangles of each pose, so the bound holds for the shapes
drawn at that pose, whatever the skinning did to the triangles' sizes.

Public functions
----------------
cover_radius(a, b, c) -> (m,) float64
grid_barycentrics(level) -> (g, 3) float64
nearest_on_candidates(points_v, sample_idx, sample_bary, target_v, target_tri, candidates)
    -> (distance (N,) float64, triangle (N,) int64, barycentric (N, 3) float64)
triangle_corner_bound(v, tri, vertex_distance) -> (m,) float64
CandidateQuery(sample_idx, sample_bary, target_tri, candidates).distances(src_v, target_v)
    the same as ``nearest_on_candidates``, checked once and evaluated on many poses
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


# ------------------------------------------------------------------------------ kernels
@njit(cache=True, inline="always")
def _closest_on_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Squared distance from p to triangle abc and the barycentrics (u, v, w) of the closest
    point (Ericson, Real-Time Collision Detection, 5.1.5).  float64 throughout."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        u, v, w = 1.0, 0.0, 0.0
    else:
        bpx, bpy, bpz = px - bx, py - by, pz - bz
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        if d3 >= 0.0 and d4 <= d3:
            u, v, w = 0.0, 1.0, 0.0
        else:
            vc = d1 * d4 - d3 * d2
            if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
                t = d1 / (d1 - d3)
                u, v, w = 1.0 - t, t, 0.0
            else:
                cpx, cpy, cpz = px - cx, py - cy, pz - cz
                d5 = abx * cpx + aby * cpy + abz * cpz
                d6 = acx * cpx + acy * cpy + acz * cpz
                if d6 >= 0.0 and d5 <= d6:
                    u, v, w = 0.0, 0.0, 1.0
                else:
                    vb = d5 * d2 - d1 * d6
                    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
                        t = d2 / (d2 - d6)
                        u, v, w = 1.0 - t, 0.0, t
                    else:
                        va = d3 * d6 - d5 * d4
                        if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
                            t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
                            u, v, w = 0.0, 1.0 - t, t
                        else:
                            den = va + vb + vc
                            if den == 0.0:  # degenerate triangle: nearest corner
                                u, v, w = 1.0, 0.0, 0.0
                            else:
                                v = vb / den
                                w = vc / den
                                u = 1.0 - v - w
    qx = u * ax + v * bx + w * cx
    qy = u * ay + v * by + w * cy
    qz = u * az + v * bz + w * cz
    dx, dy, dz = px - qx, py - qy, pz - qz
    d = dx * dx + dy * dy + dz * dz
    # a degenerate triangle can hide a nearer corner or edge point: check the corners
    if d > 0.0 and (u == 1.0 and v == 0.0 and w == 0.0):
        for k in range(2):
            ex = bx if k == 0 else cx
            ey = by if k == 0 else cy
            ez = bz if k == 0 else cz
            e = (px - ex) ** 2 + (py - ey) ** 2 + (pz - ez) ** 2
            if e < d:
                d = e
                if k == 0:
                    u, v, w = 0.0, 1.0, 0.0
                else:
                    u, v, w = 0.0, 0.0, 1.0
    return d, u, v, w


@njit(parallel=True, cache=True)
def _nearest_on_candidates(src_all, s_idx, s_bary, tgt_all, tgt_t, cand, out_d, out_t, out_b):
    """For each pose and sample (a barycentric combination of three source vertices), the exact
    distance to the nearest of its candidate target triangles (``cand`` row, -1 padded).
    Poses are the first axis of ``src_all``/``tgt_all``/``out_*`` (one parallel loop over
    pose x sample, so short per-pose work is not dominated by thread start-up)."""
    N = s_idx.shape[0]
    for fi in prange(src_all.shape[0] * N):
        f = fi // N
        i = fi - f * N
        src_v = src_all[f]
        tgt_v = tgt_all[f]
        i0, i1, i2 = s_idx[i, 0], s_idx[i, 1], s_idx[i, 2]
        b0, b1, b2 = np.float64(s_bary[i, 0]), np.float64(s_bary[i, 1]), np.float64(s_bary[i, 2])
        px = b0 * np.float64(src_v[i0, 0]) + b1 * np.float64(src_v[i1, 0]) + b2 * np.float64(src_v[i2, 0])
        py = b0 * np.float64(src_v[i0, 1]) + b1 * np.float64(src_v[i1, 1]) + b2 * np.float64(src_v[i2, 1])
        pz = b0 * np.float64(src_v[i0, 2]) + b1 * np.float64(src_v[i1, 2]) + b2 * np.float64(src_v[i2, 2])
        best = np.inf
        bt = -1
        bu, bv, bw = 1.0, 0.0, 0.0
        for c in range(cand.shape[1]):
            j = cand[i, c]
            if j < 0:
                break
            a, b, cc = tgt_t[j, 0], tgt_t[j, 1], tgt_t[j, 2]
            d, u, v, w = _closest_on_triangle(
                px, py, pz,
                np.float64(tgt_v[a, 0]), np.float64(tgt_v[a, 1]), np.float64(tgt_v[a, 2]),
                np.float64(tgt_v[b, 0]), np.float64(tgt_v[b, 1]), np.float64(tgt_v[b, 2]),
                np.float64(tgt_v[cc, 0]), np.float64(tgt_v[cc, 1]), np.float64(tgt_v[cc, 2]))
            if d < best:
                best, bt, bu, bv, bw = d, j, u, v, w
        out_d[f, i] = np.sqrt(best)
        out_t[f, i] = bt
        out_b[f, i, 0], out_b[f, i, 1], out_b[f, i, 2] = bu, bv, bw


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


@njit(cache=True)
def _corner_bound(v_all, tri, dv_all, out):
    # serial: a few flops per triangle (a parallel loop would cost more to compile than it saves)
    m = tri.shape[0]
    for ft in range(v_all.shape[0] * m):
        f = ft // m
        t = ft - f * m
        v = v_all[f]
        dv = dv_all[f]
        a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
        r = _cover(np.float64(v[a, 0]), np.float64(v[a, 1]), np.float64(v[a, 2]),
                   np.float64(v[b, 0]), np.float64(v[b, 1]), np.float64(v[b, 2]),
                   np.float64(v[c, 0]), np.float64(v[c, 1]), np.float64(v[c, 2]))
        out[f, t] = max(dv[a], dv[b], dv[c]) + r


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
def _tri_args(v, tri):
    """Vertices as ``(F, n, 3)`` float32 (bulk geometry; the kernels compute in float64, and one
    dtype means one compiled signature) and int64 triangles."""
    v = np.ascontiguousarray(v, dtype=np.float32)
    tri = np.ascontiguousarray(tri, dtype=np.int64)
    if v.ndim == 2:
        v = v[None]
    if v.ndim != 3 or v.shape[2] != 3:
        raise ValueError(f"vertices: expected shape (n, 3) or (F, n, 3), got {v.shape}")
    if tri.ndim != 2 or tri.shape[1] != 3:
        raise ValueError(f"triangles: expected shape (m, 3), got {tri.shape}")
    if tri.size and (tri.min() < 0 or tri.max() >= v.shape[1]):
        raise ValueError(f"triangles: expected indices in [0, {v.shape[1]}), got {tri.min()}..{tri.max()}")
    return v, tri


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
    v, tri = _tri_args(v, tri)
    out = np.empty((len(v), len(tri)))
    _cover_many(v, tri, out)
    return out[0] if single else out


def triangle_corner_bound(v: np.ndarray, tri: np.ndarray, vertex_distance: np.ndarray) -> np.ndarray:
    """Upper bound of the distance function over each triangle from its corners' values.

    Parameters
    ----------
    v : (n, 3) or (F, n, 3) float32 vertex positions
    tri : (m, 3) int
    vertex_distance : (n,) or (F, n) float64, an upper bound of the distance at each vertex

    Returns
    -------
    (m,) or (F, m) float64: ``max(corner distances) + cover_radius``.
    """
    single = np.ndim(v) == 2
    v, tri = _tri_args(v, tri)
    dv = np.ascontiguousarray(vertex_distance, dtype=np.float64).reshape(-1, v.shape[1]) if np.size(vertex_distance) else np.zeros((len(v), 0))
    if dv.shape != v.shape[:2]:
        raise ValueError(f"vertex_distance: expected shape {v.shape[:2]}, got {np.shape(vertex_distance)}")
    out = np.empty((len(v), len(tri)))
    _corner_bound(v, tri, dv, out)
    return out[0] if single else out


def grid_barycentrics(level: int, corners: bool = True) -> np.ndarray:
    """Barycentric coordinates of the level-``s`` grid on a triangle.

    Returns ``((s + 1) (s + 2) / 2, 3)`` float64 (without the 3 corners when ``corners`` is
    False); the grid splits the triangle into ``s**2`` copies of itself scaled by ``1 / s``.
    """
    s = int(level)
    if s < 1:
        raise ValueError(f"grid level: expected >= 1, got {level}")
    i, j = np.meshgrid(np.arange(s + 1), np.arange(s + 1), indexing="ij")
    keep = (i + j) <= s
    i, j = i[keep], j[keep]
    b = np.stack([s - i - j, i, j], axis=1) / s
    if not corners:
        b = b[(b == 1.0).sum(axis=1) == 0]
    return b.astype(np.float64)


class CandidateQuery:
    """Samples and candidate triangles checked once, evaluated on many poses (the vertex
    positions change, the connectivity does not).  See :func:`nearest_on_candidates`."""

    def __init__(self, sample_idx, sample_bary, target_tri, candidates, src_count: int, target_count: int):
        self.s_idx = np.ascontiguousarray(sample_idx, dtype=np.int64)
        self.s_bary = np.ascontiguousarray(sample_bary, dtype=np.float64)
        self.tri = np.ascontiguousarray(target_tri, dtype=np.int64)
        self.cand = np.ascontiguousarray(candidates, dtype=np.int64)
        N = len(self.s_idx)
        if self.s_idx.shape != (N, 3) or self.s_bary.shape != (N, 3):
            raise ValueError(f"samples: expected (N, 3) indices and barycentrics, got {self.s_idx.shape} "
                             f"and {self.s_bary.shape}")
        if N and (self.s_idx.min() < 0 or self.s_idx.max() >= src_count):
            raise ValueError(f"sample_idx: expected indices in [0, {src_count}), got "
                             f"{self.s_idx.min()}..{self.s_idx.max()}")
        if self.tri.ndim != 2 or self.tri.shape[1] != 3:
            raise ValueError(f"target triangles: expected shape (m, 3), got {self.tri.shape}")
        if self.tri.size and (self.tri.min() < 0 or self.tri.max() >= target_count):
            raise ValueError(f"target triangles: expected indices in [0, {target_count}), got "
                             f"{self.tri.min()}..{self.tri.max()}")
        if self.cand.ndim != 2 or self.cand.shape[0] != N:
            raise ValueError(f"candidates: expected shape ({N}, k), got {self.cand.shape}")
        if self.cand.size and self.cand.max() >= len(self.tri):
            raise ValueError(f"candidates: expected indices below {len(self.tri)}, got {self.cand.max()}")
        self.src_count, self.target_count = int(src_count), int(target_count)

    def distances(self, src_v, target_v, full: bool = False):
        """Distances for one pose (``(n, 3)`` vertices: ``(N,)``) or F poses (``(F, n, 3)``:
        ``(F, N)``), float64 (``full``: also nearest triangles and barycentrics, as
        :func:`nearest_on_candidates`)."""
        single = np.ndim(src_v) == 2
        src_v = np.ascontiguousarray(src_v, dtype=np.float32)
        target_v = np.ascontiguousarray(target_v, dtype=np.float32)
        if single:
            src_v, target_v = src_v[None], target_v[None]
        F = len(src_v)
        if src_v.shape != (F, self.src_count, 3) or target_v.shape != (F, self.target_count, 3):
            raise ValueError(f"pose vertices: expected ({F}, {self.src_count}, 3) and ({F}, {self.target_count}, 3), "
                             f"got {src_v.shape} and {target_v.shape}")
        N = len(self.s_idx)
        out_d = np.empty((F, N))
        out_t = np.empty((F, N), np.int64)
        out_b = np.empty((F, N, 3))
        _nearest_on_candidates(src_v, self.s_idx, self.s_bary, target_v, self.tri, self.cand, out_d, out_t, out_b)
        if single:
            out_d, out_t, out_b = out_d[0], out_t[0], out_b[0]
        return (out_d, out_t, out_b) if full else out_d


def nearest_on_candidates(src_v, sample_idx, sample_bary, target_v, target_tri, candidates):
    """Exact distance from each sample point to the nearest of its candidate target triangles.

    Parameters
    ----------
    src_v : (n, 3) float32 (other dtypes are converted)
        Vertices the samples are made of.
    sample_idx : (N, 3) int
        Three source vertices of each sample (a vertex sample repeats one index).
    sample_bary : (N, 3) float
        Barycentric weights of the sample on those vertices.
    target_v : (n_t, 3) float32
    target_tri : (m_t, 3) int
    candidates : (N, k) int
        Target triangles to try for each sample; -1 ends a row early.

    Returns
    -------
    distance : (N,) float64
        An upper bound of the distance to the whole target (exact when the nearest triangle is
        among the candidates); ``inf`` for a sample without candidates.
    triangle : (N,) int64, the nearest candidate (-1 without candidates).
    barycentric : (N, 3) float64, the nearest point on it.
    """
    src_v = np.asarray(src_v)
    target_v = np.asarray(target_v)
    if src_v.ndim != 2 or src_v.shape[1] != 3 or target_v.ndim != 2 or target_v.shape[1] != 3:
        raise ValueError(f"vertices: expected shapes (n, 3), got {src_v.shape} and {target_v.shape}")
    q = CandidateQuery(sample_idx, sample_bary, target_tri, candidates, len(src_v), len(target_v))
    return q.distances(src_v, target_v, full=True)
