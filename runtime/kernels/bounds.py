"""Sound bounds on where a part's skinned vertices can be, without skinning them.

Shared by the runtime (culling spheres, certifying the spheres of any pose), the frame proof
(tiers K and D) and the continuous-time certificate.  Everything is float64, column-vector.
Between two samples of a clip (how far a vertex strays from its chord) the bounds are in
:mod:`runtime.kernels.interval`, in the notation below.

Notation.  Joint ``b``'s stage transform at a pose is ``N_b`` (joint -> stage: ``world @ skel``),
its bind transform ``B_b``; a vertex ``v`` (mesh space) has weights ``w_b(v)`` and its copy in
``b``'s bind space is ``u_b(v) = B_b^-1 G v`` (``G`` the geomBindTransform), so its skinned
point is ``x(v) = sum_b w_b N_b u_b(v)`` (UsdSkel's LBS).  Part ``P`` belongs to joint ``J``; its
sphere at the pose is centre ``C = N_J c_P``, radius ``R = r_P mu(N_J)`` (``mu``: the largest
column norm of the 3x3 part, the contract's "largest axis scale").  For each part and each
joint ``b`` with a non-zero weight on one of its vertices (the ``pj`` CSR of
:func:`runtime.asset.part_joint_spheres`) a ball ``(c_b, r_b)`` in ``b``'s bind space holds
``u_b(v)`` for every such vertex.  Per part: ``a_P = max_v sum_b |w_b(v)|`` and
``eps_P = max_v |sum_b w_b(v) - 1|`` (1 and 0 for normalised non-negative weights, up to float32
rounding).  ``||L||`` below is an upper bound of the spectral norm of a 3x3 linear part
(:func:`_norm2`: the square root of the largest absolute row sum of ``L^T L``, Gershgorin's bound
on its largest eigenvalue; exact for a rotation times a uniform scale).

**Lemma (LBS is a weighted sum).**  ``x - C = sum_b w_b (N_b u_b - C) + (s - 1) C`` with
``s = sum_b w_b``, so ``|x - C| <= a_P max_b |N_b u_b - C| + eps_P |C|``.  For non-negative
weights summing to 1 this is the convex-hull lemma of Kavan & Zara (2005): the skinned vertex
lies in the convex hull of its bone-transformed copies.

**Test K** (:func:`_pose_bounds`, ``kb``).  ``u_b`` in the ball gives ``|N_b u_b - C| <=
|N_b c_b - C| + ||L(N_b)|| r_b``, hence every vertex of the part is within
``K = a_P max_b (|N_b c_b - C| + ||L(N_b)|| r_b) + eps_P |C|`` of ``C``.  Cost
O(parts x influencing joints).

**Test D** (``db``; the BD-tree bound of James & Pai (2004) specialised to LBS).  With
``X_b = B_J^-1 B_b`` (so ``u_J = X_b u_b``) and ``E_b = N_b - N_J X_b`` (zero in the bind pose),
``x - C = N_J (u_J - c_P) + sum_{b != J} w_b E_b u_b + (s - 1) N_J u_J``, so
``|x - C| <= ||L(N_J)|| d(v) + sum_{b != J} |w_b(v)| e_b + eps_P (||L(N_J)|| max_v d(v) + |C|)``
with ``d(v) = |u_J(v) - c_P|`` (fixed, precomputed) and ``e_b = |E_b c_b| + ||L(E_b)|| r_b``.
The right side is linear in ``(||L(N_J)||, e) >= 0``, so its maximum over the part's vertices is
reached on a vertex that no other vertex dominates in ``(d, |w_b|)`` (every coordinate >=): only
that Pareto set ``H_P`` (precomputed by :func:`pareto_set`) is visited, O(|H_P| k) per pose.

Both are sufficient: when the bound is within the part's radius (plus the proof's tolerance) the
part's sphere holds at that pose; otherwise the exact tier skins the part.  Float rounding: the
bounds are padded by :data:`ROUND` (relative) and :data:`ROUND_ABS` times the magnitudes
involved, far above float64's 1e-16 yet far below the proof's tolerance.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .config import FASTMATH_PROOF
from .skin import PARALLEL_WORK

#: Relative padding of every bound (float64 rounding of the few dozen operations behind it).
ROUND = 1e-12


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _norm2(m):
    """Upper bound of the spectral norm of the 3x3 linear part of a 4x4 ``m`` (see the module
    docstring), padded by :data:`ROUND`."""
    best = 0.0
    for i in range(3):
        row = 0.0
        for j in range(3):
            g = m[0, i] * m[0, j] + m[1, i] * m[1, j] + m[2, i] * m[2, j]
            row += abs(g)
        if row > best:
            best = row
    return math.sqrt(best) * (1.0 + ROUND)


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _colmax(m):
    """Largest column norm of the 3x3 part of ``m`` (the contract's radius scale)."""
    s = 0.0
    for c in range(3):
        n = math.sqrt(m[0, c] * m[0, c] + m[1, c] * m[1, c] + m[2, c] * m[2, c])
        if n > s:
            s = n
    return s


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _xf(m, x, y, z):
    """``m @ (x, y, z, 1)`` for a 4x4 (or 3x4) column-vector ``m``: three float64."""
    return (m[0, 0] * x + m[0, 1] * y + m[0, 2] * z + m[0, 3], m[1, 0] * x + m[1, 1] * y + m[1, 2] * z + m[1, 3],
            m[2, 0] * x + m[2, 1] * y + m[2, 2] * z + m[2, 3])


@njit(cache=True, inline="always", fastmath=FASTMATH_PROOF)
def _pose_bound(f, p, world, part_joint, part_centers, part_radii, pj_offsets, pj_joint, pj_center,
                pj_radius, pj_rel, part_wabs, part_wdev, h_offsets, h_dist, h_w, sph, kb, db, e, E):
    """Part ``p`` at pose ``f``: sphere ``sph[f, p]`` (centre, radius), bounds ``kb[f, p]`` (test
    K) and ``db[f, p]`` (test D; inf when the part has no Pareto set) on the distance of any of
    its skinned vertices from the centre.  ``e`` (>= the part's joint count,) and ``E`` (4, 4)
    are scratch."""
    J = part_joint[p]
    NJ = world[f, J]
    wx, wy, wz = _xf(NJ, part_centers[p, 0], part_centers[p, 1], part_centers[p, 2])
    sph[f, p, 0] = wx
    sph[f, p, 1] = wy
    sph[f, p, 2] = wz
    sph[f, p, 3] = part_radii[p] * _colmax(NJ)
    cnorm = math.sqrt(wx * wx + wy * wy + wz * wz)
    sJ = _norm2(NJ)
    far = 0.0
    lo, hi = pj_offsets[p], pj_offsets[p + 1]
    for i in range(lo, hi):
        b = pj_joint[i]
        ox, oy, oz = pj_center[i, 0], pj_center[i, 1], pj_center[i, 2]
        x, y, z = _xf(world[f, b], ox, oy, oz)
        d = math.sqrt((x - wx) ** 2 + (y - wy) ** 2 + (z - wz) ** 2) + _norm2(world[f, b]) * pj_radius[i]
        if not (d <= far):  # NaN reads as far
            far = d if d == d else np.inf
        e[i - lo] = 0.0
        if b == J:
            continue
        for r in range(3):  # E_b = N_b - N_J X_b (X_b = B_J^-1 B_b)
            for c in range(4):
                acc = world[f, b, r, c]
                for q in range(4):
                    acc -= NJ[r, q] * pj_rel[i, q, c]
                E[r, c] = acc
        x, y, z = _xf(E, ox, oy, oz)
        e[i - lo] = math.sqrt(x * x + y * y + z * z) + _norm2(E) * pj_radius[i]
    pad = (1.0 + ROUND)
    kb[f, p] = (part_wabs[p] * far + part_wdev[p] * cnorm) * pad
    h0, h1 = h_offsets[p], h_offsets[p + 1]
    if h1 == h0:
        db[f, p] = np.inf
        return
    best = 0.0
    dmax = 0.0
    for h in range(h0, h1):
        acc = sJ * h_dist[h]
        dmax = max(dmax, h_dist[h])
        for i in range(hi - lo):
            acc += h_w[h, i] * e[i]
        if not (acc <= best):
            best = acc if acc == acc else np.inf
    db[f, p] = (best + part_wdev[p] * (sJ * dmax + cnorm)) * pad


@njit(cache=True, parallel=True, fastmath=FASTMATH_PROOF)
def _pose_bounds(world, part_joint, part_centers, part_radii, pj_offsets, pj_joint, pj_center, pj_radius,
                 pj_rel, part_wabs, part_wdev, h_offsets, h_dist, h_w, sph, kb, db):
    """:func:`_pose_bound` for every (pose, part): world (F, J, 4, 4) joint -> stage; sph
    (F, P, 4), kb, db (F, P) out.  Threaded (large inputs only, see :func:`pose_bounds`)."""
    F, P = world.shape[0], part_joint.shape[0]
    for task in prange(F * P):
        f = task // P
        _pose_bound(f, task - f * P, world, part_joint, part_centers, part_radii, pj_offsets, pj_joint,
                    pj_center, pj_radius, pj_rel, part_wabs, part_wdev, h_offsets, h_dist, h_w, sph, kb, db,
                    np.empty(h_w.shape[1]), np.empty((4, 4)))


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _pose_bounds_serial(world, part_joint, part_centers, part_radii, pj_offsets, pj_joint, pj_center,
                        pj_radius, pj_rel, part_wabs, part_wdev, h_offsets, h_dist, h_w, sph, kb, db):
    """:func:`_pose_bounds` on one thread (the runtime's per-frame call, and small proofs)."""
    e = np.empty(h_w.shape[1])
    E = np.empty((4, 4))
    for f in range(world.shape[0]):
        for p in range(part_joint.shape[0]):
            _pose_bound(f, p, world, part_joint, part_centers, part_radii, pj_offsets, pj_joint, pj_center,
                        pj_radius, pj_rel, part_wabs, part_wdev, h_offsets, h_dist, h_w, sph, kb, db, e, E)


# ------------------------------------------------------------------------ precomputed data
#: Test D visits at most this many Pareto vertices per part (beyond it D is not worth it: the
#: exact tier costs little more).
PARETO_MAX = 96
#: Rows per block of :func:`pareto_set`'s vectorised dominance test.
_PARETO_BLOCK = 64


class BoundData:
    """Per-part data of the bounds, precomputed once per asset (:func:`bound_data`).

    Attributes (P parts, M (part, joint) pairs, H Pareto vertices)
    ----------
    part_joint (P,) int64, part_centers (P, 3) float64, part_radii (P,) float64
    pj_offsets (P+1,) int64, pj_joint (M,) int64, pj_center (M, 3), pj_radius (M,): the ball of
        each part's vertices that joint influences, in that joint's bind space
    pj_rel (M, 4, 4): ``B_J^-1 B_b``; pj_wmax (M,): the largest |weight| of that joint in the part
    part_wabs (P,): ``a_P``; part_wdev (P,): ``eps_P`` (module docstring)
    h_offsets (P+1,), h_dist (H,), h_w (H, kmax): the Pareto vertices of test D (``d(v)`` and the
        |weights| aligned with the part's pj entries); empty for a part where D is skipped
    """

    FIELDS = ("part_joint", "part_centers", "part_radii", "pj_offsets", "pj_joint", "pj_center", "pj_radius",
              "pj_rel", "part_wabs", "part_wdev", "h_offsets", "h_dist", "h_w")

    def __init__(self, **kw):
        for k in self.FIELDS + ("pj_wmax",):
            setattr(self, k, kw[k])

    def args(self):
        """The kernels' argument tuple, in :data:`FIELDS` order."""
        return tuple(getattr(self, k) for k in self.FIELDS)


def pareto_set(d, w, limit=PARETO_MAX):
    """Indices of the rows of ``(d (n,), w (n, k))`` that no other row dominates (every
    coordinate >=, one of them >); None when there are more than ``limit``."""
    n = len(d)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    _, first = np.unique(np.c_[d, w], axis=0, return_index=True)  # identical rows once
    order = first[np.argsort(-d[first], kind="stable")]  # larger d first: only later rows can be dominated
    # A row is dropped when an earlier row (in ``order``) has every weight >= its own.  Checking
    # all earlier rows drops the same rows as checking the kept ones (an earlier dropped row is
    # itself below a kept one), so it runs in blocks: each block's rows against the rows kept
    # before it and against the block's earlier rows, vectorised (was one numpy call per row).
    kept = np.zeros(0, dtype=np.int64)
    for s in range(0, len(order), _PARETO_BLOCK):
        b = order[s:s + _PARETO_BLOCK]
        wb = w[b]
        below = (wb[None, :, :] >= wb[:, None, :]).all(2)  # [i, j]: row j of the block >= row i
        out = (below & np.tri(len(b), k=-1, dtype=bool)).any(1)
        if len(kept):
            out |= (w[kept][None, :, :] >= wb[:, None, :]).all(2).any(1)
        kept = np.r_[kept, b[~out]]
        if len(kept) > limit:
            return None
    return kept


def bound_data(points, joint_indices, joint_weights, geom_bind, bind, part_joint, part_centers, part_radii,
               vert_offsets, verts, pareto_max=PARETO_MAX) -> BoundData:
    """Precompute :class:`BoundData` for an asset.

    Parameters
    ----------
    points (V, 3) float32 mesh space; joint_indices (V, k) int; joint_weights (V, k) float32;
    geom_bind (4, 4), bind (J, 4, 4) column-vector; part_joint (P,) int; part_centers (P, 3) and
    part_radii (P,) (joint space); vert_offsets (P+1,), verts: CSR of each part's vertices.
    """
    pts = np.asarray(points, dtype=np.float64)
    ji = np.asarray(joint_indices, dtype=np.int64)
    jw = np.asarray(joint_weights, dtype=np.float64)
    bind = np.asarray(bind, dtype=np.float64)
    inv_bind = np.linalg.inv(bind)
    G = np.asarray(geom_bind, dtype=np.float64)
    part_joint = np.asarray(part_joint, dtype=np.int64)
    centers = np.asarray(part_centers, dtype=np.float64).reshape(-1, 3)
    vert_offsets = np.asarray(vert_offsets, dtype=np.int64)
    verts = np.asarray(verts, dtype=np.int64)
    P, Jn = len(part_joint), len(bind)
    mesh_h = np.c_[pts, np.ones(len(pts))] @ G.T  # (V, 4) skeleton space at bind
    pj_off, pj_j, pj_c, pj_r, pj_rel, pj_wm = [0], [], [], [], [], []
    h_off, h_d, h_w = [0], [], []
    wabs = np.zeros(P)
    wdev = np.zeros(P)
    kmax = 1
    per_part_w = []
    for p in range(P):
        vs = verts[vert_offsets[p]:vert_offsets[p + 1]]
        J = int(part_joint[p])
        a = ji[vs]
        w = jw[vs]
        if len(vs):
            wabs[p] = np.abs(w).sum(1).max()
            wdev[p] = np.abs(w.sum(1) - 1.0).max()
        joints = np.unique(a[w != 0]) if len(vs) else np.zeros(0, np.int64)
        dense = np.zeros((len(vs), len(joints)))
        for c, b in enumerate(joints):
            dense[:, c] = np.where(a == b, np.abs(w), 0.0).sum(1)
            sel = dense[:, c] > 0
            u = (mesh_h[vs[sel]] @ inv_bind[b].T)[:, :3]
            lo, hi = u.min(0), u.max(0)
            ctr = (lo + hi) / 2
            rad = np.linalg.norm(u - ctr, axis=1).max()
            pj_j.append(int(b))
            pj_c.append(ctr)
            pj_r.append(rad * (1 + 1e-9) + 1e-12 * (1 + np.abs(ctr).max() + rad))
            pj_rel.append(inv_bind[J] @ bind[b])
            pj_wm.append(dense[:, c].max() if len(vs) else 0.0)
        pj_off.append(len(pj_j))
        kmax = max(kmax, len(joints))
        per_part_w.append((joints, dense))
        # test D: d(v) = |u_J(v) - c_P| and the Pareto set over (d, |w_b|, b != J)
        if len(vs):
            uJ = (mesh_h[vs] @ inv_bind[J].T)[:, :3]
            d = np.linalg.norm(uJ - centers[p], axis=1)
            wD = dense.copy()
            wD[:, joints == J] = 0.0
            keep = pareto_set(d, wD, pareto_max)
            if keep is not None:
                h_d.extend(d[keep] * (1 + 1e-12))
                h_w.extend(list(wD[keep]))
        h_off.append(len(h_d))
    hw = np.zeros((len(h_w), kmax))
    row = 0
    for p in range(P):
        n = h_off[p + 1] - h_off[p]
        k = pj_off[p + 1] - pj_off[p]
        for i in range(n):
            hw[row, :k] = h_w[row]
            row += 1
    return BoundData(
        part_joint=part_joint, part_centers=np.ascontiguousarray(centers),
        part_radii=np.ascontiguousarray(part_radii, dtype=np.float64),
        pj_offsets=np.array(pj_off, dtype=np.int64), pj_joint=np.array(pj_j, dtype=np.int64),
        pj_center=np.ascontiguousarray(np.array(pj_c, dtype=np.float64).reshape(-1, 3)),
        pj_radius=np.array(pj_r, dtype=np.float64),
        pj_rel=np.ascontiguousarray(np.array(pj_rel, dtype=np.float64).reshape(-1, 4, 4)),
        pj_wmax=np.array(pj_wm, dtype=np.float64), part_wabs=wabs, part_wdev=wdev,
        h_offsets=np.array(h_off, dtype=np.int64), h_dist=np.array(h_d, dtype=np.float64),
        h_w=np.ascontiguousarray(hw))


def pose_bounds(world, bd: BoundData, parallel=None):
    """Spheres and bounds of every part at every pose.

    Parameters
    ----------
    world : (F, J, 4, 4) or (J, 4, 4) float64 joint -> stage transforms (column-vector)
    bd : :class:`BoundData`

    Returns
    -------
    spheres (F, P, 4) centre + radius (the contract's moved sphere), kb (F, P) test K bound,
    db (F, P) test D bound (inf where D is skipped): upper bounds of the distance from the centre
    of any skinned vertex of the part.
    """
    w = np.ascontiguousarray(world, dtype=np.float64)
    if w.ndim == 3:
        w = w[None]
    F, P = w.shape[0], len(bd.part_joint)
    sph = np.empty((F, P, 4))
    kb = np.empty((F, P))
    db = np.empty((F, P))
    if parallel is None:  # a (pose, part) pair costs about as much as skinning 4 vertices
        parallel = F * len(bd.pj_joint) * 16 > PARALLEL_WORK
    (_pose_bounds if parallel else _pose_bounds_serial)(w, *bd.args(), sph, kb, db)
    return sph, kb, db


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _cull_spheres(sph, kb, db, spheres, cull):
    """spheres (P, 4) = sph[0]; cull (P, 4): same centres, radius = the better of tests K and D,
    padded for the float32 rounding of the posed points the queries read (relative 1e-5 of the
    radius plus 2e-6 of the coordinates' magnitude), so culling never drops a triangle."""
    for p in range(spheres.shape[0]):
        far = min(kb[0, p], db[0, p])
        for c in range(4):
            spheres[p, c] = sph[0, p, c]
        cx, cy, cz = sph[0, p, 0], sph[0, p, 1], sph[0, p, 2]
        cull[p, 0] = cx
        cull[p, 1] = cy
        cull[p, 2] = cz
        cull[p, 3] = far * (1.0 + 1e-5) + 2e-6 * (abs(cx) + abs(cy) + abs(cz) + far) + 1e-9
