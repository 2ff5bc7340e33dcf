"""The two triangle primitives of the project's queries, shared by the runtime's query kernels
(:mod:`runtime.kernels.query`) and the import's surface distance
(:mod:`pipeline.geometry._distance_kernels`): one copy of each.

* :func:`ray_triangle`: Möller-Trumbore (1997) on scalars, both sides;
* :func:`closest_on_triangle`: Ericson's ClosestPtPointTriangle (Real-Time Collision Detection
  5.1.5) with barycentrics, and the nearest edge point of a degenerate (collinear) triangle.

Both are inlined into their callers (``inline="always"``); a caller that calls one from many
places may wrap it in a small kernel of its own so it is inlined once (compile time).  Their readable
numpy references, written on purpose by another route, are ``ray_triangles`` and
``closest_point_on_triangles`` in ``tests/references/naive_queries.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .config import FASTMATH_OFF


@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
def ray_triangle(ox, oy, oz, dx, dy, dz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Möller-Trumbore on scalars, both sides: (t, u, v) or t = inf on a miss (u, v weights of
    the 2nd and 3rd corner). Scalars only: array arguments would cost refcounting per call."""
    e1x = bx - ax
    e1y = by - ay
    e1z = bz - az
    e2x = cx - ax
    e2y = cy - ay
    e2z = cz - az
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    if det == 0.0 or not math.isfinite(det):
        return np.inf, 0.0, 0.0
    inv = 1.0 / det
    sx = ox - ax
    sy = oy - ay
    sz = oz - az
    u = (sx * px + sy * py + sz * pz) * inv
    if u < 0.0 or u > 1.0:
        return np.inf, 0.0, 0.0
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    if v < 0.0 or u + v > 1.0:
        return np.inf, 0.0, 0.0
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    if t < 0.0:
        return np.inf, 0.0, 0.0
    return t, u, v


@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
def closest_on_triangle(px, py, pz, points, ia, ib, ic, out):
    """Ericson's ClosestPtPointTriangle (Real-Time Collision Detection 5.1.5), with barycentrics.

    out[:3] closest point, out[3:6] barycentric (weights of vertices ia, ib, ic)."""
    ax, ay, az = np.float64(points[ia, 0]), np.float64(points[ia, 1]), np.float64(points[ia, 2])
    bx, by, bz = np.float64(points[ib, 0]), np.float64(points[ib, 1]), np.float64(points[ib, 2])
    cx, cy, cz = np.float64(points[ic, 0]), np.float64(points[ic, 1]), np.float64(points[ic, 2])
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    u = 1.0
    v = 0.0
    w = 0.0
    done = False
    if d1 <= 0.0 and d2 <= 0.0:  # vertex region A
        done = True
    if not done:
        bpx, bpy, bpz = px - bx, py - by, pz - bz
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        if d3 >= 0.0 and d4 <= d3:  # vertex region B
            u, v, w = 0.0, 1.0, 0.0
            done = True
    if not done:
        vc = d1 * d4 - d3 * d2
        if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0 and d1 - d3 > 0.0:  # edge AB
            t = d1 / (d1 - d3)
            u, v, w = 1.0 - t, t, 0.0
            done = True
    if not done:
        cpx, cpy, cpz = px - cx, py - cy, pz - cz
        d5 = abx * cpx + aby * cpy + abz * cpz
        d6 = acx * cpx + acy * cpy + acz * cpz
        if d6 >= 0.0 and d5 <= d6:  # vertex region C
            u, v, w = 0.0, 0.0, 1.0
            done = True
    if not done:
        vb = d5 * d2 - d1 * d6
        if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0 and d2 - d6 > 0.0:  # edge AC
            t = d2 / (d2 - d6)
            u, v, w = 1.0 - t, 0.0, t
            done = True
    if not done:
        va = d3 * d6 - d5 * d4
        e0 = d4 - d3
        e1 = d5 - d6
        if va <= 0.0 and e0 >= 0.0 and e1 >= 0.0 and e0 + e1 > 0.0:  # edge BC
            t = e0 / (e0 + e1)
            u, v, w = 0.0, 1.0 - t, t
            done = True
    if not done:
        den = va + vb + vc
        if den > 0.0:  # face region
            v = vb / den
            w = vc / den
            u = 1.0 - v - w
        else:  # degenerate (collinear) triangle: nearest of the three edges
            bestd = np.inf
            for e in range(3):
                if e == 0:
                    sx, sy, sz, ex, ey, ez = ax, ay, az, bx, by, bz
                elif e == 1:
                    sx, sy, sz, ex, ey, ez = bx, by, bz, cx, cy, cz
                else:
                    sx, sy, sz, ex, ey, ez = cx, cy, cz, ax, ay, az
                lx, ly, lz = ex - sx, ey - sy, ez - sz
                ll = lx * lx + ly * ly + lz * lz
                t = 0.0
                if ll > 0.0:
                    t = min(1.0, max(0.0, ((px - sx) * lx + (py - sy) * ly + (pz - sz) * lz) / ll))
                qx, qy, qz = sx + t * lx - px, sy + t * ly - py, sz + t * lz - pz
                dd = qx * qx + qy * qy + qz * qz
                if dd < bestd:
                    bestd = dd
                    if e == 0:
                        u, v, w = 1.0 - t, t, 0.0
                    elif e == 1:
                        u, v, w = 0.0, 1.0 - t, t
                    else:
                        u, v, w = t, 0.0, 1.0 - t
    out[0] = u * ax + v * bx + w * cx
    out[1] = u * ay + v * by + w * cy
    out[2] = u * az + v * bz + w * cz
    out[3] = u
    out[4] = v
    out[5] = w
