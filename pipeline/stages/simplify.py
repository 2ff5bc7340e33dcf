"""``simplify``: a collision proxy of a target size that carries the skin, with a bound on how far
it strays from the full skinned mesh on every frame of every clip.

Off by default; ``colossus import --target-faces N`` and/or ``--max-deviation D`` (stage units,
or ``D%`` of the model size) turn it on.  It runs **after** ``bind`` and before ``parts``: the
full mesh it measures against is then the collider colossus would write without it (unweighted
vertices resolved, at most ``--max-influences`` normalised influences, joints parents-first), and
the proxy's parts, spheres and the every-frame proof are made exactly as for any mesh.

1. Decimation order: `fast-simplification`_ (MIT, pyvista's binding of Fast-Quadric-Mesh-
   Simplification), chosen over libigl's ``qslim`` (refuses non-manifold input; 12.8 s against
   1.1 s on the 200,000-triangle benchmark tube), VTK's ``vtkQuadricDecimation`` (89 s, no
   collapse map) and pymeshlab (GPL): the fastest, numpy only, and it returns its **collapse
   history**.  Its history is prefix-stable (a run to a lower target repeats the run to a higher
   one, then goes on), so one run below the target gives every coarser proxy as a prefix.

   Part boundaries: the library chooses its collapses on an *embedding* of the rest mesh in which
   each vertex is moved along its normal by ``h(bone) * SIMPLIFY_BONE_BOUNDARY`` times its mean
   edge length, ``h`` a level per dominant bone that differs between neighbouring parts (a
   greedy colouring of the part adjacency graph).  Every part boundary becomes a step about half
   an edge high; a collapse across it pays about the step squared in the quadric error, so it
   waits (Unreal's "enforce bone boundaries", as a penalty: on the corpus characters it cuts the
   collapses across bones several times over and lowers the measured posed deviation on most of
   them).  When the steps make the replay refuse so many collapses that the target is out of
   reach (very fine meshes decimated far: the library folds the step's strips, which the replay
   on the real surface refuses), the history is made again without them.  The embedding is
   scaled to unit size first: the library's error schedule is absolute.

2. Topology and placement: :func:`pipeline.geometry.collapse.apply_collapses` replays that
   history on the real rest positions and accepts a collapse only when the mesh stays a
   two-manifold of the same topology (link condition, interior manifold ends, no face turned
   over; open borders and the source's own defects never move).  So every closed shell stays
   closed with its Euler characteristic, which is checked again on the result.  The replay stops
   at ``--target-faces``; when refusals use up the library's history first, the library runs
   again to a lower target.  Each merged vertex sits at its cluster's quadric-optimal point.

3. Skin: closest-point transfer on the full rest mesh.  Each proxy vertex takes the per-bone
   weights of its nearest point on its own shell of the full rest surface (a rigid part or a
   second skin beside the body keeps its own joints), interpolated barycentrically over that
   triangle's corners (weights of each bone are interpolated, joint indices never); the strongest
   ``--max-influences`` are kept and renormalised by :func:`pipeline.stages.bind.limit_influences`,
   the same code ``bind`` uses.  This is local at joints, where a cluster average would blend the
   weights of the whole (possibly large) cluster.

4. Deviation (:func:`deviation`): on the bind pose and every frame of every clip, both meshes are
   skinned (:func:`runtime.kernels.skin.skin_frames`, the one skinning kernel, once per pose for
   both directions) and
   the two-sided distance between the skinned surfaces is bounded from above by
   :func:`pipeline.geometry.surface_distance.deviation_bound` (a Lipschitz bound and a convexity
   bound per piece, pieces subdivided where they are more than ``DEVIATION_REFINE`` above the
   largest distance found), plus ``DEVIATION_PAD * size`` for float32 rounding.

``--max-deviation`` keeps the longest prefix of the history whose bound stays within the limit
(a bisection over the prefix length; each prefix is only *decided*: subdivided down to the limit,
rejected at the first distance measured above it), then measures the one kept in full.

.. _fast-simplification: https://github.com/pyvista/fast-simplification
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from colossus.runtime.kernels.skin import skin_frames

from ..geometry.collapse import apply_collapses, vertex_quadrics
from ..geometry.surface_distance import deviation_bound, nearest_on_candidates
from ..model import SkinnedMesh, skel_transforms
from ..options import parse_max_deviation, resolve_max_deviation
from ..tolerances import (DEVIATION_MAX_DEPTH, DEVIATION_PAD, DEVIATION_REFINE, DEVIATION_RESOLUTION,
                          SIMPLIFY_BONE_BOUNDARY, model_scale)
from . import StageReport
from .bind import limit_influences
from .orient import orient

#: Candidate triangles per sample: of the dense full mesh (proxy -> full, the weight transfer) ...
FULL_CANDIDATES = 16
#: ... and of the coarse proxy (full -> proxy).
PROXY_CANDIDATES = 8
#: The library is asked for this fraction of the target, so that refused collapses still leave
#: enough history to reach the target ...
LIBRARY_UNDERSHOOT = 0.8
#: ... and runs again (lower) at most this many times when they do not.
MAX_DECIMATIONS = 3
#: The bone-boundary steps are dropped when, with them, the proxy stays above the target (the
#: refusals they cause ate the history) by more than this fraction ...
PENALTY_SLACK = 0.0
#: ... and without a second try when the first leaves it this far above.
HOPELESS = 0.25
#: --max-deviation: the prefix search stops when the prefixes bracketing the limit differ by less
#: than this fraction of the collapses.
PREFIX_TOLERANCE = 0.02
#: With --max-deviation and no --target-faces, the history goes down to this fraction of the
#: faces (at least MIN_FACES), and the prefix search picks the longest prefix within the limit.
FLOOR_FRACTION = 0.005
MIN_FACES = 64
#: Skinned poses kept in memory by the deviation when they fit in this many bytes.
SKIN_CACHE_BYTES = 512 * 2 ** 20


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


def _chunks(F: int, vertices: int, budget: int = 8_000_000):
    """Pose indices ``0..F-1`` in chunks whose skinned vertices stay under ~100 MB."""
    step = max(1, int(budget // max(1, 3 * vertices)))
    return [np.arange(i, min(F, i + step)) for i in range(0, F, step)]


# ------------------------------------------------------------------------------ deviation
@dataclass
class Deviation:
    """The two-sided deviation bound between a proxy and the full mesh.

    bound : float, stage units (max over poses and both directions, pad included)
    pose_bound : (F,) float64, an upper bound of the deviation at each pose (pad included)
    sampled : float, the largest distance actually measured between the surfaces (a sample point
        and its nearest candidate triangle: the truth, from below, unless a candidate list
        missed the nearest triangle); the bound is at most ``sampled * (1 + refine)`` plus the
        resolution wherever the subdivision depth sufficed
    pose_sampled : (F,) float64, the largest distance measured at each pose
    worst_pose : int, worst_joint : int, direction : str
        Where ``sampled`` was measured: the pose, the dominant joint of the sample's vertex, and
        ``"full->proxy"`` (a point of the full surface far from the proxy) or ``"proxy->full"``
    samples : int, sample points made (both directions)
    exceeded : bool, a ``decide`` run stopped at a distance above its limit
    directions : {"full->proxy": OneSided, "proxy->full": OneSided}
    """

    bound: float
    pose_bound: np.ndarray
    sampled: float
    pose_sampled: np.ndarray
    worst_pose: int
    worst_joint: int
    direction: str
    samples: int
    exceeded: bool = False
    directions: dict = field(default_factory=dict)


def _dominant_joint(mesh: SkinnedMesh, v: int) -> int:
    """The strongest joint of vertex ``v``."""
    return int(mesh.joint_indices[v][int(np.argmax(mesh.joint_weights[v]))])


def deviation(full: SkinnedMesh, proxy: SkinnedMesh, poses: Poses | None = None,
              refine: float = DEVIATION_REFINE, limit: float | None = None, decide: bool = False) -> Deviation:
    """Upper bound of the two-sided distance between the skinned surfaces of ``full`` and
    ``proxy`` (same skeleton) on every pose.

    Parameters
    ----------
    full, proxy : SkinnedMesh
    poses : Poses, optional (default :func:`mesh_poses` of ``full``: bind pose and every frame);
        its first pose is where candidates are chosen (the bind pose in :func:`mesh_poses`)
    refine : float
        Pieces are subdivided while their bound is more than this fraction above the largest
        sampled distance (see :func:`pipeline.geometry.surface_distance.deviation_bound`).
    limit : float, optional
        Subdivide until the bound is within ``limit`` where possible.
    decide : bool
        Only decide ``bound <= limit`` (cheaper; ``exceeded`` says no).

    Returns
    -------
    Deviation
    """
    poses = poses or mesh_poses(full)
    size = model_scale(_rest_skel(full))
    F = len(poses.mats)
    nv = full.vertex_count + proxy.vertex_count
    cache = {}
    if F * nv * 12 <= SKIN_CACHE_BYTES:  # every pose skinned once, in a few kernel calls
        cache["a"] = np.empty((F, full.vertex_count, 3), np.float32)
        cache["b"] = np.empty((F, proxy.vertex_count, 3), np.float32)
        for ch in _chunks(F, nv):
            cache["a"][ch] = skin_frames(full.positions, full.joint_indices, full.joint_weights, poses.mats[ch])
            cache["b"][ch] = skin_frames(proxy.positions, proxy.joint_indices, proxy.joint_weights, poses.mats[ch])

    def frames(idx):
        if cache:
            if len(idx) and idx[-1] - idx[0] == len(idx) - 1:  # a run of poses: views, no copy
                return cache["a"][idx[0]:idx[-1] + 1], cache["b"][idx[0]:idx[-1] + 1]
            return cache["a"][idx], cache["b"][idx]
        m = poses.mats[idx]
        return (skin_frames(full.positions, full.joint_indices, full.joint_weights, m),
                skin_frames(proxy.positions, proxy.joint_indices, proxy.joint_weights, m))

    pad = DEVIATION_PAD * size
    a, b = deviation_bound(frames, F, full.triangles, proxy.triangles, refine, DEVIATION_RESOLUTION * size,
                           candidates=(PROXY_CANDIDATES, FULL_CANDIDATES), max_depth=DEVIATION_MAX_DEPTH,
                           limit=None if limit is None else limit - pad, decide=decide)
    worst, src, direction = (a, full, "full->proxy") if a.sampled >= b.sampled else (b, proxy, "proxy->full")
    return Deviation(bound=max(a.bound, b.bound) + pad, pose_bound=np.maximum(a.pose_bound, b.pose_bound) + pad,
                     sampled=worst.sampled, pose_sampled=np.maximum(a.pose_sampled, b.pose_sampled),
                     worst_pose=worst.sampled_pose, worst_joint=_dominant_joint(src, worst.sampled_vertex),
                     direction=direction, samples=a.samples + b.samples, exceeded=a.exceeded or b.exceeded,
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
    """Rest positions (scaled to unit size) moved along their normals by a level per dominant bone
    (``_bone_levels``, in [-1, 1]) times ``step`` times the vertex's mean edge length: a part
    boundary becomes a step about ``step`` edges high, whatever the mesh's resolution."""
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
    e = np.linalg.norm(p[t] - p[t[:, [1, 2, 0]]], axis=2)
    edge = np.bincount(t.ravel(), weights=e.ravel(), minlength=len(p)) / \
        np.maximum(np.bincount(t.ravel(), minlength=len(p)), 1)
    h = _bone_levels(dominant, t, bones)
    return p + step * (edge * h[dominant])[:, None] * vn


