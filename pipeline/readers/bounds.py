"""Sizes of what a reader does not carry, measured on the mesh it did read (for the
``bound_relative`` of :mod:`pipeline.notcarried` records).

Everything here works on a reader's :class:`~pipeline.model.SkinnedMesh` in the source's own
space (skeleton space = the scene's world space): its clip frames are posed by plain linear
blend skinning (:func:`~pipeline.model.skin_points`), on at most :data:`MAX_POSED_VALUES`
vertex-frames (frames evenly picked over every clip when there are more), so a bound costs a
few numpy passes even on a 200k-vertex mesh.
"""

from __future__ import annotations

import numpy as np

from ..model import SkinnedMesh, skel_transforms, skin_points
from ..tolerances import model_scale
from ..xforms import matrix_to_quat

#: Largest vertices x frames posed for a bound (memory: 24 bytes each).
MAX_POSED_VALUES = 4_000_000


def frames(mesh: SkinnedMesh) -> list:
    """``[(clip index, frame index)]`` to pose: every frame of every clip, evenly thinned to
    :data:`MAX_POSED_VALUES` / vertices; ``[(-1, -1)]`` (the bind pose) when there is no clip."""
    allf = [(ci, fi) for ci, c in enumerate(mesh.clips) for fi in range(c.frame_count)]
    if not allf:
        return [(-1, -1)]
    cap = max(2, MAX_POSED_VALUES // max(1, mesh.vertex_count))
    if len(allf) > cap:
        pick = np.unique(np.round(np.linspace(0, len(allf) - 1, cap)).astype(int))
        allf = [allf[i] for i in pick]
    return allf


def skel_at(mesh: SkinnedMesh, which) -> np.ndarray:
    """(f, b, 4, 4) skeleton-space joint transforms at ``which`` (:func:`frames`)."""
    out = []
    for ci, fi in which:
        out.append(mesh.bind_transforms if ci < 0 else skel_transforms(mesh.clips[ci].local[fi], mesh.parents))
    return np.array(out)


def posed(mesh: SkinnedMesh, which=None) -> np.ndarray:
    """(f, n, 3) linearly skinned points at ``which`` (default :func:`frames`)."""
    which = frames(mesh) if which is None else which
    return skin_points(mesh, skel_at(mesh, which))


def posed_size(mesh: SkinnedMesh, points=None) -> float:
    """The model size (the contract's posed size, over the frames posed)."""
    p = posed(mesh) if points is None else points
    return model_scale(p.reshape(-1, 3))


def dq_lbs_gap(mesh: SkinnedMesh, which=None, rows=None) -> np.ndarray:
    """(f,) largest distance, over the vertices ``rows`` (default all), between linear blend
    and dual-quaternion skinning of ``mesh`` at ``which``.

    Dual quaternions as UsdSkel blends them: each skinning matrix split into a rigid part
    (rotation by polar decomposition, translation) blended as dual quaternions, and a
    scale-shear part blended linearly and applied first."""
    which = frames(mesh) if which is None else which
    skel = skel_at(mesh, which)
    inv_bind = np.linalg.inv(mesh.bind_transforms)
    ji = mesh.joint_indices if rows is None else mesh.joint_indices[rows]
    jw = mesh.joint_weights.astype(np.float64) if rows is None else mesh.joint_weights[rows].astype(np.float64)
    p = np.c_[mesh.positions.astype(np.float64), np.ones(mesh.vertex_count)] @ mesh.geom_bind.T
    p = p[:, :3] if rows is None else p[rows, :3]
    out = np.zeros(len(which))
    for f in range(len(which)):
        m = skel[f] @ inv_bind  # (b, 4, 4)
        a = m[:, :3, :3]
        u, _, vt = np.linalg.svd(a)
        r = u @ vt
        flip = np.linalg.det(r) < 0
        if flip.any():
            u[flip, :, -1] *= -1
            r = u @ vt
        s = np.swapaxes(r, 1, 2) @ a  # a = r @ s
        q = matrix_to_quat(r)  # (b, 4) x y z w
        t = m[:, :3, 3]
        # dual part: 0.5 * (t, 0) * q
        tq = np.c_[t, np.zeros(len(t))]
        d = 0.5 * _qmul(tq, q)
        lbs = np.zeros((len(p), 3))
        qb = np.zeros((len(p), 4))
        db = np.zeros((len(p), 4))
        sb = np.zeros((len(p), 3, 3))
        ref = q[ji[:, 0]]
        for k in range(ji.shape[1]):
            w = jw[:, k]
            j = ji[:, k]
            lbs += w[:, None] * (np.einsum("nij,nj->ni", a[j], p) + t[j])
            sign = np.where(np.sum(q[j] * ref, axis=1) < 0, -1.0, 1.0)
            qb += (w * sign)[:, None] * q[j]
            db += (w * sign)[:, None] * d[j]
            sb += w[:, None, None] * s[j]
        n = np.linalg.norm(qb, axis=1, keepdims=True)
        n = np.where(n > 0, n, 1.0)
        qb, db = qb / n, db / n
        ps = np.einsum("nij,nj->ni", sb, p)
        rot = _rotate(qb, ps)
        trans = 2.0 * _qmul(db, _conj(qb))[:, :3]
        dq = rot + trans
        out[f] = float(np.linalg.norm(dq - lbs, axis=1).max()) if len(p) else 0.0
    return out


def _qmul(a, b):
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def _conj(q):
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def _rotate(q, v):
    u = q[:, :3]
    w = q[:, 3:4]
    c = np.cross(u, v)
    return v + 2.0 * (w * c + np.cross(u, c))
