"""Slow, readable references for the fast kernels (stumpy-style): tests compare against these.

Nothing here is clever; every function is a direct transcription of its definition.  Nothing here
imports or calls project code (``pipeline``, ``validators``, ``runtime``): a reference that called
the code under test would check it against itself.  Functions take the project's data objects
(e.g. a ``SkinnedMesh``) only to read their arrays.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.optimize import minimize, nnls


# -- weld -------------------------------------------------------------------------------------

def influences_equal(ja, wa, jb, wb, weight_tol):
    """Same set of (joint, weight) pairs with weight > 0, weights within ``weight_tol``."""
    a = sorted((int(j), float(w)) for j, w in zip(ja, wa) if w > 0)
    b = sorted((int(j), float(w)) for j, w in zip(jb, wb) if w > 0)
    if [j for j, _ in a] != [j for j, _ in b]:
        return False
    return all(abs(x - y) <= weight_tol for (_, x), (_, y) in zip(a, b))


def weld_maps(positions, joint_indices, joint_weights, tolerance, weight_tol):
    """O(n^2) weld: union-find over every pair within ``tolerance`` with equal influences.

    Returns ``keep, inverse, conflicts`` like :func:`pipeline.stages.weld.weld_maps` (conflicts
    counted as output vertices within ``tolerance`` of an output vertex with other influences).
    """
    p = np.asarray(positions, dtype=np.float64)
    n = len(p)
    parent = list(range(n))

    def find(a):
        while parent[a] != a:
            a = parent[a]
        return a

    rejected = []
    for a in range(n):
        for b in range(a + 1, n):
            if np.linalg.norm(p[a] - p[b]) <= tolerance:
                if influences_equal(joint_indices[a], joint_weights[a], joint_indices[b], joint_weights[b], weight_tol):
                    ra, rb = find(a), find(b)
                    parent[max(ra, rb)] = min(ra, rb)
                else:
                    rejected.append((a, b))
    roots = [find(a) for a in range(n)]
    keep = sorted(set(roots))
    rank = {r: i for i, r in enumerate(keep)}
    inverse = np.array([rank[r] for r in roots], dtype=np.int64)
    bad = set()
    for a, b in rejected:
        if inverse[a] != inverse[b]:
            bad.add(int(inverse[a]))
            bad.add(int(inverse[b]))
    return np.array(keep, dtype=np.int64), inverse, len(bad)


# -- orient -----------------------------------------------------------------------------------

def edge_uses(triangles):
    """{(lo, hi): [(face, forward), ...]} where forward is True when the face goes lo -> hi."""
    uses = {}
    for f, t in enumerate(np.asarray(triangles)):
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            a, b = int(a), int(b)
            if a == b:
                continue
            uses.setdefault((min(a, b), max(a, b)), []).append((f, a < b))
    return uses


def inconsistent_edges(triangles):
    """Edges shared by exactly two faces that traverse it in the same direction."""
    return sum(1 for u in edge_uses(triangles).values() if len(u) == 2 and u[0][0] != u[1][0] and u[0][1] == u[1][1])


def signed_volume(positions, triangles):
    p = np.asarray(positions, dtype=np.float64)
    t = np.asarray(triangles)
    return float(np.einsum("ij,ij->i", p[t[:, 0]], np.cross(p[t[:, 1]], p[t[:, 2]])).sum() / 6.0)


# -- parts ------------------------------------------------------------------------------------

def triangle_joint_sums(triangles, joint_indices, joint_weights):
    """One dict {joint: summed weight} per triangle (python loops)."""
    out = []
    for t in triangles:
        s = {}
        for v in t:
            for j, w in zip(joint_indices[v], joint_weights[v]):
                s[int(j)] = s.get(int(j), 0.0) + float(w)
        out.append(s)
    return out


def dominant_joints(triangles, joint_indices, joint_weights):
    """Joint with the largest summed weight per triangle, ties to the lowest joint index."""
    res = []
    for s in triangle_joint_sums(triangles, joint_indices, joint_weights):
        best = max(s.values())
        res.append(min(j for j, w in s.items() if w == best))
    return np.array(res, dtype=np.int64)


# -- skinning ---------------------------------------------------------------------------------

def skel_transforms(local, parents):
    """Skeleton-space joint transforms from joint-local ones: for each joint, the product of the
    local transforms up its parent chain (root first), with no assumption on joint order.

    local : (..., b, 4, 4) column-vector; parents : (b,) parent index or -1."""
    local = np.asarray(local, dtype=np.float64)
    out = np.empty_like(local)
    for j in range(len(parents)):
        m = local[..., j, :, :]
        p = int(parents[j])
        while p >= 0:
            m = local[..., p, :, :] @ m
            p = int(parents[p])
        out[..., j, :, :] = m
    return out


def skin_points(mesh, skel):
    """Linear-blend skinning of ``mesh`` (a ``SkinnedMesh``: positions, joint indices/weights,
    bind transforms, geom_bind) for skeleton transforms ``skel`` (f, b, 4, 4): a python loop over
    influences, one vertex at a time.  Returns (f, n, 3) float64 skeleton-space points."""
    skel = np.asarray(skel, dtype=np.float64)
    inv_bind = np.linalg.inv(mesh.bind_transforms)
    out = np.zeros((len(skel), mesh.vertex_count, 3))
    for v in range(mesh.vertex_count):
        p = mesh.geom_bind @ np.append(mesh.positions[v].astype(np.float64), 1.0)
        for j, w in zip(mesh.joint_indices[v], mesh.joint_weights[v]):
            if w != 0:
                out[:, v] += float(w) * (skel[:, j] @ inv_bind[j] @ p)[:, :3]
    return out


def skin_joint_space(mesh, joint, skel):
    """Skinned vertices of ``mesh`` in the space of ``joint`` for skeleton transforms ``skel``
    (b, 4, 4): a python loop over vertices and influences."""
    inv_bind = np.linalg.inv(mesh.bind_transforms)
    to_joint = np.linalg.inv(skel[joint])
    out = np.zeros((mesh.vertex_count, 3))
    for v in range(mesh.vertex_count):
        p = mesh.geom_bind @ np.append(mesh.positions[v].astype(np.float64), 1.0)
        acc = np.zeros(4)
        for j, w in zip(mesh.joint_indices[v], mesh.joint_weights[v]):
            if w != 0:
                acc += float(w) * (skel[j] @ inv_bind[j] @ p)
        out[v] = (to_joint @ acc)[:3]
    return out


def compose(local, parents):
    """(..., b, 4, 4) column-vector joint-local -> skeleton space, a python loop (parents first)."""
    local = np.asarray(local, dtype=np.float64)
    out = np.empty_like(local)
    for j, p in enumerate(parents):
        out[..., j, :, :] = local[..., j, :, :] if p < 0 else out[..., p, :, :] @ local[..., j, :, :]
    return out


def all_poses(mesh):
    """Skeleton transforms of the bind pose and of every clip frame, (F, b, 4, 4)."""
    poses = [np.asarray(mesh.bind_transforms, dtype=np.float64)[None]]
    for c in mesh.clips:
        poses.append(compose(c.local, mesh.parents))
    return np.concatenate(poses)


def naive_lbs(points, joint_indices, joint_weights, mats):
    """Linear-blend skinning by its definition: ``sum_k w[v, k] * mats[f, j[v, k]] @ (p[v], 1)``
    for every pose ``f`` of column-vector ``mats`` (F, J, 4, 4); (F, n, 3) float64.  Python loops
    over poses and influences; a zero weight contributes nothing (whatever its joint index)."""
    p = np.c_[np.asarray(points, dtype=np.float64), np.ones(len(points))]
    mats = np.asarray(mats, dtype=np.float64)
    out = np.zeros((len(mats), len(p), 3))
    for f in range(len(mats)):
        for k in range(joint_indices.shape[1]):
            w = np.asarray(joint_weights[:, k], dtype=np.float64)
            j = np.where(w != 0, joint_indices[:, k], 0)
            out[f] += w[:, None] * np.einsum("nij,nj->ni", mats[f][j][:, :3], p)
    return out


def naive_dqs(points, joint_indices, joint_weights, mats, geom_bind=None):
    """Dual-quaternion skinning by UsdSkel's definition (``_SkinPointsDQS`` in
    ``pxr/usd/usdSkel/utils.cpp``), one vertex at a time; (F, n, 3) float64.

    Per joint: ``A = mats[:3, :3]`` split by its polar decomposition ``A = R S`` (``R`` proper:
    negated where ``det A < 0``; ``|det A| < 1e-10`` is singular: zero dual quaternion, ``S = I``),
    the dual quaternion ``(q, (0, t/2) q)``.  Per vertex: ``p = G p``; the pivot is the first
    influence of largest weight; joints whose ``q`` has a negative dot with the pivot's enter
    with a negated weight; the blend ``(b, c)`` is normalised (identity when ``|b| < 1e-10``);
    the point is ``sum w S p`` when any joint of the pose has ``S`` not within 1e-6 of the
    identity (float32, elementwise), else ``p``; result ``R(b) p' + 2 Im(c b*) / |b|^2``."""
    from scipy.spatial.transform import Rotation

    mats = np.asarray(mats, dtype=np.float64)
    G = np.eye(4) if geom_bind is None else np.asarray(geom_bind, dtype=np.float64)
    P = np.c_[np.asarray(points, dtype=np.float64), np.ones(len(points))] @ G.T
    out = np.zeros((len(mats), len(points), 3))

    def qmul(a, b):
        w1, v1 = a[0], a[1:]
        w2, v2 = b[0], b[1:]
        return np.r_[w1 * w2 - v1 @ v2, w1 * v2 + w2 * v1 + np.cross(v1, v2)]

    for f in range(len(mats)):
        dqs, scales = [], []
        for M in mats[f]:
            A, t = M[:3, :3], M[:3, 3]
            if abs(np.linalg.det(A)) < 1e-10:
                dqs.append((np.zeros(4), np.zeros(4)))
                scales.append(np.eye(3))
                continue
            U, _, Vt = np.linalg.svd(A)
            R = U @ Vt
            if np.linalg.det(A) < 0:
                R = -R
            x, y, z, w = Rotation.from_matrix(R).as_quat()
            q = np.array([w, x, y, z])
            dqs.append((q, 0.5 * qmul(np.r_[0.0, t], q)))
            scales.append(R.T @ A)
        has_scale = any(np.any(np.abs(s.astype(np.float32) - np.eye(3)) >= 1e-6) for s in scales)
        for v in range(len(points)):
            w = np.asarray(joint_weights[v], dtype=np.float64)
            j = np.asarray(joint_indices[v])
            piv = int(np.argmax(w))  # the first of the largest
            qp = dqs[j[piv]][0]
            b, c, s = np.zeros(4), np.zeros(4), np.zeros(3)
            for k in range(len(w)):
                if w[k] == 0:
                    continue
                q, d = dqs[j[k]]
                s += w[k] * scales[j[k]] @ P[v, :3]
                sign = -1.0 if q @ qp < 0 else 1.0
                b += sign * w[k] * q
                c += sign * w[k] * d
            if not has_scale:
                s = P[v, :3]
            n = np.linalg.norm(b)
            if n < 1e-10:
                out[f, v] = s
                continue
            b, c = b / n, c / n
            bc = b * np.r_[1.0, -1, -1, -1]
            rot = qmul(qmul(b, np.r_[0.0, s]), bc)[1:]
            out[f, v] = rot + 2 * qmul(c, bc)[1:]
    return out


