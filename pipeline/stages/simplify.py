"""``simplify``: a collision proxy of a target size that carries the skin, with a bound on how far
it strays from the full skinned mesh on every frame of every clip.

Off by default; ``colossus import --target-faces N`` and/or ``--max-deviation D`` (stage units,
or ``D%`` of the model size) turn it on.  It runs **after** ``bind`` and before ``parts``: the
full mesh it measures against is then the collider colossus would write without it (unweighted
vertices resolved, at most ``--max-influences`` normalised influences, joints parents-first), and
the proxy's parts, spheres and the every-frame proof are made exactly as for any mesh.

1. Decimation (`fast-simplification`_, MIT, pyvista's binding of Fast-Quadric-Mesh-Simplification).
   Chosen over libigl's ``qslim`` (which refuses non-manifold input and took 12.8 s against
   1.1 s on the 200,000-triangle benchmark tube), VTK's ``vtkQuadricDecimation`` (89 s on the
   same tube, no collapse map) and pymeshlab (GPL): it is the fastest, depends on numpy only and
   returns its **collapse history**, from which the vertex clusters, any prefix of the
   decimation, and the undoing of single collapses follow with plain array operations.

   * Open borders: ``preserve_border=True`` never collapses an edge touching an open-border
     vertex, so every open border keeps its vertices and edges exactly (closed shells have none).
   * Part boundaries: the library's collapses are chosen on an *embedding* of the rest mesh in
     which each vertex is moved along its normal by ``h(bone) * SIMPLIFY_BONE_BOUNDARY * size``,
     ``h`` a level per dominant bone that differs between neighbouring parts (a greedy colouring
     of the part adjacency graph).  Every part boundary becomes a small step; a collapse across
     it must leave the step and pays about its height squared in the quadric error, so it waits
     until the rest of the mesh is that coarse (Unreal's "enforce bone boundaries", as a
     penalty).  The embedding is scaled to unit size first, since the library's error schedule
     is absolute.
   * Placement: the collapses are replayed on the real rest positions: each cluster's vertex is
     the minimiser of its members' area-weighted plane quadrics (Garland-Heckbert), regularised
     towards the members' centroid so flat or creased clusters stay put; a vertex that nothing
     collapsed into keeps its exact position.
   * Topology: the library has no link-condition test, so after every decimation each closed
     shell is checked to be closed, two-manifold (every edge used by exactly two of its faces in
     opposite directions, every vertex's fan one cycle, no duplicate face) and of unchanged Euler
     characteristic; a shell the decimation made defective keeps the longest prefix of its own
     collapses that leaves it sound (shells are independent: a collapse joins the ends of an
     edge).  When the repairs leave the proxy above ``--target-faces``, the decimation reruns
     with a lower target.

2. Skin: closest-point transfer on the full rest mesh.  Each proxy vertex takes the per-bone
   weights of its nearest point on the full rest surface, interpolated barycentrically over that
   triangle's corners (weights of each bone are interpolated, joint indices never); the strongest
   ``--max-influences`` are kept and renormalised by :func:`pipeline.stages.bind.limit_influences`,
   the same code ``bind`` uses.  This is local at joints, where a cluster average would blend the
   weights of the whole (possibly large) cluster.

3. Deviation (:func:`deviation`): on the bind pose and every frame of every clip, both meshes are
   skinned (:func:`pipeline.stages.spheres.skin_points`, the one skinning kernel here) and the
   two-sided distance between the skinned surfaces is bounded from above, each direction by the
   bound of :mod:`pipeline.geometry.surface_distance` (sampled distance to candidate triangles
   plus the sampling radius; samples refined where a triangle's bound is more than
   ``DEVIATION_REFINE`` above the largest sampled distance), plus ``DEVIATION_PAD * size`` for
   float32 rounding.  Candidate triangles are the nearest ones at rest (by centroid); missing the
   nearest triangle can only over-state the distance, never under-state it.

``--max-deviation`` keeps the longest prefix of the collapse history whose bound stays within the
limit (a bisection over the prefix length; a prefix is rejected on a subset of the frames before
all frames are measured).

.. _fast-simplification: https://github.com/pyvista/fast-simplification
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..errors import UsageError
from ..geometry.surface_distance import CandidateQuery, cover_radius, grid_barycentrics, triangle_corner_bound
from ..model import SkinnedMesh, skel_transforms
from ..tolerances import DEVIATION_PAD, DEVIATION_REFINE, DEVIATION_RESOLUTION, SIMPLIFY_BONE_BOUNDARY, model_scale
from . import StageReport
from .bind import limit_influences
from .orient import orient
from .spheres import skin_points

#: Candidate triangles per sample: of the dense full mesh (proxy -> full) ...
FULL_CANDIDATES = 16
#: ... and of the coarse proxy (full -> proxy, and the weight transfer).
PROXY_CANDIDATES = 8
#: Finest barycentric grid level the deviation refinement goes to.
MAX_LEVEL = 16
#: At most this many triangles are refined per round (the worst first).
MAX_REFINED = 20000
#: Per pose, the largest triangle bounds kept from the first pass (for the per-clip table).
TOP_PER_POSE = 32
#: Decimation reruns when repairs leave the proxy above the target.
MAX_DECIMATIONS = 6
#: --max-deviation: a prefix search stops when the face counts bracketing the limit differ by
#: less than this fraction.
PREFIX_TOLERANCE = 0.02
#: With --max-deviation and no --target-faces, the decimation goes down to this fraction of the
#: faces (at least MIN_FACES), then the prefix search picks the longest prefix within the limit.
FLOOR_FRACTION = 0.005
MIN_FACES = 64


# ------------------------------------------------------------------------------ options
def parse_max_deviation(value):
    """``--max-deviation``: ``(length, relative)`` from ``"0.01"`` (stage units) or ``"0.5%"``
    (percent of the model size); None for None.  Raises :class:`UsageError`."""
    if value is None or value == "":
        return None
    if isinstance(value, tuple):
        return value
    text = str(value).strip()
    rel = text.endswith("%")
    try:
        v = float(text[:-1] if rel else text)
    except ValueError:
        raise UsageError(f"--max-deviation {value!r}: expected a length in stage units or a percentage "
                         "of the model size, e.g. 0.01 or 0.5%") from None
    if not (np.isfinite(v) and v > 0):
        raise UsageError(f"--max-deviation {value!r}: expected a positive length")
    return v, rel


def resolve_max_deviation(spec, size: float) -> float | None:
    """The limit in stage units: ``spec`` from :func:`parse_max_deviation`, ``size`` the model size."""
    if spec is None:
        return None
    v, rel = spec
    return v * size / 100.0 if rel else v


# ------------------------------------------------------------------------------ poses
@dataclass
class Poses:
    """The poses the deviation covers: the bind pose, then every frame of every clip.

    mats : (F, b, 4, 4) float64 skinning matrices (``skel @ inv(bind) @ geom_bind``: mesh space
    to skeleton space); clip : list of clip name (None for the bind pose); frame : (F,) int;
    time : (F,) float64 time codes (nan for the bind pose)."""

    mats: np.ndarray
    clip: list
    frame: np.ndarray
    time: np.ndarray

    def label(self, i: int) -> str:
        return "bind pose" if self.clip[i] is None else f"{self.clip[i]} frame {int(self.frame[i])}"

    def subset(self, idx) -> "Poses":
        idx = np.asarray(idx)
        return Poses(self.mats[idx], [self.clip[i] for i in idx], self.frame[idx], self.time[idx])


def mesh_poses(mesh: SkinnedMesh) -> Poses:
    """:class:`Poses` of ``mesh``: its bind pose and every frame of every clip."""
    inv_bind = np.linalg.inv(mesh.bind_transforms)
    skel = [mesh.bind_transforms[None]]
    clip, frame, times = [None], [0], [np.nan]
    for c in mesh.clips:
        skel.append(skel_transforms(c.local, mesh.parents))
        clip += [c.name] * c.frame_count
        frame += list(range(c.frame_count))
        times += list(c.times)
    S = np.concatenate(skel)
    mats = S @ inv_bind[None] @ mesh.geom_bind
    return Poses(np.ascontiguousarray(mats), clip, np.array(frame, np.int64), np.array(times, np.float64))


def _rest_skel(mesh: SkinnedMesh) -> np.ndarray:
    G = mesh.geom_bind
    return mesh.positions.astype(np.float64) @ G[:3, :3].T + G[:3, 3]


def _chunks(F: int, vertices: int):
    return _chunks_of(np.arange(F), vertices)


def _chunks_of(idx, vertices: int):
    """``idx`` (pose indices) in chunks whose skinned vertices stay under ~100 MB."""
    step = max(1, int(8_000_000 // max(1, 3 * vertices)))
    return [idx[i:i + step] for i in range(0, len(idx), step)]


# ------------------------------------------------------------------------------ deviation
@dataclass
class Deviation:
    """The two-sided deviation bound between a proxy and the full mesh.

    bound : float, stage units (max over poses and both directions, pad included)
    pose_bound : (F,) float64, an upper bound of the deviation at each pose
    worst_pose : int, index into the poses; worst_joint : int; direction : str
        (``"full->proxy"``: a point of the full surface far from the proxy, or ``"proxy->full"``)
    sampled : float, the largest sampled distance (a lower end for the truth, up to candidate misses)
    samples : int, sample points evaluated per pose (both directions, all refinement rounds)
    """

    bound: float
    pose_bound: np.ndarray
    worst_pose: int
    worst_joint: int
    direction: str
    sampled: float
    samples: int
    directions: dict = field(default_factory=dict)


@dataclass
class _Side:
    pos: np.ndarray      # (n, 3) float32 mesh space
    tri: np.ndarray      # (m, 3) int64
    ji: np.ndarray
    jw: np.ndarray
    rest: np.ndarray     # (n, 3) float64 skeleton space at rest

    @classmethod
    def of(cls, mesh: SkinnedMesh):
        return cls(mesh.positions, mesh.triangles.astype(np.int64), mesh.joint_indices, mesh.joint_weights,
                   _rest_skel(mesh))

    def skin(self, mats):
        return skin_points(self.pos, self.ji, self.jw, mats)

    def dominant(self, t: int) -> int:
        j = self.ji[self.tri[t]].ravel()
        w = self.jw[self.tri[t]].ravel().astype(np.float64)
        return int(np.bincount(j, weights=w).argmax())


def _one_sided(src: _Side, tgt: _Side, poses: Poses, k: int, refine: float, size: float) -> dict:
    """Upper bound of ``max over x in src of d(x, tgt)`` at every pose (see the module docstring)."""
    F, m, n = len(poses.mats), len(src.tri), len(src.pos)
    tcent = tgt.rest[tgt.tri].mean(axis=1)
    tree = cKDTree(tcent)
    kk = int(min(k, len(tgt.tri)))

    def cands(points):
        return tree.query(points, k=kk)[1].reshape(len(points), kk)

    used = np.zeros(n, bool)
    used[src.tri.ravel()] = True
    vq = CandidateQuery(np.repeat(np.arange(n)[:, None], 3, 1), np.tile([1.0, 0.0, 0.0], (n, 1)), tgt.tri,
                        cands(src.rest), n, len(tgt.pos))
    umax = np.full(m, -np.inf)
    uarg = np.zeros(m, np.int64)
    K = min(TOP_PER_POSE, m)
    top_t = np.zeros((F, K), np.int64)
    top_u = np.zeros((F, K))
    L = 0.0
    chunks = _chunks(F, n + len(tgt.pos))
    for ch in chunks:
        ps, pt = src.skin(poses.mats[ch]), tgt.skin(poses.mats[ch])
        dv = vq.distances(ps, pt)
        dv[:, ~used] = 0.0
        L = max(L, float(dv.max()))
        Uc = triangle_corner_bound(ps, src.tri, dv)
        for i, f in enumerate(ch):
            U = Uc[i]
            better = U > umax
            umax[better] = U[better]
            uarg[better] = f
            sel = np.argpartition(-U, K - 1)[:K] if m > K else np.arange(m)
            sel = sel[np.argsort(-U[sel])]
            top_t[f], top_u[f] = sel, U[sel]
    samples = n

    # refinement: finer barycentric grids on the triangles whose bound is well above L
    level = np.ones(m, np.int64)
    ref_row = np.full(m, -1, np.int64)
    ref_vals = np.zeros((F, 0))
    while True:
        R = np.flatnonzero((umax > L * (1.0 + refine) + DEVIATION_RESOLUTION * size) & (level < MAX_LEVEL))
        if not len(R):
            break
        if len(R) > MAX_REFINED:
            R = R[np.argsort(-umax[R])[:MAX_REFINED]]
        # the next level: enough to bring the grid's radius under the slack, at least double
        level[R] = np.minimum(MAX_LEVEL, level[R] * 2)
        idx, bary, owner = [], [], []
        for s in np.unique(level[R]):
            Ts = R[level[R] == s]
            g = grid_barycentrics(int(s))
            idx.append(np.repeat(src.tri[Ts], len(g), axis=0))
            bary.append(np.tile(g, (len(Ts), 1)))
            owner.append(np.repeat(Ts, len(g)))
        idx, bary, owner = np.concatenate(idx), np.concatenate(bary), np.concatenate(owner)
        order = np.argsort(owner, kind="stable")
        idx, bary, owner = idx[order], bary[order], owner[order]
        Tr, starts = np.unique(owner, return_index=True)
        pts = np.einsum("nk,nkd->nd", bary, src.rest[idx])
        q = CandidateQuery(idx, bary, tgt.tri, cands(pts), n, len(tgt.pos))
        # only poses where some triangle's bound is above the threshold need the finer samples;
        # elsewhere every triangle is already bounded by that pose's largest bound (<= threshold)
        thr = L * (1.0 + refine) + DEVIATION_RESOLUTION * size
        pose_top = top_u[:, 0] if ref_vals.shape[1] == 0 else np.maximum(top_u[:, 0], ref_vals.max(axis=1))
        hot = np.flatnonzero(pose_top > thr)
        vals = np.repeat(pose_top[:, None], len(Tr), axis=1)
        for ch in _chunks_of(hot, n + len(tgt.pos)):
            ps, pt = src.skin(poses.mats[ch]), tgt.skin(poses.mats[ch])
            d = q.distances(ps, pt)
            L = max(L, float(d.max()))
            vals[ch] = np.maximum.reduceat(d, starts, axis=1) + cover_radius(ps, src.tri[Tr]) / level[Tr]
        samples += len(idx)
        new = ref_row[Tr] < 0
        ref_row[Tr[new]] = ref_vals.shape[1] + np.arange(int(new.sum()))
        ref_vals = np.concatenate([ref_vals, np.full((F, int(new.sum())), np.inf)], axis=1)
        rows = ref_row[Tr]
        ref_vals[:, rows] = np.minimum(ref_vals[:, rows], vals)  # both bounds hold: keep the lower
        umax[Tr] = ref_vals[:, rows].max(axis=0)
        uarg[Tr] = ref_vals[:, rows].argmax(axis=0)

    bound = float(umax.max())
    worst_t = int(umax.argmax())
    # per-pose bound: the largest first-pass value of a triangle never refined (from the kept top
    # list; when the whole list was refined, its last value bounds the rest), and the refined ones
    pose = np.empty(F)
    refined = ref_row >= 0
    for f in range(F):
        free = ~refined[top_t[f]]
        pose[f] = top_u[f][free][0] if free.any() else top_u[f, -1]
    if ref_vals.shape[1]:
        pose = np.maximum(pose, ref_vals.max(axis=1))
    pose = np.minimum(pose, bound)  # each triangle's bound over all poses holds at every pose
    return {"bound": bound, "pose": pose, "worst_pose": int(uarg[worst_t]), "worst_joint": src.dominant(worst_t),
            "sampled": L, "samples": int(samples), "refined_triangles": int(refined.sum())}


def deviation(full: SkinnedMesh, proxy: SkinnedMesh, poses: Poses | None = None,
              refine: float = DEVIATION_REFINE) -> Deviation:
    """Upper bound of the two-sided distance between the skinned surfaces of ``full`` and
    ``proxy`` (same skeleton) on every pose.

    Parameters
    ----------
    full, proxy : SkinnedMesh
    poses : Poses, optional (default :func:`mesh_poses` of ``full``: bind pose and every frame)
    refine : float
        Sampling stops when every triangle's bound is within this fraction of the largest sampled
        distance (or at :data:`MAX_LEVEL`).

    Returns
    -------
    Deviation
    """
    poses = poses or mesh_poses(full)
    size = model_scale(_rest_skel(full))
    f, p = _Side.of(full), _Side.of(proxy)
    a = _one_sided(f, p, poses, PROXY_CANDIDATES, refine, size)
    b = _one_sided(p, f, poses, FULL_CANDIDATES, refine, size)
    pad = DEVIATION_PAD * size
    worst = a if a["bound"] >= b["bound"] else b
    direction = "full->proxy" if worst is a else "proxy->full"
    return Deviation(bound=max(a["bound"], b["bound"]) + pad, pose_bound=np.maximum(a["pose"], b["pose"]) + pad,
                     worst_pose=worst["worst_pose"], worst_joint=worst["worst_joint"], direction=direction,
                     sampled=max(a["sampled"], b["sampled"]), samples=a["samples"] + b["samples"],
                     directions={"full->proxy": a, "proxy->full": b})


# ------------------------------------------------------------------------------ topology
def _shells(tris: np.ndarray, n: int):
    """Shells of a triangle mesh: faces connected through shared edges.

    Returns ``(shell (m,) int64, count, closed (count,) bool, euler (count,) int64)``; a shell is
    closed when every edge of it is used by exactly two of its faces in opposite directions."""
    t = np.asarray(tris, dtype=np.int64)
    m = len(t)
    a, b = t.ravel(), t[:, [1, 2, 0]].ravel()
    face = np.repeat(np.arange(m), 3)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * n + hi
    uk, inv = np.unique(key, return_inverse=True)
    # faces sharing an edge are one shell
    g = coo_matrix((np.ones(len(face)), (face, inv)), shape=(m, len(uk))).tocsr()
    g = (g @ g.T).tocoo()
    count, shell = connected_components(g, directed=False)
    closed, euler = _shell_stats(t, n, shell, count)
    return shell.astype(np.int64), int(count), closed, euler


def _shell_stats(t, n, shell, count):
    m = len(t)
    a, b = t.ravel(), t[:, [1, 2, 0]].ravel()
    sh = np.repeat(shell, 3)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = (sh * n + lo) * n + hi
    uk, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    fwd = np.where(a < b, 1, -1)
    bal = np.bincount(inv, weights=fwd, minlength=len(uk))
    bad_edge = (cnt != 2) | (bal != 0)
    edge_shell = uk // (n * n)
    closed = np.bincount(edge_shell[bad_edge], minlength=count) == 0
    E = np.bincount(edge_shell, minlength=count)
    Fc = np.bincount(shell, minlength=count)
    vkey = np.unique(np.repeat(shell, 3) * n + t.ravel())
    V = np.bincount(vkey // n, minlength=count)
    return closed & (Fc > 0), (V - E + Fc).astype(np.int64)


def _defect_vertices(pt: np.ndarray, nv: int, shell: np.ndarray, count: int, closed_in: np.ndarray,
                     euler_in: np.ndarray) -> np.ndarray:
    """Proxy vertices involved in a topology defect (see the module docstring): edges with 3+
    faces, duplicate faces, edges of an input-closed shell not used twice in opposite
    directions, vertices whose fan is not one cycle, and input-closed shells whose Euler
    characteristic changed or that vanished."""
    t = np.asarray(pt, dtype=np.int64)
    m = len(t)
    out = []
    if m == 0:
        return np.zeros(0, np.int64)
    a, b, c = t.ravel(), t[:, [1, 2, 0]].ravel(), t[:, [2, 0, 1]].ravel()
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    # duplicate faces (any orientation)
    st = np.sort(t, axis=1)
    _, finv, fcnt = np.unique(st, axis=0, return_inverse=True, return_counts=True)
    out.append(t[fcnt[finv.ravel()] > 1].ravel())
    # edges with 3+ faces anywhere
    ekey = lo * nv + hi
    _, einv, ecnt = np.unique(ekey, return_inverse=True, return_counts=True)
    over = ecnt[einv] >= 3
    out += [a[over], b[over], c[over]]
    # edges of input-closed shells
    sh = np.repeat(shell, 3)
    in_closed = closed_in[sh]
    skey = (sh * nv + lo) * nv + hi
    uk, sinv, scnt = np.unique(skey, return_inverse=True, return_counts=True)
    bal = np.bincount(sinv, weights=np.where(a < b, 1, -1), minlength=len(uk))
    bad = in_closed & ((scnt[sinv] != 2) | (bal[sinv] != 0))
    out += [a[bad], b[bad], c[bad]]
    # vertex fans: link edges (b, c) around corner a connect the directed pairs (a, b), (a, c)
    nodes, ninv = np.unique(np.concatenate([a * nv + b, a * nv + c]), return_inverse=True)
    g = coo_matrix((np.ones(3 * m), (ninv[:3 * m], ninv[3 * m:])), shape=(len(nodes), len(nodes)))
    _, lab = connected_components(g, directed=False)
    vl = np.unique(np.c_[nodes // nv, lab], axis=0)
    fans = np.bincount(vl[:, 0], minlength=nv)
    pinched = np.flatnonzero(fans > 1)
    if len(pinched):
        hit = np.isin(a, pinched)
        out += [a[hit], b[hit], c[hit]]
    # closed shells: Euler characteristic, and vanished shells
    present = np.bincount(shell, minlength=count) > 0
    _, euler = _shell_stats(t, nv, shell, count)
    changed = closed_in & present & (euler != euler_in)
    if changed.any():
        out.append(t[changed[shell]].ravel())
    out = np.unique(np.concatenate(out)) if out else np.zeros(0, np.int64)
    return out


# ------------------------------------------------------------------------------ decimation
def _bone_levels(dominant: np.ndarray, tris: np.ndarray, bones: int) -> np.ndarray:
    """A level in [-1, 1] per bone, different for bones whose parts share an edge (greedy
    colouring of the part adjacency graph, highest degree first)."""
    d = dominant[tris]
    a, b = d.ravel(), d[:, [1, 2, 0]].ravel()
    diff = a != b
    pairs = np.unique(np.sort(np.c_[a[diff], b[diff]], axis=1), axis=0)
    nbrs = [[] for _ in range(bones)]
    for x, y in pairs:
        nbrs[x].append(y)
        nbrs[y].append(x)
    colour = np.full(bones, -1, np.int64)
    for j in sorted(range(bones), key=lambda j: -len(nbrs[j])):
        taken = {colour[k] for k in nbrs[j]}
        c = 0
        while c in taken:
            c += 1
        colour[j] = c
    top = max(int(colour.max()), 1)
    return np.where(colour >= 0, 2.0 * colour / top - 1.0, 0.0)


def _embedding(pos: np.ndarray, tris: np.ndarray, dominant: np.ndarray, bones: int, step: float) -> np.ndarray:
    """Rest positions (scaled to unit size) moved along their normals by a level per dominant bone."""
    p = pos.astype(np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    size = float(np.linalg.norm(hi - lo)) or 1.0
    p = (p - 0.5 * (lo + hi)) / size
    t = tris.astype(np.int64)
    fn = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    vn = np.zeros_like(p)
    for k in range(3):
        np.add.at(vn, t[:, k], fn)
    ln = np.linalg.norm(vn, axis=1)
    vn = np.where(ln[:, None] > 0, vn / np.where(ln > 0, ln, 1.0)[:, None], 0.0)
    h = _bone_levels(dominant, t, bones)
    return p + step * h[dominant][:, None] * vn


def _collapses(embedded: np.ndarray, tris: np.ndarray, target: int) -> np.ndarray:
    import fast_simplification as fs

    if target >= len(tris):
        return np.zeros((0, 2), np.int64)
    _, _, col = fs.simplify(embedded, tris.astype(np.int32), target_count=int(target), agg=7.0,
                            return_collapses=True, preserve_border=True)
    return np.asarray(col, dtype=np.int64).reshape(-1, 2)


def _roots(n: int, col: np.ndarray) -> np.ndarray:
    """Cluster root of every vertex after the collapses ``col`` ((k, 2): ``col[i, 1]`` merged
    into ``col[i, 0]``; each vertex is merged away at most once)."""
    parent = np.arange(n)
    parent[col[:, 1]] = col[:, 0]
    while True:
        nxt = parent[parent]
        if np.array_equal(nxt, parent):
            return parent
        parent = nxt


def _vertex_quadrics(pos: np.ndarray, tris: np.ndarray):
    """Area-weighted plane quadrics per vertex: ``A (n, 3, 3)``, ``b (n, 3)``, and the area
    ``w (n,)`` (each face's area shared by its corners)."""
    p = pos.astype(np.float64)
    t = tris.astype(np.int64)
    n = len(p)
    cr = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    area = 0.5 * np.linalg.norm(cr, axis=1)
    nrm = cr / np.where(area > 0, 2 * area, 1.0)[:, None]
    off = np.einsum("ij,ij->i", nrm, p[t[:, 0]])
    Af = area[:, None, None] * nrm[:, :, None] * nrm[:, None, :]
    bf = (area * off)[:, None] * nrm
    A = np.zeros((n, 3, 3))
    b = np.zeros((n, 3))
    w = np.zeros(n)
    for k in range(3):
        np.add.at(A, t[:, k], Af)
        np.add.at(b, t[:, k], bf)
        np.add.at(w, t[:, k], area / 3.0)
    return A, b, w


def _proxy_geometry(pos, tris, root, quadrics):
    """Proxy vertices and triangles from the cluster roots (see the module docstring).

    Returns ``(positions (n', 3) float32, triangles (m', 3) int64, kept_faces (m,) bool,
    vertex_of_root (n,) int64 (-1 where a root is no proxy vertex), singleton (n',) bool)``."""
    n = len(pos)
    t = root[tris]
    kept = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])
    t = t[kept]
    verts = np.unique(t)
    new = np.full(n, -1, np.int64)
    new[verts] = np.arange(len(verts))
    A, b, w = quadrics
    size = np.bincount(root, minlength=n)
    Ac = np.zeros((n, 3, 3))
    np.add.at(Ac, root, A)
    bc = np.zeros((n, 3))
    np.add.at(bc, root, b)
    ws = np.bincount(root, weights=w + 1e-30, minlength=n)
    cen = np.zeros((n, 3))
    cen[verts] = np.stack([np.bincount(root, weights=(w + 1e-30) * pos[:, k], minlength=n)[verts]
                           for k in range(3)], 1) / ws[verts, None]
    Av, bv, cv = Ac[verts], bc[verts], cen[verts]
    lam = 1e-3 * np.trace(Av, axis1=1, axis2=2)[:, None, None] / 3.0 + 1e-30
    opt = np.linalg.solve(Av + lam * np.eye(3), (bv + lam[:, :, 0] * cv)[:, :, None])[:, :, 0]
    # a placement far outside the cluster (an ill-conditioned quadric) falls back to its centroid
    rad = np.zeros(n)
    np.maximum.at(rad, root, np.linalg.norm(pos - cen[root], axis=1))
    far = np.linalg.norm(opt - cv, axis=1) > 2.0 * rad[verts] + 1e-12
    opt[far] = cv[far]
    single = size[verts] == 1
    opt[single] = pos[verts[single]]
    return opt.astype(np.float32), new[t], kept, new, single