def _collapses(embedded: np.ndarray, tris: np.ndarray, target: int) -> np.ndarray:
    """fast-simplification's collapse history down to ``target`` faces: ``(k, 2)`` int64,
    ``[a, b]`` = ``b`` merged into ``a``."""
    import fast_simplification as fs

    if target >= len(tris):
        return np.zeros((0, 2), np.int64)
    _, _, col = fs.simplify(embedded, tris.astype(np.int32), target_count=int(max(target, 1)), agg=7.0,
                            return_collapses=True, preserve_border=True)
    return np.asarray(col, dtype=np.int64).reshape(-1, 2)


def transfer_weights(full: SkinnedMesh, points: np.ndarray, max_influences: int, point_shell=None, face_shell=None):
    """Skin weights at ``points`` (mesh space, rest) by closest-point transfer on the full rest
    mesh: per-bone weights interpolated barycentrically over the nearest triangle, strongest
    ``max_influences`` kept and renormalised.

    ``point_shell`` (n',) int and ``face_shell`` (m,) int, when given, keep each point to the
    triangles of its own shell: a rigid part (a helmet bound to the head with weight 1) or another
    skin merged into the one skeleton must not take the weights of a different shell that happens
    to lie nearer (a point of a shell with no triangle, ``-1``, looks at every triangle).

    Returns ``(joint_indices (n', max_influences) int32, joint_weights (n', max_influences)
    float32, distance (n',) float64)``: the distance from each point to its full rest surface."""
    rest = full.positions
    tri = full.triangles.astype(np.int64)
    pts = np.asarray(points, dtype=np.float32)
    n2 = len(pts)
    kk = int(min(FULL_CANDIDATES, len(tri)))
    centroids = rest.astype(np.float64)[tri].mean(axis=1)
    if point_shell is None or face_shell is None:
        cand = cKDTree(centroids).query(pts, k=kk)[1].reshape(n2, kk)
    else:
        point_shell = np.asarray(point_shell, dtype=np.int64)
        face_shell = np.asarray(face_shell, dtype=np.int64)
        cand = np.empty((n2, kk), np.int64)
        mine = np.isin(point_shell, face_shell)
        if not mine.all():
            cand[~mine] = cKDTree(centroids).query(pts[~mine], k=kk)[1].reshape(-1, kk)
        order = np.argsort(face_shell, kind="stable")
        shells, first, count = np.unique(face_shell[order], return_index=True, return_counts=True)
        for s, f0, c in zip(shells, first, count):
            rows = np.flatnonzero(point_shell == s)
            if not len(rows):
                continue
            faces = order[f0:f0 + c]
            k = int(min(kk, c))
            near = cKDTree(centroids[faces]).query(pts[rows], k=k)[1].reshape(len(rows), k)
            # a shell with fewer triangles than kk repeats its nearest one (a duplicate candidate)
            cand[rows] = faces[np.pad(near, ((0, 0), (0, kk - k)), mode="edge")]
    d, t, bary = nearest_on_candidates(pts, np.repeat(np.arange(n2)[:, None], 3, 1),
                                       np.tile([1.0, 0.0, 0.0], (n2, 1)), rest, tri, cand)
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
    limit: int                       # history steps looked at
    collapses: int                   # accepted
    refused: int
    crossing: int                    # accepted collapses joining different dominant bones
    deviation: Deviation | None = None


