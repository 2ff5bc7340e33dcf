"""The continuous certificate's levels B and C, compiled and batched: the per-vertex chord bound
of every open (part, sub-interval) node of one subdivision level in one kernel call.

:func:`runtime.certify.continuous` states the levels and why they hold; the per-vertex chord
bound is the one of :func:`runtime.kernels.interval.chord_tasks` (its readable numpy twin, kept
as the reference the tests compare against), in the notation of :mod:`runtime.kernels.bounds`:
for node ``n`` (part ``p`` of joint ``J``, sub-interval ``[a, b]`` of a sample interval, the
fraction ``f`` of it) and every vertex ``v`` of the part::

    U(v) = max(|y_v(a) - c_P|, |y_v(b) - c_P|) + sum_i |w_i(v)| (f^2 delta + pert)[j_i(v)]

bounds ``|y_v(tau) - c_P|`` for every ``tau`` in ``[a, b]`` (``y_v`` the vertex in ``J``'s space;
LBS is linear in the joint transforms, so the vertex strays from its chord by at most the
weighted strays of its copies, ``delta`` scaled by ``f^2`` on a sub-interval; the chord stays
within the larger end distance).  The node's bound is ``max_v U(v)`` padded by
:data:`~runtime.kernels.bounds.ROUND`; a NaN or a value above 1e300 reads as infinitely far.

What is batched and cached:

* :func:`pose_at`: the skeleton-space transforms of many times at once (UsdSkel's interpolation
  by the runtime's port :func:`runtime.kernels.pose.locals_at`, slerp / lerp / half lerp exactly
  as the certificate's other paths, then one composition kernel) and the skinning transforms
  ``skel @ inv_bind @ geom_bind`` (``inv_bind @ geom_bind`` computed once per rig by the caller);
* :func:`chord_nodes`: the J-space transforms of a node's two ends (``inv(skel_J) @ skin``, the
  affine inverse by the adjugate, only for the joints that influence the part) and the bound
  above for every node, threaded over the nodes on large levels.  Inputs are checked once by
  the caller (:class:`runtime.certify.Rig`), never inside the loop.

Fast math: :data:`~runtime.kernels.config.FASTMATH_PROOF` (the results decide a proof; NaN and
inf keep their IEEE meaning).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .bounds import ROUND
from .config import FASTMATH_PROOF
from .interval import _inv_affine_into
from .pose import compose, locals_at
from .skin import PARALLEL_WORK, _lbs


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _compose_many(local, parents, topo, ibg, skel, skin):
    """skel (T, J, 4, 4) = the joint-local transforms ``local`` composed parents first;
    skin (T, J, 4, 4) = ``skel @ ibg`` (``ibg`` (J, 4, 4) = ``inv_bind @ geom_bind``)."""
    T, J = local.shape[0], local.shape[1]
    for t in range(T):
        for n in range(J):
            j = topo[n]
            p = parents[j]
            if p < 0:
                for r in range(4):
                    for c in range(4):
                        skel[t, j, r, c] = local[t, j, r, c]
            else:
                for r in range(4):
                    a0, a1, a2, a3 = skel[t, p, r, 0], skel[t, p, r, 1], skel[t, p, r, 2], skel[t, p, r, 3]
                    for c in range(4):
                        skel[t, j, r, c] = (a0 * local[t, j, 0, c] + a1 * local[t, j, 1, c]
                                            + a2 * local[t, j, 2, c] + a3 * local[t, j, 3, c])
            for r in range(4):
                a0, a1, a2, a3 = skel[t, j, r, 0], skel[t, j, r, 1], skel[t, j, r, 2], skel[t, j, r, 3]
                for c in range(4):
                    skin[t, j, r, c] = a0 * ibg[j, 0, c] + a1 * ibg[j, 1, c] + a2 * ibg[j, 2, c] + a3 * ibg[j, 3, c]


#: Below this many (time, joint) transforms :func:`pose_at` composes in numpy (the same products).
COMPOSE_KERNEL_MIN = 4096


def pose_at(clip, times, rest_local, parents, topo, ibg):
    """Skeleton-space (T, J, 4, 4) and skinning (T, J, 4, 4) transforms of ``clip`` at ``times``
    (T,), interpolated as UsdSkel does (:func:`runtime.kernels.pose.locals_at`, its kernel)."""
    local = locals_at(clip, times, rest_local)  # the kernel on large batches (its own size rule)
    T, J = local.shape[:2]
    if T * J < COMPOSE_KERNEL_MIN:  # numpy: nothing to compile for a demo-sized asset
        skel = compose(local, parents, topo)
        return skel, skel @ ibg
    skel = np.empty((T, J, 4, 4))
    skin = np.empty((T, J, 4, 4))
    _compose_many(local, parents, topo, ibg, skel, skin)
    return skel, skin


@njit(cache=True, inline="always", fastmath=FASTMATH_PROOF)
def _chord_node(n, points, ji, jw, poff, pverts, part_joint, pj_offsets, pj_joint, centers, skel, skin,
                node_part, node_ta, node_tb, node_row, node_scale, drow, prow, out_u, out_vu, out_d0, out_v0,
                out_d1, out_v1, m, inv, x):
    """Node ``n`` of :func:`chord_nodes`; ``m`` (2, J, 12), ``inv`` (4, 4), ``x`` (J,) scratch."""
    p = node_part[n]
    lo, hi = poff[p], poff[p + 1]
    if hi == lo:  # nothing to hold
        out_u[n] = -1.0
        out_d0[n] = -1.0
        out_d1[n] = -1.0
        out_vu[n] = -1
        out_v0[n] = -1
        out_v1[n] = -1
        return
    J = part_joint[p]
    row = node_row[n]
    sc = node_scale[n]
    for e in range(2):
        t = node_ta[n] if e == 0 else node_tb[n]
        _inv_affine_into(skel[t, J], inv)
        for k in range(pj_offsets[p], pj_offsets[p + 1]):
            b = pj_joint[k]
            for r in range(3):
                i0, i1, i2, i3 = inv[r, 0], inv[r, 1], inv[r, 2], inv[r, 3]
                for c in range(4):
                    m[e, b, 4 * r + c] = (i0 * skin[t, b, 0, c] + i1 * skin[t, b, 1, c] + i2 * skin[t, b, 2, c]
                                          + i3 * skin[t, b, 3, c])
    for k in range(pj_offsets[p], pj_offsets[p + 1]):
        b = pj_joint[k]
        x[b] = sc * drow[row, b] + prow[row, b]
    cx, cy, cz = centers[p, 0], centers[p, 1], centers[p, 2]
    bu, b0, b1 = -1.0, -1.0, -1.0
    vu = v0 = v1 = np.int64(pverts[lo])
    for i in range(lo, hi):
        v = np.int64(pverts[i])
        ax, ay, az = _lbs(v, 0, points, ji, jw, m)
        d0 = math.sqrt((ax - cx) ** 2 + (ay - cy) ** 2 + (az - cz) ** 2)
        if not (d0 <= 1e300):  # NaN reads as far
            d0 = np.inf
        bx, by, bz = _lbs(v, 1, points, ji, jw, m)
        d1 = math.sqrt((bx - cx) ** 2 + (by - cy) ** 2 + (bz - cz) ** 2)
        if not (d1 <= 1e300):
            d1 = np.inf
        dev = 0.0
        for q in range(ji.shape[1]):
            w = np.float64(jw[v, q])
            if w != 0.0:
                dev += abs(w) * x[ji[v, q]]
        u = max(d0, d1) + dev
        if not (u <= 1e300):
            u = np.inf
        if u > bu:
            bu, vu = u, v
        if d0 > b0:
            b0, v0 = d0, v
        if d1 > b1:
            b1, v1 = d1, v
    out_u[n] = bu * (1.0 + ROUND)
    out_vu[n] = vu
    out_d0[n] = b0
    out_v0[n] = v0
    out_d1[n] = b1
    out_v1[n] = v1


@njit(cache=True, parallel=True, fastmath=FASTMATH_PROOF)
def _chord_nodes_parallel(points, ji, jw, poff, pverts, part_joint, pj_offsets, pj_joint, centers, skel, skin,
                          node_part, node_ta, node_tb, node_row, node_scale, drow, prow, out_u, out_vu, out_d0,
                          out_v0, out_d1, out_v1):
    """:func:`_chord_node` for every node, threaded over the nodes."""
    J = skel.shape[1]
    for n in prange(node_part.shape[0]):
        _chord_node(n, points, ji, jw, poff, pverts, part_joint, pj_offsets, pj_joint, centers, skel, skin,
                    node_part, node_ta, node_tb, node_row, node_scale, drow, prow, out_u, out_vu, out_d0, out_v0,
                    out_d1, out_v1, np.zeros((2, J, 12)), np.empty((4, 4)), np.zeros(J))


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _chord_nodes_serial(points, ji, jw, poff, pverts, part_joint, pj_offsets, pj_joint, centers, skel, skin,
                        node_part, node_ta, node_tb, node_row, node_scale, drow, prow, out_u, out_vu, out_d0,
                        out_v0, out_d1, out_v1):
    """:func:`_chord_nodes_parallel` on one thread (small levels)."""
    J = skel.shape[1]
    m = np.zeros((2, J, 12))
    inv = np.empty((4, 4))
    x = np.zeros(J)
    for n in range(node_part.shape[0]):
        _chord_node(n, points, ji, jw, poff, pverts, part_joint, pj_offsets, pj_joint, centers, skel, skin,
                    node_part, node_ta, node_tb, node_row, node_scale, drow, prow, out_u, out_vu, out_d0, out_v0,
                    out_d1, out_v1, m, inv, x)


def chord_nodes(points, ji, jw, poff, pverts, part_joint, pj_offsets, pj_joint, centers, skel, skin, node_part,
                node_ta, node_tb, node_row, node_scale, drow, prow):
    """The per-vertex chord bound (module docstring) of every node.

    Parameters (already checked and converted by the caller: :class:`runtime.certify.Rig`)
    ----------
    points (V, 3) float32, ji (V, k) int32, jw (V, k) float32: the skin (zero weights padding);
    poff (P + 1,) int64, pverts (sum,) int32: each part's vertices (CSR); part_joint (P,) int64;
    pj_offsets (P + 1,), pj_joint (M,) int64: the joints influencing each part
    (:class:`~runtime.kernels.bounds.BoundData`); centers (P, 3) float64 J-space centres;
    skel, skin (T, J, 4, 4) float64: skeleton-space and skinning transforms at the level's times
    (:func:`pose_at`); node_part, node_ta, node_tb, node_row (N,) int64: each node's part, the
    rows of its two end times in ``skel``, its row of ``drow`` / ``prow``; node_scale (N,) the
    square of its fraction of the sample interval; drow, prow (R, J) float64: per (interval, part)
    the chord deviation ``delta`` and the half-precision rounding ``pert`` of each joint's copy
    (0 for the part's own joint and for joints outside the part).

    Returns
    -------
    (N,) arrays: the bound ``max_v U(v)`` and its vertex, the largest end distances and their
    vertices (-1 for an empty part).
    """
    N = len(node_part)
    out_u, out_d0, out_d1 = np.empty(N), np.empty(N), np.empty(N)
    out_vu, out_v0, out_v1 = (np.empty(N, np.int64) for _ in range(3))
    if N == 0:
        return out_u, out_vu, out_d0, out_v0, out_d1, out_v1
    sizes = np.diff(poff)[node_part]
    work = int(sizes.sum()) * ji.shape[1] * 2
    kern = _chord_nodes_parallel if work > PARALLEL_WORK // 4 else _chord_nodes_serial
    kern(points, ji, jw, poff, pverts, part_joint, pj_offsets, pj_joint, centers, skel, skin, node_part, node_ta,
         node_tb, node_row, node_scale, drow, prow, out_u, out_vu, out_d0, out_v0, out_d1, out_v1)
    return out_u, out_vu, out_d0, out_v0, out_d1, out_v1