def _bad_shells(n, col, active, tris, shell, count, closed_in, euler_in, vshell, pos, quadrics):
    """Build the proxy for the ``active`` collapses; returns ``(geometry, bad (count,) bool)``:
    the shells with a topology defect (see :func:`_defect_vertices`) or, if closed, removed."""
    root = _roots(n, col[active])
    geo = _proxy_geometry(pos, tris, root, quadrics)
    _, pt, kept, new, single = geo
    badv = _defect_vertices(pt, len(single), shell[kept], count, closed_in, euler_in)
    bad = np.zeros(count, bool)
    bad[vshell[np.flatnonzero(new >= 0)[badv]]] = True
    bad |= closed_in & (np.bincount(shell[kept], minlength=count) == 0)
    return geo, bad


def _repair(n, col, active, tris, shell, count, closed_in, euler_in, pos, quadrics):
    """Undo collapses until no shell has a topology defect the decimation made.

    Shells are independent (a collapse joins the two ends of an edge), so each defective shell
    is bisected on its own collapse sequence for the longest prefix that leaves it sound, all
    shells at once.  Shells already defective in the input are left as the decimation made them
    (their defects are the source's).  Returns ``(active, geometry, undone)``."""
    vshell = np.zeros(n, np.int64)
    vshell[tris.ravel()] = np.repeat(shell, 3)
    _, inherited = _bad_shells(n, col, np.zeros(len(col), bool), tris, shell, count, closed_in, euler_in, vshell,
                               pos, quadrics)
    cshell = vshell[col[:, 0]]
    active = active.copy()
    undone = 0
    for _ in range(3):
        geo, bad = _bad_shells(n, col, active, tris, shell, count, closed_in, euler_in, vshell, pos, quadrics)
        bad &= ~inherited
        if not bad.any():
            return active, geo, undone
        todo = {int(s): np.flatnonzero(active & (cshell == s)) for s in np.flatnonzero(bad)}
        lo = {s: 0 for s in todo}
        hi = {s: len(ix) for s, ix in todo.items()}
        while any(hi[s] - lo[s] > 1 for s in todo):
            trial = active.copy()
            mids = {}
            for s, ix in todo.items():
                mids[s] = (lo[s] + hi[s]) // 2 if hi[s] - lo[s] > 1 else lo[s]
                trial[ix[mids[s]:]] = False
            _, tb = _bad_shells(n, col, trial, tris, shell, count, closed_in, euler_in, vshell, pos, quadrics)
            for s in todo:
                if hi[s] - lo[s] > 1:
                    if tb[s]:
                        hi[s] = mids[s]
                    else:
                        lo[s] = mids[s]
        for s, ix in todo.items():
            active[ix[lo[s]:]] = False
            undone += len(ix) - lo[s]
    geo, bad = _bad_shells(n, col, active, tris, shell, count, closed_in, euler_in, vshell, pos, quadrics)
    bad &= ~inherited
    if bad.any():  # not monotone after all: those shells are kept as they came in
        off = active & bad[cshell]
        undone += int(off.sum())
        active[off] = False
        geo, _ = _bad_shells(n, col, active, tris, shell, count, closed_in, euler_in, vshell, pos, quadrics)
    return active, geo, undone


