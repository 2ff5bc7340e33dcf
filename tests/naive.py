"""Slow, readable references for the fast kernels (stumpy-style): tests compare against these.

Nothing here is clever; every function is a direct transcription of its definition.
"""

from __future__ import annotations

import itertools

import numpy as np

from pipeline.model import skel_transforms


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


def all_poses(mesh):
    """Skeleton transforms of the bind pose and of every clip frame, (F, b, 4, 4)."""
    poses = [mesh.bind_transforms[None]]
    for c in mesh.clips:
        poses.append(skel_transforms(c.local, mesh.parents))
    return np.concatenate(poses)


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
    from pipeline.geometry.collapse import vertex_quadrics

    P = np.asarray(positions, dtype=np.float64).copy()
    n = len(P)
    tris = {f: [int(v) for v in t] for f, t in enumerate(np.asarray(triangles))}
    locked = ~interior_vertices(triangles, n)
    A, b, w = (x.copy() for x in vertex_quadrics(P, np.asarray(triangles)))
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
