"""Small synthetic skinned meshes for the stage tests (no files, fully deterministic)."""

from __future__ import annotations

import numpy as np

from colossus.pipeline.model import Clip, SkinnedMesh


def translate(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def rot(axis, angle):
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def tube_geometry(around=16, rings=10, length=3.0, radius=0.4):
    """Closed capped cylinder along +Y from y=0 to y=length, outward-facing.

    Returns positions (n, 3) float64 and triangles (m, 3) int64."""
    theta = 2 * np.pi * np.arange(around) / around
    ys = np.linspace(0.0, length, rings)
    ring = np.stack([radius * np.cos(theta), np.zeros(around), radius * np.sin(theta)], 1)
    pos = np.concatenate([ring + [0, y, 0] for y in ys] + [[[0, 0, 0]], [[0, length, 0]]])
    vid = lambda i, s: i * around + s % around  # noqa: E731
    tris = []
    for i in range(rings - 1):
        for s in range(around):
            a, b, c, d = vid(i, s), vid(i, s + 1), vid(i + 1, s + 1), vid(i + 1, s)
            tris += [(a, c, b), (a, d, c)]
    bottom, top = rings * around, rings * around + 1
    for s in range(around):
        tris.append((bottom, vid(0, s), vid(0, s + 1)))
        tris.append((top, vid(rings - 1, s + 1), vid(rings - 1, s)))
    return pos, np.array(tris, dtype=np.int64)


def chain_weights(y, length, k=4, sigma=None):
    """Smooth weights of a 3-joint chain along Y; (n, k) joints and weights, padded with weight 0."""
    centers = np.array([1, 3, 5]) * length / 6
    sigma = sigma or length / 5
    w = np.exp(-(((y[:, None] - centers[None]) / sigma) ** 2))
    w /= w.sum(1, keepdims=True)
    ji = np.zeros((len(y), k), np.int32)
    jw = np.zeros((len(y), k), np.float32)
    ji[:, :3] = [0, 1, 2]
    jw[:, :3] = w
    return ji, jw


def make_tube(around=16, rings=10, length=3.0, radius=0.4, frames=5, offset=(0.3, -0.2, 0.1)):
    """A capped tube skinned to a 3-joint chain (root at y=0, then y=L/3, y=2L/3) with two clips
    that bend and twist it; ``geom_bind`` is a translation by ``offset`` (mesh -> skeleton)."""
    pos, tris = tube_geometry(around, rings, length, radius)
    ji, jw = chain_weights(pos[:, 1], length)
    seg = length / 3
    bind = np.stack([translate(0, 0, 0), translate(0, seg, 0), translate(0, 2 * seg, 0)])
    rest = np.stack([translate(0, 0, 0), translate(0, seg, 0), translate(0, seg, 0)])
    t = np.linspace(0, 1, frames)
    bend = np.empty((frames, 3, 4, 4))
    twist = np.empty((frames, 3, 4, 4))
    for f, a in enumerate(t):
        bend[f, 0] = translate(0.2 * a, 0, 0) @ rot("y", 0.3 * a)
        bend[f, 1] = translate(0, seg, 0) @ rot("z", 1.2 * a)
        bend[f, 2] = translate(0, seg, 0) @ rot("z", 0.9 * a) @ rot("x", 0.4 * a)
        twist[f, 0] = rot("x", -0.5 * a)
        twist[f, 1] = translate(0, seg, 0) @ rot("y", 2.0 * a)
        twist[f, 2] = translate(0, seg, 0) @ rot("x", -1.1 * a)
    return SkinnedMesh(
        positions=pos - np.asarray(offset),
        triangles=tris,
        joint_indices=ji,
        joint_weights=jw,
        joint_names=("root", "mid", "tip"),
        parents=np.array([-1, 0, 1]),
        bind_transforms=bind,
        rest_transforms=rest,
        geom_bind=translate(*offset),
        clips=(Clip("bend", np.arange(frames, dtype=float), bend),
               Clip("twist", np.arange(frames, dtype=float), twist)),
        source={"synthetic": "tube"},
    )


def rigid_mesh(positions, triangles, joint_names=("root",)):
    """A mesh fully skinned to joint 0 of a one-joint skeleton, no clips."""
    n = len(positions)
    b = len(joint_names)
    return SkinnedMesh(
        positions=positions,
        triangles=triangles,
        joint_indices=np.zeros((n, 1), np.int32),
        joint_weights=np.ones((n, 1), np.float32),
        joint_names=joint_names,
        parents=np.arange(b) - 1,
        bind_transforms=np.tile(np.eye(4), (b, 1, 1)),
        rest_transforms=np.tile(np.eye(4), (b, 1, 1)),
    )


def icosphere(subdivisions=2, radius=1.0, center=(0, 0, 0)):
    """Outward-facing icosphere (positions, triangles) from trimesh."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(s.vertices) + np.asarray(center), np.asarray(s.faces, dtype=np.int64)


def split_corners(mesh: SkinnedMesh, permute_columns=False, seed=0) -> SkinnedMesh:
    """Every triangle corner becomes its own vertex (positions and influences copied); with
    ``permute_columns`` each copy's influence columns are shuffled."""
    t = mesh.triangles.reshape(-1)
    ji, jw = mesh.joint_indices[t].copy(), mesh.joint_weights[t].copy()
    if permute_columns:
        rng = np.random.default_rng(seed)
        perm = np.argsort(rng.random(ji.shape), axis=1)
        ji, jw = np.take_along_axis(ji, perm, 1), np.take_along_axis(jw, perm, 1)
    return mesh.replace(positions=mesh.positions[t], triangles=np.arange(len(t)).reshape(-1, 3),
                        joint_indices=ji, joint_weights=jw, parts=None)


def mobius(n=24, width=0.3):
    """A triangulated Möbius strip (non-orientable): positions and triangles."""
    pts = []
    for i in range(n):
        a = 2 * np.pi * i / n
        for s in (-1, 1):
            r = 1 + s * width * np.cos(a / 2)
            pts.append((r * np.cos(a), r * np.sin(a), s * width * np.sin(a / 2)))
    tris = []
    for i in range(n):
        a, b = 2 * i, 2 * i + 1
        if i + 1 < n:
            c, d = 2 * (i + 1) + 1, 2 * (i + 1)
        else:  # the half twist: the rows swap where the strip closes
            c, d = 0, 1
        tris += [(a, b, c), (a, c, d)]
    return np.array(pts), np.array(tris, dtype=np.int64)
