"""The character controller's kernels (:mod:`runtime.controller`, behind its public wrappers
``resolve_push`` and ``carry_point`` and its step): summarising a sphere's contacts into one
resolving push, carrying a point with a moving surface frame, and the small vector helpers of a
step.  Their readable numpy references are ``naive_push``, ``naive_carry`` and ``naive_along`` in
``tests/references/naive_queries.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .config import FASTMATH_OFF

#: A contact counts towards a push only when its normal is within ~78 degrees of the push.
_MIN_COS = 0.2


@njit(cache=True, fastmath=FASTMATH_OFF)
def _summarize(normal, depth, skin, tol, up, cos_slope, cap, ground, out):
    """Summarise the contacts of a sphere queried with radius ``r + skin``.

    normal (C, 3) unit, depth (C,) against ``r + skin`` (so ``depth - skin`` is the penetration
    at the radius), up (3,) unit, ground (C,) bool out: normal within the slope of up.
    out (12,) float64: [0:3] the push that resolves the penetrating contacts (zeros when the
    deepest is within ``tol``): direction the penetration-weighted mean normal u, length
    max(pen_i / (n_i . u)) over penetrating contacts with n_i . u > _MIN_COS, at most ``cap``;
    [3] deepest penetration (-inf when C = 0); [4] its index (-1); [5:8] unit mean normal of
    all contacts; [8:11] unit mean normal of the ground contacts; [11] ground count."""
    C = normal.shape[0]
    wx = wy = wz = 0.0
    mx = my = mz = 0.0
    gx = gy = gz = 0.0
    ng = 0
    pen_max = -np.inf
    deepest = -1
    for i in range(C):
        nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
        p = depth[i] - skin
        if p > pen_max:
            pen_max = p
            deepest = i
        if p > 0.0:
            wx += p * nx
            wy += p * ny
            wz += p * nz
        mx += nx
        my += ny
        mz += nz
        g = nx * up[0] + ny * up[1] + nz * up[2] >= cos_slope
        ground[i] = g
        if g:
            gx += nx
            gy += ny
            gz += nz
            ng += 1
    px = py = pz = 0.0
    ln = math.sqrt(wx * wx + wy * wy + wz * wz)
    if pen_max > tol and ln > 0.0:
        ux, uy, uz = wx / ln, wy / ln, wz / ln
        s = 0.0
        for i in range(C):
            p = depth[i] - skin
            if p > 0.0:
                c = normal[i, 0] * ux + normal[i, 1] * uy + normal[i, 2] * uz
                if c > _MIN_COS and p / c > s:
                    s = p / c
        s = min(s, cap)
        px, py, pz = ux * s, uy * s, uz * s
    out[0], out[1], out[2] = px, py, pz
    out[3] = pen_max
    out[4] = deepest
    ln = math.sqrt(mx * mx + my * my + mz * mz)
    if ln > 0.0:
        mx, my, mz = mx / ln, my / ln, mz / ln
    out[5], out[6], out[7] = mx, my, mz
    ln = math.sqrt(gx * gx + gy * gy + gz * gz)
    if ln > 0.0:
        gx, gy, gz = gx / ln, gy / ln, gz / ln
    out[8], out[9], out[10] = gx, gy, gz
    out[11] = ng


@njit(cache=True, fastmath=FASTMATH_OFF)
def _carry(pos, f0, f1, dt, out, vel):
    """Carry ``pos`` (3,) with a surface frame: f0, f1 (6,) are the frames (centroid, unit mean
    normal) before and after.  out (3,) = c1 + R (pos - c0), R the least rotation taking n0 to
    n1 (Rodrigues with w = n0 x n1, c = n0 . n1: R v = c v + w x v + w (w . v) / (1 + c));
    translation only when a normal is zero or they are (nearly) opposite.  vel (3,) = (c1 - c0)
    / dt; returns its length."""
    vx, vy, vz = pos[0] - f0[0], pos[1] - f0[1], pos[2] - f0[2]
    c = f0[3] * f1[3] + f0[4] * f1[4] + f0[5] * f1[5]
    ok = (f0[3] * f0[3] + f0[4] * f0[4] + f0[5] * f0[5]) > 0.5 and \
        (f1[3] * f1[3] + f1[4] * f1[4] + f1[5] * f1[5]) > 0.5
    if ok and c > -0.99:
        wx = f0[4] * f1[5] - f0[5] * f1[4]
        wy = f0[5] * f1[3] - f0[3] * f1[5]
        wz = f0[3] * f1[4] - f0[4] * f1[3]
        k = (wx * vx + wy * vy + wz * vz) / (1.0 + c)
        rx = c * vx + (wy * vz - wz * vy) + wx * k
        ry = c * vy + (wz * vx - wx * vz) + wy * k
        rz = c * vz + (wx * vy - wy * vx) + wz * k
        vx, vy, vz = rx, ry, rz
    out[0], out[1], out[2] = f1[0] + vx, f1[1] + vy, f1[2] + vz
    s2 = 0.0
    for k in range(3):
        vel[k] = (f1[k] - f0[k]) / dt
        s2 += vel[k] * vel[k]
    return math.sqrt(s2)


@njit(cache=True, fastmath=FASTMATH_OFF)
def _tangential(a, b, c, normal):
    """Length of the part of ``a - b - c`` (3,) across unit ``normal``: the slip."""
    x, y, z = a[0] - b[0] - c[0], a[1] - b[1] - c[1], a[2] - b[2] - c[2]
    d = x * normal[0] + y * normal[1] + z * normal[2]
    x, y, z = x - d * normal[0], y - d * normal[1], z - d * normal[2]
    return math.sqrt(x * x + y * y + z * z)


@njit(cache=True, fastmath=FASTMATH_OFF)
def _length(v):
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


@njit(cache=True, fastmath=FASTMATH_OFF)
def _along(move, normal, speed, out):
    """out (3,): ``move`` projected onto the plane of unit ``normal``, rescaled to keep its
    length, times ``speed`` (zeros when move is along the normal or zero)."""
    d = move[0] * normal[0] + move[1] * normal[1] + move[2] * normal[2]
    tx, ty, tz = move[0] - d * normal[0], move[1] - d * normal[1], move[2] - d * normal[2]
    lt = math.sqrt(tx * tx + ty * ty + tz * tz)
    lm = math.sqrt(move[0] * move[0] + move[1] * move[1] + move[2] * move[2])
    s = speed * lm / lt if lt > 1e-12 * max(lm, 1e-300) else 0.0
    out[0], out[1], out[2] = tx * s, ty * s, tz * s
