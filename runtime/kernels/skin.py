"""The one skinning kernel of the project (linear blend and dual quaternion, one loop structure
with a method switch): the runtime's posing, the frame proof, the continuous certificate and the
import's spheres stage all skin through this module.

Dual-quaternion skinning (UsdSkel's ``primvars:skel:skinningMethod = "dualQuaternion"``) uses a
wider layout of the folded transforms (:func:`fold_dq`, ``(F, J, 1, DQ_WIDTH)``): the per-vertex
function ``_skin_vertex`` picks ``_lbs`` or ``_dqs`` by the array's dimension when numba types
the loop (a numba ``overload``: each loop compiles only the method it is called with), so every loop below
(and every caller of them) skins with whichever method its transforms were folded for
(:func:`fold_method`).  ``_dqs`` follows usd-core's ``_SkinPointsDQS`` step by step (see its
docstring and :func:`dq_parts`); its readable reference is ``tests/references/naive.py::naive_dqs``
and it is checked against ``UsdSkel.SkinPoints`` in ``tests/runtime/test_kernels.py``.

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

import math

import numpy as np
from numba import njit, prange
from numba.extending import overload

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


@njit(cache=True, fastmath=FASTMATH_PROOF, inline="always")
def _dqs(v, f, points, ji, jw, m):
    """Dual-quaternion skinned position of vertex ``v`` under pose ``f`` of the DQ-folded
    transforms ``m`` (F, J, :data:`DQ_WIDTH`) (:func:`fold_dq`), exactly as
    ``UsdSkelSkinPointsDQ`` (``pxr/usd/usdSkel/utils.cpp``, ``_SkinPointsDQS``): the pivot is the
    first influence of largest weight; a joint whose rotation lies in the other hemisphere from
    the pivot's enters with its weight negated; the blended dual quaternion is normalised
    (identity when its real part is shorter than 1e-10) and moves the point, which is first
    ``sum_k w_k S_k G p`` (the joints' scale/shear, blended linearly) when any joint of the pose
    has a scale, else ``G p``; then the post transform (the skeleton's local-to-world)."""
    px = np.float64(points[v, 0])
    py = np.float64(points[v, 1])
    pz = np.float64(points[v, 2])
    k = ji.shape[1]
    piv = 0
    best = np.float64(jw[v, 0])
    for i in range(1, k):
        if np.float64(jw[v, i]) > best:
            best = np.float64(jw[v, i])
            piv = i
    jp = ji[v, piv]
    pw, pxq, pyq, pzq = m[f, jp, 0, 12], m[f, jp, 0, 13], m[f, jp, 0, 14], m[f, jp, 0, 15]
    scaled = m[f, 0, 0, 44] != 0.0
    sx = 0.0
    sy = 0.0
    sz = 0.0
    rw = 0.0
    rx = 0.0
    ry = 0.0
    rz = 0.0
    dw = 0.0
    dx = 0.0
    dy = 0.0
    dz = 0.0
    for i in range(k):
        w = np.float64(jw[v, i])
        if w == 0.0:
            continue
        j = ji[v, i]
        if scaled:
            sx += w * (m[f, j, 0, 0] * px + m[f, j, 0, 1] * py + m[f, j, 0, 2] * pz + m[f, j, 0, 3])
            sy += w * (m[f, j, 0, 4] * px + m[f, j, 0, 5] * py + m[f, j, 0, 6] * pz + m[f, j, 0, 7])
            sz += w * (m[f, j, 0, 8] * px + m[f, j, 0, 9] * py + m[f, j, 0, 10] * pz + m[f, j, 0, 11])
        if m[f, j, 0, 12] * pw + m[f, j, 0, 13] * pxq + m[f, j, 0, 14] * pyq + m[f, j, 0, 15] * pzq < 0.0:
            w = -w
        rw += w * m[f, j, 0, 12]
        rx += w * m[f, j, 0, 13]
        ry += w * m[f, j, 0, 14]
        rz += w * m[f, j, 0, 15]
        dw += w * m[f, j, 0, 16]
        dx += w * m[f, j, 0, 17]
        dy += w * m[f, j, 0, 18]
        dz += w * m[f, j, 0, 19]
    if not scaled:  # G p (the geomBindTransform, slots 32..43)
        sx = m[f, 0, 0, 32] * px + m[f, 0, 0, 33] * py + m[f, 0, 0, 34] * pz + m[f, 0, 0, 35]
        sy = m[f, 0, 0, 36] * px + m[f, 0, 0, 37] * py + m[f, 0, 0, 38] * pz + m[f, 0, 0, 39]
        sz = m[f, 0, 0, 40] * px + m[f, 0, 0, 41] * py + m[f, 0, 0, 42] * pz + m[f, 0, 0, 43]
    n = math.sqrt(rw * rw + rx * rx + ry * ry + rz * rz)
    if n < 1e-10:  # GfDualQuat::Normalize: the identity
        yx, yy, yz = sx, sy, sz
    else:
        rw /= n
        rx /= n
        ry /= n
        rz /= n
        dw /= n
        dx /= n
        dy /= n
        dz /= n
        # translation 2 Im(d r*) (GfDualQuat::GetTranslation)
        tx = -2.0 * (dw * rx - rw * dx + (dy * rz - dz * ry))
        ty = -2.0 * (dw * ry - rw * dy + (dz * rx - dx * rz))
        tz = -2.0 * (dw * rz - rw * dz + (dx * ry - dy * rx))
        # rotation of s by the unit quaternion r: s + 2 r_w (u x s) + 2 u x (u x s)
        cx = ry * sz - rz * sy
        cy = rz * sx - rx * sz
        cz = rx * sy - ry * sx
        yx = sx + 2.0 * (rw * cx + (ry * cz - rz * cy)) + tx
        yy = sy + 2.0 * (rw * cy + (rz * cx - rx * cz)) + ty
        yz = sz + 2.0 * (rw * cz + (rx * cy - ry * cx)) + tz
    # the post transform (slots 20..31)
    return (m[f, 0, 0, 20] * yx + m[f, 0, 0, 21] * yy + m[f, 0, 0, 22] * yz + m[f, 0, 0, 23],
            m[f, 0, 0, 24] * yx + m[f, 0, 0, 25] * yy + m[f, 0, 0, 26] * yz + m[f, 0, 0, 27],
            m[f, 0, 0, 28] * yx + m[f, 0, 0, 29] * yy + m[f, 0, 0, 30] * yz + m[f, 0, 0, 31])


def _skin_vertex(v, f, points, ji, jw, m):
    """The method switch of every loop below (resolved when numba types the loop, below)."""
    raise NotImplementedError("compiled only")


@overload(_skin_vertex, inline="always")
def _skin_vertex_typed(v, f, points, ji, jw, m):
    """The layout of the folded transforms says the method, at typing time: ``(F, J, 12)``
    linear blend (:func:`_lbs`), ``(F, J, 1, DQ_WIDTH)`` dual quaternion (:func:`_dqs`).  Each
    loop is compiled for the method it is called with only (a runtime branch compiled both into
    every loop and more than doubled their compile time), and inlined into it with the loop's
    fast-math policy."""
    if m.ndim == 3:
        return lambda v, f, points, ji, jw, m: _lbs(v, f, points, ji, jw, m)
    return lambda v, f, points, ji, jw, m: _dqs(v, f, points, ji, jw, m)


@njit(cache=True, parallel=True, fastmath=FASTMATH_PROOF)
def _skin_frames(points, ji, jw, m, out):
    """out (F, n, 3) float32 = every vertex skinned by every pose of ``m`` (F, J, 12);
    parallel over (pose, vertex)."""
    F, n = m.shape[0], points.shape[0]
    for task in prange(F * n):
        f = task // n
        v = task - f * n
        x, y, z = _skin_vertex(v, f, points, ji, jw, m)
        out[f, v, 0] = x
        out[f, v, 1] = y
        out[f, v, 2] = z


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _skin_frames_serial(points, ji, jw, m, out):
    """:func:`_skin_frames` on one thread (below :data:`PARALLEL_WORK`)."""
    for f in range(m.shape[0]):
        for v in range(points.shape[0]):
            x, y, z = _skin_vertex(v, f, points, ji, jw, m)
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
            x, y, z = _skin_vertex(v, f, points, ji, jw, m)
            out[f, v] = (x - centers[f, 0]) ** 2 + (y - centers[f, 1]) ** 2 + (z - centers[f, 2]) ** 2


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _skin_subset(verts, lo, hi, points, ji, jw, m, out):
    """out[verts[i]] (n, 3) float32 for ``lo <= i < hi``: vertices skinned by pose 0 of ``m``."""
    for i in range(lo, hi):
        v = np.int64(verts[i])
        x, y, z = _skin_vertex(v, 0, points, ji, jw, m)
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


# ------------------------------------------------------------------ dual-quaternion layout
#: The skinning methods (UsdSkel's ``primvars:skel:skinningMethod`` tokens).
CLASSIC_LINEAR = "classicLinear"
DUAL_QUATERNION = "dualQuaternion"
METHODS = (CLASSIC_LINEAR, DUAL_QUATERNION)
#: Width of the dual-quaternion layout (:func:`fold_dq`, ``(F, J, 1, DQ_WIDTH)``: one more axis
#: than the linear ``(F, J, 12)``, so the kernels tell them apart by type): per (pose, joint) ``[0:12]`` the
#: joint's scale/shear ``S_j`` times the geomBindTransform ``G`` (3x4, row by row), ``[12:16]``
#: the real part ``(w, x, y, z)``, ``[16:20]`` the dual part, ``[20:32]`` the post transform
#: (3x4), ``[32:44]`` ``G`` (3x4), ``[44]`` 1.0 when any joint of the pose has a scale.
DQ_WIDTH = 45
#: ``GfMatrix4d::Factor``'s default ``eps``: a skinning transform whose 3x3 determinant is
#: smaller in magnitude is "singular" to UsdSkel, which gives it a zero dual quaternion and an
#: identity scale.
DQ_SINGULAR_DET = 1e-10
#: UsdSkel's test of a joint scale against the identity (``GfIsClose(GfMatrix3f, 1, 1e-6)``).
DQ_SCALE_TOL = 1e-6


def _quat_of(R):
    """(..., 3, 3) proper rotations (column-vector) -> (..., 4) unit quaternions ``(w, x, y, z)``
    (either sign; DQS is sign-invariant: the hemisphere test flips weights, not points)."""
    R = np.asarray(R, dtype=np.float64)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    cands = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    k = np.argmax(cands, -1)
    s = 0.5 / np.sqrt(np.maximum(np.take_along_axis(cands, k[..., None], -1)[..., 0], 1e-300))
    # w-largest
    qa = np.stack([0.25 / s, (R[..., 2, 1] - R[..., 1, 2]) * s, (R[..., 0, 2] - R[..., 2, 0]) * s,
                   (R[..., 1, 0] - R[..., 0, 1]) * s], -1)
    qb = np.stack([(R[..., 2, 1] - R[..., 1, 2]) * s, 0.25 / s, (R[..., 0, 1] + R[..., 1, 0]) * s,
                   (R[..., 0, 2] + R[..., 2, 0]) * s], -1)
    qc = np.stack([(R[..., 0, 2] - R[..., 2, 0]) * s, (R[..., 0, 1] + R[..., 1, 0]) * s, 0.25 / s,
                   (R[..., 1, 2] + R[..., 2, 1]) * s], -1)
    qd = np.stack([(R[..., 1, 0] - R[..., 0, 1]) * s, (R[..., 0, 2] + R[..., 2, 0]) * s,
                   (R[..., 1, 2] + R[..., 2, 1]) * s, 0.25 / s], -1)
    q = np.choose(k[..., None], [qa, qb, qc, qd])
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _qmul(a, b):
    """Hamilton product of (..., 4) ``(w, x, y, z)`` quaternions."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1)


def dq_parts(skin):
    """UsdSkel's split of skinning transforms for dual-quaternion skinning
    (``_ConvertToDualQuaternions``: ``GfMatrix4d::Factor``, the rotation orthonormalised).

    ``skin`` (F, J, 4, 4) column-vector ``skel @ inv_bind`` (no geomBindTransform, no
    local-to-world).  With ``A`` the 3x3 part and ``t`` the translation: ``A = R S`` its polar
    decomposition (``R`` a proper rotation; where ``det A < 0`` UsdSkel's Factor negates the
    scales, so ``R = -U V^T`` and ``S`` is negative definite), ``S = R^T A``.  A transform with
    ``|det A| < 1e-10`` is singular to Factor: zero dual quaternion, identity ``S``.

    Returns ``real (F, J, 4)``, ``dual (F, J, 4)`` (``(w, x, y, z)``; ``dual = (0, t / 2) real``),
    ``S (F, J, 3, 3)`` and ``scaled (F,)`` bool (a joint of the pose has ``S`` not within 1e-6 of
    the identity in float32: UsdSkel's ``hasJointScale``)."""
    skin = np.asarray(skin, dtype=np.float64)
    if skin.ndim == 3:
        skin = skin[None]
    A = skin[..., :3, :3]
    t = skin[..., :3, 3]
    with np.errstate(all="ignore"):
        det = np.linalg.det(A)
        singular = ~(np.abs(det) >= DQ_SINGULAR_DET)
        safe = np.where(singular[..., None, None], np.eye(3), A)
        U, _, Vt = np.linalg.svd(safe)
        R = U @ Vt
        R = np.where((np.linalg.det(safe) < 0)[..., None, None], -R, R)
        S = np.swapaxes(R, -1, -2) @ safe
        S = np.where(singular[..., None, None], np.eye(3), S)
        real = _quat_of(R)
        tq = np.concatenate([np.zeros(t.shape[:-1] + (1,)), 0.5 * t], -1)
        dual = _qmul(tq, real)
    real[singular] = 0.0
    dual[singular] = 0.0
    dev = np.abs(S.astype(np.float32).astype(np.float64) - np.eye(3))
    scaled = ~(dev < DQ_SCALE_TOL).reshape(S.shape[0], -1).all(1)
    return real, dual, S, scaled


def fold_dq(skin, geom_bind=None, world=None) -> np.ndarray:
    """The dual-quaternion layout ``(F, J, 1, DQ_WIDTH)`` (see :data:`DQ_WIDTH`) of skinning
    transforms ``skin`` (F, J, 4, 4) or (J, 4, 4) = ``skel @ inv_bind`` (skeleton space),
    ``geom_bind`` (4, 4) applied to the points first and ``world`` (4, 4) or (F, 4, 4) applied
    to the skinned point last (UsdSkel skins in skeleton space)."""
    real, dual, S, scaled = dq_parts(skin)
    F, J = real.shape[:2]
    G = np.eye(4) if geom_bind is None else np.asarray(geom_bind, dtype=np.float64)
    W = np.eye(4) if world is None else np.asarray(world, dtype=np.float64)
    W = np.broadcast_to(W, (F, 4, 4)) if W.ndim == 2 else W.reshape(F, 4, 4)
    out = np.empty((F, J, 1, DQ_WIDTH))
    SG = S @ G[:3, :]  # (F, J, 3, 4)
    out[..., 0, 0:12] = SG.reshape(F, J, 12)
    out[..., 0, 12:16] = real
    out[..., 0, 16:20] = dual
    out[..., 0, 20:32] = W[:, None, :3, :].reshape(F, 1, 12)
    out[..., 0, 32:44] = G[:3, :].reshape(12)
    out[..., 0, 44] = scaled.astype(np.float64)[:, None]
    return out


def fold_method(method: str, skin, geom_bind=None, world=None) -> np.ndarray:
    """The kernels' layout of skinning transforms ``skin = skel @ inv_bind`` (F, J, 4, 4) for
    ``method``: linear blend folds ``world @ skin @ geom_bind`` (:func:`fold`); dual quaternion
    keeps them apart (:func:`fold_dq`)."""
    if method == DUAL_QUATERNION:
        return fold_dq(skin, geom_bind, world)
    if method != CLASSIC_LINEAR:
        raise ValueError(f"skinning method: expected one of {METHODS}, got {method!r}")
    m = np.asarray(skin, dtype=np.float64)
    if geom_bind is not None:
        m = m @ np.asarray(geom_bind, dtype=np.float64)
    if world is not None:
        w = np.asarray(world, dtype=np.float64)
        m = (w @ m) if w.ndim == 2 else (w[:, None] @ m)
    return fold(m)


def _skin(pts, ji, jw, m, out):
    """The one-thread or the threaded kernel, by the size of the job (inputs already checked)."""
    work = out.shape[0] * out.shape[1] * ji.shape[1]
    (_skin_frames if work > PARALLEL_WORK else _skin_frames_serial)(pts, ji, jw, m, out)


def _folded(x):
    a = np.asarray(x, dtype=np.float64)
    if (a.ndim == 3 and a.shape[-1] == 12) or (a.ndim == 4 and a.shape[-2:] == (1, DQ_WIDTH)):
        return np.ascontiguousarray(a)
    return fold(a)
