"""Slow, readable references for the runtime kernels (stumpy-style), and tests of them.

Nothing here is clever: every function is a direct transcription of its definition, vectorised
over triangles with numpy at most. The runtime tests compare the fast kernels with these.
"""

from __future__ import annotations

import numpy as np


def naive_raycast(points, triangles, origins, directions, max_distance=np.inf):
    """Nearest hit over ALL triangles for each ray (Möller-Trumbore in numpy, both sides).

    Returns distance (R,), triangle (R,), barycentric (R, 3); a miss: inf, -1, zeros."""
    p = np.asarray(points, dtype=np.float64)
    a, b, c = p[triangles[:, 0]], p[triangles[:, 1]], p[triangles[:, 2]]
    e1, e2 = b - a, c - a
    R = len(origins)
    dist = np.full(R, np.inf)
    tri = np.full(R, -1)
    bary = np.zeros((R, 3))
    for r in range(R):
        o = origins[r]
        d = directions[r] / np.linalg.norm(directions[r])
        pv = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, pv)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = o - a
            u = np.einsum("ij,ij->i", s, pv) / det
            q = np.cross(s, e1)
            v = q @ d / det
            t = np.einsum("ij,ij->i", e2, q) / det
        ok = (det != 0) & (u >= 0) & (u <= 1) & (v >= 0) & (u + v <= 1) & (t >= 0) & (t <= max_distance)
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
    """Linear-blend skinning, a python loop over influences (row-vector matrices)."""
    hom = np.c_[np.asarray(rest, np.float64), np.ones(len(rest))] @ geom_bind
    out = np.zeros((len(rest), 4))
    for i in range(ji.shape[1]):
        m = inv_bind[ji[:, i]] @ skel[ji[:, i]]
        out += jw[:, i, None] * np.einsum("vi,vij->vj", hom, m)
    out[:, 3] = 1.0
    return (out @ local_to_world)[:, :3]


# -- the references themselves ----------------------------------------------------------------


def test_closest_point_reference_is_closest():
    rng = np.random.default_rng(1)
    for _ in range(20):
        a, b, c = rng.normal(size=(3, 1, 3))
        p = rng.normal(size=3) * 2
        q, bary = closest_point_on_triangles(p, a, b, c)
        w = rng.dirichlet([1, 1, 1], 20000)
        samples = w[:, :1] * a + w[:, 1:2] * b + w[:, 2:] * c
        assert np.linalg.norm(q[0] - p) <= np.linalg.norm(samples - p, axis=1).min() + 1e-12
        assert np.allclose(bary[0] @ np.concatenate([a, b, c]), q[0])


def test_raycast_reference_on_a_square():
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    o = np.array([[0.75, 0.25, 1.0], [0.25, 0.75, -2.0], [2, 2, 1]])
    d = np.array([[0, 0, -1], [0, 0, 2], [0, 0, -1]], float)
    dist, tri, bary = naive_raycast(pts, tris, o, d)
    assert np.allclose(dist[:2], [1, 2]) and dist[2] == np.inf
    assert list(tri) == [0, 1, -1]
    assert np.allclose(bary[0] @ pts[tris[0]], [0.75, 0.25, 0])

