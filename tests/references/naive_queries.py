"""Slow, readable references for the runtime query kernels (stumpy-style); checked on cases solved by
hand in ``tests/runtime/test_naive_queries.py``.

Nothing here is clever: every function is a direct transcription of its definition, vectorised
over triangles with numpy at most. The runtime tests compare the fast kernels with these.
"""

from __future__ import annotations

import numpy as np


def cross(x, y):
    """Cross products along the first axis of (3, ...) arrays (components first: numpy's
    ``np.cross`` is several times slower on many rows)."""
    return np.array([x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]])


def ray_triangles(o, d, a, b, c):
    """Möller-Trumbore of one ray (origin ``o``, unit direction ``d``, (3,)) against triangles
    with corners ``a, b, c`` (n, 3), both sides: ``t, u, v`` (n,) each, ``t = inf`` where the ray
    misses (u, v are the weights of the 2nd and 3rd corner)."""
    a, b, c = (np.asarray(x, dtype=np.float64).T for x in (a, b, c))  # (3, n)
    e1, e2 = b - a, c - a
    pv = cross(np.broadcast_to(d[:, None], e2.shape), e2)
    det = (e1 * pv).sum(0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = o[:, None] - a
        u = (s * pv).sum(0) / det
        q = cross(s, e1)
        v = d @ q / det
        t = (e2 * q).sum(0) / det
        ok = (det != 0) & (u >= 0) & (u <= 1) & (v >= 0) & (u + v <= 1) & (t >= 0)
    return np.where(ok, t, np.inf), u, v


def naive_raycast(points, triangles, origins, directions, max_distance=np.inf):
    """Nearest hit over ALL triangles for each ray (Möller-Trumbore in numpy, both sides; ties
    to the lowest triangle index).

    Returns distance (R,), triangle (R,), barycentric (R, 3); a miss: inf, -1, zeros."""
    p = np.asarray(points, dtype=np.float64)
    a, b, c = p[triangles[:, 0]], p[triangles[:, 1]], p[triangles[:, 2]]
    R = len(origins)
    dist = np.full(R, np.inf)
    tri = np.full(R, -1)
    bary = np.zeros((R, 3))
    for r in range(R):
        d = directions[r] / np.linalg.norm(directions[r])
        t, u, v = ray_triangles(np.asarray(origins[r], dtype=np.float64), d, a, b, c)
        ok = np.isfinite(t) & (t <= max_distance)
        if ok.any():
            i = np.nonzero(ok)[0][np.argmin(t[ok])]
            dist[r], tri[r] = t[i], i
            bary[r] = (1 - u[i] - v[i], u[i], v[i])
    return dist, tri, bary


def closest_point_on_segment(p, a, b):
    ab = b - a
    ll = np.einsum("ij,ij->i", ab, ab)
    t = np.where(ll > 0, np.einsum("ij,ij->i", p - a, ab) / np.where(ll > 0, ll, 1), 0.0)
    t = np.clip(t, 0, 1)
    return a + t[:, None] * ab, t


def closest_point_on_triangles(p, a, b, c):
    """Closest point of each triangle (n, 3) to ``p`` (3,): the plane projection when it falls
    inside the triangle, else the nearest of the three edge closest points (a different route
    from Ericson's Voronoi regions). Returns points (n, 3) and barycentrics (n, 3)."""
    n = len(a)
    P = np.broadcast_to(p, (n, 3))
    nrm = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", nrm, nrm)
    good = nn > 1e-30
    proj = P - (np.einsum("ij,ij->i", P - a, nrm) / np.where(good, nn, 1))[:, None] * nrm
    # barycentric of the projection by sub-areas
    with np.errstate(divide="ignore", invalid="ignore"):
        wa = np.einsum("ij,ij->i", np.cross(b - proj, c - proj), nrm) / nn
        wb = np.einsum("ij,ij->i", np.cross(c - proj, a - proj), nrm) / nn
    wc = 1 - wa - wb
    inside = good & (wa >= 0) & (wb >= 0) & (wc >= 0)
    cands, bars = [], []
    for (s, e, i, j) in ((a, b, 0, 1), (b, c, 1, 2), (c, a, 2, 0)):
        q, t = closest_point_on_segment(P, s, e)
        bb = np.zeros((n, 3))
        bb[:, i] = 1 - t
        bb[:, j] = t
        cands.append(q)
        bars.append(bb)
    cands, bars = np.stack(cands), np.stack(bars)
    k = np.argmin(np.linalg.norm(cands - P[None], axis=2), 0)
    point = cands[k, np.arange(n)]
    bary = bars[k, np.arange(n)]
    point[inside] = proj[inside]
    bary[inside] = np.stack([wa, wb, wc], 1)[inside]
    return point, bary


def naive_sphere_contacts(points, triangles, center, radius):
    """Every triangle (over ALL triangles) within ``radius``: triangle, point, depth, bary."""
    p = np.asarray(points, dtype=np.float64)
    q, bary = closest_point_on_triangles(np.asarray(center, float), p[triangles[:, 0]],
                                         p[triangles[:, 1]], p[triangles[:, 2]])
    d = np.linalg.norm(q - center, axis=1)
    idx = np.nonzero(d <= radius)[0]
    return idx, q[idx], radius - d[idx], bary[idx]


def naive_skin(rest, ji, jw, skel, inv_bind, geom_bind, local_to_world):
    """Linear-blend skinning, a python loop over influences (column-vector matrices)."""
    hom = np.c_[np.asarray(rest, np.float64), np.ones(len(rest))] @ geom_bind.T
    out = np.zeros((len(rest), 4))
    for i in range(ji.shape[1]):
        m = skel[ji[:, i]] @ inv_bind[ji[:, i]]
        out += jw[:, i, None] * np.einsum("vij,vj->vi", m, hom)
    out[:, 3] = 1.0
    return (out @ local_to_world.T)[:, :3]


# -- character controller (runtime.kernels.contact, behind runtime.controller) -----------------


def naive_push(normal, pen, tolerance=0.0, cap=np.inf):
    """The controller's resolution push, written out: the direction is the normalised sum of
    ``pen_i * n_i`` over the penetrating contacts (pen_i > 0); the length is the largest
    ``pen_i / (n_i . u)`` over those facing it (n_i . u > 0.2), at most ``cap``; zero when no
    contact is deeper than ``tolerance``."""
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    pen = np.asarray(pen, dtype=np.float64).reshape(-1)
    if len(pen) == 0 or pen.max() <= tolerance:
        return np.zeros(3)
    m = pen > 0
    w = (pen[m, None] * n[m]).sum(0)
    if not np.linalg.norm(w) > 0:
        return np.zeros(3)
    u = w / np.linalg.norm(w)
    c = n[m] @ u
    ok = c > 0.2
    s = float((pen[m][ok] / c[ok]).max()) if ok.any() else 0.0
    return u * min(s, cap)


def naive_carry(position, a0, n0, a1, n1):
    """``position`` moved with a surface frame: translated from a0 to a1 and turned about
    ``n0 x n1`` by the angle between the unit normals (scipy's Rotation; not for opposite
    normals)."""
    from scipy.spatial.transform import Rotation

    axis = np.cross(n0, n1)
    s, c = np.linalg.norm(axis), float(np.dot(n0, n1))
    rot = Rotation.identity() if s < 1e-15 else Rotation.from_rotvec(axis / s * np.arctan2(s, c))
    return np.asarray(a1, float) + rot.apply(np.asarray(position, float) - a0)


def naive_along(move, normal, speed):
    """``move`` projected on the plane of unit ``normal``, rescaled to its own length, x speed."""
    move, normal = np.asarray(move, float), np.asarray(normal, float)
    t = move - np.dot(move, normal) * normal
    if np.linalg.norm(t) == 0:
        return np.zeros(3)
    return t / np.linalg.norm(t) * np.linalg.norm(move) * speed


def inside_closed_mesh(points, triangles, p, direction=(0.3, 0.9, 0.31)):
    """Is ``p`` inside the closed mesh: the parity of the crossings of a ray from ``p``
    (Moller-Trumbore over all triangles, every hit counted)."""
    P = np.asarray(points, dtype=np.float64)
    a, b, c = P[triangles[:, 0]], P[triangles[:, 1]], P[triangles[:, 2]]
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    e1, e2 = b - a, c - a
    pv = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, pv)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = p - a
        u = np.einsum("ij,ij->i", s, pv) / det
        q = np.cross(s, e1)
        v = q @ d / det
        t = np.einsum("ij,ij->i", e2, q) / det
    hits = (det != 0) & (u >= 0) & (u <= 1) & (v >= 0) & (u + v <= 1) & (t > 0)
    return bool(hits.sum() % 2)


# -- the references themselves ----------------------------------------------------------------
