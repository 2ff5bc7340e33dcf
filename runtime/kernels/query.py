"""Query kernels of the runtime: ray casts, sphere contacts, surface points (private,
``_``-prefixed, behind the validating wrappers in :mod:`runtime.collider` and the backends of
:mod:`runtime.backends`).  Each has a slow readable numpy reference in
``tests/references/naive_queries.py``; the triangle tests themselves (Möller-Trumbore, Ericson's
closest point) are :mod:`runtime.kernels.triangle`'s.

Queries read posed points ``(V, 3) float32`` in stage space and work in float64.  A part is made
queryable lazily (:func:`_prepare_part`): its vertices are skinned by the one skinning kernel
(:mod:`runtime.kernels.skin`) and its chunk spheres computed, the first time a query reaches it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .config import FASTMATH_OFF
from .skin import _skin_subset
from .triangle import closest_on_triangle, ray_triangle


@njit(cache=True, fastmath=FASTMATH_OFF)
def _prepare_part(p, version, lz, points, part_chunks, chunk_sph):
    """Make part ``p`` queryable at pose ``version``: skin its vertices (unless the whole skin
    is at this version), then compute its chunk spheres.  ``lz`` is what that needs (built by
    ``Pose._lazy``): (version fully skinned, rest points, joint indices, joint weights,
    skinning transforms, the parts' vertex CSR offsets and vertices, the chunks' vertex CSR
    offsets and vertices)."""
    if lz[0] != version:
        _skin_subset(lz[6], lz[5][p], lz[5][p + 1], lz[1], lz[2], lz[3], lz[4], points)
    _chunk_spheres(p, points, lz[7], lz[8], part_chunks, chunk_sph)


# -- ray casting -------------------------------------------------------------------------------


@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
def _mt_face(ox, oy, oz, dx, dy, dz, points, triangles, f):
    """:func:`~runtime.kernels.triangle.ray_triangle` on triangle ``f`` of the posed ``points``
    (its corners read as float64)."""
    a, b, c = triangles[f, 0], triangles[f, 1], triangles[f, 2]
    return ray_triangle(ox, oy, oz, dx, dy, dz,
               np.float64(points[a, 0]), np.float64(points[a, 1]), np.float64(points[a, 2]),
               np.float64(points[b, 0]), np.float64(points[b, 1]), np.float64(points[b, 2]),
               np.float64(points[c, 0]), np.float64(points[c, 1]), np.float64(points[c, 2]))


@njit(cache=True, fastmath=FASTMATH_OFF)
def _chunk_spheres(p, points, chunk_vert_offsets, chunk_verts, part_chunks, chunk_sph):
    """Bounding spheres of part ``p``'s chunks (a few faces each) on the posed points:
    centre = box centre of the chunk's vertices, radius = half the box diagonal (padded).
    Each chunk's distinct vertices are read once (``chunk_vert_offsets`` / ``chunk_verts``, a
    CSR built at load: a 16-face chunk has ~15 of them against 48 face corners)."""
    for c in range(part_chunks[p], part_chunks[p + 1]):
        q = chunk_verts[chunk_vert_offsets[c]]  # a chunk has at least one face
        lo0 = hi0 = np.float64(points[q, 0])
        lo1 = hi1 = np.float64(points[q, 1])
        lo2 = hi2 = np.float64(points[q, 2])
        for i in range(chunk_vert_offsets[c] + 1, chunk_vert_offsets[c + 1]):
            q = chunk_verts[i]
            x, y, z = points[q, 0], points[q, 1], points[q, 2]
            if x < lo0:
                lo0 = x
            if x > hi0:
                hi0 = x
            if y < lo1:
                lo1 = y
            if y > hi1:
                hi1 = y
            if z < lo2:
                lo2 = z
            if z > hi2:
                hi2 = z
        cx, cy, cz = 0.5 * (lo0 + hi0), 0.5 * (lo1 + hi1), 0.5 * (lo2 + hi2)
        hx, hy, hz = 0.5 * (hi0 - lo0), 0.5 * (hi1 - lo1), 0.5 * (hi2 - lo2)
        r2 = hx * hx + hy * hy + hz * hz  # the sphere around the box: one pass over the chunk
        chunk_sph[c, 0] = cx
        chunk_sph[c, 1] = cy
        chunk_sph[c, 2] = cz
        chunk_sph[c, 3] = math.sqrt(r2) * (1.0 + 1e-6) + 1e-9


@njit(cache=True, parallel=True, fastmath=FASTMATH_OFF)
def _all_chunk_spheres(points, chunk_vert_offsets, chunk_verts, part_chunks, chunk_sph, ready, version):
    """Chunk spheres of every part not yet ``ready`` at this pose ``version``."""
    for p in prange(part_chunks.shape[0] - 1):
        if ready[p] != version:
            _chunk_spheres(p, points, chunk_vert_offsets, chunk_verts, part_chunks, chunk_sph)
            ready[p] = version


@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
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


@njit(cache=True, fastmath=FASTMATH_OFF)
def _ray_one(r, origins, directions, max_distance, points, triangles, cull, faces, chunk_offsets,
             part_chunks, chunk_sph, ready, version, lz, distance, triangle, part, bary):
    ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
    dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
    best = max_distance
    bf = -1
    bp = -1
    bu = 0.0
    bv = 0.0
    for p in range(cull.shape[0]):
        if not _ray_enters(ox, oy, oz, dx, dy, dz, cull[p, 0], cull[p, 1], cull[p, 2], cull[p, 3], best):
            continue
        if ready[p] != version:
            _prepare_part(p, version, lz, points, part_chunks, chunk_sph)
            ready[p] = version
        for c in range(part_chunks[p], part_chunks[p + 1]):
            if not _ray_enters(ox, oy, oz, dx, dy, dz, chunk_sph[c, 0], chunk_sph[c, 1],
                               chunk_sph[c, 2], chunk_sph[c, 3], best):
                continue
            for i in range(chunk_offsets[c], chunk_offsets[c + 1]):
                f = faces[i]
                t, u, v = _mt_face(ox, oy, oz, dx, dy, dz, points, triangles, f)
                if t <= best and t < np.inf and (t < best or bf < 0 or f < bf or (f == bf and p < bp)):
                    best, bf, bp, bu, bv = t, f, p, u, v
    _ray_store(r, best, bf, bp, bu, bv, distance, triangle, part, bary)


@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
def _ray_store(r, best, bf, bp, bu, bv, distance, triangle, part, bary):
    """Write ray ``r``'s nearest hit (triangle ``bf`` < 0: a miss)."""
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


