"""The slow, readable query references (references/naive_queries.py) checked on cases solved by hand."""

from __future__ import annotations

import numpy as np

from references.naive_queries import naive_raycast, closest_point_on_triangles, naive_push, naive_carry, inside_closed_mesh


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


def test_push_reference_clears_planes():
    # one plane: the push is the depth along its normal
    assert np.allclose(naive_push([[0, 1, 0]], [0.3]), [0, 0.3, 0])
    # a crease of two planes at 90 degrees: along the bisector, far enough to clear both
    n = np.array([[1, 0, 0], [0, 1, 0]], float)
    push = naive_push(n, [0.2, 0.2])
    assert np.all(n @ push >= 0.2 - 1e-12)
    assert np.allclose(naive_push(n, [0.001, 0.002], tolerance=0.01), 0)


def test_carry_reference_is_a_rigid_turn():
    rng = np.random.default_rng(4)
    for _ in range(20):
        n0, n1 = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 3)))
        if n0 @ n1 < -0.9:
            continue
        a0, a1, p = rng.normal(size=(3, 3))
        q = naive_carry(p, a0, n0, a1, n1)
        assert np.isclose(np.linalg.norm(q - a1), np.linalg.norm(p - a0))
        assert np.isclose((q - a1) @ n1, (p - a0) @ n0)  # height above the surface kept
        assert np.allclose(naive_carry(a0 + n0, a0, n0, a1, n1), a1 + n1)


def test_inside_reference_on_a_cube():
    import trimesh

    box = trimesh.creation.box()
    assert inside_closed_mesh(box.vertices, box.faces, np.array([0.1, 0.05, -0.2]))
    assert not inside_closed_mesh(box.vertices, box.faces, np.array([0.7, 0.0, 0.0]))
