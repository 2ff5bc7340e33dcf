"""Two-sided distance between two animated triangle surfaces, as a sound upper bound on every pose
(used by ``simplify`` to bound how far a collision proxy strays from the full skinned mesh).

The two bounds (after Metro's sampling and libigl's ``hausdorff`` lower/upper bounds)
------------------------------------------------------------------------------------
For a source surface ``S`` and a target surface ``T`` at one pose, the one-sided distance is
``h(S, T) = max over x in S of d(x, T)``.  Every bound below uses only distances to *some*
triangles of ``T`` (``d(x, T) <= d(x, T_j)`` for any target triangle ``T_j``), so a candidate
list that misses the nearest triangle can over-state the distance, never under-state it.
For a triangle ``tau`` of the source (or a piece of one) with corners ``x_0, x_1, x_2``:

* **Lipschitz**: ``d(., T)`` is 1-Lipschitz, and every point of ``tau`` is within
  ``cover(tau)`` (:func:`cover_radius`, the exact covering radius of a triangle by its corners)
  of a corner, so ``max over tau of d(x, T) <= max_i u_i + cover(tau)`` for any upper bounds
  ``u_i >= d(x_i, T)``.
* **Convexity**: the distance to one triangle ``T_h`` (a convex set) is a convex function, so
  its maximum over ``tau`` is at a corner: ``max over tau of d(x, T) <= max_i d(x_i, T_h)``.
  This one is exact where the two surfaces coincide (a proxy triangle the decimation left as it
  was, a full triangle lying on one proxy triangle), where the Lipschitz bound would need samples
  finer than the distance itself.

A piece's bound is the smaller of the two.  Pieces whose bound is more than ``refine`` above the
largest distance sampled so far (``L``, over both directions and every pose) are split into four
(midpoints of the sides: the cover radius halves) *at the poses where they are above*, up to
``max_depth`` times; a piece at ``max_depth`` keeps its bound, which stays an upper bound.  So the
result is an upper bound of the two-sided distance at every pose, and where the depth suffices it
is at most ``L (1 + refine) + resolution`` with ``L`` a distance actually found.

Work shared across poses
------------------------
Candidate triangles (the ``k`` nearest target triangles by centroid) and each sample's nearest
target triangle ("home") are chosen once, on the setup pose (pose 0, the bind pose).  On every
other pose a sample is first bounded by its exact distance to its home triangle alone (one
point-triangle test); only samples of pieces still above the threshold get the exact distance to
all their candidates.  Both directions share one skinning per pose chunk (``frames``).

The kernels and their checking wrappers (:func:`sample_distances`, :func:`nearest_on_candidates`,
:func:`piece_bounds`, :func:`triangle_bounds`, :func:`cover_radius`, :func:`vertex_triangles`,
public here) are in :mod:`pipeline.geometry._distance_kernels`; this module is the refinement
driver (:func:`deviation_bound`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ._distance_kernels import (_pose_array, cover_radius, nearest_on_candidates,  # noqa: F401  (public here)
                                piece_bounds, sample_distances, triangle_bounds, vertex_triangles)

#: Exact distances on poses other than the setup pose walk at most this many steps to nearer
#: neighbouring triangles after the candidates.
WALK_STEPS = 8
#: A source triangle's home is chosen among its corners' nearest triangles and the first three
#: target triangles in the first this many candidates of all three corners.
HOME_CANDIDATES = 8
#: Candidate searches widen up to this many nearest centroids.
MAX_CANDIDATE_SEARCH = 32
#: Integer barycentric resolution of the pieces: 2**MAX_DEPTH_LIMIT subdivisions per side at most.
MAX_DEPTH_LIMIT = 10
_D = 1 << MAX_DEPTH_LIMIT


# ------------------------------------------------------------------------------ the bound
@dataclass
class OneSided:
    """Upper bound of ``max over x in source of d(x, target)`` on every pose (one direction).

    bound : float, the largest over the poses
    pose_bound : (F,) float64, an upper bound at each pose
    worst_pose : int, worst_triangle : int (the source triangle where ``bound`` is reached)
    sampled : float, the largest distance sampled in this direction (exact distance to the
        candidate triangles: the truth, unless the candidates missed the nearest triangle)
    pose_sampled : (F,) float64, the largest distance sampled at each pose (0 where none was)
    sampled_pose : int, sampled_vertex : int (a source vertex of the sample where ``sampled`` was
        found)
    samples : int, sample points made (vertices, then piece corners)
    pieces : int, pieces made (source triangles and their subdivisions)
    evaluations : int, (pose, piece) pairs bounded
    depth : int, the deepest subdivision used
    exceeded : bool, the search stopped at a distance above ``limit`` (``decide``): ``bound`` and
        ``pose_bound`` are then not bounds, only ``bound >= sampled > limit`` is known
    """

    bound: float
    pose_bound: np.ndarray
    worst_pose: int
    worst_triangle: int
    sampled: float
    pose_sampled: np.ndarray
    sampled_pose: int
    sampled_vertex: int
    samples: int
    pieces: int
    evaluations: int
    depth: int
    exceeded: bool = False


@dataclass
class _Shared:
    """What both directions share: the largest sampled distance and the threshold from it.

    With a ``limit`` the threshold never exceeds it (the bound then stays within the limit
    wherever the depth allows); ``decide`` only asks whether the bound is within the limit: the
    threshold is the limit itself, and the work stops as soon as a distance above it is found."""

    sampled: float
    refine: float
    resolution: float
    limit: float = np.inf
    decide: bool = False

    def threshold(self) -> float:
        if self.decide:
            return self.limit
        return min(self.sampled * (1.0 + self.refine) + self.resolution, self.limit)

    @property
    def exceeded(self) -> bool:
        return self.decide and self.sampled > self.limit


_CORNER_UV = np.array([[_D, 0], [0, _D], [0, 0]], np.int64)


class _Targets:
    """Candidate target triangles for points on the setup pose: the ``k`` nearest by centroid,
    widened (k x 4, up to ``MAX_CANDIDATE_SEARCH``) until the nearest triangle is certainly among
    them (no other centroid is close enough: ``k-th centroid distance - largest triangle radius >=
    the best distance found``); each row keeps the ``k`` most promising (smallest lower bound
    ``|x - centroid| - radius``), the nearest first."""

    def __init__(self, t0: np.ndarray, tri: np.ndarray):
        v = t0.astype(np.float64)[tri]
        self.tri = tri
        self.t0 = t0
        self.c = v.mean(axis=1)
        self.r = np.linalg.norm(v - self.c[:, None], axis=2).max(axis=1)
        self.rmax = float(self.r.max()) if len(self.r) else 0.0
        self.tree = cKDTree(self.c)

    def query(self, points: np.ndarray, k: int):
        """``(candidates (N, k) int64, nearest (N,) int64)`` for ``points`` (N, 3) float64."""
        m = len(self.tri)
        k = int(min(k, m))
        N = len(points)
        cand = np.empty((N, k), np.int64)
        near = np.empty(N, np.int64)
        todo = np.arange(N)
        kk = k
        pts32 = np.ascontiguousarray(points, dtype=np.float32)
        while len(todo):
            dd, jj = self.tree.query(points[todo], k=kk, workers=-1)
            dd, jj = dd.reshape(len(todo), kk), jj.reshape(len(todo), kk).astype(np.int64)
            n = len(todo)
            d, t, _ = sample_distances(pts32[todo], np.repeat(np.arange(n)[:, None], 3, 1),
                                       np.tile(np.array([1.0, 0.0, 0.0]), (n, 1)), self.t0, self.tri, jj)
            last = kk >= min(m, MAX_CANDIDATE_SEARCH)
            sure = (dd[:, -1] - self.rmax >= d) | last
            i = np.flatnonzero(sure)
            lb = dd[i] - self.r[jj[i]]
            lb[jj[i] == t[i, None]] = -np.inf       # the nearest first
            order = np.argsort(lb, axis=1, kind="stable")[:, :k]
            cand[todo[i]] = np.take_along_axis(jj[i], order, axis=1)
            near[todo[i]] = t[i]
            todo = todo[~sure]
            kk = min(m, kk * 4, MAX_CANDIDATE_SEARCH)
        return cand, near


class _Side:
    """One direction (source -> target): its samples, pieces, and the bound so far."""

    def __init__(self, src_tri, tgt_tri, s0, t0, k: int, count: int, max_depth: int):
        self.tri = np.ascontiguousarray(src_tri, dtype=np.int64)
        self.ttri = np.ascontiguousarray(tgt_tri, dtype=np.int64)
        self.s0, self.t0 = s0, t0          # (1, n, 3) float32 setup pose
        self.max_depth = int(max_depth)
        n, m = s0.shape[1], len(self.tri)
        self.targets = _Targets(t0[0], self.ttri)
        self.fans = vertex_triangles(self.ttri, t0.shape[1])
        self.k = int(k)
        self.s_idx = np.repeat(np.arange(n, dtype=np.int64)[:, None], 3, axis=1)
        self.s_bary = np.tile(np.array([1.0, 0.0, 0.0]), (n, 1))
        self.cand, self.near = self.targets.query(s0[0].astype(np.float64), self.k)
        d = sample_distances(s0, self.s_idx, self.s_bary, t0, self.ttri, self.near[:, None])[0]
        used = np.zeros(n, bool)
        used[self.tri.ravel()] = True
        self.used = np.flatnonzero(used)
        self.sampled = 0.0
        self.sampled_at = (0, 0)
        self.pose_sampled = np.zeros(count)
        self.saw(np.zeros(len(self.used), np.int64), self.used, d[self.used])
        self.corners = self.tri.copy()
        self.src = np.arange(m, dtype=np.int64)
        self.uv = np.broadcast_to(_CORNER_UV, (m, 3, 2)).copy()
        self.depth = np.zeros(m, np.int64)
        self.home = self._homes(self.corners, None)
        self.pose_bound = np.zeros(count)
        self.best = (-1.0, 0, 0)
        self.evaluations = 0
        self.deepest = 0
        self.pending = []

    def saw(self, poses, samples, d) -> None:
        """Exact sampled distances ``d`` of ``samples`` at global ``poses``: the largest found."""
        if not len(d):
            return
        np.maximum.at(self.pose_sampled, poses, d)
        i = int(np.argmax(d))
        if d[i] > self.sampled:
            self.sampled = float(d[i])
            self.sampled_at = (int(poses[i]), int(samples[i]))

    def _homes(self, corners, parent) -> np.ndarray:
        """Per piece, the target triangle with the smallest largest corner distance on the setup
        pose, among its corners' nearest triangles and either the first three triangles in all
        three corners' candidate rows (source triangles, ``parent`` None: where the surfaces
        coincide, the triangle under the piece is one of them) or the ``parent``'s home."""
        if parent is None:
            h = min(HOME_CANDIDATES, self.cand.shape[1])
            r0, r1, r2 = (self.cand[corners[:, i], :h] for i in range(3))
            common = (r0[:, :, None] == r1[:, None, :]).any(2) & (r0[:, :, None] == r2[:, None, :]).any(2)
            pick = np.argsort(~common, axis=1, kind="stable")[:, :3]           # the first three in common
            both = np.take_along_axis(common, pick, 1)
            C = np.c_[self.near[corners], np.where(both, np.take_along_axis(r0, pick, 1), self.near[corners[:, :1]])]
        else:
            C = np.c_[self.near[corners], parent]
        Q, c = C.shape
        sample = np.repeat(corners, c, axis=1).ravel()           # (q, corner, candidate)
        rows = np.tile(C, (1, 3)).reshape(-1, 1)
        d, _, _ = sample_distances(self.s0, self.s_idx, self.s_bary, self.t0, self.ttri, rows,
                                   sample=sample, row=np.arange(len(sample)))
        worst = d.reshape(Q, 3, c).max(axis=1)
        return C[np.arange(Q), np.argmin(worst, axis=1)]

    def split(self, q: np.ndarray) -> np.ndarray:
        """Four children (midpoint subdivision) of each piece ``q`` (U,); returns (U, 4) ids."""
        c, uv, src = self.corners[q], self.uv[q], self.src[q]
        mid_uv = np.stack([(uv[:, 0] + uv[:, 1]) // 2, (uv[:, 1] + uv[:, 2]) // 2, (uv[:, 2] + uv[:, 0]) // 2], 1)
        base = (_D + 1) ** 2
        keys = src[:, None] * base + mid_uv[..., 0] * (_D + 1) + mid_uv[..., 1]
        uk, inv = np.unique(keys.ravel(), return_inverse=True)
        st, u, v = uk // base, (uk % base) // (_D + 1), uk % (_D + 1)
        idx = self.tri[st]
        bary = np.stack([u, v, _D - u - v], axis=1) / _D
        pts = np.einsum("nk,nkd->nd", bary, self.s0[0].astype(np.float64)[idx])
        first = len(self.s_idx)
        cand, near = self.targets.query(pts, self.k)
        self.s_idx = np.concatenate([self.s_idx, idx])
        self.s_bary = np.concatenate([self.s_bary, bary])
        self.cand = np.concatenate([self.cand, cand])
        self.near = np.concatenate([self.near, near])
        m = (first + inv).reshape(-1, 3)                      # m01, m12, m20
        kids = np.stack([np.c_[c[:, 0], m[:, 0], m[:, 2]], np.c_[m[:, 0], c[:, 1], m[:, 1]],
                         np.c_[m[:, 2], m[:, 1], c[:, 2]], np.c_[m[:, 0], m[:, 1], m[:, 2]]], axis=1)
        kuv = np.stack([np.stack([uv[:, 0], mid_uv[:, 0], mid_uv[:, 2]], 1),
                        np.stack([mid_uv[:, 0], uv[:, 1], mid_uv[:, 1]], 1),
                        np.stack([mid_uv[:, 2], mid_uv[:, 1], uv[:, 2]], 1),
                        np.stack([mid_uv[:, 0], mid_uv[:, 1], mid_uv[:, 2]], 1)], axis=1)
        U = len(q)
        ids = len(self.corners) + np.arange(4 * U).reshape(U, 4)
        kc = kids.reshape(-1, 3)
        self.corners = np.concatenate([self.corners, kc])
        self.uv = np.concatenate([self.uv, kuv.reshape(-1, 3, 2)])
        self.src = np.concatenate([self.src, np.repeat(src, 4)])
        self.depth = np.concatenate([self.depth, np.repeat(self.depth[q] + 1, 4)])
        self.home = np.concatenate([self.home, self._homes(kc, np.repeat(self.home[q], 4))])
        return ids

    def evaluate(self, sv, tv, ch, lf, q, shared: _Shared):
        """Bound the pairs (local pose ``lf`` into ``sv``/``tv``, whose global poses are ``ch``,
        piece ``q``); record the resolved ones, keep the others pending (see the module
        docstring)."""
        if not len(q):
            return
        gf = ch[lf]
        self.evaluations += len(q)
        thr = shared.threshold()
        B, rad = piece_bounds(sv, self.s_idx, self.s_bary, tv, self.ttri, self.corners, self.near, self.home, lf, q,
                              threshold=thr, cover=True)
        # exact corner distances can only lower the Lipschitz term to (corner bounds) + cover: not
        # worth it for a piece whose cover alone is above the threshold (it is split anyway)
        hot = np.flatnonzero((B > thr) & (rad < thr))
        if len(hot):
            # the corners of the pieces above: exact distance to all their candidates, each once
            N = len(self.s_idx)
            uk, inv = np.unique((lf[hot, None] * N + self.corners[q[hot]]).ravel(), return_inverse=True)
            ef, es = uk // N, uk % N
            ex = sample_distances(sv, self.s_idx, self.s_bary, tv, self.ttri, self.cand, pose=ef, sample=es, row=es,
                                  walk=WALK_STEPS, fans=self.fans)[0]
            self.saw(ch[ef], es, ex)
            shared.sampled = max(shared.sampled, self.sampled)
            thr = shared.threshold()
            B[hot] = piece_bounds(sv, self.s_idx, self.s_bary, tv, self.ttri, self.corners, self.near, self.home,
                                  lf[hot], q[hot], corner_bounds=ex[inv].reshape(-1, 3), threshold=thr)
        done = (B <= thr) | (self.depth[q] >= self.max_depth)
        self._record(gf[done], q[done], B[done])
        keep = ~done
        if keep.any():
            self.pending.append((gf[keep], q[keep], B[keep]))

    def evaluate_all(self, sv, tv, ch, shared: _Shared):
        """Round 0: every source triangle on every pose of the chunk (global poses ``ch``), with
        the dense kernel; records the resolved ones, keeps the others pending."""
        F, m, n = sv.shape[0], len(self.tri), sv.shape[1]
        self.evaluations += F * m
        thr = shared.threshold()
        B, rad, _ = triangle_bounds(sv, self.tri, tv, self.ttri, self.near[:n], self.home[:m], threshold=thr)
        fh, th = np.nonzero((B > thr) & (rad < thr))
        if len(fh):
            key = (fh[:, None] * n + self.tri[th]).ravel()
            mark = np.zeros(F * n, bool)
            mark[key] = True
            uk = np.flatnonzero(mark)
            inv = (np.cumsum(mark) - 1)[key]
            ef, es = uk // n, uk % n
            ex = sample_distances(sv, self.s_idx, self.s_bary, tv, self.ttri, self.cand, pose=ef, sample=es, row=es,
                                  walk=WALK_STEPS, fans=self.fans)[0]
            self.saw(ch[ef], es, ex)
            shared.sampled = max(shared.sampled, self.sampled)
            thr = shared.threshold()
            B[fh, th] = piece_bounds(sv, self.s_idx, self.s_bary, tv, self.ttri, self.corners, self.near, self.home,
                                     fh, th, corner_bounds=ex[inv].reshape(-1, 3), threshold=thr)
        done = B <= thr if self.max_depth > 0 else np.ones_like(B, bool)
        low = np.where(done, B, -np.inf)
        top = low.max(axis=1)
        self.pose_bound[ch] = np.maximum(self.pose_bound[ch], top)
        f = int(np.argmax(top))
        if top[f] > self.best[0]:
            self.best = (float(top[f]), int(ch[f]), int(np.argmax(low[f])))
        pf, pq = np.nonzero(~done)
        if len(pf):
            self.pending.append((ch[pf], pq, B[pf, pq]))

    def _record(self, gf, q, B):
        if not len(B):
            return
        np.maximum.at(self.pose_bound, gf, B)
        i = int(np.argmax(B))
        if B[i] > self.best[0]:
            self.best = (float(B[i]), int(gf[i]), int(self.src[q[i]]))
        self.deepest = max(self.deepest, int(self.depth[q].max()))

    def _take_pending(self):
        p, self.pending = self.pending, []
        if not p:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        return tuple(np.concatenate(x) for x in zip(*p))

    def next_round(self, shared: _Shared):
        """Pending pairs still above the threshold, split: returns (pose, child piece) pairs."""
        gf, q, B = self._take_pending()
        ok = B <= shared.threshold()
        self._record(gf[ok], q[ok], B[ok])
        gf, q = gf[~ok], q[~ok]
        if not len(q):
            return gf, q
        uq, inv = np.unique(q, return_inverse=True)
        kids = self.split(uq)
        return np.repeat(gf, 4), kids[inv].ravel()

    def result(self, exceeded: bool = False) -> OneSided:
        if exceeded:  # stopped early: nothing below the measured distance is known
            self.best = (max(self.best[0], self.sampled), self.sampled_at[0], self.best[2])
        return OneSided(exceeded=exceeded, bound=max(self.best[0], 0.0), pose_bound=self.pose_bound,
                        worst_pose=self.best[1], worst_triangle=self.best[2], sampled=self.sampled,
                        pose_sampled=self.pose_sampled,
                        sampled_pose=self.sampled_at[0], sampled_vertex=int(self.s_idx[self.sampled_at[1], 0]),
                        samples=len(self.s_idx), pieces=len(self.corners), evaluations=self.evaluations,
                        depth=self.deepest)


def _pose_chunks(poses: np.ndarray, vertices: int, budget: int):
    step = max(1, int(budget // max(1, 12 * vertices)))
    return [poses[i:i + step] for i in range(0, len(poses), step)]


def deviation_bound(frames, count: int, tri_a, tri_b, refine: float, resolution: float,
                    candidates=(8, 16), max_depth: int = 6, probes: int = 8, limit: float | None = None,
                    decide: bool = False, frame_bytes: int = 128 * 2 ** 20, pair_budget: int = 1_000_000):
    """Upper bounds of both one-sided distances between two animated surfaces on every pose.

    Parameters
    ----------
    frames : callable
        ``frames(poses)`` ((p,) int) returns ``(a, b)``: ``(p, n_a, 3)`` and ``(p, n_b, 3)``
        float32 vertex positions of the two surfaces at those poses.  Pose 0 is the setup pose
        (candidates and home triangles are chosen on it).
    count : int, the number of poses
    tri_a, tri_b : (m_a, 3), (m_b, 3) int, the two surfaces' triangles
    refine : float
        Pieces are subdivided while their bound is more than this fraction above the largest
        sampled distance (over both directions and every pose) ...
    resolution : float
        ... plus this length.
    candidates : (k_ab, k_ba)
        Candidate target triangles per sample for a -> b and for b -> a.
    max_depth : int, at most ``MAX_DEPTH_LIMIT``
        Subdivisions at most (a piece at this depth keeps its bound).
    probes : int
        Poses (evenly spaced) on which every vertex is measured exactly before the sweep, to
        start the threshold near the truth.
    limit : float, optional
        Subdivide at least until the bound is within ``limit`` (where the depth allows).
    decide : bool
        Only decide whether the bound is within ``limit``: subdivide only down to the limit, and
        stop as soon as a distance above it is measured (the results then say ``exceeded``).

    Returns
    -------
    (OneSided a -> b, OneSided b -> a)
    """
    if not 0 <= max_depth <= MAX_DEPTH_LIMIT:
        raise ValueError(f"max_depth: expected 0..{MAX_DEPTH_LIMIT}, got {max_depth}")
    a0, b0 = frames(np.array([0]))
    a0, b0 = _pose_array(a0, "frames a"), _pose_array(b0, "frames b")
    sides = (_Side(tri_a, tri_b, a0, b0, candidates[0], count, max_depth),
             _Side(tri_b, tri_a, b0, a0, candidates[1], count, max_depth))
    shared = _Shared(max(s.sampled for s in sides), float(refine), float(resolution),
                     np.inf if limit is None else float(limit), bool(decide and limit is not None))

    def done():
        return [s.result(shared.exceeded) for s in sides]

    if shared.exceeded:
        return done()
    nv = a0.shape[1] + b0.shape[1]
    # probes: exact distances of every vertex on a few poses
    pp = np.unique(np.linspace(0, count - 1, min(count, max(probes, 1))).astype(np.int64))
    for ch in _pose_chunks(pp, nv, frame_bytes):
        va, vb = frames(ch)
        for s, sv, tv in ((sides[0], va, vb), (sides[1], vb, va)):
            step = max(1, pair_budget // max(len(s.used), 1))
            for i in range(0, len(ch), step):
                f = np.repeat(np.arange(i, min(len(ch), i + step)), len(s.used))
                u = np.tile(s.used, len(f) // max(len(s.used), 1))
                d = sample_distances(sv, s.s_idx, s.s_bary, tv, s.ttri, s.cand, pose=f, sample=u, row=u,
                                     walk=WALK_STEPS, fans=s.fans)[0]
                s.saw(ch[f], u, d)
        shared.sampled = max(shared.sampled, *(s.sampled for s in sides))
        if shared.exceeded:
            return done()
    # round 0: every piece (source triangle) on every pose
    per = max(len(sides[0].tri), len(sides[1].tri), 1)
    step = max(1, min(4 * pair_budget // per, int(frame_bytes // max(1, 12 * nv))))
    for lo in range(0, count, step):
        ch = np.arange(lo, min(count, lo + step))
        va, vb = frames(ch)
        for s, sv, tv in ((sides[0], va, vb), (sides[1], vb, va)):
            s.evaluate_all(sv, tv, ch, shared)
        if shared.exceeded:
            return done()
    # refinement rounds: the pending pairs split, on the poses where they are above
    for _ in range(max_depth):
        todo = []
        for s in sides:
            gf, q = s.next_round(shared)
            order = np.argsort(gf, kind="stable")
            todo.append((gf[order], q[order]))
        if not any(len(q) for _, q in todo):
            break
        poses = np.unique(np.concatenate([gf for gf, _ in todo]))
        for ch in _pose_chunks(poses, nv, frame_bytes):
            va, vb = frames(ch)
            for (gf, q), s, sv, tv in zip(todo, sides, (va, vb), (vb, va)):
                i0, i1 = np.searchsorted(gf, ch[0]), np.searchsorted(gf, ch[-1], side="right")
                for i in range(i0, i1, pair_budget):
                    j = min(i1, i + pair_budget)
                    s.evaluate(sv, tv, ch, np.searchsorted(ch, gf[i:j]), q[i:j], shared)
            if shared.exceeded:
                return done()
    for s in sides:  # pairs left at the last round keep their bound
        gf, q, B = s._take_pending()
        s._record(gf, q, B)
    return done()