@njit(cache=True, fastmath=FASTMATH_OFF)
def _raycast(origins, directions, max_distance, points, triangles, cull, faces, chunk_offsets,
             part_chunks, chunk_sph, ready, version, lz, distance, triangle, part, bary):
    """Nearest hit per ray (serial; the wrapper picks this for few rays). Part spheres, then
    chunk spheres (computed on first use at this pose), then Möller-Trumbore."""
    for r in range(origins.shape[0]):
        _ray_one(r, origins, directions, max_distance, points, triangles, cull, faces,
                 chunk_offsets, part_chunks, chunk_sph, ready, version, lz, distance,
                 triangle, part, bary)


@njit(cache=True, parallel=True, fastmath=FASTMATH_OFF)
def _raycast_parallel(origins, directions, max_distance, points, triangles, cull, faces,
                      chunk_offsets, part_chunks, chunk_sph, ready, version, lz, distance,
                      triangle, part, bary):
    """Nearest hit per ray, rays in parallel (every part's chunk spheres must be ready)."""
    for r in prange(origins.shape[0]):
        _ray_one(r, origins, directions, max_distance, points, triangles, cull, faces,
                 chunk_offsets, part_chunks, chunk_sph, ready, version, lz, distance,
                 triangle, part, bary)


@njit(cache=True, fastmath=FASTMATH_OFF)
def _raycast_all(origins, directions, max_distance, points, triangles, distance, triangle, part, bary):
    """Nearest hit per ray over every triangle, no culling: the brute-force backend (the
    reference the culled kernels are tested against).  A kernel of its own, so game code, which
    never calls it, never compiles it; ``part`` is written -1 (the caller maps triangles to
    their first part)."""
    for r in range(origins.shape[0]):
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
        best = max_distance
        bf = -1
        bu = 0.0
        bv = 0.0
        for f in range(triangles.shape[0]):
            t, u, v = _mt_face(ox, oy, oz, dx, dy, dz, points, triangles, f)
            if t <= best and t < np.inf and (t < best or bf < 0 or f < bf):
                best, bf, bu, bv = t, f, u, v
        _ray_store(r, best, bf, -1, bu, bv, distance, triangle, part, bary)


