"""Sound bounds on where a part's skinned vertices can be, without skinning them.

Shared by the runtime (culling spheres, certifying the spheres of any pose), the frame proof
(tiers K and D) and the continuous-time certificate.  Everything is float64, column-vector.

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

from .config import FASTMATH_PROOF as _FM
from .skin import PARALLEL_WORK, skin_frames

#: Relative padding of every bound (float64 rounding of the few dozen operations behind it).
ROUND = 1e-12


@njit(cache=True, fastmath=_FM)
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


@njit(cache=True, fastmath=_FM)
def _colmax(m):
    """Largest column norm of the 3x3 part of ``m`` (the contract's radius scale)."""
    s = 0.0
    for c in range(3):
        n = math.sqrt(m[0, c] * m[0, c] + m[1, c] * m[1, c] + m[2, c] * m[2, c])
        if n > s:
            s = n
    return s


@njit(cache=True, fastmath=_FM)
def _xf(m, x, y, z):
    """``m @ (x, y, z, 1)`` for a 4x4 (or 3x4) column-vector ``m``: three float64."""
    return (m[0, 0] * x + m[0, 1] * y + m[0, 2] * z + m[0, 3], m[1, 0] * x + m[1, 1] * y + m[1, 2] * z + m[1, 3],
            m[2, 0] * x + m[2, 1] * y + m[2, 2] * z + m[2, 3])


@njit(cache=True, inline="always", fastmath=_FM)
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


@njit(cache=True, parallel=True, fastmath=_FM)
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


@njit(cache=True, fastmath=_FM)
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
    kept = []
    kw = np.empty((0, w.shape[1]))
    for i in order:
        if len(kept) and np.any(np.all(kw >= w[i], axis=1)):
            continue
        kept.append(i)
        if len(kept) > limit:
            return None
        kw = np.vstack([kw, w[i:i + 1]])
    return np.array(kept, dtype=np.int64)


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


@njit(cache=True, fastmath=_FM)
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


# ------------------------------------------------------------------ continuous time (chords)
#: The chord bounds below are numpy over the one skinning kernel (no kernel of their own to
#: compile on a new user's first import or validation); the chain bounds are a kernel (numpy was
#: 10x slower on the proof benchmark).
#: :func:`chord_tasks` handles at most this many (task, vertex, influence) terms at once.
CHORD_BLOCK = 1 << 14


@njit(cache=True, inline="always", fastmath=_FM)
def _chain_task(i, k, L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius, pair_part, part_centers, e0, e1, delta, lam, pert):
    """Pair ``k`` over interval ``i`` of :func:`_chain_bounds_serial`."""
    a0x, a0y, a0z = pj_center[k, 0], pj_center[k, 1], pj_center[k, 2]
    a1x, a1y, a1z = a0x, a0y, a0z
    r = pj_radius[k]
    m = math.sqrt(a0x * a0x + a0y * a0y + a0z * a0z) + r
    v = 0.0
    a = 0.0
    lm = 1.0
    pe = 0.0
    for s in range(path_off[k], path_off[k + 1]):
        j = path_j[s]
        if path_dir[s] > 0:
            n0, n1, n2 = fw[i, j, 0], fw[i, j, 1], fw[i, j, 2]
            mz = m
            vz = v
            pe = n0 * pe + eps[i, j, 0] * m
            a0x, a0y, a0z = _xf(L0[i, j], a0x, a0y, a0z)
            a1x, a1y, a1z = _xf(L1[i, j], a1x, a1y, a1z)
        else:
            n0, n1, n2 = iv[i, j, 0], iv[i, j, 1], iv[i, j, 2]
            zx, zy, zz = a0x - L0[i, j, 0, 3], a0y - L0[i, j, 1, 3], a0z - L0[i, j, 2, 3]
            wx, wy, wz = a1x - L1[i, j, 0, 3], a1y - L1[i, j, 1, 3], a1z - L1[i, j, 2, 3]
            mz = max(math.sqrt(zx * zx + zy * zy + zz * zz), math.sqrt(wx * wx + wy * wy + wz * wz)) + a / 8.0 + r * lm
            vz = v + dt[i, j]
            pe = n0 * pe + eps[i, j, 1] * mz
            a0x, a0y, a0z = _xf(Li0[i, j], a0x, a0y, a0z)
            a1x, a1y, a1z = _xf(Li1[i, j], a1x, a1y, a1z)
        # forward p = T + F q: |p'| <= dt + n1 m + n0 v, |p''| <= n2 m + 2 n1 v + n0 a;
        # inverse p = F^-1 (q - T): the same with m -> m_z and v -> v + dt (and no dt term)
        v, a = n1 * mz + n0 * vz + (dt[i, j] if path_dir[s] > 0 else 0.0), n2 * mz + 2.0 * n1 * vz + n0 * a
        lm = lm * n0
        m = max(math.sqrt(a0x * a0x + a0y * a0y + a0z * a0z),
                math.sqrt(a1x * a1x + a1y * a1y + a1z * a1z)) + a / 8.0 + r * lm
    p = pair_part[k]
    cx, cy, cz = part_centers[p, 0], part_centers[p, 1], part_centers[p, 2]
    e0[i, k] = math.sqrt((a0x - cx) ** 2 + (a0y - cy) ** 2 + (a0z - cz) ** 2)
    e1[i, k] = math.sqrt((a1x - cx) ** 2 + (a1y - cy) ** 2 + (a1z - cz) ** 2)
    delta[i, k] = a / 8.0 * (1.0 + 1e-9)
    lam[i, k] = lm
    pert[i, k] = pe * (1.0 + 1e-9)


@njit(cache=True, fastmath=_FM)
def _chain_bounds_serial(L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius, pair_part, part_centers, e0, e1, delta, lam, pert):
    """Deviation-from-chord bounds of every (part, joint) ball over every interval.

    For interval ``i`` (normalised time ``tau`` in [0, 1]) and pair ``k`` (part P of joint J,
    joint b, ball (c, r) in b's bind space) the ball moves in J's space by the chain
    ``A(tau) = G_J^-1 G_b`` = the path factors ``path_j[path_off[k]:path_off[k+1]]``, innermost
    first: forward local transforms ``L_j`` (``path_dir`` +1, from b up to the common ancestor)
    then inverse ones ``L_j^-1`` (-1, down to J).  Per joint and interval: ``L0/L1`` (I, J, 4, 4)
    the local transform at the two samples, ``Li0/Li1`` their inverses, ``fw/iv`` (I, J, 3) the
    bounds ``(n0, n1, n2)`` on the norms of the linear part of the factor and of its first and
    second derivative in tau, ``dt`` (I, J) the change of its translation.

    Recursion over the factors (``q`` the moving point, ``m, v, a`` bounds of ``|q|``, ``|q'|``,
    ``|q''|`` over tau, for every point of the ball; ``lm`` of the norm of the product so far):

    * forward ``p = T + F q`` (F = R S): ``|p'| <= dt + n1 m + n0 v``,
      ``|p''| <= n2 m + 2 n1 v + n0 a`` (T is linear in tau: no T'');
    * inverse ``p = F^-1 (q - T)``: with ``m_z >= sup |q - T|``, ``|p'| <= n1 m_z + n0 (v + dt)``,
      ``|p''| <= n2 m_z + 2 n1 (v + dt) + n0 a``;
    * after each factor ``m = max(|q(0)|, |q(1)|) + a / 8 + r lm`` (the ball's centre is
      computed exactly at both samples; between them it is within ``a / 8`` of its chord, and the
      ball adds ``lm r``).

    ``eps`` (I, J, 2): bounds of the error of the factor's linear part (forward, inverse) from
    UsdSkel's half-precision scale lerp (not smooth, so not in ``a``): ``pert`` accumulates it,
    ``pert <- n0 pert + eps m`` (the input's magnitude), and bounds how far the point is from the
    smooth path; unlike ``delta`` it does not shrink when the interval is subdivided.

    Outputs (I, M): ``e0, e1`` = |A(0) c - c_P|, |A(1) c - c_P| (J space), ``delta = a / 8``
    bounds the distance of every point of the moving ball from its chord for every tau (the
    vector form of the linear-interpolation error, ``|p(tau) - chord| <= tau (1 - tau) / 2 sup
    |p''|``), ``lam`` bounds the norm of A's linear part."""
    M = pj_center.shape[0]
    for task in range(L0.shape[0] * M):
        _chain_task(task // M, task % M, L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius, pair_part, part_centers, e0, e1, delta, lam, pert)


@njit(cache=True, parallel=True, fastmath=_FM)
def _chain_bounds_parallel(L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius, pair_part, part_centers, e0, e1, delta, lam, pert):
    """:func:`_chain_bounds_serial` over threads (large inputs; see :func:`chain_bounds`)."""
    M = pj_center.shape[0]
    for task in prange(L0.shape[0] * M):
        _chain_task(task // M, task % M, L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius, pair_part, part_centers, e0, e1, delta, lam, pert)


#: Below this many path factors in all (intervals x factors) :func:`chain_bounds` runs the
#: vectorised numpy recursion (:func:`_chain_bounds_numpy`): a demo-sized clip takes a few
#: milliseconds so, and not compiling saves ~1.2 s of a cold start.
CHAIN_KERNEL_MIN = 100_000


def chain_bounds(L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius, pair_part, part_centers, e0, e1, delta, lam, pert, compiled=None):
    """Run :func:`_chain_bounds_serial` (or its threaded twin on large inputs: more than
    :data:`PARALLEL_WORK` path factors in all; or, below :data:`CHAIN_KERNEL_MIN`, the same
    recursion vectorised in numpy; ``compiled`` forces the choice)."""
    work = L0.shape[0] * int(path_off[-1]) if len(path_off) else 0
    if compiled is None:
        compiled = work >= CHAIN_KERNEL_MIN
    if not compiled:
        _chain_bounds_numpy(L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius,
                            pair_part, part_centers, e0, e1, delta, lam, pert)
        return
    kern = _chain_bounds_parallel if work > PARALLEL_WORK else _chain_bounds_serial
    kern(L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius, pair_part, part_centers, e0, e1, delta, lam, pert)


def _chain_bounds_numpy(L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius,
                        pair_part, part_centers, e0, e1, delta, lam, pert):
    """:func:`_chain_task` for every (interval, pair) at once, one path step at a time (the
    pairs whose path is that long); the same operations, so the same bounds."""
    I, M = L0.shape[0], pj_center.shape[0]
    if I == 0 or M == 0:
        return
    lens = np.diff(path_off)
    c = np.broadcast_to(pj_center, (I, M, 3))
    a0, a1 = c.copy(), c.copy()
    r = np.asarray(pj_radius, dtype=np.float64)[None]
    m = np.sqrt(np.einsum("imk,imk->im", a0, a0)) + r
    v, a, lm, pe = np.zeros((I, M)), np.zeros((I, M)), np.ones((I, M)), np.zeros((I, M))

    def xf(T, p):  # (I, K, 4, 4) @ (I, K, 3) points
        return np.einsum("ikab,ikb->ika", T[..., :3, :3], p) + T[..., :3, 3]

    def norm(p):
        return np.sqrt(np.einsum("ikc,ikc->ik", p, p))

    with np.errstate(invalid="ignore", over="ignore"):
        for step in range(int(lens.max(initial=0))):
            k = np.flatnonzero(lens > step)
            sidx = path_off[k] + step
            j, fwd = path_j[sidx], path_dir[sidx] > 0
            kf, jf, kb, jb = k[fwd], j[fwd], k[~fwd], j[~fwd]
            n = np.empty((I, len(k), 3))
            mz, vz = np.empty((I, len(k))), np.empty((I, len(k)))
            dtj = dt[:, j]
            if len(kf):
                n[:, fwd] = fw[:, jf]
                mz[:, fwd], vz[:, fwd] = m[:, kf], v[:, kf]
                pe[:, kf] = n[:, fwd, 0] * pe[:, kf] + eps[:, jf, 0] * m[:, kf]
                a0[:, kf], a1[:, kf] = xf(L0[:, jf], a0[:, kf]), xf(L1[:, jf], a1[:, kf])
            if len(kb):
                n[:, ~fwd] = iv[:, jb]
                z = a0[:, kb] - L0[:, jb][..., :3, 3]
                w = a1[:, kb] - L1[:, jb][..., :3, 3]
                mzb = np.maximum(norm(z), norm(w)) + a[:, kb] / 8.0 + r[:, kb] * lm[:, kb]
                mz[:, ~fwd], vz[:, ~fwd] = mzb, v[:, kb] + dt[:, jb]
                pe[:, kb] = n[:, ~fwd, 0] * pe[:, kb] + eps[:, jb, 1] * mzb
                a0[:, kb], a1[:, kb] = xf(Li0[:, jb], a0[:, kb]), xf(Li1[:, jb], a1[:, kb])
            n0, n1, n2 = n[..., 0], n[..., 1], n[..., 2]
            v[:, k] = n1 * mz + n0 * vz + np.where(fwd[None], dtj, 0.0)
            a[:, k] = n2 * mz + 2.0 * n1 * vz + n0 * a[:, k]
            lm[:, k] = lm[:, k] * n0
            m[:, k] = np.maximum(norm(a0[:, k]), norm(a1[:, k])) + a[:, k] / 8.0 + r[:, k] * lm[:, k]
        cp = part_centers[pair_part][None]
        e0[:] = norm(a0 - cp)
        e1[:] = norm(a1 - cp)
        delta[:] = a / 8.0 * (1.0 + 1e-9)
        lam[:] = lm
        pert[:] = pe * (1.0 + 1e-9)


def chord_tasks(points, ji, jw, mats, poff, pverts, centers, task_part, task_a, task_b, task_delta, task_scale,
                delta, pert):
    """Per-vertex chord bound of (part, time interval) tasks.

    Task ``t``: part ``p = task_part[t]``; the J-space skinning transforms of the interval's two
    ends are ``mats[task_a[t]]`` and ``mats[task_b[t]]`` ((T, J, 12), J = the part's joint);
    ``delta[task_delta[t]]`` (J,) the chord deviation of each joint's copy of the part's points
    over the whole sample interval, times ``task_scale[t]`` (the square of the sub-interval's
    fraction of it), plus ``pert[task_delta[t]]`` (J,) the half-precision scale rounding (not
    scaled).  For every vertex v of the part:
    ``U(v) = max(|y_v(a) - c|, |y_v(b) - c|) + sum_i |w_i(v)| (scale delta + pert)[j_i(v)]`` bounds
    ``|y_v(tau) - c|`` on the whole sub-interval (LBS is linear in the joint transforms, so the
    vertex strays from its chord by at most the weighted strays of its copies; the chord stays
    within the larger end distance).  Returns (T,) arrays: the largest U and its vertex, the largest end
    distances and their vertices.

    numpy, one part at a time: the part's vertices are skinned at every transform its tasks
    name by the one skinning kernel (:func:`runtime.kernels.skin.skin_frames`, float64)."""
    T = len(task_part)
    out_u, out_d0, out_d1 = np.empty(T), np.empty(T), np.empty(T)
    out_vu, out_v0, out_v1 = (np.full(T, -1, np.int64) for _ in range(3))
    for p in np.unique(task_part):
        t_all = np.flatnonzero(task_part == p)
        vs = pverts[poff[p]:poff[p + 1]]
        if len(vs) == 0:  # nothing to hold
            out_u[t_all], out_d0[t_all], out_d1[t_all] = -1.0, -1.0, -1.0
            continue
        step = max(1, CHORD_BLOCK // (len(vs) * ji.shape[1]))
        for s in range(0, len(t_all), step):
            _chord_block(t_all[s:s + step], p, vs, points, ji, jw, mats, centers, task_a, task_b, task_delta,
                         task_scale, delta, pert, out_u, out_vu, out_d0, out_v0, out_d1, out_v1)
    return out_u, out_vu, out_d0, out_v0, out_d1, out_v1


def _chord_block(t, p, vs, points, ji, jw, mats, centers, task_a, task_b, task_delta, task_scale, delta, pert,
                 out_u, out_vu, out_d0, out_v0, out_d1, out_v1):
    """:func:`chord_tasks` for the tasks ``t`` of part ``p`` (vertices ``vs``)."""
    need, inv = np.unique(np.r_[task_a[t], task_b[t]], return_inverse=True)
    y = skin_frames(points[vs], ji[vs], jw[vs], mats[need], dtype=np.float64)  # (R, n, 3)
    y -= centers[p]
    d = np.sqrt(np.einsum("rvi,rvi->rv", y, y))
    d = np.where(d <= 1e300, d, np.inf)  # NaN reads as far
    d0, d1 = d[inv[:len(t)]], d[inv[len(t):]]
    x = task_scale[t, None] * delta[task_delta[t]] + pert[task_delta[t]]  # (n_t, J)
    w = np.abs(jw[vs].astype(np.float64))
    dev = np.einsum("tvk,vk->tv", x[:, ji[vs]], w)
    u = np.maximum(d0, d1) + dev
    u = np.where(u <= 1e300, u, np.inf)
    for arr, vals, vout in ((out_u, u, out_vu), (out_d0, d0, out_v0), (out_d1, d1, out_v1)):
        i = np.argmax(vals, axis=1)
        arr[t] = vals[np.arange(len(t)), i]
        vout[t] = vs[i]
    out_u[t] *= (1.0 + ROUND)


# -------------------------------------------------------------------- continuous-time factors
@njit(cache=True)
def _inv_affine_into(m, out):
    """``out`` = inverse of the affine 4x4 ``m`` (last row 0 0 0 1), by the 3x3 adjugate."""
    a00, a01, a02 = m[0, 0], m[0, 1], m[0, 2]
    a10, a11, a12 = m[1, 0], m[1, 1], m[1, 2]
    a20, a21, a22 = m[2, 0], m[2, 1], m[2, 2]
    c00 = a11 * a22 - a12 * a21
    c01 = a02 * a21 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c10 = a12 * a20 - a10 * a22
    c11 = a00 * a22 - a02 * a20
    c12 = a02 * a10 - a00 * a12
    c20 = a10 * a21 - a11 * a20
    c21 = a01 * a20 - a00 * a21
    c22 = a00 * a11 - a01 * a10
    det = a00 * c00 + a01 * c10 + a02 * c20
    inv = 1.0 / det if det != 0.0 else math.inf
    out[0, 0], out[0, 1], out[0, 2] = c00 * inv, c01 * inv, c02 * inv
    out[1, 0], out[1, 1], out[1, 2] = c10 * inv, c11 * inv, c12 * inv
    out[2, 0], out[2, 1], out[2, 2] = c20 * inv, c21 * inv, c22 * inv
    for r in range(3):
        out[r, 3] = -(out[r, 0] * m[0, 3] + out[r, 1] * m[1, 3] + out[r, 2] * m[2, 3])
    out[3, 0] = out[3, 1] = out[3, 2] = 0.0
    out[3, 3] = 1.0


@njit(cache=True)
def _factor_terms(L, t, q, s, anim, omega_margin, alpha_margin, half_rel, Li, fw, iv, dt, eps, iso):
    """The kernel of :func:`factor_terms` (no fastmath: infinities are meaningful here)."""
    T, J = L.shape[0], L.shape[1]
    for k in range(T):
        for j in range(J):
            _inv_affine_into(L[k, j], Li[k, j])
    I, A = T - 1, anim.shape[0]
    for i in range(I):
        for k in range(A):
            j = anim[k]
            # rotation: GfSlerp's shortest arc between the normalised quaternions
            n0 = math.sqrt(q[i, k, 0] ** 2 + q[i, k, 1] ** 2 + q[i, k, 2] ** 2 + q[i, k, 3] ** 2)
            n1 = math.sqrt(q[i + 1, k, 0] ** 2 + q[i + 1, k, 1] ** 2 + q[i + 1, k, 2] ** 2 + q[i + 1, k, 3] ** 2)
            dot = 0.0
            for c in range(4):
                dot += (q[i, k, c] / n0) * (q[i + 1, k, c] / n1)
            sg = -1.0 if dot < 0.0 else 1.0
            dm = 0.0
            dp = 0.0
            for c in range(4):
                a0 = q[i, k, c] / n0
                a1 = sg * q[i + 1, k, c] / n1
                dm += (a0 - a1) ** 2
                dp += (a0 + a1) ** 2
            theta = 4.0 * math.atan2(math.sqrt(dm), math.sqrt(dp))
            om = omega_margin * theta
            al = alpha_margin * theta * theta
            # scales: lerped; extremes at the ends, a sign change makes the inverse unbounded
            smax = 0.0
            smin = math.inf
            ds = 0.0
            flip = False
            u0 = True
            u1 = True
            for c in range(3):
                x0, x1 = s[i, k, c], s[i + 1, k, c]
                smax = max(smax, abs(x0), abs(x1))
                smin = min(smin, abs(x0), abs(x1))
                ds = max(ds, abs(x1 - x0))
                if (x0 > 0.0) != (x1 > 0.0) or (x0 == 0.0) != (x1 == 0.0) or (x0 < 0.0) != (x1 < 0.0):
                    flip = True
                if x0 != s[i, k, 0]:
                    u0 = False
                if x1 != s[i + 1, k, 0]:
                    u1 = False
            if flip:
                smin = 0.0
            inv_s = 1.0 / smin if smin > 0.0 else math.inf
            fw[i, j, 0] = smax
            fw[i, j, 1] = om * smax + ds
            fw[i, j, 2] = al * smax + 2.0 * om * ds
            if smin > 0.0:
                iv[i, j, 0] = inv_s
                iv[i, j, 1] = ds * inv_s * inv_s + om * inv_s
                iv[i, j, 2] = 2.0 * ds * ds * inv_s ** 3 + 2.0 * om * ds * inv_s * inv_s + al * inv_s
            else:
                iv[i, j, 0] = iv[i, j, 1] = iv[i, j, 2] = math.inf
            dt[i, j] = math.sqrt((t[i + 1, k, 0] - t[i, k, 0]) ** 2 + (t[i + 1, k, 1] - t[i, k, 1]) ** 2
                                 + (t[i + 1, k, 2] - t[i, k, 2]) ** 2)
            e = half_rel * smax if ds > 0.0 else 0.0
            eps[i, j, 0] = e
            if e > 0.0:
                eps[i, j, 1] = e / (smin * (smin - e)) if smin > e else math.inf
            else:
                eps[i, j, 1] = 0.0
            iso[i, j] = u0 and u1


#: Below this many (interval, joint) pairs :func:`factor_terms` runs vectorised numpy instead of
#: the compiled kernel: a demo-sized clip is done in well under a millisecond either way, and not
#: compiling saves ~1.5 s of a cold start (``tools/compile-profile``); the benchmark's 500 frames x
#: 40 joints take the kernel (4x faster there).
FACTOR_KERNEL_MIN = 8_000


def factor_terms(L, t, q, s, anim, rest_local, omega_margin: float, alpha_margin: float, compiled=None):
    """Per sample interval and joint, the factor bounds of the continuous certificate
    (:func:`runtime.certify.factor_bounds` documents and proves them).

    Parameters
    ----------
    L : (T, J, 4, 4) float64 joint-local transforms at the samples; t, q, s : (T, A, 3 | 4 | 3)
    the animated joints' translations, (x, y, z, w) rotations and scales there; anim : (A,) int
    their joint indices; rest_local : (J, 4, 4) the other joints' constant transforms.

    Returns
    -------
    Li (T, J, 4, 4) the inverses of ``L``; fw, iv (I, J, 3) forward / inverse ``(n0, n1, n2)``;
    dt (I, J); eps (I, J, 2); iso (I, J) bool (I = T - 1).  ``compiled``: force the kernel (True)
    or the numpy path (False); default by size (:data:`FACTOR_KERNEL_MIN`).  Both are checked
    against the loop reference ``tests/references/naive.py:factor_terms``.
    """
    L = np.ascontiguousarray(L, dtype=np.float64)
    T, J = L.shape[:2]
    I = max(T - 1, 0)
    lin = np.asarray(rest_local, dtype=np.float64)[:, :3, :3]
    sv = np.linalg.svd(lin, compute_uv=False)
    fw, iv = np.zeros((I, J, 3)), np.zeros((I, J, 3))
    fw[:, :, 0] = (sv[:, 0] * (1 + 1e-12))[None]
    with np.errstate(divide="ignore"):
        iv[:, :, 0] = (np.where(sv[:, -1] > 0, 1.0 / sv[:, -1], np.inf) * (1 + 1e-12))[None]
    iso = np.repeat((sv[:, 0] - sv[:, -1] <= 1e-12 * sv[:, 0])[None], I, 0)
    dt, eps = np.zeros((I, J)), np.zeros((I, J, 2))
    f64 = (lambda a: np.ascontiguousarray(a, dtype=np.float64))
    anim = np.ascontiguousarray(anim, dtype=np.int64)
    if compiled is None:
        compiled = I * J >= FACTOR_KERNEL_MIN
    if compiled:
        Li = np.empty_like(L)
        _factor_terms(L, f64(t), f64(q), f64(s), anim, float(omega_margin), float(alpha_margin), HALF_LERP_REL,
                      Li, fw, iv, dt, eps, iso)
    else:
        Li = _inv_affine_numpy(L)
        if len(anim) and I > 0:
            _factor_terms_numpy(f64(t), f64(q), f64(s), anim, float(omega_margin), float(alpha_margin),
                                fw, iv, dt, eps, iso)
    return Li, fw, iv, dt, eps, iso


#: UsdSkel lerps half3 scales in half precision: three roundings, each within 2^-11 of the value.
HALF_LERP_REL = 3.0 * 2.0 ** -11


def _norm_last(x):
    """Euclidean norms over the last axis (``np.linalg.norm(x, axis=-1)`` without its overhead)."""
    return np.sqrt(np.einsum("...k,...k->...", x, x))


def _max3(x):
    """Largest of the last axis (length 3): numpy reduces such short axes slowly."""
    return np.maximum(np.maximum(x[..., 0], x[..., 1]), x[..., 2])


def _min3(x):
    return np.minimum(np.minimum(x[..., 0], x[..., 1]), x[..., 2])


def _inv_affine_numpy(L):
    """:func:`_inv_affine_into` vectorised over (..., 4, 4), component by component."""
    m = [[L[..., i, j] for j in range(3)] for i in range(3)]
    adj = [[m[1][1] * m[2][2] - m[1][2] * m[2][1], m[0][2] * m[2][1] - m[0][1] * m[2][2],
            m[0][1] * m[1][2] - m[0][2] * m[1][1]],
           [m[1][2] * m[2][0] - m[1][0] * m[2][2], m[0][0] * m[2][2] - m[0][2] * m[2][0],
            m[0][2] * m[1][0] - m[0][0] * m[1][2]],
           [m[1][0] * m[2][1] - m[1][1] * m[2][0], m[0][1] * m[2][0] - m[0][0] * m[2][1],
            m[0][0] * m[1][1] - m[0][1] * m[1][0]]]
    det = m[0][0] * adj[0][0] + m[0][1] * adj[1][0] + m[0][2] * adj[2][0]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_det = np.where(det != 0.0, 1.0 / np.where(det != 0.0, det, 1.0), np.inf)
    out = np.zeros_like(L)
    t = [L[..., i, 3] for i in range(3)]
    with np.errstate(invalid="ignore"):
        for i in range(3):
            for j in range(3):
                out[..., i, j] = adj[i][j] * inv_det
            out[..., i, 3] = -(out[..., i, 0] * t[0] + out[..., i, 1] * t[1] + out[..., i, 2] * t[2])
    out[..., 3, 3] = 1.0
    return out


def _factor_terms_numpy(t, q, s, a, omega_margin, alpha_margin, fw, iv, dt, eps, iso):
    """:func:`_factor_terms`'s interval loop, vectorised (fills the animated joints' columns)."""
    qn = q / _norm_last(q)[..., None]
    q0, q1 = qn[:-1], qn[1:]
    sq1 = np.where(np.einsum("iak,iak->ia", q0, q1) < 0, -1.0, 1.0)[..., None] * q1
    theta = 4.0 * np.arctan2(_norm_last(q0 - sq1), _norm_last(q0 + sq1))
    om = omega_margin * theta
    al = alpha_margin * theta ** 2
    sa = np.abs(s)
    smax = np.maximum(_max3(sa[:-1]), _max3(sa[1:]))
    smin = np.minimum(_min3(sa[:-1]), _min3(sa[1:]))
    smin = np.where(_max3(np.sign(s[:-1]) != np.sign(s[1:])), 0.0, smin)
    ds = _max3(np.abs(s[1:] - s[:-1]))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv_s = np.where(smin > 0, 1.0 / np.where(smin > 0, smin, 1.0), np.inf)
        fw[:, a] = np.stack([smax, om * smax + ds, al * smax + 2 * om * ds], -1)
        ivs = np.stack([inv_s, ds * inv_s ** 2 + om * inv_s,
                        2 * ds ** 2 * inv_s ** 3 + 2 * om * ds * inv_s ** 2 + al * inv_s], -1)
        iv[:, a] = np.where((smin > 0)[..., None] & np.isfinite(ivs), ivs, np.inf)
        dt[:, a] = _norm_last(t[1:] - t[:-1])
        e = np.where(ds > 0, HALF_LERP_REL * smax, 0.0)
        ei = np.where(e > 0, e / np.where(e > 0, smin * (smin - e), 1.0), 0.0)
    iso[:, a] = (_max3(s[:-1]) == _min3(s[:-1])) & (_max3(s[1:]) == _min3(s[1:]))  # uniform at both ends
    eps[:, a, 0] = e
    eps[:, a, 1] = np.where((e > 0) & ~(smin > e), np.inf, ei)
