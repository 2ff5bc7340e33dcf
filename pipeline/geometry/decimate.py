"""Decimation of a skinned mesh into a collision proxy that keeps its topology: :class:`Decimator`.

Collapse order: `fast-simplification`_ (MIT, pyvista's binding of Fast-Quadric-Mesh-
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

Topology and placement: :func:`colossus.pipeline.geometry.collapse.apply_collapses` replays that
history on the real rest positions and accepts a collapse only when the mesh stays a
two-manifold of the same topology (link condition, interior manifold ends, no face turned
over; open borders and the source's own defects never move).  So every closed shell stays
closed with its Euler characteristic, which is checked again on the result.  The replay stops
at ``--target-faces``; when refusals use up the library's history first, the library runs
again to a lower target.  Each merged vertex sits at its cluster's quadric-optimal point.

.. _fast-simplification: https://github.com/pyvista/fast-simplification
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..model import SkinnedMesh
from ..tolerances import SIMPLIFY_BONE_BOUNDARY
from .collapse import apply_collapses, vertex_quadrics
from .deviation import Deviation
from .transfer import transfer_shapes, transfer_weights

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


def shells(tris: np.ndarray, n: int):
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

@dataclass
class Candidate:
    mesh: SkinnedMesh
    limit: int                       # history steps looked at
    collapses: int                   # accepted
    refused: int
    crossing: int                    # accepted collapses joining different dominant bones
    deviation: Deviation | None = None


class Decimator:
    """The rest mesh, its collapse history and the replay (see the module docstring)."""

    def __init__(self, mesh: SkinnedMesh, max_influences: int):
        self.mesh = mesh
        self.max_influences = int(max_influences)
        n = mesh.vertex_count
        self.tris = mesh.triangles.astype(np.int64)
        self.shell, self.count, self.closed, self.euler = shells(self.tris, n)
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

    def build(self, goal: int, limit: int | None = None) -> Candidate:
        r = self.replay(goal, limit)
        # each proxy vertex keeps to its own shell's skin (collapses never join shells)
        pshell = np.full(len(r.positions), -1, np.int64)
        live = r.vertex_map >= 0
        pshell[r.vertex_map[live]] = self.vshell[live]
        ji, jw, _, tri, bary = transfer_weights(self.mesh, r.positions, self.max_influences, pshell, self.shell)
        shapes = transfer_shapes(self.mesh, tri, bary) if self.mesh.blend_shapes else ()
        proxy = self.mesh.replace(positions=r.positions, triangles=r.triangles.astype(np.int32), joint_indices=ji,
                                  joint_weights=jw, parts=None, blend_shapes=shapes)
        acc = self.col[r.accepted]
        crossing = int(np.count_nonzero(self.dominant[acc[:, 0]] != self.dominant[acc[:, 1]]))
        return Candidate(proxy, r.looked_at, int(r.accepted.sum()), int(r.looked_at - r.accepted.sum()), crossing)
