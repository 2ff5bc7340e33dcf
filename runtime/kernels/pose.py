"""Joint transforms at any time, as UsdSkel computes them (``UsdSkelAnimQuery`` +
``UsdSkelSkeletonQuery``), and composition of any joint-local pose.

Conventions (:mod:`runtime.schema`): matrices are **column-vector** ``(4, 4) float64``
(``p' = M @ p``, translation in the last column); quaternions are ``(x, y, z, w)``.

UsdSkel's interpolation between time samples (``pxr/usd/usd/interpolators.h``): translations and
scales are lerped, rotations are ``GfSlerp``-ed; outside the sampled range the first / last
sample is held.  Scales are ``half3``: ``GfLerp`` on them rounds every operation to half
precision (:func:`_half`), so an in-between scale is within ``3 x 2^-11`` (relative) of the exact
lerp; the continuous certificate charges that (:func:`runtime.certify.factor_bounds`).  ``GfSlerp`` takes the **shortest arc** (it negates ``q1`` when ``q0 . q1 < 0``)
and falls back to a linear blend when ``1 - |q0 . q1| <= 1e-5`` (the cosine from the float
components of ``GfQuatf``), which it does not renormalise; :func:`_slerp` does exactly the same.  The shortest-arc behaviour is
checked against usd-core in ``tests/runtime/test_kernels.py``.  A joint-local matrix is ``T R S`` (scale,
then rotate, then translate: ``UsdSkelMakeTransform``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .config import FASTMATH_OFF, FASTMATH_PROOF


@njit(cache=True, fastmath=FASTMATH_OFF)
def _bracket(times, t):
    """Sample index ``i`` and weight ``a`` so the value at ``t`` is ``lerp(v[i], v[i+1], a)``;
    held (clamped) outside the sampled range, exact on a sample (``a == 0``).  (A binary search
    written out: ``np.searchsorted`` costs a second of compiling.)"""
    n = times.shape[0]
    if n == 1 or t <= times[0]:
        return 0, 0.0
    if t >= times[n - 1]:
        return n - 1, 0.0
    lo, hi = 0, n - 1  # times[lo] < t < times[hi] or t == times[lo]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if times[mid] <= t:
            lo = mid
        else:
            hi = mid
    return lo, (t - times[lo]) / (times[lo + 1] - times[lo])


@njit(cache=True, fastmath=FASTMATH_OFF)
def _half(x):
    """``x`` rounded to the nearest IEEE half (ties to even), as ``GfHalf`` stores it (normal
    range; UsdSkel's scales are ``half3``)."""
    if x == 0.0 or not math.isfinite(x):
        return x
    m, e = math.frexp(x)
    q = math.ldexp(1.0, max(e, -13) - 11)  # the half's quantum at this magnitude (subnormals below 2^-14)
    return np.rint(x / q) * q


@njit(cache=True, fastmath=FASTMATH_OFF)
def _slerp(q0x, q0y, q0z, q0w, q1x, q1y, q1z, q1w, a):
    """GfSlerp of two (x, y, z, w) quaternions exactly as usd-core interpolates ``quatf`` samples:
    the cosine from the float components (GfQuatf's float dot), shortest arc, and on the linear
    branch (``1 - cos <= 1e-5``) a plain lerp that is *not* renormalised (GfSlerp does not, and
    UsdSkel builds the joint matrix from that slightly short quaternion; renormalising here made
    the runtime differ from UsdSkel by up to ~5e-6 of a joint's reach); returns four float64."""
    f32 = np.float32
    cos_t = np.float64(f32(f32(f32(f32(q0x) * f32(q1x)) + f32(f32(q0y) * f32(q1y))) + f32(f32(q0z) * f32(q1z)))
                       + f32(f32(q0w) * f32(q1w)))
    sign = 1.0
    if cos_t < 0.0:
        cos_t = -cos_t
        sign = -1.0
    if 1.0 - cos_t > 0.00001:
        theta = math.acos(min(cos_t, 1.0))
        s = math.sin(theta)
        s0 = math.sin((1.0 - a) * theta) / s
        s1 = math.sin(a * theta) / s
    else:
        s0 = 1.0 - a
        s1 = a
    s1 *= sign
    return s0 * q0x + s1 * q1x, s0 * q0y + s1 * q1y, s0 * q0z + s1 * q1z, s0 * q0w + s1 * q1w


@njit(cache=True, fastmath=FASTMATH_OFF)
def _trs_matrix(tx, ty, tz, x, y, z, w, sx, sy, sz, m):
    """m (4, 4) = T R S, column-vector (``GfMatrix4d::SetRotate(quat)`` transposed, columns
    scaled)."""
    m[0, 0] = (1.0 - 2.0 * (y * y + z * z)) * sx
    m[1, 0] = (2.0 * (x * y + z * w)) * sx
    m[2, 0] = (2.0 * (z * x - y * w)) * sx
    m[0, 1] = (2.0 * (x * y - z * w)) * sy
    m[1, 1] = (1.0 - 2.0 * (z * z + x * x)) * sy
    m[2, 1] = (2.0 * (y * z + x * w)) * sy
    m[0, 2] = (2.0 * (z * x + y * w)) * sz
    m[1, 2] = (2.0 * (y * z - x * w)) * sz
    m[2, 2] = (1.0 - 2.0 * (x * x + y * y)) * sz
    m[0, 3] = tx
    m[1, 3] = ty
    m[2, 3] = tz
    m[3, 0] = 0.0
    m[3, 1] = 0.0
    m[3, 2] = 0.0
    m[3, 3] = 1.0


@njit(cache=True, fastmath=FASTMATH_OFF)
def _trs_one(k, iT, aT, iR, aR, iS, aS, vt, vr, vs):
    """Translation, rotation (x, y, z, w) and scale of animated joint ``k`` between the samples
    bracketing a time (:func:`_bracket` of each channel's times): ten float64."""
    if aT == 0.0:
        tx, ty, tz = vt[iT, k, 0], vt[iT, k, 1], vt[iT, k, 2]
    else:
        tx = (1.0 - aT) * vt[iT, k, 0] + aT * vt[iT + 1, k, 0]
        ty = (1.0 - aT) * vt[iT, k, 1] + aT * vt[iT + 1, k, 1]
        tz = (1.0 - aT) * vt[iT, k, 2] + aT * vt[iT + 1, k, 2]
    if aS == 0.0:
        sx, sy, sz = vs[iS, k, 0], vs[iS, k, 1], vs[iS, k, 2]
    else:  # GfLerp on GfVec3h: every operation rounds to half
        sx = _half(_half((1.0 - aS) * vs[iS, k, 0]) + _half(aS * vs[iS + 1, k, 0]))
        sy = _half(_half((1.0 - aS) * vs[iS, k, 1]) + _half(aS * vs[iS + 1, k, 1]))
        sz = _half(_half((1.0 - aS) * vs[iS, k, 2]) + _half(aS * vs[iS + 1, k, 2]))
    if aR == 0.0:
        x, y, z, w = vr[iR, k, 0], vr[iR, k, 1], vr[iR, k, 2], vr[iR, k, 3]
    else:
        x, y, z, w = _slerp(vr[iR, k, 0], vr[iR, k, 1], vr[iR, k, 2], vr[iR, k, 3],
                            vr[iR + 1, k, 0], vr[iR + 1, k, 1], vr[iR + 1, k, 2], vr[iR + 1, k, 3], aR)
    return tx, ty, tz, x, y, z, w, sx, sy, sz


@njit(cache=True, fastmath=FASTMATH_OFF)
def _locals_at(times, tt, vt, tr, vr, ts, vs, anim_to_skel, rest_local, local, trs):
    """The clip's joint-local transforms at each time code ``times[n]`` (T,): ``local[n]``
    (J, 4, 4) (joints the clip does not animate keep ``rest_local``), and the animated joints'
    translation, rotation (x, y, z, w) and scale in ``trs[n]`` (A, 10), interpolated as UsdSkel
    does.  Element loops, no allocation: slice assignment, ``np.empty`` and ``np.searchsorted``
    would each add compile time to a new user's first call."""
    for n in range(times.shape[0]):
        t = times[n]
        for j in range(local.shape[1]):
            for r in range(4):
                for c in range(4):
                    local[n, j, r, c] = rest_local[j, r, c]
        iT, aT = _bracket(tt, t)
        iR, aR = _bracket(tr, t)
        iS, aS = _bracket(ts, t)
        for k in range(anim_to_skel.shape[0]):
            tx, ty, tz, x, y, z, w, sx, sy, sz = _trs_one(k, iT, aT, iR, aR, iS, aS, vt, vr, vs)
            trs[n, k, 0], trs[n, k, 1], trs[n, k, 2] = tx, ty, tz
            trs[n, k, 3], trs[n, k, 4], trs[n, k, 5], trs[n, k, 6] = x, y, z, w
            trs[n, k, 7], trs[n, k, 8], trs[n, k, 9] = sx, sy, sz
            _trs_matrix(tx, ty, tz, x, y, z, w, sx, sy, sz, local[n, anim_to_skel[k]])


@njit(cache=True, fastmath=FASTMATH_OFF)
def _mul44(a, b, out):
    """out = a @ b for 4x4 (no allocation; ``out`` must not alias ``a`` or ``b``)."""
    for i in range(4):
        a0, a1, a2, a3 = a[i, 0], a[i, 1], a[i, 2], a[i, 3]
        for k in range(4):
            out[i, k] = a0 * b[0, k] + a1 * b[1, k] + a2 * b[2, k] + a3 * b[3, k]


@njit(cache=True, fastmath=FASTMATH_PROOF)
def _compose(local, parents, topo_order, inv_bind, geom_bind, local_to_world, skel_out, skin_out,
             world_out, folded):
    """Compose joint-local transforms (J, 4, 4) into

    skel_out (J, 4, 4): skeleton space (``ComputeJointSkelTransforms``);
    skin_out (J, 4, 4): ``skel @ inv_bind @ geom_bind`` (mesh -> skeleton space, UsdSkel's
      skinning transform with the geomBindTransform folded in);
    world_out (J, 4, 4): ``local_to_world @ skel`` (joint -> stage space);
    folded (1, J, 12): ``local_to_world @ skin`` in :func:`runtime.kernels.skin.fold` layout.
    """
    J = local.shape[0]
    for n in range(J):
        j = topo_order[n]
        p = parents[j]
        if p < 0:
            for r in range(4):
                for c in range(4):
                    skel_out[j, r, c] = local[j, r, c]
        else:
            _mul44(skel_out[p], local[j], skel_out[j])
        _mul44(skel_out[j], inv_bind[j], world_out[j])  # world_out[j] as scratch, overwritten below
        _mul44(world_out[j], geom_bind, skin_out[j])
        _mul44(local_to_world, skel_out[j], world_out[j])
        for r in range(3):
            for c in range(4):
                folded[0, j, 4 * r + c] = (local_to_world[r, 0] * skin_out[j, 0, c] + local_to_world[r, 1] * skin_out[j, 1, c]
                                           + local_to_world[r, 2] * skin_out[j, 2, c] + local_to_world[r, 3] * skin_out[j, 3, c])


# ------------------------------------------------------------------------ public wrappers
#: Below this many (time, animated joint) values :func:`locals_at` runs vectorised numpy instead
#: of the compiled kernel: the proof's per-clip calls on a demo-sized asset take well under a
#: millisecond either way, and not compiling saves ~1.8 s of a cold start.  (The runtime's
#: per-frame pose calls the kernel directly.)
LOCALS_KERNEL_MIN = 900


def locals_at(clip, times, rest_local, trs=False, compiled=None):
    """(T, J, 4, 4) float64 joint-local transforms of ``clip`` (a :class:`runtime.schema.Clip`)
    at time codes ``times`` (T,), interpolated as UsdSkel does; with ``trs=True`` also the
    animated joints' translations (T, A, 3), rotations (T, A, 4) (x, y, z, w) and scales
    (T, A, 3).  ``compiled``: force the kernel (True) or the numpy path (False, the same
    operations: :func:`_locals_at_numpy`); default by size (:data:`LOCALS_KERNEL_MIN`)."""
    rest = np.ascontiguousarray(rest_local, dtype=np.float64)
    times = np.ascontiguousarray(np.atleast_1d(np.asarray(times, dtype=np.float64)))
    A = len(clip.anim_to_skel)
    if compiled is None:
        compiled = len(times) * A >= LOCALS_KERNEL_MIN
    if compiled:
        out = np.empty((len(times),) + rest.shape)
        v = np.empty((len(times), A, 10))
        _locals_at(times, clip.tt, clip.vt, clip.tr, clip.vr, clip.ts, clip.vs, clip.anim_to_skel, rest, out, v)
    else:
        out, v = _locals_at_numpy(times, clip, rest)
    return (out, v[..., :3], v[..., 3:7], v[..., 7:]) if trs else out


def _bracket_numpy(times, t):
    """:func:`_bracket` for every time of ``t`` (T,): indices (T,) int and weights (T,)."""
    n = len(times)
    if n == 1:
        return np.zeros(len(t), np.int64), np.zeros(len(t))
    i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, n - 2)
    a = (t - times[i]) / (times[i + 1] - times[i])
    low, high = t <= times[0], t >= times[n - 1]
    i = np.where(high, n - 1, np.where(low, 0, i))
    a = np.where(low | high, 0.0, a)
    return i, a


