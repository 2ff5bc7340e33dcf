"""Numba kernels of the runtime (private, ``_``-prefixed, behind the validating wrappers in
:mod:`runtime.collider`). Each has a slow readable numpy reference in ``tests/test_runtime_naive.py``.

Conventions (USD's): matrices are row-vector ``(4, 4) float64``, a point transforms as
``[x, y, z, 1] @ M``; quaternions are stored ``(x, y, z, w)`` as pxr hands them to numpy.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# -- joint transforms (UsdSkel.AnimQuery + SkeletonQuery, any time) ------------------------------


@njit(cache=True, inline="always")
def _bracket(times, t):
    """Sample index ``i`` and weight ``a`` so the value at ``t`` is ``lerp(v[i], v[i+1], a)``;
    held (clamped) outside the sampled range, exact on a sample (``a == 0``)."""
    n = times.shape[0]
    if n == 1 or t <= times[0]:
        return 0, 0.0
    if t >= times[n - 1]:
        return n - 1, 0.0
    i = np.searchsorted(times, t, side="right") - 1
    a = (t - times[i]) / (times[i + 1] - times[i])
    return i, a


@njit(cache=True)
def _slerp(q0, q1, a, out):
    """GfSlerp of two (x, y, z, w) quaternions exactly as usd-core interpolates ``quatf`` samples:
    the cosine from the float components (GfQuatf's float dot), shortest arc, and on the linear
    branch (``1 - cos <= 1e-5``) a plain lerp that is *not* renormalised (GfSlerp does not; the
    SkelAnimation's consumers then build the joint matrix from that slightly short quaternion, so
    this kernel does too, to show the same shape as UsdSkel)."""
    f32 = np.float32
    cos_t = np.float64(f32(f32(f32(f32(q0[0]) * f32(q1[0])) + f32(f32(q0[1]) * f32(q1[1]))) + f32(f32(q0[2]) * f32(q1[2])))
                       + f32(f32(q0[3]) * f32(q1[3])))
    sign = 1.0
    if cos_t < 0.0:
        cos_t = -cos_t
        sign = -1.0
    if 1.0 - cos_t > 0.00001:
        theta = math.acos(min(cos_t, 1.0))
        s = math.sin(theta)
        s0 = math.sin((1.0 - a) * theta) / s
        s1 = math.sin(a * theta) / s
    else:
        s0 = 1.0 - a
        s1 = a
    s1 *= sign
    for c in range(4):
        out[c] = s0 * q0[c] + s1 * q1[c]


@njit(cache=True)
def _joint_transforms(t, tt, vt, tr, vr, ts, vs, anim_to_skel, rest_local, parents, topo_order,
                      inv_bind, geom_bind, local_to_world, local_buf, skel_out, skin_out, world_out):
    """Joint transforms of one skeleton at time code ``t``.

    tt, vt : (nT,), (nT, A, 3) translation sample times and values (A animated joints)
    tr, vr : (nR,), (nR, A, 4) rotations (x, y, z, w);  ts, vs : (nS,), (nS, A, 3) scales
    anim_to_skel : (A,) skeleton joint of each animated joint
    rest_local : (J, 4, 4) local transforms of joints the clip does not animate
    parents : (J,) parent joint or -1;  topo_order : (J,) joints, parents first
    inv_bind : (J, 4, 4);  geom_bind, local_to_world : (4, 4)
    skel_out : (J, 4, 4) joint skeleton-space transforms (ComputeJointSkelTransforms)
    skin_out : (J, 4, 4) geom_bind @ inv_bind @ skel (UsdSkel skinning transform with geomBind)
    world_out : (J, 4, 4) skel @ local_to_world;  local_buf : (J, 4, 4) scratch
    """
    J = rest_local.shape[0]
    local = local_buf
    local[:] = rest_local
    iT, aT = _bracket(tt, t)
    iR, aR = _bracket(tr, t)
    iS, aS = _bracket(ts, t)
    q = np.empty(4)
    for k in range(anim_to_skel.shape[0]):
        j = anim_to_skel[k]
        if aT == 0.0:
            tx, ty, tz = vt[iT, k, 0], vt[iT, k, 1], vt[iT, k, 2]
        else:
            tx = (1.0 - aT) * vt[iT, k, 0] + aT * vt[iT + 1, k, 0]
            ty = (1.0 - aT) * vt[iT, k, 1] + aT * vt[iT + 1, k, 1]
            tz = (1.0 - aT) * vt[iT, k, 2] + aT * vt[iT + 1, k, 2]
        if aS == 0.0:
            sx, sy, sz = vs[iS, k, 0], vs[iS, k, 1], vs[iS, k, 2]
        else:
            sx = (1.0 - aS) * vs[iS, k, 0] + aS * vs[iS + 1, k, 0]
            sy = (1.0 - aS) * vs[iS, k, 1] + aS * vs[iS + 1, k, 1]
            sz = (1.0 - aS) * vs[iS, k, 2] + aS * vs[iS + 1, k, 2]
        if aR == 0.0:
            for c in range(4):
                q[c] = vr[iR, k, c]
        else:
            _slerp(vr[iR, k], vr[iR + 1, k], aR, q)
        x, y, z, w = q[0], q[1], q[2], q[3]
        # GfMatrix4d::SetRotate(quat) (row-vector), then scale rows (S * R * T)
        m = local[j]
        m[0, 0] = (1.0 - 2.0 * (y * y + z * z)) * sx
        m[0, 1] = (2.0 * (x * y + z * w)) * sx
        m[0, 2] = (2.0 * (z * x - y * w)) * sx
        m[1, 0] = (2.0 * (x * y - z * w)) * sy
        m[1, 1] = (1.0 - 2.0 * (z * z + x * x)) * sy
        m[1, 2] = (2.0 * (y * z + x * w)) * sy
        m[2, 0] = (2.0 * (z * x + y * w)) * sz
        m[2, 1] = (2.0 * (y * z - x * w)) * sz
        m[2, 2] = (1.0 - 2.0 * (x * x + y * y)) * sz
        m[0, 3] = 0.0
        m[1, 3] = 0.0
        m[2, 3] = 0.0
        m[3, 0] = tx
        m[3, 1] = ty
        m[3, 2] = tz
        m[3, 3] = 1.0
    tmp = np.empty((4, 4))
    for n in range(J):
        j = topo_order[n]
        p = parents[j]
        if p < 0:
            skel_out[j] = local[j]
        else:
            _mul44(local[j], skel_out[p], skel_out[j])
        _mul44(inv_bind[j], skel_out[j], tmp)
        _mul44(geom_bind, tmp, skin_out[j])
        _mul44(skel_out[j], local_to_world, world_out[j])


@njit(cache=True, inline="always")
def _mul44(a, b, out):
    """out = a @ b for 4x4 (no allocation; ``out`` must not alias ``a`` or ``b``)."""
    for i in range(4):
        a0, a1, a2, a3 = a[i, 0], a[i, 1], a[i, 2], a[i, 3]
        for k in range(4):
            out[i, k] = a0 * b[0, k] + a1 * b[1, k] + a2 * b[2, k] + a3 * b[3, k]


# -- skinning ----------------------------------------------------------------------------------


@njit(cache=True)
def _fold(skin, local_to_world, out):
    """Skinning transforms straight into stage space, flattened for the skinning loop.

    skin (J, 4, 4) row-vector skinning transforms, local_to_world (4, 4);
    out (J, 12): the first three columns of ``skin[j] @ local_to_world`` stored row by row of
    the column-vector matrix, so ``x' = out[j, 0:4] . (x, y, z, 1)`` and so on."""
    for j in range(skin.shape[0]):
        for c in range(3):
            for r in range(4):
                acc = 0.0
                for t in range(4):
                    acc += skin[j, r, t] * local_to_world[t, c]
                out[j, 4 * c + r] = acc


@njit(cache=True, inline="always")
def _skin_vertex(v, rest, joint_indices, joint_weights, m, out):
    """Vertex ``v`` skinned by the flattened stage-space transforms ``m`` (J, 12) of
    :func:`_fold` (contiguous rows: one cache line or two per influence)."""
    px = np.float64(rest[v, 0])
    py = np.float64(rest[v, 1])
    pz = np.float64(rest[v, 2])
    ax = 0.0
    ay = 0.0
    az = 0.0
    for i in range(joint_indices.shape[1]):
        w = np.float64(joint_weights[v, i])
        if w == 0.0:
            break  # weights are sorted strongest first at load: the rest are padding
        j = joint_indices[v, i]  # no row views in hot loops: they cost refcounting
        ax += w * (m[j, 0] * px + m[j, 1] * py + m[j, 2] * pz + m[j, 3])
        ay += w * (m[j, 4] * px + m[j, 5] * py + m[j, 6] * pz + m[j, 7])
        az += w * (m[j, 8] * px + m[j, 9] * py + m[j, 10] * pz + m[j, 11])
    out[v, 0] = ax
    out[v, 1] = ay
    out[v, 2] = az


@njit(cache=True, parallel=True, fastmath=True)
def _skin_lbs(rest, joint_indices, joint_weights, skin, out):
    """Linear-blend skinning (UsdSkelSkinPointsLBS) into stage space.

    rest (V, 3) float32, joint_indices (V, k) int32 (valid, checked at load), joint_weights
    (V, k) float32, skin (J, 12) float64 stage-space skinning transforms from :func:`_fold`,
    out (V, 3) float32."""
    for v in prange(rest.shape[0]):
        _skin_vertex(v, rest, joint_indices, joint_weights, skin, out)


@njit(cache=True, fastmath=True)
def _skin_lbs_serial(rest, joint_indices, joint_weights, skin, out):
    """:func:`_skin_lbs` on one thread (small meshes: no thread-pool wake-up)."""
    for v in range(rest.shape[0]):
        _skin_vertex(v, rest, joint_indices, joint_weights, skin, out)


@njit(cache=True)
def _cull_bounds(spheres, pj_offsets, pj_joint, pj_center, pj_radius, world, cull):
    """Culling spheres that provably hold without skinning a vertex.

    A part's posed vertex is a convex combination (weights >= 0, summing to 1) of its images
    under each influencing joint i, and those images lie in the sphere (pj_center, pj_radius)
    of the part's vertices influenced by i, in i's bind space, moved by ``world[i]``. So a
    sphere about the part's centre reaching past all of those spheres bounds the part."""
    for p in range(spheres.shape[0]):
        cx, cy, cz = spheres[p, 0], spheres[p, 1], spheres[p, 2]
        far = 0.0
        for k in range(pj_offsets[p], pj_offsets[p + 1]):
            m = world[pj_joint[k]]
            ox, oy, oz = pj_center[k, 0], pj_center[k, 1], pj_center[k, 2]
            x = ox * m[0, 0] + oy * m[1, 0] + oz * m[2, 0] + m[3, 0] - cx
            y = ox * m[0, 1] + oy * m[1, 1] + oz * m[2, 1] + m[3, 1] - cy
            z = ox * m[0, 2] + oy * m[1, 2] + oz * m[2, 2] + m[3, 2] - cz
            sc = 0.0
            for r in range(3):
                sc = max(sc, math.sqrt(m[r, 0] * m[r, 0] + m[r, 1] * m[r, 1] + m[r, 2] * m[r, 2]))
            far = max(far, math.sqrt(x * x + y * y + z * z) + pj_radius[k] * sc)
        cull[p, 0] = cx
        cull[p, 1] = cy
        cull[p, 2] = cz
        cull[p, 3] = far * (1.0 + 1e-5) + 2e-6 * (abs(cx) + abs(cy) + abs(cz) + far) + 1e-9


@njit(cache=True)
def _prepare_part(p, skinned, rest, joint_indices, joint_weights, skin,
                  vert_offsets, verts, points, triangles, faces, chunk_offsets, part_chunks,
                  chunk_sph):
    """Make part ``p`` queryable at this pose: skin its vertices (unless ``skinned``), then
    compute its chunk spheres."""
    if not skinned:
        for i in range(vert_offsets[p], vert_offsets[p + 1]):
            _skin_vertex(verts[i], rest, joint_indices, joint_weights, skin, points)
    _chunk_spheres(p, points, triangles, faces, chunk_offsets, part_chunks, chunk_sph)


@njit(cache=True)
def _part_spheres(centers, radii, part_joint, world, points, vert_offsets, verts, spheres, cull,
                  exact):
    """Part spheres moved with their joints and the culling spheres that bound the posed part.

    centers (P, 3) joint space, radii (P,), part_joint (P,), world (J, 4, 4) joint-to-stage,
    points (V, 3) posed, vert_offsets (P+1,) / verts: CSR of each part's vertices.
    spheres (P, 4) out: centre + radius scaled by the joint's largest axis scale.
    cull (P, 4) out (only if ``exact``, from skinned ``points``): same centre, radius =
    max(sphere radius, farthest posed part vertex), so culling against it can never drop a
    triangle even if the asset sphere does not hold."""
    P = centers.shape[0]
    for p in range(P):
        m = world[part_joint[p]]
        cx, cy, cz = centers[p, 0], centers[p, 1], centers[p, 2]
        x = cx * m[0, 0] + cy * m[1, 0] + cz * m[2, 0] + m[3, 0]
        y = cx * m[0, 1] + cy * m[1, 1] + cz * m[2, 1] + m[3, 1]
        z = cx * m[0, 2] + cy * m[1, 2] + cz * m[2, 2] + m[3, 2]
        s = 0.0
        for r in range(3):
            n = math.sqrt(m[r, 0] * m[r, 0] + m[r, 1] * m[r, 1] + m[r, 2] * m[r, 2])
            if n > s:
                s = n
        rad = radii[p] * s
        spheres[p, 0] = x
        spheres[p, 1] = y
        spheres[p, 2] = z
        spheres[p, 3] = rad
        if not exact:
            continue
        far2 = 0.0
        for i in range(vert_offsets[p], vert_offsets[p + 1]):
            v = verts[i]
            dx = points[v, 0] - x
            dy = points[v, 1] - y
            dz = points[v, 2] - z
            d2 = dx * dx + dy * dy + dz * dz
            if d2 > far2:
                far2 = d2
        far = math.sqrt(far2) * (1.0 + 1e-6) + 1e-9
        cull[p, 0] = x
        cull[p, 1] = y
        cull[p, 2] = z
        cull[p, 3] = max(rad, far)


# -- ray casting -------------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _mt(ox, oy, oz, dx, dy, dz, ax, ay, az, bx, by, bz, cx, cy, cz):
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


@njit(cache=True)
def _chunk_spheres(p, points, triangles, faces, chunk_offsets, part_chunks, chunk_sph):
    """Bounding spheres of part ``p``'s chunks (a few faces each) on the posed points:
    centre = box centre of the chunk's vertices, radius = half the box diagonal (padded)."""
    for c in range(part_chunks[p], part_chunks[p + 1]):
        lo0 = lo1 = lo2 = np.inf
        hi0 = hi1 = hi2 = -np.inf
        for i in range(chunk_offsets[c], chunk_offsets[c + 1]):
            f = faces[i]
            for k in range(3):
                q = triangles[f, k]
                x, y, z = points[q, 0], points[q, 1], points[q, 2]
                lo0 = min(lo0, x)
                lo1 = min(lo1, y)
                lo2 = min(lo2, z)
                hi0 = max(hi0, x)
                hi1 = max(hi1, y)
                hi2 = max(hi2, z)
        cx, cy, cz = 0.5 * (lo0 + hi0), 0.5 * (lo1 + hi1), 0.5 * (lo2 + hi2)
        hx, hy, hz = 0.5 * (hi0 - lo0), 0.5 * (hi1 - lo1), 0.5 * (hi2 - lo2)
        r2 = hx * hx + hy * hy + hz * hz  # the sphere around the box: one pass over the chunk
        chunk_sph[c, 0] = cx
        chunk_sph[c, 1] = cy
        chunk_sph[c, 2] = cz
        chunk_sph[c, 3] = math.sqrt(r2) * (1.0 + 1e-6) + 1e-9


@njit(cache=True, parallel=True)
def _all_chunk_spheres(points, triangles, faces, chunk_offsets, part_chunks, chunk_sph, ready, version):
    """Chunk spheres of every part not yet ``ready`` at this pose ``version``."""
    for p in prange(part_chunks.shape[0] - 1):
        if ready[p] != version:
            _chunk_spheres(p, points, triangles, faces, chunk_offsets, part_chunks, chunk_sph)
            ready[p] = version


@njit(cache=True, inline="always")
def _ray_enters(ox, oy, oz, dx, dy, dz, cx, cy, cz, rad, best):
    """Does the segment ``o + t d``, ``0 <= t <= best`` (unit d) meet the sphere?"""
    lx = cx - ox
    ly = cy - oy
    lz = cz - oz
    tca = lx * dx + ly * dy + lz * dz
    d2 = lx * lx + ly * ly + lz * lz - tca * tca
    if d2 > rad * rad:
        return False
    thc = math.sqrt(rad * rad - d2)
    return not (tca + thc < 0.0 or tca - thc > best)


@njit(cache=True)
def _ray_one(r, origins, directions, max_distance, points, triangles, cull, faces, chunk_offsets,
             part_chunks, chunk_sph, ready, version, lz, use_parts, distance, triangle, part, bary):
    ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
    dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
    best = max_distance
    bf = -1
    bp = -1
    bu = 0.0
    bv = 0.0
    if use_parts:
        for p in range(cull.shape[0]):
            if not _ray_enters(ox, oy, oz, dx, dy, dz, cull[p, 0], cull[p, 1], cull[p, 2], cull[p, 3], best):
                continue
            if ready[p] != version:
                _prepare_part(p, lz[0] == version, lz[1], lz[2], lz[3], lz[4], lz[5],
                              lz[6], points, triangles, faces, chunk_offsets, part_chunks, chunk_sph)
                ready[p] = version
            for c in range(part_chunks[p], part_chunks[p + 1]):
                if not _ray_enters(ox, oy, oz, dx, dy, dz, chunk_sph[c, 0], chunk_sph[c, 1],
                                   chunk_sph[c, 2], chunk_sph[c, 3], best):
                    continue
                for i in range(chunk_offsets[c], chunk_offsets[c + 1]):
                    f = faces[i]
                    t, u, v = _mt(ox, oy, oz, dx, dy, dz,
                                  np.float64(points[triangles[f, 0], 0]), np.float64(points[triangles[f, 0], 1]),
                                  np.float64(points[triangles[f, 0], 2]), np.float64(points[triangles[f, 1], 0]),
                                  np.float64(points[triangles[f, 1], 1]), np.float64(points[triangles[f, 1], 2]),
                                  np.float64(points[triangles[f, 2], 0]), np.float64(points[triangles[f, 2], 1]),
                                  np.float64(points[triangles[f, 2], 2]))
                    if t <= best and t < np.inf and (t < best or bf < 0 or f < bf or (f == bf and p < bp)):
                        best, bf, bp, bu, bv = t, f, p, u, v
    else:
        for f in range(triangles.shape[0]):
            t, u, v = _mt(ox, oy, oz, dx, dy, dz,
                                  np.float64(points[triangles[f, 0], 0]), np.float64(points[triangles[f, 0], 1]),
                                  np.float64(points[triangles[f, 0], 2]), np.float64(points[triangles[f, 1], 0]),
                                  np.float64(points[triangles[f, 1], 1]), np.float64(points[triangles[f, 1], 2]),
                                  np.float64(points[triangles[f, 2], 0]), np.float64(points[triangles[f, 2], 1]),
                                  np.float64(points[triangles[f, 2], 2]))
            if t <= best and t < np.inf and (t < best or bf < 0 or f < bf):
                best, bf, bu, bv = t, f, u, v
    if bf < 0:
        distance[r] = np.inf
        triangle[r] = -1
        part[r] = -1
        bary[r, 0] = 0.0
        bary[r, 1] = 0.0
        bary[r, 2] = 0.0
    else:
        distance[r] = best
        triangle[r] = bf
        part[r] = bp
        bary[r, 0] = 1.0 - bu - bv
        bary[r, 1] = bu
        bary[r, 2] = bv


@njit(cache=True)
def _raycast(origins, directions, max_distance, points, triangles, cull, faces, chunk_offsets,
             part_chunks, chunk_sph, ready, version, lz, use_parts, distance, triangle, part, bary):
    """Nearest hit per ray (serial; the wrapper picks this for few rays). Part spheres, then
    chunk spheres (computed on first use at this pose), then Möller-Trumbore."""
    for r in range(origins.shape[0]):
        _ray_one(r, origins, directions, max_distance, points, triangles, cull, faces,
                 chunk_offsets, part_chunks, chunk_sph, ready, version, lz, use_parts, distance,
                 triangle, part, bary)


@njit(cache=True, parallel=True)
def _raycast_parallel(origins, directions, max_distance, points, triangles, cull, faces,
                      chunk_offsets, part_chunks, chunk_sph, ready, version, lz, use_parts, distance,
                      triangle, part, bary):
    """Nearest hit per ray, rays in parallel (every part's chunk spheres must be ready)."""
    for r in prange(origins.shape[0]):
        _ray_one(r, origins, directions, max_distance, points, triangles, cull, faces,
                 chunk_offsets, part_chunks, chunk_sph, ready, version, lz, use_parts, distance,
                 triangle, part, bary)


# -- sphere contacts ---------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _closest_on_triangle(px, py, pz, points, ia, ib, ic, out):
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


@njit(cache=True)
def _write_contact(f, px, py, pz, radius, d2, points, triangles, tmp, n, tri_out, point_out,
                   normal_out, depth_out, bary_out):
    """Record triangle ``f`` (closest point and barycentric in ``tmp``) as contact ``n``.
    Called only for contacts: passing arrays to a call that is not inlined costs refcounting."""
    dx, dy, dz = px - tmp[0], py - tmp[1], pz - tmp[2]
    d = math.sqrt(d2)
    if d > 0.0:
        nx, ny, nz = dx / d, dy / d, dz / d
    else:  # centre on the surface: the face normal
        a, b, c = triangles[f, 0], triangles[f, 1], triangles[f, 2]
        e1x = points[b, 0] - points[a, 0]
        e1y = points[b, 1] - points[a, 1]
        e1z = points[b, 2] - points[a, 2]
        e2x = points[c, 0] - points[a, 0]
        e2y = points[c, 1] - points[a, 1]
        e2z = points[c, 2] - points[a, 2]
        nx = np.float64(e1y * e2z - e1z * e2y)
        ny = np.float64(e1z * e2x - e1x * e2z)
        nz = np.float64(e1x * e2y - e1y * e2x)
        ln = math.sqrt(nx * nx + ny * ny + nz * nz)
        if ln > 0.0:
            nx, ny, nz = nx / ln, ny / ln, nz / ln
    tri_out[n] = f
    point_out[n, 0] = tmp[0]
    point_out[n, 1] = tmp[1]
    point_out[n, 2] = tmp[2]
    normal_out[n, 0] = nx
    normal_out[n, 1] = ny
    normal_out[n, 2] = nz
    depth_out[n] = radius - d
    bary_out[n, 0] = tmp[3]
    bary_out[n, 1] = tmp[4]
    bary_out[n, 2] = tmp[5]
    return n + 1


@njit(cache=True)
def _sphere_contacts(center, radius, points, triangles, cull, faces, chunk_offsets, part_chunks,
                     chunk_sph, ready, version, lz, use_parts, mark, stamp, tri_out, point_out,
                     normal_out, depth_out, bary_out):
    """Every triangle within ``radius`` of ``center``; returns the count written to the outputs.

    Part spheres, then chunk spheres, then Ericson's closest point. ``mark`` (F,) int64 with
    ``stamp`` dedupes triangles shared by several parts without clearing."""
    px, py, pz = center[0], center[1], center[2]
    r2 = radius * radius
    tmp = np.empty(6)
    n = 0
    if use_parts:
        for p in range(cull.shape[0]):
            dx = cull[p, 0] - px
            dy = cull[p, 1] - py
            dz = cull[p, 2] - pz
            rr = cull[p, 3] + radius
            if dx * dx + dy * dy + dz * dz > rr * rr:
                continue
            if ready[p] != version:
                _prepare_part(p, lz[0] == version, lz[1], lz[2], lz[3], lz[4], lz[5],
                              lz[6], points, triangles, faces, chunk_offsets, part_chunks, chunk_sph)
                ready[p] = version
            for c in range(part_chunks[p], part_chunks[p + 1]):
                dx = chunk_sph[c, 0] - px
                dy = chunk_sph[c, 1] - py
                dz = chunk_sph[c, 2] - pz
                rr = chunk_sph[c, 3] + radius
                if dx * dx + dy * dy + dz * dz > rr * rr:
                    continue
                for i in range(chunk_offsets[c], chunk_offsets[c + 1]):
                    f = faces[i]
                    if mark[f] == stamp:
                        continue
                    mark[f] = stamp
                    _closest_on_triangle(px, py, pz, points, triangles[f, 0], triangles[f, 1],
                                         triangles[f, 2], tmp)
                    dx, dy, dz = px - tmp[0], py - tmp[1], pz - tmp[2]
                    d2 = dx * dx + dy * dy + dz * dz
                    if d2 <= r2:
                        n = _write_contact(f, px, py, pz, radius, d2, points, triangles, tmp, n,
                                           tri_out, point_out, normal_out, depth_out, bary_out)
    else:
        for f in range(triangles.shape[0]):
            _closest_on_triangle(px, py, pz, points, triangles[f, 0], triangles[f, 1],
                                 triangles[f, 2], tmp)
            dx, dy, dz = px - tmp[0], py - tmp[1], pz - tmp[2]
            d2 = dx * dx + dy * dy + dz * dz
            if d2 <= r2:
                n = _write_contact(f, px, py, pz, radius, d2, points, triangles, tmp, n, tri_out,
                                   point_out, normal_out, depth_out, bary_out)
    return n


# -- surface points ----------------------------------------------------------------------------


@njit(cache=True)
def _surface_points(points, triangles, tri, bary, out):
    """World positions of barycentric points on triangles: out[i] = sum_k bary[i,k] * p[tri[i],k]."""
    for i in range(tri.shape[0]):
        f = tri[i]
        a, b, c3 = triangles[f, 0], triangles[f, 1], triangles[f, 2]
        for c in range(3):
            out[i, c] = (bary[i, 0] * points[a, c] + bary[i, 1] * points[b, c]
                         + bary[i, 2] * points[c3, c])


@njit(cache=True)
def _face_normals(points, triangles, tri, out):
    """Unit geometric normals (e1 x e2, counter-clockwise = outward) of triangles ``tri``;
    zero for a degenerate triangle."""
    for i in range(tri.shape[0]):
        f = tri[i]
        a, b, c = triangles[f, 0], triangles[f, 1], triangles[f, 2]
        e1x = np.float64(points[b, 0]) - points[a, 0]
        e1y = np.float64(points[b, 1]) - points[a, 1]
        e1z = np.float64(points[b, 2]) - points[a, 2]
        e2x = np.float64(points[c, 0]) - points[a, 0]
        e2y = np.float64(points[c, 1]) - points[a, 1]
        e2z = np.float64(points[c, 2]) - points[a, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        ln = math.sqrt(nx * nx + ny * ny + nz * nz)
        if ln > 0.0:
            out[i, 0] = nx / ln
            out[i, 1] = ny / ln
            out[i, 2] = nz / ln
        else:
            out[i, 0] = 0.0
            out[i, 1] = 0.0
            out[i, 2] = 0.0


@njit(cache=True)
def _hit_fill(origins, directions, distance, triangle, points, triangles, point, normal):
    """Hit points and normals of the rays that hit (NaN for misses)."""
    for r in range(origins.shape[0]):
        if triangle[r] < 0:
            for c in range(3):
                point[r, c] = np.nan
                normal[r, c] = np.nan
        else:
            for c in range(3):
                point[r, c] = origins[r, c] + distance[r] * directions[r, c]
    idx = np.nonzero(triangle >= 0)[0]
    tmp = np.empty((idx.shape[0], 3))
    _face_normals(points, triangles, triangle[idx], tmp)
    for i in range(idx.shape[0]):
        for c in range(3):
            normal[idx[i], c] = tmp[i, c]