# -- sphere contacts ---------------------------------------------------------------------------


@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
def _apart(spheres, k, px, py, pz, radius):
    """Is sphere ``k`` of ``spheres`` (n, 4) beyond ``radius`` of ``(px, py, pz)``?"""
    dx = spheres[k, 0] - px
    dy = spheres[k, 1] - py
    dz = spheres[k, 2] - pz
    rr = spheres[k, 3] + radius
    return dx * dx + dy * dy + dz * dz > rr * rr


@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
def _box_gap2(px, py, pz, points, ia, ib, ic):
    """Squared distance from ``(px, py, pz)`` to the bounding box of triangle (ia, ib, ic): a
    lower bound of the squared distance to the triangle, so a face whose box is beyond the
    radius is skipped before the closest-point test (most faces of a reached chunk are)."""
    g = 0.0
    for k in range(3):
        a, b, c = np.float64(points[ia, k]), np.float64(points[ib, k]), np.float64(points[ic, k])
        q = px if k == 0 else (py if k == 1 else pz)
        lo = min(a, min(b, c))
        hi = max(a, max(b, c))
        if q < lo:
            g += (lo - q) * (lo - q)
        elif q > hi:
            g += (q - hi) * (q - hi)
    return g


@njit(cache=True, fastmath=FASTMATH_OFF)
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


@njit(cache=True, inline="always", fastmath=FASTMATH_OFF)
def _face_contact(f, ia, ib, ic, px, py, pz, radius, r2, points, triangles, tmp, n, tri_out, point_out,
                  normal_out, depth_out, bary_out):
    """Test triangle ``f`` (corners ia, ib, ic) against the sphere: record it as contact ``n``
    when its closest point (Ericson's, into ``tmp``) is within the radius; returns the count."""
    closest_on_triangle(px, py, pz, points, ia, ib, ic, tmp)
    dx, dy, dz = px - tmp[0], py - tmp[1], pz - tmp[2]
    d2 = dx * dx + dy * dy + dz * dz
    if d2 <= r2:
        n = _write_contact(f, px, py, pz, radius, d2, points, triangles, tmp, n, tri_out, point_out,
                           normal_out, depth_out, bary_out)
    return n


@njit(cache=True, fastmath=FASTMATH_OFF)
def _sphere_contacts(center, radius, points, triangles, cull, faces, chunk_offsets, part_chunks,
                     chunk_sph, ready, version, lz, dedup, mark, stamp, tri_out, point_out,
                     normal_out, depth_out, bary_out):
    """Every triangle within ``radius`` of ``center``; returns the count written to the outputs.

    Part spheres, then chunk spheres, then Ericson's closest point.  With ``dedup`` (some face
    is in several parts), ``mark`` (F,) int64 with ``stamp`` dedupes them without clearing;
    without, ``mark`` is not read (a fresh pose's first query would miss the cache on it)."""
    px, py, pz = center[0], center[1], center[2]
    r2 = radius * radius
    r2_box = r2 * (1.0 + 1e-9)  # the box test's reach, padded: rounding never culls a contact
    tmp = np.empty(6)
    n = np.int64(0)  # not a literal 0: _write_contact then compiles once, not twice
    for p in range(cull.shape[0]):
        if _apart(cull, p, px, py, pz, radius):
            continue
        if ready[p] != version:
            _prepare_part(p, version, lz, points, part_chunks, chunk_sph)
            ready[p] = version
        for c in range(part_chunks[p], part_chunks[p + 1]):
            if _apart(chunk_sph, c, px, py, pz, radius):
                continue
            for i in range(chunk_offsets[c], chunk_offsets[c + 1]):
                f = faces[i]
                if dedup:
                    if mark[f] == stamp:
                        continue
                    mark[f] = stamp
                ia, ib, ic = triangles[f, 0], triangles[f, 1], triangles[f, 2]
                if _box_gap2(px, py, pz, points, ia, ib, ic) > r2_box:  # its box is out of reach
                    continue
                n = _face_contact(f, ia, ib, ic, px, py, pz, radius, r2, points, triangles, tmp, n,
                                  tri_out, point_out, normal_out, depth_out, bary_out)
    return n


