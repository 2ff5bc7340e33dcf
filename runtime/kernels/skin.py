"""The one linear-blend-skinning kernel of the project: the runtime's posing, the frame proof,
the continuous certificate and the import's spheres stage all skin through this module.

Layout: skinning transforms are folded into ``(F, J, 12)`` float64 arrays: for pose ``f`` and
joint ``j`` the first three rows of the **column-vector** 4x4 matrix ``M`` (``p' = M @ p``), row
by row, so ``x' = m[f, j, 0:4] . (x, y, z, 1)``, ``y' = m[f, j, 4:8] . (...)``, ``z' = m[f, j,
8:12] . (...)`` (:func:`fold`).  Points are ``(n, 3)`` float32, influences ``(n, k)`` int32
joint indices and float32 weights.  Arithmetic is float64.

One padding policy (:func:`check_skin_inputs`): a weight of exactly 0 is padding, its joint index
may be anything (it is mapped to 0 and never read); a non-zero weight must name a joint in
``[0, J)``.  The skinned point is ``sum_k w[v, k] * M[j[v, k]] @ (p[v], 1)``, exactly what
``UsdSkel.SkinPointsLBS`` computes (the weights are not renormalised; translations are weighted).

Kernels (private) and their readable numpy reference ``tests/references/naive.py::naive_lbs``:

* ``_lbs(v, f, points, ji, jw, m)``: one vertex (inlined into the loops below);
* ``_skin_frames`` / ``_skin_frames_serial``: every vertex of every pose into ``(F, n, 3)``;
* ``_skin_subset``: the vertices ``verts`` of one pose (the runtime's lazy per-part skinning);
* ``_skin_dist2``: squared distances of the skinned vertices from a centre per pose, behind
  :func:`part_farthest` (per (pose, part), the part's skinned vertex farthest from a centre, only
  for the pairs asked for: the frame proof's exact tier).

The loop body is ``_lbs`` behind a one-thread driver and a ``prange`` driver; the wrapper picks
the threaded one only above :data:`PARALLEL_WORK` (numba compiles a kernel on its first call, so
the threaded driver compiles only for large inputs).  Every kernel is kept small: numba's compile
time grows with the code and the arguments it types, and a new user's first import, validation
or game frame pays it.

Fast math: :data:`runtime.kernels.config.FASTMATH_PROOF` everywhere (no nnan/ninf): the same
kernel serves the proof and the game, so it keeps NaN semantics.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .config import FASTMATH_PROOF

#: The wrappers use the multi-threaded kernels only above this many vertex-influence evaluations
#: (about 10 ms of one thread): below it one thread is faster than waking a pool (on a busy
#: machine a parallel launch can cost milliseconds), and the parallel kernels, which take
#: seconds to compile, are never compiled for the small inputs of a first import, validation or
#: game frame.
PARALLEL_WORK = 4_000_000
#: :func:`part_farthest` skins at most this many vertex-poses at once (a 256 KB temporary).
FARTHEST_BLOCK = 1 << 15


@njit(cache=True, fastmath=FASTMATH_PROOF, inline="always")
def _lbs(v, f, points, ji, jw, m):
    """Skinned position of vertex ``v`` under pose ``f`` of the folded transforms ``m``
    (F, J, 12); returns three float64.  Zero weights are padding (skipped).  Inlined into each
    loop by numba: LLVM does not inline a call across numba's separately compiled functions,
    and the call per vertex made every skinning loop 3x slower (20,000 vertices on one thread:
    about 600 us called, 180 us inlined; the same bits)."""
    px = np.float64(points[v, 0])
    py = np.float64(points[v, 1])
    pz = np.float64(points[v, 2])
    ax = 0.0
    ay = 0.0
    az = 0.0
    for i in range(ji.shape[1]):
        w = np.float64(jw[v, i])
        if w == 0.0:
            continue
        j = ji[v, i]  # no row views in hot loops: they cost refcounting
        ax += w * (m[f, j, 0] * px + m[f, j, 1] * py + m[f, j, 2] * pz + m[f, j, 3])
        ay += w * (m[f, j, 4] * px + m[f, j, 5] * py + m[f, j, 6] * pz + m[f, j, 7])
        az += w * (m[f, j, 8] * px + m[f, j, 9] * py + m[f, j, 10] * pz + m[f, j, 11])
    return ax, ay, az


@njit(cache=True, parallel=True, fastmath=FASTMATH_PROOF)
def _skin_frames(points, ji, jw, m, out):
    """out (F, n, 3) float32 = every vertex skinned by every pose of ``m`` (F, J, 12);
    parallel over (pose, vertex)."""
    F, n = m.shape[0], points.shape[0]
    for task in prange(F * n):
        f = task // n
        v = task - f * n
        x, y, z = _lbs(v, f, points, ji, jw, m)
        out[f, v, 0] = x
        out[f, v, 1] = y
        out[f, v, 2] = z


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _skin_frames_serial(points, ji, jw, m, out):
    """:func:`_skin_frames` on one thread (below :data:`PARALLEL_WORK`)."""
    for f in range(m.shape[0]):
        for v in range(points.shape[0]):
            x, y, z = _lbs(v, f, points, ji, jw, m)
            out[f, v, 0] = x
            out[f, v, 1] = y
            out[f, v, 2] = z


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _skin_dist2(points, ji, jw, m, centers, out):
    """out (F, n) float64 = squared distance of every vertex skinned by pose f of ``m`` from
    ``centers[f]`` (F, 3): the farthest-vertex search of :func:`part_farthest` without storing
    the points."""
    for f in range(m.shape[0]):
        for v in range(points.shape[0]):
            x, y, z = _lbs(v, f, points, ji, jw, m)
            out[f, v] = (x - centers[f, 0]) ** 2 + (y - centers[f, 1]) ** 2 + (z - centers[f, 2]) ** 2


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _skin_subset(verts, lo, hi, points, ji, jw, m, out):
    """out[verts[i]] (n, 3) float32 for ``lo <= i < hi``: vertices skinned by pose 0 of ``m``."""
    for i in range(lo, hi):
        v = np.int64(verts[i])
        x, y, z = _lbs(v, 0, points, ji, jw, m)
        out[v, 0] = x
        out[v, 1] = y
        out[v, 2] = z


# ------------------------------------------------------------------------ public wrappers
def fold(mats) -> np.ndarray:
    """Column-vector ``(..., J, 4, 4)`` (or ``(..., J, 3, 4)``) float64 -> the kernels'
    ``(F, J, 12)`` layout (a single pose ``(J, 4, 4)`` becomes ``(1, J, 12)``)."""
    m = np.asarray(mats, dtype=np.float64)
    if m.ndim == 3:
        m = m[None]
    if m.ndim != 4 or m.shape[-1] != 4 or m.shape[-2] not in (3, 4):
        raise ValueError(f"skinning transforms: expected (F, J, 4, 4), got {m.shape}")
    return np.ascontiguousarray(m[..., :3, :].reshape(m.shape[0], m.shape[1], 12))


def check_skin_inputs(points, joint_indices, joint_weights, joint_count: int):
    """Validate and convert skin inputs (the one padding policy, see the module docstring).

    Returns ``points (n, 3) float32, ji (n, k) int32, jw (n, k) float32`` (contiguous; zero-
    weight indices mapped to 0).  Raises ``ValueError`` quoting expected and actual values."""
    pts = np.ascontiguousarray(points, dtype=np.float32)
    ji = np.asarray(joint_indices)
    jw = np.ascontiguousarray(joint_weights, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points: expected (n, 3), got {pts.shape}")
    n = len(pts)
    if ji.ndim != 2 or ji.shape[0] != n:
        raise ValueError(f"joint_indices: expected ({n}, k), got {ji.shape}")
    if jw.shape != ji.shape:
        raise ValueError(f"joint_weights: expected {ji.shape}, got {jw.shape}")
    bad = ((ji < 0) | (ji >= joint_count)) & (jw != 0)
    if bad.any():
        raise ValueError(f"joint_indices: expected values in [0, {joint_count}) where the weight is not 0, "
                         f"got {int(ji[bad][0])}")
    ji = np.ascontiguousarray(np.where(jw == 0, 0, ji), dtype=np.int32)
    return pts, ji, jw


def skin_frames(points, joint_indices, joint_weights, skin_xforms, out=None, dtype=np.float32) -> np.ndarray:
    """Linear-blend skinning of ``F`` poses (compiled; parallel above 20,000 vertex-poses).

    Parameters
    ----------
    points : (n, 3) float32
    joint_indices : (n, k) int, joint_weights : (n, k) float32
    skin_xforms : (F, J, 4, 4) or (J, 4, 4) float64 column-vector skinning transforms (or
        already folded ``(F, J, 12)``)
    out : (F, n, 3) ``dtype``, optional
    dtype : float32 (the default: the runtime's and the asset's points) or float64 (the exact
        float64 skinned points, as the spheres stage measures them)

    Returns
    -------
    (F, n, 3) ``dtype``: ``sum_k w[v,k] * skin_xforms[f, j[v,k]] @ (p[v], 1)``.
    """
    m = _folded(skin_xforms)
    pts, ji, jw = check_skin_inputs(points, joint_indices, joint_weights, m.shape[1])
    shape = (m.shape[0], len(pts), 3)
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise ValueError(f"dtype: expected float32 or float64, got {dtype}")
    if out is None:
        out = np.empty(shape, dtype=dtype)
    elif out.shape != shape or out.dtype != dtype or not out.flags.c_contiguous:
        raise ValueError(f"out: expected C-contiguous {dtype} {shape}, got {out.dtype} {out.shape}")
    _skin(pts, ji, jw, m, out)
    return out


def part_farthest(points, joint_indices, joint_weights, skin_xforms, part_offsets, part_vertices,
                  centers, todo=None):
    """For every pose and part, the skinned vertex of the part farthest from ``centers``.

    Parameters
    ----------
    points, joint_indices, joint_weights, skin_xforms : as :func:`skin_frames`
    part_offsets : (P + 1,) int, part_vertices : (sum,) int
        CSR: vertices of part ``p`` are ``part_vertices[part_offsets[p]:part_offsets[p + 1]]``.
    centers : (F, P, 3) float64   sphere centres at each pose, same space as the skin
    todo : (F, P) bool, optional  only these pairs (default all); the others are NaN / -1

    Returns
    -------
    distance : (F, P) float64   distance of the farthest vertex (inf if a skinned point is NaN;
                                0 for an empty part)
    vertex : (F, P) int32       its index (-1 for an empty part)
    """
    m = _folded(skin_xforms)
    pts, ji, jw = check_skin_inputs(points, joint_indices, joint_weights, m.shape[1])
    poff = np.ascontiguousarray(part_offsets, dtype=np.int64)
    pv = np.ascontiguousarray(part_vertices, dtype=np.int32)
    F, P = m.shape[0], len(poff) - 1
    c = np.ascontiguousarray(centers, dtype=np.float64)
    if c.shape != (F, P, 3):
        raise ValueError(f"centers: expected ({F}, {P}, 3), got {c.shape}")
    if P >= 0 and (poff[0] != 0 or poff[-1] != len(pv) or np.any(np.diff(poff) < 0)):
        raise ValueError("part_offsets: expected non-decreasing from 0 to len(part_vertices)")
    if pv.size and (pv.min() < 0 or pv.max() >= len(pts)):
        raise ValueError(f"part_vertices: expected values in [0, {len(pts)})")
    t = np.ones((F, P), dtype=np.bool_) if todo is None else np.ascontiguousarray(todo, dtype=np.bool_)
    if t.shape != (F, P):
        raise ValueError(f"todo: expected ({F}, {P}), got {t.shape}")
    d = np.full((F, P), np.nan)
    v = np.full((F, P), -1, dtype=np.int32)
    for p in np.flatnonzero(t.any(0)) if F else ():
        todo_f = np.flatnonzero(t[:, p])
        vs = pv[poff[p]:poff[p + 1]]
        if len(vs) == 0:
            d[todo_f, p] = 0.0
            continue
        args = (pts[vs], ji[vs], jw[vs])
        step = max(1, FARTHEST_BLOCK // len(vs))  # poses per pass: bounded temporaries
        for s in range(0, len(todo_f), step):
            frames = todo_f[s:s + step]
            d2 = np.empty((len(frames), len(vs)))
            _skin_dist2(*args, np.ascontiguousarray(m[frames]), np.ascontiguousarray(c[frames, p]), d2)
            d2[~(d2 <= 1e300)] = np.inf  # NaN or inf: as far as it gets
            i = np.argmax(d2, axis=1)
            d[frames, p] = np.sqrt(d2[np.arange(len(frames)), i])
            v[frames, p] = vs[i]
    return d, v


def _skin(pts, ji, jw, m, out):
    """The one-thread or the threaded kernel, by the size of the job (inputs already checked)."""
    work = out.shape[0] * out.shape[1] * ji.shape[1]
    (_skin_frames if work > PARALLEL_WORK else _skin_frames_serial)(pts, ji, jw, m, out)


def _folded(x):
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 3 and a.shape[-1] == 12:
        return np.ascontiguousarray(a)
    return fold(a)
