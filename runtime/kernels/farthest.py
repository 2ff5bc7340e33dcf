"""The sampled proof's exact tier, compiled and threaded: per (pose, part), the part's skinned
vertex farthest from a centre, exactly, skinning only the chunks of vertices that can hold it.

Notation of :mod:`runtime.kernels.bounds`.  Each part's vertices are ordered along a Morton curve
of their mesh-space positions and cut into chunks of :data:`CHUNK_VERTS` (:func:`chunk_data`,
once per rig).  A chunk ``c`` has a ball ``(o_c, r_c)`` in mesh space holding its points, the
joints ``b`` with a non-zero weight on one of its vertices, ``a_c = max_v sum_b |w_b(v)|`` and
``eps_c = max_v |sum_b w_b(v) - 1|`` over its vertices.

**Chunk bound (test K of a chunk, in mesh space).**  With ``M_b`` the skinning transform of joint
``b`` (mesh -> stage: ``world @ skel_b @ inv_bind_b @ geom_bind``), a vertex's skinned point is
``x(v) = sum_b w_b M_b v``, so by the lemma of :mod:`runtime.kernels.bounds` (LBS is a weighted
sum) ``|x(v) - C| <= a_c max_b |M_b v - C| + eps_c |C|``, and ``|v - o_c| <= r_c`` gives
``|M_b v - C| <= |M_b o_c - C| + ||L(M_b)|| r_c``; hence every vertex of the chunk is within::

    K_c = a_c max_b (|M_b o_c - C| + ||L(M_b)|| r_c) + eps_c |C|

of ``C`` (``||L||`` the Gershgorin bound of :func:`runtime.kernels.bounds._norm2`).

**Chunk bound (test D of a chunk).**  With ``J`` the part's joint and ``E_b = M_b - M_J``,
``x(v) - C = (M_J v - C) + sum_{b != J} w_b E_b v + (s - 1) M_J v`` (``s = sum_b w_b``), so with
``wmax_b`` the largest ``|w_b(v)|`` over the chunk and the ball as above::

    D_c = |M_J o_c - C| + ||L(M_J)|| r_c + sum_{b != J} wmax_b (|E_b o_c| + ||L(E_b)|| r_c)
          + eps_c (|M_J o_c| + ||L(M_J)|| r_c)

(tighter than ``K_c`` where the other joints' weights are small or move with ``J``).  The
chunk's bound is ``min(K_c, D_c)``, padded by :data:`~runtime.kernels.bounds.ROUND`.

**Exact farthest vertex.**  The chunks are visited by decreasing ``K_c``; each visited chunk is
skinned exactly (the one LBS kernel, :func:`runtime.kernels.skin._lbs`) and the farthest vertex so
far kept.  Once ``K_c`` is below the farthest distance found, no vertex of that chunk or of the
chunks after it can reach it, so the search stops: the result is the exact maximum over the whole
part, and its vertex the one :func:`runtime.kernels.skin.part_farthest` returns (the first of the
part's vertices at that distance: ties are broken by the position in the part's vertex list, and
a chunk is skipped only when its bound is strictly below the best squared distance, never a
candidate for a tie).  A NaN or a squared distance above 1e300 reads as infinitely far, as in
``part_farthest``; a chunk whose bound is NaN or too large for that test is always skinned.

Fast math: :data:`~runtime.kernels.config.FASTMATH_PROOF` (the results decide a proof).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .bounds import ROUND
from .config import FASTMATH_PROOF
from .skin import PARALLEL_WORK, _lbs

#: Vertices per chunk of the exact tier's search.
CHUNK_VERTS = 8


class ChunkData:
    """Per-part chunks of vertices (:func:`chunk_data`): ``part_chunks`` (P + 1,) into the
    chunks; ``pos_offsets`` (C + 1,) / ``pos`` (n,): each chunk's vertices as positions in the
    parts' vertex CSR (the vertex is ``part_vertices[pos]``); ``center`` (C, 3), ``radius`` (C,)
    the mesh-space ball; ``wabs``, ``wdev`` (C,) ``a_c`` and ``eps_c``; ``joint_offsets`` (C + 1,),
    ``joints``: the joints with a non-zero weight in the chunk, ``jwmax`` the largest |weight| of
    each (summed over a vertex's influences naming it); ``cpoints``, ``cji``, ``cjw``: the skin of
    the vertices ``part_vertices[pos]`` in that order (contiguous for the search)."""

    FIELDS = ("part_chunks", "pos_offsets", "pos", "center", "radius", "wabs", "wdev", "joint_offsets", "joints",
              "jwmax", "cpoints", "cji", "cjw")

    def __init__(self, **kw):
        for k in self.FIELDS:
            setattr(self, k, kw[k])

    def args(self):
        return tuple(getattr(self, k) for k in self.FIELDS)


def _morton_order(x):
    """Order of the points ``x`` (n, 3) along a Morton curve of their bounding box."""
    lo, hi = x.min(0), x.max(0)
    q = np.clip(((x - lo) / np.where(hi > lo, hi - lo, 1.0) * 1023).astype(np.int64), 0, 1023)
    code = np.zeros(len(x), np.int64)
    for bit in range(10):
        for a in range(3):
            code |= ((q[:, a] >> bit) & 1) << (3 * bit + a)
    return np.argsort(code, kind="stable")


def chunk_data(points, joint_indices, joint_weights, part_offsets, part_vertices, size=CHUNK_VERTS) -> ChunkData:
    pv_all = np.asarray(part_vertices, dtype=np.int64)
    with np.errstate(invalid="ignore", over="ignore"):  # a corrupt asset's NaN points: their chunks are never pruned
        out = _chunk_data(points, joint_indices, joint_weights, part_offsets, pv_all, size)
    vs = pv_all[out.pos]
    out.cpoints = np.ascontiguousarray(np.asarray(points)[vs], dtype=np.float32)
    out.cji = np.ascontiguousarray(np.asarray(joint_indices)[vs], dtype=np.int32)
    out.cjw = np.ascontiguousarray(np.asarray(joint_weights)[vs], dtype=np.float32)
    return out


def _chunk_data(points, joint_indices, joint_weights, part_offsets, part_vertices, size):
    """Chunks of every part's vertices and their bound data (module docstring): points (V, 3)
    float32 mesh space; joint_indices / joint_weights (V, k) (zero weights padding); the parts'
    vertex CSR ``part_offsets`` (P + 1,), ``part_vertices``."""
    pts = np.asarray(points, dtype=np.float64)
    ji = np.asarray(joint_indices, dtype=np.int64)
    jw = np.asarray(joint_weights, dtype=np.float64)
    poff = np.asarray(part_offsets, dtype=np.int64)
    pv = np.asarray(part_vertices, dtype=np.int64)
    part_chunks, pos_off, pos = [0], [0], []
    center, radius, wabs, wdev, j_off, joints, jwmax = [], [], [], [], [0], [], []
    for p in range(len(poff) - 1):
        lo, hi = int(poff[p]), int(poff[p + 1])
        if hi > lo:
            order = lo + _morton_order(pts[pv[lo:hi]])
            for s in range(0, hi - lo, size):
                ps = np.sort(order[s:s + size])
                vs = pv[ps]
                x = pts[vs]
                ctr = (x.min(0) + x.max(0)) / 2
                rad = np.sqrt(((x - ctr) ** 2).sum(1)).max()
                w = jw[vs]
                pos.extend(ps.tolist())
                pos_off.append(len(pos))
                center.append(ctr)
                radius.append(rad * (1 + 1e-9) + 1e-12 * (1 + np.abs(ctr).max() + rad))
                wabs.append(np.abs(w).sum(1).max() * (1 + 1e-12))
                wdev.append(np.abs(w.sum(1) - 1.0).max() * (1 + 1e-12) + 1e-15)
                a = ji[vs]
                js = np.unique(a[w != 0])
                joints.extend(js.tolist())
                jwmax.extend([np.where(a == b, np.abs(w), 0.0).sum(1).max() * (1 + 1e-12) for b in js])
                j_off.append(len(joints))
        part_chunks.append(len(pos_off) - 1)
    return ChunkData(part_chunks=np.array(part_chunks, np.int64), pos_offsets=np.array(pos_off, np.int64),
                     pos=np.array(pos, np.int64), center=np.array(center, np.float64).reshape(-1, 3),
                     radius=np.array(radius, np.float64), wabs=np.array(wabs, np.float64),
                     wdev=np.array(wdev, np.float64), joint_offsets=np.array(j_off, np.int64),
                     joints=np.array(joints, np.int64), jwmax=np.array(jwmax, np.float64), cpoints=None, cji=None,
                     cjw=None)


@njit(cache=True, inline="always", fastmath=FASTMATH_PROOF)
def _norm2_folded(m, f, j):
    """:func:`runtime.kernels.bounds._norm2` of the linear part of the folded transform
    ``m[f, j]`` (rows ``m[f, j, 4 r:4 r + 3]``), padded by :data:`ROUND`."""
    best = 0.0
    for a in range(3):
        row = 0.0
        for b in range(3):
            row += abs(m[f, j, a] * m[f, j, b] + m[f, j, 4 + a] * m[f, j, 4 + b] + m[f, j, 8 + a] * m[f, j, 8 + b])
        if row > best:
            best = row
    return math.sqrt(best) * (1.0 + ROUND)


@njit(cache=True, inline="always", fastmath=FASTMATH_PROOF)
def _norm2_diff(m, f, j, J):
    """:func:`_norm2_folded` of ``L(m[f, j]) - L(m[f, J])``."""
    best = 0.0
    for a in range(3):
        row = 0.0
        for b in range(3):
            g = 0.0
            for r in range(3):
                g += (m[f, j, 4 * r + a] - m[f, J, 4 * r + a]) * (m[f, j, 4 * r + b] - m[f, J, 4 * r + b])
            row += abs(g)
        if row > best:
            best = row
    return math.sqrt(best) * (1.0 + ROUND)


@njit(cache=True, inline="always", fastmath=FASTMATH_PROOF)
def _chunk_bound(f, c, J, m, cx, cy, cz, center, radius, wabs, wdev, joint_offsets, joints, jwmax):
    """``min(K_c, D_c)`` of chunk ``c`` (of a part of joint ``J``) at pose ``f`` of the folded
    transforms ``m`` about ``(cx, cy, cz)`` (module docstring); NaN reads as inf."""
    ox, oy, oz = center[c, 0], center[c, 1], center[c, 2]
    r = radius[c]
    jx = m[f, J, 0] * ox + m[f, J, 1] * oy + m[f, J, 2] * oz + m[f, J, 3]
    jy = m[f, J, 4] * ox + m[f, J, 5] * oy + m[f, J, 6] * oz + m[f, J, 7]
    jz = m[f, J, 8] * ox + m[f, J, 9] * oy + m[f, J, 10] * oz + m[f, J, 11]
    nJ = _norm2_folded(m, f, J)
    far = 0.0
    dsum = 0.0
    for k in range(joint_offsets[c], joint_offsets[c + 1]):
        j = joints[k]
        x = m[f, j, 0] * ox + m[f, j, 1] * oy + m[f, j, 2] * oz + m[f, j, 3]
        y = m[f, j, 4] * ox + m[f, j, 5] * oy + m[f, j, 6] * oz + m[f, j, 7]
        z = m[f, j, 8] * ox + m[f, j, 9] * oy + m[f, j, 10] * oz + m[f, j, 11]
        d = math.sqrt((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) + _norm2_folded(m, f, j) * r
        if not (d <= far):
            far = d if d == d else np.inf
        if j != J:
            dsum += jwmax[k] * (math.sqrt((x - jx) ** 2 + (y - jy) ** 2 + (z - jz) ** 2) + _norm2_diff(m, f, j, J) * r)
    cn = math.sqrt(cx * cx + cy * cy + cz * cz)
    kc = (wabs[c] * far + wdev[c] * cn) * (1.0 + ROUND)
    dc = (math.sqrt((jx - cx) ** 2 + (jy - cy) ** 2 + (jz - cz) ** 2) + nJ * r + dsum
          + wdev[c] * (math.sqrt(jx * jx + jy * jy + jz * jz) + nJ * r)) * (1.0 + ROUND)
    if not (kc == kc):
        kc = np.inf
    if not (dc == dc):
        dc = np.inf
    return min(kc, dc)


@njit(cache=True, inline="always", fastmath=FASTMATH_PROOF)
def _farthest_task(t, task_f, task_p, points, ji, jw, m, pverts, centers, part_joint, part_chunks, pos_offsets, pos,
                   center, radius, wabs, wdev, joint_offsets, joints, jwmax, cpoints, cji, cjw, out_d, out_v, out_skinned):
    f, p = task_f[t], task_p[t]
    c0, c1 = part_chunks[p], part_chunks[p + 1]
    if c1 == c0:
        out_d[t] = 0.0
        out_v[t] = -1
        out_skinned[t] = 0
        return
    cx, cy, cz = centers[f, p, 0], centers[f, p, 1], centers[f, p, 2]
    J = part_joint[p]
    kb = np.empty(c1 - c0)
    for c in range(c0, c1):
        kb[c - c0] = _chunk_bound(f, c, J, m, cx, cy, cz, center, radius, wabs, wdev, joint_offsets, joints, jwmax)
    order = np.argsort(-kb)
    buf = np.empty(pos_offsets[c1] - pos_offsets[c0])  # >= the largest chunk
    best2 = -1.0
    bpos = -1
    skinned = 0
    for n in range(c1 - c0):
        c = c0 + order[n]
        k = kb[order[n]]
        if k * k <= 1e300 and k * k < best2:  # no vertex of this chunk, or of the next, can reach it
            break
        i0, i1 = pos_offsets[c], pos_offsets[c + 1]
        for i in range(i0, i1):  # skin the chunk (no branch: the loop LLVM optimises best)
            x, y, z = _lbs(i, f, cpoints, cji, cjw, m)
            buf[i - i0] = (x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2
        for i in range(i0, i1):
            d2 = buf[i - i0]
            if not (d2 <= 1e300):  # NaN or inf: as far as it gets
                d2 = np.inf
            if d2 >= best2:
                q = pos[i]
                if d2 > best2 or q < bpos:
                    best2 = d2
                    bpos = q
        skinned += pos_offsets[c + 1] - pos_offsets[c]
    out_d[t] = math.sqrt(best2)
    out_v[t] = pverts[bpos]
    out_skinned[t] = skinned


@njit(cache=True, parallel=True, fastmath=FASTMATH_PROOF)
def _farthest_parallel(task_f, task_p, points, ji, jw, m, pverts, centers, part_joint, part_chunks, pos_offsets, pos,
                       center, radius, wabs, wdev, joint_offsets, joints, jwmax, cpoints, cji, cjw, out_d, out_v, out_skinned):
    """:func:`_farthest_task` for every task, threaded."""
    for t in prange(task_f.shape[0]):
        _farthest_task(t, task_f, task_p, points, ji, jw, m, pverts, centers, part_joint, part_chunks, pos_offsets, pos,
                       center, radius, wabs, wdev, joint_offsets, joints, jwmax, cpoints, cji, cjw, out_d, out_v, out_skinned)


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _farthest_serial(task_f, task_p, points, ji, jw, m, pverts, centers, part_joint, part_chunks, pos_offsets, pos,
                     center, radius, wabs, wdev, joint_offsets, joints, jwmax, cpoints, cji, cjw, out_d, out_v, out_skinned):
    """:func:`_farthest_parallel` on one thread (small jobs)."""
    for t in range(task_f.shape[0]):
        _farthest_task(t, task_f, task_p, points, ji, jw, m, pverts, centers, part_joint, part_chunks, pos_offsets, pos,
                       center, radius, wabs, wdev, joint_offsets, joints, jwmax, cpoints, cji, cjw, out_d, out_v, out_skinned)


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _chunk_bounds(m, centers, part_joint, chunk_part, center, radius, wabs, wdev, joint_offsets, joints, jwmax, out):
    """out (F, C) = :func:`_chunk_bound` of every chunk at every pose, about its part's centre."""
    for f in range(m.shape[0]):
        for c in range(center.shape[0]):
            p = chunk_part[c]
            out[f, c] = _chunk_bound(f, c, part_joint[p], m, centers[f, p, 0], centers[f, p, 1], centers[f, p, 2],
                                     center, radius, wabs, wdev, joint_offsets, joints, jwmax)


def chunk_bounds(m, centers, part_joint, chunks: ChunkData):
    """(F, C) the bound ``K_c`` of every chunk at every pose of the folded transforms ``m``
    (F, J, 12), about its part's centre ``centers`` (F, P, 3), ``part_joint`` (P,) each part's
    joint (the module docstring: ``min(K_c, D_c)``; what the
    search of :func:`farthest` prunes with)."""
    part = np.repeat(np.arange(len(chunks.part_chunks) - 1), np.diff(chunks.part_chunks)).astype(np.int64)
    out = np.empty((m.shape[0], len(chunks.radius)))
    _chunk_bounds(np.ascontiguousarray(m, dtype=np.float64), np.ascontiguousarray(centers, dtype=np.float64),
                  np.asarray(part_joint, dtype=np.int64), part, chunks.center, chunks.radius, chunks.wabs, chunks.wdev,
                  chunks.joint_offsets, chunks.joints, chunks.jwmax, out)
    return out


def farthest(points, ji, jw, m, part_offsets, part_vertices, part_joint, centers, todo, chunks: ChunkData):
    """For every (pose, part) pair of ``todo``, the exact farthest skinned vertex of the part from
    ``centers`` (what :func:`runtime.kernels.skin.part_farthest` returns, by the chunk search of
    the module docstring).

    Parameters (checked and converted by the caller, :class:`runtime.certify.Rig`)
    ----------
    points (V, 3) float32, ji (V, k) int32, jw (V, k) float32; m (F, J, 12) folded skinning
    transforms; part_offsets (P + 1,) int64, part_vertices (n,) int32; part_joint (P,) each part's
    joint; centers (F, P, 3) float64
    (same space as ``m``); todo (F, P) bool; chunks: :func:`chunk_data` of the same parts.

    Returns
    -------
    distance (F, P) float64 (NaN where not asked, inf for a NaN point, 0 for an empty part),
    vertex (F, P) int32 (-1 where not asked or empty), skinned: how many vertex-poses were skinned.
    """
    F, P = todo.shape
    d = np.full((F, P), np.nan)
    v = np.full((F, P), -1, dtype=np.int32)
    tf, tp = np.nonzero(todo)
    if len(tf) == 0:
        return d, v, 0
    tf, tp = tf.astype(np.int64), tp.astype(np.int64)
    od, ov, os_ = np.empty(len(tf)), np.empty(len(tf), np.int64), np.empty(len(tf), np.int64)
    work = int(np.diff(part_offsets)[tp].sum()) * ji.shape[1]
    kern = _farthest_parallel if work > PARALLEL_WORK else _farthest_serial
    kern(tf, tp, points, ji, jw, m, part_vertices, np.ascontiguousarray(centers, dtype=np.float64),
         np.asarray(part_joint, dtype=np.int64), *chunks.args(), od, ov, os_)
    d[tf, tp] = od
    v[tf, tp] = ov
    return d, v, int(os_.sum())