@njit(cache=True, fastmath=FASTMATH_OFF)
def _sphere_contacts_all(center, radius, points, triangles, tri_out, point_out, normal_out, depth_out,
                         bary_out):
    """:func:`_sphere_contacts` over every triangle, no culling: the brute-force backend (the
    reference).  A kernel of its own, so game code never compiles a second copy of the inlined
    closest-point routine."""
    px, py, pz = center[0], center[1], center[2]
    r2 = radius * radius
    tmp = np.empty(6)
    n = np.int64(0)
    for f in range(triangles.shape[0]):
        n = _face_contact(f, triangles[f, 0], triangles[f, 1], triangles[f, 2], px, py, pz, radius, r2,
                          points, triangles, tmp, n, tri_out, point_out, normal_out, depth_out, bary_out)
    return n


# -- surface points ----------------------------------------------------------------------------


@njit(cache=True, fastmath=FASTMATH_OFF)
def _ready_faces(tri, face_part, ready, version, lz, points, part_chunks, chunk_sph):
    """Make the corners of triangles ``tri`` valid at pose ``version`` without skinning the
    rest: prepare (:func:`_prepare_part`) each holding part not yet ``ready``.  Returns False,
    touching nothing, when an index is outside ``0 .. len(face_part) - 1``."""
    F = face_part.shape[0]
    for i in range(tri.shape[0]):
        if tri[i] < 0 or tri[i] >= F:
            return False
    if lz[0] == version:
        return True
    for i in range(tri.shape[0]):
        p = face_part[tri[i]]
        if ready[p] != version:
            _prepare_part(p, version, lz, points, part_chunks, chunk_sph)
            ready[p] = version
    return True


@njit(cache=True, fastmath=FASTMATH_OFF)
def _surface_frame(points, triangles, tri, bary, out):
    """The frame of surface points (tri (C,), barycentric bary (C, 3)) on the posed ``points``
    (V, 3) float32: out (6,) = [centroid of the points, unit mean of their triangles' unit
    normals (counter-clockwise = outward; zeros if they cancel or C = 0)].  What
    :func:`_surface_points` and :func:`_face_normals` give, fused into one pass.  Returns False,
    writing nothing, when an index is outside ``0 .. len(triangles) - 1``."""
    C = tri.shape[0]
    F = triangles.shape[0]
    for i in range(C):
        if tri[i] < 0 or tri[i] >= F:
            return False
    for k in range(6):
        out[k] = 0.0
    for i in range(C):
        f = tri[i]
        a, b, c = triangles[f, 0], triangles[f, 1], triangles[f, 2]
        ax, ay, az = np.float64(points[a, 0]), np.float64(points[a, 1]), np.float64(points[a, 2])
        bx, by, bz = np.float64(points[b, 0]), np.float64(points[b, 1]), np.float64(points[b, 2])
        cx, cy, cz = np.float64(points[c, 0]), np.float64(points[c, 1]), np.float64(points[c, 2])
        u, v, w = bary[i, 0], bary[i, 1], bary[i, 2]
        out[0] += u * ax + v * bx + w * cx
        out[1] += u * ay + v * by + w * cy
        out[2] += u * az + v * bz + w * cz
        e1x, e1y, e1z = bx - ax, by - ay, bz - az
        e2x, e2y, e2z = cx - ax, cy - ay, cz - az
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        ln = math.sqrt(nx * nx + ny * ny + nz * nz)
        if ln > 0.0:
            out[3] += nx / ln
            out[4] += ny / ln
            out[5] += nz / ln
    if C > 0:
        for k in range(3):
            out[k] /= C
    ln = math.sqrt(out[3] * out[3] + out[4] * out[4] + out[5] * out[5])
    if ln > 0.0:
        for k in range(3, 6):
            out[k] /= ln
    return True


@njit(cache=True, fastmath=FASTMATH_OFF)
def _surface_points(points, triangles, tri, bary, out):
    """World positions of barycentric points on triangles: out[i] = sum_k bary[i,k] * p[tri[i],k]."""
    for i in range(tri.shape[0]):
        f = tri[i]
        a, b, c3 = triangles[f, 0], triangles[f, 1], triangles[f, 2]
        for c in range(3):
            out[i, c] = (bary[i, 0] * points[a, c] + bary[i, 1] * points[b, c]
                         + bary[i, 2] * points[c3, c])


@njit(cache=True, fastmath=FASTMATH_OFF)
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


@njit(cache=True, fastmath=FASTMATH_OFF)
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
