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

from .config import FASTMATH_OFF
from .triangle import closest_on_triangle


@njit(cache=True, fastmath=FASTMATH_OFF)
def _first_contact(xa, xb, dev, c0, c1, radius, tol, max_iter, limit, out):
    """First contact of the sphere ``(c(tau), radius)`` with the inflated chord triangles.

    xa, xb : (K, 3, 3) float64 corners at the segment's ends; dev : (K,) inflation of each;
    c0, c1 : (3,) the centre at the ends; radius, tol : float; max_iter : int; limit : float, only
    contacts before it are looked for (1.0 for the whole segment).

    Returns the index of the first triangle touched (-1: none before ``limit``) and writes
    ``out`` (11,): tau, barycentric (3), point on ``T(tau)`` (3), unit normal of ``T(tau)``
    (counter-clockwise = outward; the direction to the centre for a degenerate triangle) (3),
    and ``reach``: over the triangles whose swept boxes meet the sphere's, the largest
    ``L + 4 dev`` (a bound of any of their points' motion relative to the centre, per unit tau:
    the chord's plus ``4 dev`` for the deviation's slope, ``|e'| <= sup|e''| / 2 = 4 dev``)."""
    K = xa.shape[0]
    vcx, vcy, vcz = c1[0] - c0[0], c1[1] - c0[1], c1[2] - c0[2]
    lo = np.empty(3)
    hi = np.empty(3)
    for a in range(3):
        lo[a] = min(c0[a], c1[a])
        hi[a] = max(c0[a], c1[a])
    tri = np.empty((3, 3))
    cp = np.empty(6)
    best = limit
    found = -1
    reach = 0.0
    for k in range(K):
        pad = radius + dev[k]
        skip = False
        for a in range(3):
            mn = min(xa[k, 0, a], xa[k, 1, a], xa[k, 2, a], xb[k, 0, a], xb[k, 1, a], xb[k, 2, a]) - pad
            mx = max(xa[k, 0, a], xa[k, 1, a], xa[k, 2, a], xb[k, 0, a], xb[k, 1, a], xb[k, 2, a]) + pad
            if mx < lo[a] or mn > hi[a]:
                skip = True
        if skip:
            continue
        L = 0.0
        for i in range(3):
            dx = xb[k, i, 0] - xa[k, i, 0] - vcx
            dy = xb[k, i, 1] - xa[k, i, 1] - vcy
            dz = xb[k, i, 2] - xa[k, i, 2] - vcz
            L = max(L, math.sqrt(dx * dx + dy * dy + dz * dz))
        reach = max(reach, L + 4.0 * dev[k])
        tau = 0.0
        it = 0
        while tau < best:
            for i in range(3):
                for a in range(3):
                    tri[i, a] = xa[k, i, a] + tau * (xb[k, i, a] - xa[k, i, a])
            px = c0[0] + tau * vcx
            py = c0[1] + tau * vcy
            pz = c0[2] + tau * vcz
            closest_on_triangle(px, py, pz, tri, 0, 1, 2, cp)
            dx, dy, dz = px - cp[0], py - cp[1], pz - cp[2]
            f = math.sqrt(dx * dx + dy * dy + dz * dz) - pad
            it += 1
            if f <= tol or it > max_iter:
                best = tau
                found = k
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
                else:
                    d = math.sqrt(dx * dx + dy * dy + dz * dz)
                    if d > 0.0:
                        out[7], out[8], out[9] = dx / d, dy / d, dz / d
                    else:
                        out[7], out[8], out[9] = 0.0, 0.0, 0.0
                break
            if L <= 0.0:
                break  # nothing moves relative to the centre: never closer than now
            tau += f / L
    out[10] = reach
    return found