def trs(t, q, s):
    """(..., 4, 4) column-vector T R S from translations, (x, y, z, w) quaternions, scales
    (the unit-quaternion rotation matrix written out)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    R = np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                  np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                  np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)
    m = np.zeros(q.shape[:-1] + (4, 4))
    m[..., :3, :3] = R * np.asarray(s, dtype=np.float64)[..., None, :]
    m[..., :3, 3] = t
    m[..., 3, 3] = 1
    return m


def slerp(q0, q1, a):
    """Shortest-arc slerp of (..., 4) quaternions by ``a`` (textbook formula, sign flip)."""
    q0 = np.asarray(q0, dtype=np.float64)
    q1 = np.asarray(q1, dtype=np.float64)
    d = np.sum(q0 * q1, -1, keepdims=True)
    q1 = np.where(d < 0, -q1, q1)
    d = np.abs(d)
    th = np.arccos(np.clip(d, -1, 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        s0 = np.where(th > 1e-9, np.sin((1 - a) * th) / np.sin(th), 1 - a)
        s1 = np.where(th > 1e-9, np.sin(a * th) / np.sin(th), a)
    q = s0 * q0 + s1 * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


# -- minimal sphere ---------------------------------------------------------------------------

def circumsphere(pts):
    """Sphere through 1-4 points centred in their affine hull, or None when degenerate."""
    pts = np.asarray(pts, dtype=np.float64)
    a = pts[0]
    if len(pts) == 1:
        return a.copy(), 0.0
    A = pts[1:] - a  # rows u, v, (t)
    # centre c = a + A^T x with 2 (A A^T) x = |A_i|^2  (centre in the affine hull)
    G = A @ A.T
    rhs = 0.5 * np.einsum("ij,ij->i", A, A)
    if abs(np.linalg.det(G)) <= 1e-12 * max(np.prod(np.diag(G)), 1e-300):
        return None
    x = np.linalg.solve(G, rhs)
    c = a + A.T @ x
    return c, float(np.linalg.norm(pts - c, axis=1).max())


def min_sphere_brute(points, rel=1e-9):
    """Minimal enclosing sphere by trying every support set of size <= 4 (O(n^5))."""
    p = np.asarray(points, dtype=np.float64)
    best = None
    for size in range(1, min(4, len(p)) + 1):
        for idx in itertools.combinations(range(len(p)), size):
            s = circumsphere(p[list(idx)])
            if s is None:
                continue
            c, r = s
            if best is not None and r >= best[1]:
                continue
            if np.linalg.norm(p - c, axis=1).max() <= r * (1 + rel) + 1e-12:
                best = (c, r)
    return best


def dual_lower_bound(points, weights):
    """A lower bound of the minimal enclosing radius from any convex weights (the Lagrange dual).

    For weights ``l >= 0`` summing to 1 and ``m = sum l_i p_i``, every centre ``c`` has
    ``max_i |p_i - c|^2 >= sum l_i |p_i - c|^2 = sum l_i |p_i - m|^2 + |m - c|^2``, so
    ``sqrt(sum l_i |p_i - m|^2) <= r*``, whoever chose the weights."""
    p = np.asarray(points, dtype=np.float64)
    lam = np.clip(np.asarray(weights, dtype=np.float64), 0, None)
    lam = lam / lam.sum()
    m = lam @ p
    return float(np.sqrt(lam @ np.einsum("ij,ij->i", p - m, p - m)))


def support_weights(points, center, radius, rel=1e-9):
    """Convex weights on the points farthest from ``center`` (within ``rel`` of ``radius``) whose
    mean is as close to ``center`` as non-negative least squares gets it (the KKT condition of the
    minimal sphere: its centre is a convex combination of the boundary points)."""
    p = np.asarray(points, dtype=np.float64)
    d = np.linalg.norm(p - center, axis=1)
    on = np.nonzero(d >= radius * (1 - rel) - 1e-300)[0]
    big = 1e3 * max(radius, 1e-300)  # weighs the sum-to-one row
    A = np.vstack([(p[on] - center).T, np.full(len(on), big)])
    b = np.r_[np.zeros(3), big]
    lam_on, _ = nnls(A, b)
    lam = np.zeros(len(p))
    lam[on] = lam_on
    return lam


def min_sphere_bounds(points):
    """Bracket the minimal enclosing sphere of ``points`` (n, 3) without project code.

    Upper bound: the farthest point from the centre scipy's SLSQP finds for ``min t`` subject to
    ``|p_i - c|^2 <= t`` (any centre gives an enclosing sphere), polished by the exact sphere of
    the best support set (<= 4 points) among the points nearly farthest from it.  Lower bound:
    :func:`dual_lower_bound` with :func:`support_weights` there.  Returns ``(centre, lower,
    upper)`` with ``lower <= r* <= upper`` guaranteed (up to float64 rounding)."""
    p = np.asarray(points, dtype=np.float64)
    c0 = (p.min(0) + p.max(0)) / 2
    if len(p) > 1:
        scale = max(float(np.abs(p - c0).max()), 1e-300)
        q = (p - c0) / scale  # well-scaled for the optimiser
        t0 = float(np.einsum("ij,ij->i", q, q).max())
        res = minimize(lambda x: x[3], np.r_[0.0, 0.0, 0.0, t0], jac=lambda x: np.r_[0.0, 0.0, 0.0, 1.0],
                       method="SLSQP", options={"maxiter": 500, "ftol": 1e-15},
                       constraints=[{"type": "ineq",
                                     "fun": lambda x: x[3] - np.einsum("ij,ij->i", q - x[:3], q - x[:3]),
                                     "jac": lambda x: np.c_[2 * (q - x[:3]), np.ones(len(q))]}])
        c0 = c0 + scale * res.x[:3]
    center = c0
    upper = float(np.linalg.norm(p - center, axis=1).max())
    # polish: the exact sphere of the best support set among the points nearly farthest from the
    # centre, until that no longer improves (the optimiser stops a little short on round inputs)
    for _ in range(20):
        best = upper
        cand = np.argsort(-np.linalg.norm(p - center, axis=1))[:10]
        for size in range(1, min(4, len(cand)) + 1):
            for idx in itertools.combinations(cand, size):
                s = circumsphere(p[list(idx)])
                if s is None:
                    continue
                r = float(np.linalg.norm(p - s[0], axis=1).max())
                if r < upper:
                    center, upper = s[0], r
        if upper >= best:
            break
    lower = dual_lower_bound(p, support_weights(p, center, upper)) if upper > 0 else 0.0
    return center, min(lower, upper), upper


# -- simplify: edge collapses -----------------------------------------------------------------

def interior_vertices(triangles, n):
    """Vertices whose star is a closed disk: every incident edge in exactly two faces, opposite
    directions, and the faces around the vertex one cycle (walked face to face)."""
    uses = edge_uses(triangles)
    tris = [tuple(int(v) for v in t) for t in np.asarray(triangles)]
    out = np.zeros(n, bool)
    for v in {int(x) for t in tris for x in t}:
        faces = [f for f, t in enumerate(tris) if v in t]
        edges = [e for e in uses if v in e]
        if any(len(uses[e]) != 2 or uses[e][0][1] == uses[e][1][1] for e in edges):
            continue
        # walk the fan: from a face, cross the edge (v, w) to the other face of it
        seen, f = set(), faces[0]
        while f not in seen:
            seen.add(f)
            t = tris[f]
            w = t[(t.index(v) + 1) % 3]
            f = next(g for g, _ in uses[(min(v, w), max(v, w))] if g != f)
        out[v] = len(seen) == len(faces)
    return out


def apply_collapses(positions, triangles, collapses, stop_faces=0, limit=None, vertex_shell=None, min_cos=0.2,
                    reg=1e-3):
    """Replay ``collapses`` with the rules of :mod:`pipeline.geometry.collapse`, on python sets.

    Returns ``(positions (n, 3) of every vertex, live triangles (list of tuples), accepted
    (k,) bool)``."""
    P = np.asarray(positions, dtype=np.float64).copy()
    n = len(P)
    tris = {f: [int(v) for v in t] for f, t in enumerate(np.asarray(triangles))}
    locked = ~interior_vertices(triangles, n)
    # area-weighted plane quadrics, each face's area shared by its three corners
    A, b, w = np.zeros((n, 3, 3)), np.zeros((n, 3)), np.zeros(n)
    for t in tris.values():
        cr = np.cross(P[t[1]] - P[t[0]], P[t[2]] - P[t[0]])
        area = 0.5 * np.linalg.norm(cr)
        nrm = cr / (2 * area) if area > 0 else cr
        for v in t:
            A[v] += area / 3 * np.outer(nrm, nrm)
            b[v] += area / 3 * (nrm @ P[t[0]]) * nrm
            w[v] += area / 3
    C = P.copy()                              # cluster centroids
    R = np.zeros(n)                           # cluster radius bounds
    shell = np.zeros(n, np.int64) if vertex_shell is None else np.asarray(vertex_shell)
    members = {}
    for t in tris.values():
        for v in t:
            members.setdefault(int(shell[v]), set()).add(v)
    accepted = np.zeros(len(collapses), bool)
    k = len(collapses) if limit is None else limit
    for i, (a, c) in enumerate(np.asarray(collapses)[:k]):
        if len(tris) <= stop_faces:
            break
        a, c = int(a), int(c)
        if a == c or locked[a] or locked[c] or len(members[int(shell[a])]) <= 4:
            continue
        fa = {f for f, t in tris.items() if a in t}
        fc = {f for f, t in tris.items() if c in t}
        shared = fa & fc
        if len(shared) != 2:
            continue
        link_a = {v for f in fa for v in tris[f]} - {a, c}
        link_c = {v for f in fc for v in tris[f]} - {a, c}
        if len(link_a & link_c) != 2:
            continue
        wa, wc = w[a] + w[c], None
        cen = (w[a] * C[a] + w[c] * C[c]) / wa
        Aq = A[a] + A[c]
        lam = reg * np.trace(Aq) / 3.0 + 1e-300
        rad = max(R[a] + np.linalg.norm(cen - C[a]) if w[a] > 0 else R[a],
                  R[c] + np.linalg.norm(cen - C[c]) if w[c] > 0 else R[c],
                  np.linalg.norm(cen - positions[a]), np.linalg.norm(cen - positions[c]))
        p = cen
        try:
            x = np.linalg.solve(Aq + lam * np.eye(3), b[a] + b[c] + lam * cen)
            if np.linalg.norm(x - cen) <= 2 * rad + 1e-12 * (1 + rad):
                p = x
        except np.linalg.LinAlgError:
            pass

        def normal(t, moved):
            q = [p if moved and v in (a, c) else P[v] for v in t]
            return np.cross(q[1] - q[0], q[2] - q[0])

        ok = True
        for f in (fa | fc) - shared:
            o, nw = normal(tris[f], False), normal(tris[f], True)
            if not np.linalg.norm(nw) > 0 or o @ nw < min_cos * np.linalg.norm(o) * np.linalg.norm(nw):
                ok = False
                break
        if not ok:
            continue
        for f in shared:
            del tris[f]
        for f in fc - shared:
            tris[f] = [a if v == c else v for v in tris[f]]
        P[a] = p
        A[a] += A[c]
        b[a] += b[c]
        C[a], w[a], R[a] = cen, wa, rad
        members[int(shell[a])].discard(c)
        accepted[i] = True
    return P, [tuple(tris[f]) for f in sorted(tris)], accepted


# -- continuous-time factor bounds -----------------------------------------------------------

def factor_terms(L, t, q, s, anim, rest_local, omega_margin, alpha_margin):
    """Numpy transcription of ``runtime.certify.factor_bounds``'s factor bounds (per interval
    and joint; see its docstring for the derivation): returns Li, fw, iv, dt, eps, iso."""
    T, J = L.shape[:2]
    I = T - 1
    Li = np.full_like(L, np.nan)
    regular = np.linalg.det(L) != 0
    Li[regular] = np.linalg.inv(L[regular])  # a zero scale has no inverse (the kernel gives inf)
    lin = rest_local[:, :3, :3]
    fw, iv = np.zeros((I, J, 3)), np.zeros((I, J, 3))
    sv = np.linalg.svd(lin, compute_uv=False)
    fw[:, :, 0] = sv[:, 0]
    iv[:, :, 0] = 1.0 / sv[:, -1]
    iso = np.repeat((sv[:, 0] - sv[:, -1] <= 1e-12 * sv[:, 0])[None], I, 0)
    dt, eps = np.zeros((I, J)), np.zeros((I, J, 2))
    for i in range(I):
        for k, j in enumerate(anim):
            q0 = q[i, k] / np.linalg.norm(q[i, k])
            q1 = q[i + 1, k] / np.linalg.norm(q[i + 1, k])
            if np.dot(q0, q1) < 0:
                q1 = -q1
            theta = 4.0 * np.arctan2(np.linalg.norm(q0 - q1), np.linalg.norm(q0 + q1))
            om, al = omega_margin * theta, alpha_margin * theta ** 2
            s0, s1 = s[i, k], s[i + 1, k]
            smax = max(np.abs(s0).max(), np.abs(s1).max())
            smin = 0.0 if np.any(np.sign(s0) != np.sign(s1)) else min(np.abs(s0).min(), np.abs(s1).min())
            ds = np.abs(s1 - s0).max()
            fw[i, j] = (smax, om * smax + ds, al * smax + 2 * om * ds)
            if smin > 0:
                r = 1.0 / smin
                iv[i, j] = (r, ds * r ** 2 + om * r, 2 * ds ** 2 * r ** 3 + 2 * om * ds * r ** 2 + al * r)
            else:
                iv[i, j] = np.inf
            dt[i, j] = np.linalg.norm(t[i + 1, k] - t[i, k])
            e = 3.0 * 2.0 ** -11 * smax if ds > 0 else 0.0
            eps[i, j, 0] = e
            eps[i, j, 1] = 0.0 if e == 0 else (e / (smin * (smin - e)) if smin > e else np.inf)
            iso[i, j] = bool(np.all(s0 == s0[0]) and np.all(s1 == s1[0]))
    return Li, fw, iv, dt, eps, iso
