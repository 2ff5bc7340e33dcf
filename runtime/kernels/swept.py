"""The continuous contact kernel of :mod:`runtime.sweep`: a sphere moving along a segment against
triangles whose corners move along their chords, each triangle inflated by a bound of how far the
true (skinned) triangle strays from the chord triangle.

Conservative advancement (Mirtich 1996; Tang, Kim & Manocha 2009).  Over one segment of the body's
motion, with time ``tau`` in [0, 1], the sphere's centre is ``c(tau) = c0 + tau (c1 - c0)`` and a
triangle's corners are ``x_i(tau) = xa_i + tau (xb_i - xa_i)`` (the chord triangle ``T(tau)``).
The true triangle is within ``dev`` (Hausdorff) of ``T(tau)``: each of its points is a barycentric
combination of corners each within ``dev`` of the chord corners.  So a true contact at ``tau``
(distance <= ``radius``) implies ``f(tau) = dist(c(tau), T(tau)) - radius - dev <= 0``.

``f`` is Lipschitz in ``tau`` with constant ``L = max_i |(xb_i - xa_i) - (c1 - c0)|``: for fixed
barycentric weights ``beta`` the distance ``|c - sum beta_i x_i|`` changes at most at the speed
``|c' - sum beta_i x_i'| <= max_i |c' - x_i'|`` (a convex combination), and a minimum of
L-Lipschitz functions is L-Lipschitz.  Hence no contact can occur before ``tau + f(tau) / L``, and
stepping so (conservative advancement) never steps over a contact.  The kernel stops when ``f <=
tol`` (the contact is reported up to ``tol / L`` early), or after ``max_iter`` steps at the current
``tau`` (early too): it may report a contact slightly early, never late, never miss one.

Fast math: :data:`~runtime.kernels.config.FASTMATH_OFF` (a query kernel).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .config import FASTMATH_OFF, FASTMATH_PROOF
from .triangle import closest_on_triangle


@njit(cache=True, fastmath=FASTMATH_OFF)
def _sweep_segment(pa, pb, tris, faces, chunk_offsets, part_chunks, chunk_vert_offsets, chunk_verts, near, pad,
                   skip, c0, c1, radius, tol, max_iter, limit, out):
    """First contact of the sphere ``(c(tau), radius)`` with the inflated chord triangles of the
    parts ``near`` over one segment.

    pa, pb : (V, 3) float32 posed points at the segment's ends (the corners of the near parts'
    faces skinned at both); tris (F, 3); faces, chunk_offsets, part_chunks, chunk_vert_offsets,
    chunk_verts: the asset's CSR of each part's chunks of faces and each chunk's vertices
    (:class:`runtime.asset.ColliderData`); near : (N,) parts; pad : (P,) each part's inflation;
    skip : (F,) bool faces left out; c0, c1 : (3,) the centre at the ends; radius, tol : float;
    max_iter : int; limit : float, only contacts before it (in tau) are looked for (0: none, the
    reach alone).

    A chunk is skipped when the box of its vertices at both ends, grown by its part's ``pad``
    and ``radius``, misses the box of the centre's path (every point of the chunk's chord
    triangles lies in the box of their corners at both ends; the true ones within ``pad``); so is
    a face, by the same test on its corners.

    Returns (face, part) of the first contact (-1, -1: none before ``limit``) and writes ``out``
    (11,): tau, barycentric (3), point on ``T(tau)`` (3), unit normal of ``T(tau)``
    (counter-clockwise = outward; the direction to the centre for a degenerate triangle) (3),
    and ``reach``: over the faces not skipped by the box tests, the largest ``L + 4 pad`` (a
    bound of any of their points' motion relative to the centre, per unit tau: the chord's plus
    ``4 pad`` for the deviation's slope, ``|e'| <= sup|e''| / 2 = 4 D``)."""
    vcx, vcy, vcz = c1[0] - c0[0], c1[1] - c0[1], c1[2] - c0[2]
    lo = np.empty(3)
    hi = np.empty(3)
    for a in range(3):
        lo[a] = min(c0[a], c1[a])
        hi[a] = max(c0[a], c1[a])
    tri = np.empty((3, 3))
    cp = np.empty(6)
    bmin = np.empty(3)
    bmax = np.empty(3)
    best = limit
    found = -1
    fpart = -1
    reach = 0.0
    for ni in range(near.shape[0]):
        p = near[ni]
        g = radius + pad[p]
        for c in range(part_chunks[p], part_chunks[p + 1]):
            for a in range(3):
                bmin[a] = np.inf
                bmax[a] = -np.inf
            for i in range(chunk_vert_offsets[c], chunk_vert_offsets[c + 1]):
                q = chunk_verts[i]
                for a in range(3):
                    x = np.float64(pa[q, a])
                    y = np.float64(pb[q, a])
                    bmin[a] = min(bmin[a], x, y)
                    bmax[a] = max(bmax[a], x, y)
            miss = False
            for a in range(3):
                if bmax[a] + g < lo[a] or bmin[a] - g > hi[a]:
                    miss = True
            if miss:
                continue
            for fi in range(chunk_offsets[c], chunk_offsets[c + 1]):
                f = faces[fi]
                if skip[f]:
                    continue
                miss = False
                for a in range(3):
                    mn = np.inf
                    mx = -np.inf
                    for i in range(3):
                        x = np.float64(pa[tris[f, i], a])
                        y = np.float64(pb[tris[f, i], a])
                        mn = min(mn, x, y)
                        mx = max(mx, x, y)
                    if mx + g < lo[a] or mn - g > hi[a]:
                        miss = True
                if miss:
                    continue
                L = 0.0
                for i in range(3):
                    v = tris[f, i]
                    dx = np.float64(pb[v, 0]) - np.float64(pa[v, 0]) - vcx
                    dy = np.float64(pb[v, 1]) - np.float64(pa[v, 1]) - vcy
                    dz = np.float64(pb[v, 2]) - np.float64(pa[v, 2]) - vcz
                    L = max(L, math.sqrt(dx * dx + dy * dy + dz * dz))
                reach = max(reach, L + 4.0 * pad[p])
                tau = 0.0
                it = 0
                while tau < best:
                    for i in range(3):
                        v = tris[f, i]
                        for a in range(3):
                            x = np.float64(pa[v, a])
                            tri[i, a] = x + tau * (np.float64(pb[v, a]) - x)
                    px = c0[0] + tau * vcx
                    py = c0[1] + tau * vcy
                    pz = c0[2] + tau * vcz
                    closest_on_triangle(px, py, pz, tri, 0, 1, 2, cp)
                    dx, dy, dz = px - cp[0], py - cp[1], pz - cp[2]
                    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
                    fv = dist - g
                    it += 1
                    if fv <= tol or it > max_iter:
                        best = tau
                        found = f
                        fpart = p
                        out[0] = tau
                        for a in range(3):
                            out[1 + a] = cp[3 + a]
                            out[4 + a] = cp[a]
                        e1x, e1y, e1z = tri[1, 0] - tri[0, 0], tri[1, 1] - tri[0, 1], tri[1, 2] - tri[0, 2]
                        e2x, e2y, e2z = tri[2, 0] - tri[0, 0], tri[2, 1] - tri[0, 1], tri[2, 2] - tri[0, 2]
                        nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
                        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
                        if nn > 0.0:
                            out[7], out[8], out[9] = nx / nn, ny / nn, nz / nn
                        elif dist > 0.0:
                            out[7], out[8], out[9] = dx / dist, dy / dist, dz / dist
                        else:
                            out[7], out[8], out[9] = 0.0, 0.0, 0.0
                        break
                    if L <= 0.0:
                        break  # nothing moves relative to the centre: never closer than now
                    tau += fv / L
    out[10] = reach
    return found, fpart


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _part_deviation(delta, pert, pj_offsets, pj_wmax, part_wabs, w, out):
    """``out[i, p] = w min(a_P max_b (delta + pert)[i, b], sum_b wmax_b (delta + pert)[i, b])``
    over part ``p``'s (part, joint) pairs ``b`` (:mod:`runtime.sweep` derives it), padded by
    ``1e-9`` relative; 0 for a part without pairs; a NaN reads as unbounded (inf)."""
    I = delta.shape[0]
    P = pj_offsets.shape[0] - 1
    for i in range(I):
        for p in range(P):
            mx = 0.0
            sm = 0.0
            bad = False
            for k in range(pj_offsets[p], pj_offsets[p + 1]):
                x = delta[i, k] + pert[i, k]
                if not (x >= 0.0):
                    bad = True
                mx = max(mx, x)
                sm += pj_wmax[k] * x
            v = min(part_wabs[p] * mx, sm) * w * (1.0 + 1e-9)
            out[i, p] = math.inf if (bad or not (v >= 0.0)) else v