def _half_numpy(x):
    """:func:`_half` elementwise."""
    x = np.asarray(x, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        _, e = np.frexp(x)
        q = np.ldexp(1.0, np.maximum(e, -13) - 11)
        r = np.rint(x / q) * q
    return np.where((x == 0.0) | ~np.isfinite(x), x, r)


def _slerp_numpy(q0, q1, a):
    """:func:`_slerp` over (T, A, 4) quaternion pairs and (T, 1) fractions: the float32 cosine
    summed in GfQuatf's order, the shortest arc, the unnormalised linear branch."""
    f0, f1 = q0.astype(np.float32), q1.astype(np.float32)
    p = f0 * f1  # float32 products
    cos_t = (((p[..., 0] + p[..., 1]) + p[..., 2]) + p[..., 3]).astype(np.float64)
    sign = np.where(cos_t < 0.0, -1.0, 1.0)
    cos_t = np.abs(cos_t)
    a = np.broadcast_to(a, cos_t.shape)
    lin = ~(1.0 - cos_t > 0.00001)
    theta = np.arccos(np.minimum(cos_t, 1.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        st = np.sin(theta)
        s0 = np.where(lin, 1.0 - a, np.sin((1.0 - a) * theta) / st)
        s1 = np.where(lin, a, np.sin(a * theta) / st) * sign
    return s0[..., None] * q0 + s1[..., None] * q1


def _locals_at_numpy(times, clip, rest):
    """:func:`_locals_at` vectorised: ``(local (T, J, 4, 4), trs (T, A, 10))``."""
    T, A = len(times), len(clip.anim_to_skel)
    out = np.broadcast_to(rest, (T,) + rest.shape).copy()
    v = np.empty((T, A, 10))
    if A == 0 or T == 0:
        return out, v
    iT, aT = _bracket_numpy(clip.tt, times)
    iR, aR = _bracket_numpy(clip.tr, times)
    iS, aS = _bracket_numpy(clip.ts, times)
    nT, nR, nS = len(clip.tt) - 1, len(clip.tr) - 1, len(clip.ts) - 1
    aT, aR, aS = aT[:, None, None], aR[:, None], aS[:, None, None]
    t0, t1 = clip.vt[iT], clip.vt[np.minimum(iT + 1, nT)]
    t = np.where(aT == 0.0, t0, (1.0 - aT) * t0 + aT * t1)
    s0, s1 = clip.vs[iS], clip.vs[np.minimum(iS + 1, nS)]
    s = np.where(aS == 0.0, s0, _half_numpy(_half_numpy((1.0 - aS) * s0) + _half_numpy(aS * s1)))
    r0, r1 = clip.vr[iR], clip.vr[np.minimum(iR + 1, nR)]
    q = np.where((aR == 0.0)[..., None], r0, _slerp_numpy(r0, r1, aR))
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    m = np.zeros((T, A, 4, 4))
    m[..., 0, 0] = (1.0 - 2.0 * (y * y + z * z)) * s[..., 0]
    m[..., 1, 0] = (2.0 * (x * y + z * w)) * s[..., 0]
    m[..., 2, 0] = (2.0 * (z * x - y * w)) * s[..., 0]
    m[..., 0, 1] = (2.0 * (x * y - z * w)) * s[..., 1]
    m[..., 1, 1] = (1.0 - 2.0 * (z * z + x * x)) * s[..., 1]
    m[..., 2, 1] = (2.0 * (y * z + x * w)) * s[..., 1]
    m[..., 0, 2] = (2.0 * (z * x + y * w)) * s[..., 2]
    m[..., 1, 2] = (2.0 * (y * z - x * w)) * s[..., 2]
    m[..., 2, 2] = (1.0 - 2.0 * (x * x + y * y)) * s[..., 2]
    m[..., :3, 3] = t
    m[..., 3, 3] = 1.0
    out[:, clip.anim_to_skel] = m
    v[..., :3], v[..., 3:7], v[..., 7:] = t, q, s
    return out, v


def trs_at(clip, times):
    """Translations (T, A, 3), rotations (T, A, 4) (x, y, z, w) and scales (T, A, 3) of the
    clip's animated joints at ``times``, interpolated as UsdSkel does."""
    return locals_at(clip, times, np.tile(np.eye(4), (_joint_count(clip), 1, 1)), trs=True)[1:]


def _joint_count(clip) -> int:
    a = np.asarray(clip.anim_to_skel)
    return int(a.max()) + 1 if len(a) else 0


def compose(local, parents, topo_order=None) -> np.ndarray:
    """(..., J, 4, 4) joint-local -> skeleton-space transforms (numpy; parents first)."""
    local = np.asarray(local, dtype=np.float64)
    parents = np.asarray(parents)
    order = range(len(parents)) if topo_order is None else topo_order
    out = np.empty_like(local)
    for j in order:
        p = parents[j]
        out[..., j, :, :] = local[..., j, :, :] if p < 0 else out[..., p, :, :] @ local[..., j, :, :]
    return out


@njit(cache=True, fastmath=FASTMATH_OFF)
def _trs_matrices(t, q, s, out):
    """out (J, 4, 4) = T R S of translations (J, 3), unit quaternions (J, 4) (x, y, z, w) and
    scales (J, 3)."""
    for j in range(t.shape[0]):
        _trs_matrix(t[j, 0], t[j, 1], t[j, 2], q[j, 0], q[j, 1], q[j, 2], q[j, 3], s[j, 0], s[j, 1], s[j, 2], out[j])


def trs_matrices(translations, rotations, scales) -> np.ndarray:
    """(J, 4, 4) column-vector ``T R S`` from translations (J, 3), rotations (J, 4) ``(x, y, z,
    w)`` (normalised here) and scales (J, 3); the formula UsdSkel uses."""
    t = np.ascontiguousarray(translations, dtype=np.float64)
    q = np.asarray(rotations, dtype=np.float64)
    q = np.ascontiguousarray(q / np.linalg.norm(q, axis=-1, keepdims=True))
    s = np.ascontiguousarray(scales, dtype=np.float64)
    out = np.empty((len(t), 4, 4))
    _trs_matrices(t, q, s, out)
    return out