class _Decimator:
    """The rest mesh, its collapse history and the replay (see the module docstring)."""

    def __init__(self, mesh: SkinnedMesh, max_influences: int):
        self.mesh = mesh
        self.max_influences = int(max_influences)
        n = mesh.vertex_count
        self.tris = mesh.triangles.astype(np.int64)
        self.shell, self.count, self.closed, self.euler = _shells(self.tris, n)
        self.vshell = np.full(n, -1, np.int64)
        self.vshell[self.tris.ravel()] = np.repeat(self.shell, 3)
        self.dominant = mesh.joint_indices[np.arange(n), np.argmax(mesh.joint_weights, axis=1)].astype(np.int64)
        self.quadrics = vertex_quadrics(mesh.positions, self.tris)
        self.embedded = None
        self.step = SIMPLIFY_BONE_BOUNDARY
        self.col = np.zeros((0, 2), np.int64)
        self.runs = 0

    def history(self, goal: int) -> None:
        """A collapse history that reaches ``goal`` faces after refusals, if the library can:
        with the bone-boundary steps first, without them if they make too many collapses
        refused to reach the goal (a penalty, not a wall)."""
        if goal >= len(self.tris):
            return
        for step in (SIMPLIFY_BONE_BOUNDARY, 0.0):
            self.step = step
            self.embedded = _embedding(self.mesh.positions, self.tris, self.dominant, self.mesh.joint_count, step)
            self.col = np.zeros((0, 2), np.int64)
            ask = max(4, int(goal * LIBRARY_UNDERSHOOT))
            for _ in range(MAX_DECIMATIONS if step == 0.0 else 2):
                self.runs += 1
                col = _collapses(self.embedded, self.tris, ask)
                grew = len(col) > len(self.col)
                self.col = col
                faces = len(self.replay(goal).triangles)
                if faces <= goal or not grew or ask <= 4 or (step and faces > goal * (1.0 + HOPELESS)):
                    break
                # refusals used the history up: ask for that many more faces' worth of collapses
                ask = max(4, ask - 2 * (faces - goal) - int(0.1 * goal))
            if faces <= goal * (1.0 + PENALTY_SLACK):
                return

    def replay(self, goal: int, limit: int | None = None):
        return apply_collapses(self.mesh.positions, self.tris, self.col, stop_faces=goal, limit=limit,
                               quadrics=self.quadrics, vertex_shell=self.vshell)

    def build(self, goal: int, limit: int | None = None) -> _Candidate:
        r = self.replay(goal, limit)
        # each proxy vertex keeps to its own shell's skin (collapses never join shells)
        pshell = np.full(len(r.positions), -1, np.int64)
        live = r.vertex_map >= 0
        pshell[r.vertex_map[live]] = self.vshell[live]
        ji, jw, _ = transfer_weights(self.mesh, r.positions, self.max_influences, pshell, self.shell)
        proxy = self.mesh.replace(positions=r.positions, triangles=r.triangles.astype(np.int32), joint_indices=ji,
                                  joint_weights=jw, parts=None)
        acc = self.col[r.accepted]
        crossing = int(np.count_nonzero(self.dominant[acc[:, 0]] != self.dominant[acc[:, 1]]))
        return _Candidate(proxy, r.looked_at, int(r.accepted.sum()), int(r.looked_at - r.accepted.sum()), crossing)


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
        (:func:`colossus.pipeline.options.parse_max_deviation`).
    max_influences : int
        Influences kept per proxy vertex.

    Returns
    -------
    (SkinnedMesh, StageReport)
        Report counts: ``faces_in``, ``faces_out``, ``vertices_in``, ``vertices_out``,
        ``target_faces``, ``max_deviation_limit``, ``deviation`` (the bound, stage units),
        ``deviation_relative`` (over the model size), ``sampled_deviation`` (the largest distance
        measured), ``worst`` (``{"clip",
        "frame", "time", "bone", "direction", "measured", "samples"}``: where it was
        measured), ``worst_by_direction`` (the same per direction, with its sample count),
        ``closed_shells_in``, ``closed_shells_out``,
        ``shells_in``, ``shells_out``, ``euler_changed`` (closed shells whose Euler characteristic
        changed: 0), ``collapses``, ``collapses_refused``, ``decimations`` (library runs),
        ``bone_crossing_collapses`` (accepted collapses joining vertices of different dominant
        bones), ``bone_boundary_step`` (the step used, in edge lengths: 0 when it was dropped), ``crossing_faces_in``/``crossing_faces_out`` (faces whose corners have different
        dominant bones), ``deviation_samples``, ``decimate_seconds``, ``deviation_seconds``;
        details: ``clips`` (per clip: ``{"clip", "frames", "deviation"`` (the bound over its
        frames)``, "measured"`` (the largest distance measured)``, "frame", "time"`` (where)``}``),
        ``bind_pose_deviation`` and ``bind_pose_measured``.  ``worst`` is where the largest
        distance was measured (the bound is nearly flat near its top: where it peaks says little).
    """
    if target_faces is None and max_deviation is None:
        raise ValueError("simplify: expected target_faces or max_deviation, got neither")
    if target_faces is not None and int(target_faces) < 4:
        raise ValueError(f"simplify target_faces: expected >= 4, got {target_faces}")
    spec = parse_max_deviation(max_deviation)
    t_start = time.perf_counter()
    n, m = mesh.vertex_count, mesh.face_count
    size = model_scale(_rest_skel(mesh))
    limit = resolve_max_deviation(spec, size)
    poses = mesh_poses(mesh)
    report = StageReport("simplify")
    dec = _Decimator(mesh, max_influences)
    t_dev = 0.0

    goal = int(target_faces) if target_faces is not None else max(MIN_FACES, int(FLOOR_FRACTION * m))
    cand = _Candidate(mesh, 0, 0, 0, 0)
    if goal < m:
        dec.history(goal)
        if len(dec.col):
            cand = dec.build(goal)

    if limit is not None and cand.mesh is not mesh:
        # the longest history prefix whose bound is within the limit (bisection; each prefix is
        # only decided, the one kept is then measured in full)
        td = time.perf_counter()

        def within(c):
            d = deviation(mesh, c.mesh, poses, limit=limit, decide=True)
            return not d.exceeded and d.bound <= limit

        if not within(cand):
            lo, hi = 0, cand.limit  # history prefixes: lo within the limit (the full mesh), hi not
            best = None
            while hi - lo > max(1, PREFIX_TOLERANCE * cand.limit):
                mid = (lo + hi) // 2
                c = dec.build(goal, mid)
                if within(c):
                    lo, best = mid, c
                else:
                    hi = mid
            cand = best if best is not None else _Candidate(mesh, 0, 0, 0, 0)
        if cand.mesh is not mesh:
            cand.deviation = deviation(mesh, cand.mesh, poses, limit=limit)
        t_dev += time.perf_counter() - td
    if cand.mesh is not mesh and cand.deviation is None:
        td = time.perf_counter()
        cand.deviation = deviation(mesh, cand.mesh, poses)
        t_dev += time.perf_counter() - td

    proxy, dev = cand.mesh, cand.deviation
    _, orep = orient(proxy)
    oc = orep.counts
    shell_out, count_out, closed_out, euler_out = _shells(proxy.triangles, proxy.vertex_count)
    crossing = lambda mm: int(np.count_nonzero(  # noqa: E731
        np.ptp(mm.joint_indices[np.arange(mm.vertex_count), np.argmax(mm.joint_weights, 1)][mm.triangles], 1)))
    def where(i, joint, direction, measured, samples):
        return {"clip": poses.clip[i] or "bind pose", "frame": int(poses.frame[i]) if poses.clip[i] else -1,
                "time": float(poses.time[i]) if poses.clip[i] else "", "bone": mesh.joint_names[joint],
                "direction": direction, "measured": float(measured), "samples": int(samples)}

    by_direction = {}
    if dev is None:
        worst = {"clip": "", "frame": -1, "time": "", "bone": "", "direction": "", "measured": 0.0, "samples": 0}
        bound = 0.0
    else:
        worst = where(dev.worst_pose, dev.worst_joint, dev.direction, dev.sampled, dev.samples)
        for name, side in dev.directions.items():
            src = mesh if name == "full->proxy" else proxy
            by_direction[name] = where(side.sampled_pose, _dominant_joint(src, side.sampled_vertex), name,
                                       side.sampled, side.samples)
        bound = float(dev.bound)
    report.counts = {
        "faces_in": int(m), "faces_out": int(proxy.face_count), "vertices_in": int(n),
        "vertices_out": int(proxy.vertex_count), "target_faces": int(target_faces) if target_faces else None,
        "max_deviation_limit": float(limit) if limit is not None else None,
        "deviation": bound, "deviation_relative": bound / size,
        "sampled_deviation": float(dev.sampled) if dev else 0.0, "worst": worst, "worst_by_direction": by_direction,
        "shells_in": int(dec.count), "closed_shells_in": int(dec.closed.sum()),
        "shells_out": int(count_out), "closed_shells_out": int(closed_out.sum()),
        "euler_changed": int(abs(np.sort(dec.euler[dec.closed]).sum() - np.sort(euler_out[closed_out]).sum()) > 0
                             or int(closed_out.sum()) != int(dec.closed.sum())),
        "faces_flipped_out": int(oc["faces_flipped"]), "nonmanifold_edges_out": int(oc["nonmanifold_edges"]),
        "collapses": cand.collapses, "collapses_refused": cand.refused, "decimations": dec.runs,
        "bone_crossing_collapses": cand.crossing, "bone_boundary_step": float(dec.step),
        "crossing_faces_in": crossing(mesh), "crossing_faces_out": crossing(proxy),
        "deviation_samples": int(dev.samples) if dev else 0,
        "decimate_seconds": round(time.perf_counter() - t_start - t_dev, 4), "deviation_seconds": round(t_dev, 4),
    }
    if dev is not None:
        clips = []
        for c in mesh.clips:
            idx = np.flatnonzero(np.array([x == c.name for x in poses.clip]))
            k = idx[int(np.argmax(dev.pose_sampled[idx]))]
            clips.append({"clip": c.name, "frames": int(len(idx)), "frame": int(poses.frame[k]),
                          "time": float(poses.time[k]), "deviation": float(dev.pose_bound[idx].max()),
                          "measured": float(dev.pose_sampled[k])})
        report.details = {"clips": clips, "bind_pose_deviation": float(dev.pose_bound[0]),
                          "bind_pose_measured": float(dev.pose_sampled[0])}
    if target_faces is not None and proxy.face_count > target_faces and limit is None:
        report.warnings.append(f"simplify reached {proxy.face_count} faces, above --target-faces {target_faces} "
                               "(the remaining collapses would change a shell's topology or open border)")
    if limit is not None and proxy is mesh and m > goal:
        report.warnings.append(f"no decimation keeps the deviation within {limit:.6g}; the full mesh is kept")
    if int(closed_out.sum()) < int(dec.closed.sum()):
        report.warnings.append(f"{int(dec.closed.sum()) - int(closed_out.sum())} closed shells did not stay closed")
    return proxy, report