def transfer_weights(full: SkinnedMesh, points: np.ndarray, max_influences: int):
    """Skin weights at ``points`` (skeleton space, rest) by closest-point transfer on the full rest
    mesh: per-bone weights interpolated barycentrically over the nearest triangle, strongest
    ``max_influences`` kept and renormalised.

    Returns ``(joint_indices (n', max_influences) int32, joint_weights (n', max_influences)
    float32, distance (n',) float64)``: the distance from each point to the full rest surface."""
    rest = _rest_skel(full)
    tri = full.triangles.astype(np.int64)
    pts = np.asarray(points, dtype=np.float64)
    n2 = len(pts)
    kk = int(min(FULL_CANDIDATES, len(tri)))
    cand = cKDTree(rest[tri].mean(axis=1)).query(pts, k=kk)[1].reshape(n2, kk)
    q = CandidateQuery(np.repeat(np.arange(n2)[:, None], 3, 1), np.tile([1.0, 0.0, 0.0], (n2, 1)), tri, cand,
                       n2, len(rest))
    d, t, bary = q.distances(pts, rest, full=True)
    corners = tri[t]                                       # (n', 3)
    k = full.joint_indices.shape[1]
    ji = full.joint_indices[corners].reshape(n2, 3 * k).astype(np.int64)
    jw = (full.joint_weights[corners].astype(np.float64) * bary[:, :, None]).reshape(n2, 3 * k)
    b = max(full.joint_count, 1)
    row = np.repeat(np.arange(n2), 3 * k)
    live = jw.ravel() > 0
    key = row[live] * b + ji.ravel()[live]
    uk, inv = np.unique(key, return_inverse=True)
    wsum = np.bincount(inv, weights=jw.ravel()[live])
    r, j = uk // b, uk % b
    cnt = np.bincount(r, minlength=n2)
    width = max(int(cnt.max()) if len(cnt) else 1, 1)
    start = np.r_[0, np.cumsum(cnt)[:-1]]
    col = np.arange(len(uk)) - start[r]
    J = np.zeros((n2, width), np.int64)
    W = np.zeros((n2, width))
    J[r, col], W[r, col] = j, wsum
    tot = W.sum(axis=1, keepdims=True)
    W = W / np.where(tot > 0, tot, 1.0)
    out_j, out_w, *_ = limit_influences(J, W, max_influences)
    return out_j, out_w.astype(np.float32), d


@dataclass
class _Candidate:
    mesh: SkinnedMesh
    active: np.ndarray
    undone: int
    deviation: Deviation | None = None


def _build(full: SkinnedMesh, col, active, ctx) -> _Candidate:
    active, geo, undone = _repair(full.vertex_count, col, active, full.triangles.astype(np.int64),
                                  ctx["shell"], ctx["count"], ctx["closed"], ctx["euler"], ctx["pos"], ctx["quadrics"])
    pos, tris, *_ = geo
    G = full.geom_bind
    skel_pts = pos.astype(np.float64) @ G[:3, :3].T + G[:3, 3]
    ji, jw, _ = transfer_weights(full, skel_pts, ctx["max_influences"])
    proxy = full.replace(positions=pos, triangles=tris.astype(np.int32), joint_indices=ji, joint_weights=jw,
                         parts=None)
    return _Candidate(proxy, active, undone)


def simplify(mesh: SkinnedMesh, target_faces: int | None = None, max_deviation=None,
             max_influences: int = 4) -> tuple[SkinnedMesh, StageReport]:
    """Decimate ``mesh`` into a collision proxy, carry its skin, and bound its deviation.

    Parameters
    ----------
    mesh : SkinnedMesh
        Bound (after ``bind``), without parts.
    target_faces : int, optional
        Face count to reach (at most; fewer when ``max_deviation`` stops it first).
    max_deviation : float, str or (float, bool), optional
        Limit of the deviation bound: stage units, or ``"D%"`` of the model size
        (:func:`parse_max_deviation`).
    max_influences : int
        Influences kept per proxy vertex.

    Returns
    -------
    (SkinnedMesh, StageReport)
        Report counts: ``faces_in``, ``faces_out``, ``vertices_in``, ``vertices_out``,
        ``target_faces``, ``max_deviation_limit``, ``deviation`` (the bound, stage units),
        ``deviation_relative`` (over the model size), ``sampled_deviation``, ``worst`` (``{"clip",
        "frame", "time", "bone", "direction"}``), ``closed_shells_in``, ``closed_shells_out``,
        ``shells_in``, ``shells_out``, ``collapses``, ``collapses_undone``, ``decimations``,
        ``crossing_faces_in``/``crossing_faces_out`` (faces whose corners have different dominant
        bones), ``decimate_seconds``, ``deviation_seconds``; details: ``clips`` (the worst
        deviation of each clip: ``{"clip", "frames", "frame", "time", "deviation", "bone"}``).
    """
    if target_faces is None and max_deviation is None:
        raise ValueError("simplify: expected target_faces or max_deviation, got neither")
    if target_faces is not None and int(target_faces) < 4:
        raise ValueError(f"simplify target_faces: expected >= 4, got {target_faces}")
    spec = parse_max_deviation(max_deviation)
    t_start = time.perf_counter()
    n, m = mesh.vertex_count, mesh.face_count
    rest = _rest_skel(mesh)
    size = model_scale(rest)
    limit = resolve_max_deviation(spec, size)
    poses = mesh_poses(mesh)
    tris = mesh.triangles.astype(np.int64)
    shell, count, closed, euler = _shells(tris, n)
    dominant = mesh.joint_indices[np.arange(n), np.argmax(mesh.joint_weights, axis=1)].astype(np.int64)
    ctx = {"shell": shell, "count": count, "closed": closed, "euler": euler, "pos": mesh.positions.astype(np.float64),
           "quadrics": _vertex_quadrics(mesh.positions, tris), "max_influences": int(max_influences)}
    report = StageReport("simplify")
    t_dev = 0.0
    decimations = 0

    goal = int(target_faces) if target_faces is not None else max(MIN_FACES, int(FLOOR_FRACTION * m))
    if goal >= m:
        cand = _Candidate(mesh, np.zeros(0, bool), 0, None)
        col = np.zeros((0, 2), np.int64)
    else:
        emb = _embedding(mesh.positions, tris, dominant, mesh.joint_count, SIMPLIFY_BONE_BOUNDARY)
        ask, tried, best = goal, [], None
        for _ in range(MAX_DECIMATIONS):
            decimations += 1
            col = _collapses(emb, tris, ask)
            cand = _build(mesh, col, np.ones(len(col), bool), ctx)
            faces = cand.mesh.face_count
            tried.append((ask, faces))
            within = faces <= goal
            if best is None or (within and (best[2] > goal or faces > best[2])) or (not within and faces < best[2]):
                best = (col, cand, faces)
            if target_faces is None or within and faces >= goal * (1 - PREFIX_TOLERANCE) or ask <= 4:
                break
            # repairs add faces: aim lower (secant on the asked-for vs reached counts)
            (a0, f0), (a1, f1) = (tried[-2] if len(tried) > 1 else (goal * 2, goal * 2 + (faces - ask) * 1.0)), tried[-1]
            slope = (f1 - f0) / (a1 - a0) if a1 != a0 and f1 != f0 else 1.0
            ask = int(max(4, min(len(tris) - 1, a1 + (goal - f1) / max(slope, 0.1))))
            if any(a == ask for a, _ in tried):
                break
        col, cand, _ = best

    if limit is not None and len(col):
        td = time.perf_counter()
        coarse = poses.subset(np.unique(np.linspace(0, len(poses.mats) - 1, min(len(poses.mats), 12)).astype(int)))
        cand.deviation = deviation(mesh, cand.mesh, poses)
        if cand.deviation.bound > limit:
            lo, hi = 0, len(col)  # prefix lengths: lo within the limit (the full mesh), hi not
            best = None
            while (hi - lo) * 2 > PREFIX_TOLERANCE * max(m - 2 * lo, 1) and hi - lo > 1:
                mid = (lo + hi) // 2
                active = np.zeros(len(col), bool)
                active[:mid] = True
                c = _build(mesh, col, active, ctx)
                if deviation(mesh, c.mesh, coarse).bound > limit:
                    hi = mid
                    continue
                c.deviation = deviation(mesh, c.mesh, poses)
                if c.deviation.bound > limit:
                    hi = mid
                else:
                    lo, best = mid, c
            cand = best if best is not None else _Candidate(mesh, np.zeros(0, bool), 0, None)
        t_dev += time.perf_counter() - td
    if cand.mesh is not mesh and cand.deviation is None:
        td = time.perf_counter()
        cand.deviation = deviation(mesh, cand.mesh, poses)
        t_dev += time.perf_counter() - td

    proxy = cand.mesh
    dev = cand.deviation
    _, orep = orient(proxy)
    oc = orep.counts
    _, count_out, closed_out, _ = _shells(proxy.triangles, proxy.vertex_count)
    crossing = lambda mm: int(np.count_nonzero(  # noqa: E731
        np.ptp(mm.joint_indices[np.arange(mm.vertex_count), np.argmax(mm.joint_weights, 1)][mm.triangles], 1)))
    if dev is None:
        worst = {"clip": "", "frame": -1, "time": "", "bone": "", "direction": ""}
        bound = 0.0
    else:
        i = dev.worst_pose
        worst = {"clip": poses.clip[i] or "bind pose", "frame": int(poses.frame[i]) if poses.clip[i] else -1,
                 "time": float(poses.time[i]) if poses.clip[i] else "", "bone": mesh.joint_names[dev.worst_joint],
                 "direction": dev.direction}
        bound = float(dev.bound)
    report.counts = {
        "faces_in": int(m), "faces_out": int(proxy.face_count), "vertices_in": int(n),
        "vertices_out": int(proxy.vertex_count), "target_faces": int(target_faces) if target_faces else None,
        "max_deviation_limit": float(limit) if limit is not None else None,
        "deviation": bound, "deviation_relative": bound / size,
        "sampled_deviation": float(dev.sampled) if dev else 0.0, "worst": worst,
        "shells_in": int(count), "closed_shells_in": int(closed.sum()),
        "shells_out": int(count_out), "closed_shells_out": int(closed_out.sum()),
        "faces_flipped_out": int(oc["faces_flipped"]), "nonmanifold_edges_out": int(oc["nonmanifold_edges"]),
        "collapses": int(cand.active.sum()) if len(cand.active) else 0, "collapses_undone": int(cand.undone),
        "decimations": decimations, "crossing_faces_in": crossing(mesh), "crossing_faces_out": crossing(proxy),
        "deviation_samples": int(dev.samples) if dev else 0,
        "decimate_seconds": round(time.perf_counter() - t_start - t_dev, 4), "deviation_seconds": round(t_dev, 4),
    }
    clips = []
    if dev is not None:
        for c in mesh.clips:
            idx = np.flatnonzero(np.array([x == c.name for x in poses.clip]))
            k = idx[int(np.argmax(dev.pose_bound[idx]))]
            clips.append({"clip": c.name, "frames": int(len(idx)), "frame": int(poses.frame[k]),
                          "time": float(poses.time[k]), "deviation": float(dev.pose_bound[k])})
        report.details = {"clips": clips, "bind_pose_deviation": float(dev.pose_bound[0])}
    if target_faces is not None and proxy.face_count > target_faces:
        report.warnings.append(f"simplify reached {proxy.face_count} faces, above --target-faces {target_faces} "
                               "(collapses that would break a closed shell were undone)")
    if limit is not None and proxy is mesh and m > goal:
        report.warnings.append(f"no decimation keeps the deviation within {limit:.6g}; the full mesh is kept")
    if int(closed_out.sum()) < int(closed.sum()):
        report.warnings.append(f"{int(closed.sum()) - int(closed_out.sum())} closed shells did not stay closed")
    return proxy, report
