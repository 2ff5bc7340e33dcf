"""Sound bounds between two samples of a clip: how far a part's skinned vertices can stray, at
any time between two consecutive samples, from where the samples put them.  Used by the
continuous-time certificate (:func:`runtime.certify.continuous`, which states the levels built
on these bounds and why they hold).  Everything is float64, column-vector.

Notation of :mod:`runtime.kernels.bounds` (``N_b``, ``B_b``, ``u_b(v)``, the per (part, joint)
balls ``(c_b, r_b)`` of :class:`~runtime.kernels.bounds.BoundData`, ``a_P``, ``eps_P``, and its
lemma: LBS is a weighted sum of the joints' copies of a vertex).  Over a sample interval, with
time normalised to ``tau`` in [0, 1], joint ``b``'s copy of a vertex moves in the part joint
``J``'s space by ``A_b(tau) = G_J^-1 G_b``, a chain of joint-local transforms, each interpolated
as UsdSkel does between its two samples (:mod:`runtime.kernels.pose`).

* :func:`factor_terms`: per interval and joint, bounds ``(n0, n1, n2)`` on the norm of a local
  transform's linear part and of its first and second derivatives in ``tau`` (forward and
  inverse), the change of its translation, and the error of UsdSkel's half-precision scale lerp
  (derived in :func:`runtime.certify.factor_bounds`);
* :func:`chain_bounds`: per interval and (part, joint) pair, those bounds carried along the
  chain: ``delta`` bounds how far every point of the moving ball strays from its chord (the
  recursion and why it holds: :func:`_chain_bounds_serial`), ``e0, e1`` the distances of its
  centre from the part's centre at the two samples, ``lam`` the norm of ``A_b``'s linear part;
* :func:`chord_tasks`: per vertex, its distance from the part's centre at both ends plus the
  weighted strays of its copies (LBS is linear in the joint transforms, so a vertex strays from
  its chord by at most that; the chord stays within the larger end distance).

The chain recursion and the factor terms each have a compiled kernel and a numpy twin for small
inputs (:func:`_chain_bounds_numpy`, :func:`_factor_terms_numpy` with :func:`_inv_affine_numpy`:
the same operations; both paths are tested equal), so a demo-sized clip compiles neither.
Fast math: the chain recursion runs under :data:`~runtime.kernels.config.FASTMATH_PROOF` (it
decides a proof); the factor terms under :data:`~runtime.kernels.config.FASTMATH_OFF`
(infinities are meaningful there).  The bounds are padded for float64 rounding (``delta`` and
``pert`` by ``1 + 1e-9``, the per-vertex chord bound by :data:`~runtime.kernels.bounds.ROUND`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .bounds import ROUND, _xf
from .config import FASTMATH_OFF, FASTMATH_PROOF
from .skin import PARALLEL_WORK, skin_frames

# ------------------------------------------------------------------ continuous time (chords)
#: The chord bounds below are numpy over the one skinning kernel (no kernel of their own to
#: compile on a new user's first import or validation); the chain bounds are a kernel (numpy was
#: 10x slower on the proof benchmark).
#: :func:`chord_tasks` handles at most this many (task, vertex, influence) terms at once.
CHORD_BLOCK = 1 << 14


@njit(cache=True, inline="always", fastmath=FASTMATH_PROOF)
def _chain_task(i, k, L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius, pair_part, part_centers, e0, e1, delta, lam, pert):
    """Pair ``k`` over interval ``i`` of :func:`_chain_bounds_serial`: writes ``e0[i, k]``,
    ``e1[i, k]``, ``delta[i, k]``, ``lam[i, k]`` and ``pert[i, k]``.

    i : int, the interval (the row of every (I, ...) array); k : int, the (part, joint) pair (the
    row of every (M, ...) array, the column of the outputs).  The other arguments are
    :func:`chain_bounds`'s, which documents each: L0, L1, Li0, Li1 (I, J, 4, 4) the local
    transforms at both samples and their inverses; fw, iv (I, J, 3) the forward / inverse factor
    bounds ``(n0, n1, n2)``; dt (I, J) the translation's change; eps (I, J, 2) the scale-rounding
    error; path_off (M + 1,), path_j (S,), path_dir (S,) each pair's chain of factors (CSR);
    pj_center (M, 3), pj_radius (M,) each pair's ball; pair_part (M,) its part; part_centers
    (P, 3); e0, e1, delta, lam, pert (I, M) float64 out."""
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


@njit(cache=True, fastmath=FASTMATH_PROOF)
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


@njit(cache=True, parallel=True, fastmath=FASTMATH_PROOF)
def _chain_bounds_parallel(L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius, pair_part, part_centers, e0, e1, delta, lam, pert):
    """:func:`_chain_bounds_serial` over threads (large inputs; see :func:`chain_bounds`)."""
    M = pj_center.shape[0]
    for task in prange(L0.shape[0] * M):
        _chain_task(task // M, task % M, L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius, pair_part, part_centers, e0, e1, delta, lam, pert)


#: Below this many path factors in all (intervals x factors) :func:`chain_bounds` runs the
#: vectorised numpy recursion (:func:`_chain_bounds_numpy`): a demo-sized clip takes a few
#: milliseconds so, and not compiling saves ~1.2 s of a cold start.
CHAIN_KERNEL_MIN = 4_000


def chain_bounds(L0, L1, Li0, Li1, fw, iv, dt, eps, path_off, path_j, path_dir, pj_center, pj_radius, pair_part, part_centers, e0, e1, delta, lam, pert, compiled=None):
    """Run :func:`_chain_bounds_serial` (or its threaded twin on large inputs: more than
    :data:`PARALLEL_WORK` path factors in all; or, below :data:`CHAIN_KERNEL_MIN`, the same
    recursion vectorised in numpy; ``compiled`` forces the choice).

    Deviation-from-chord bounds of every (part, joint) ball over every sample interval; the
    recursion and why it holds are in :func:`_chain_bounds_serial`.  I sample intervals, J
    skeleton joints, M (part, joint) pairs (:class:`~runtime.kernels.bounds.BoundData`'s ``pj``
    entries, in its order), S path factors in all, P parts; every array C-contiguous.

    Parameters
    ----------
    L0, L1 : (I, J, 4, 4) float64
        Each joint's local transform (column-vector) at the interval's first and second sample.
    Li0, Li1 : (I, J, 4, 4) float64
        Their inverses.
    fw : (I, J, 3) float64
        Forward factor bounds ``(n0, n1, n2)``: the norm of the local transform's linear part and
        of its first and second derivatives in the normalised time ``tau``, over the interval.
    iv : (I, J, 3) float64
        The same for the inverse local transform (inf where it is unbounded: a scale component
        zero or changing sign over the interval).
    dt : (I, J) float64
        How far the local translation moves over the interval (``|t1 - t0|``).
    eps : (I, J, 2) float64
        Bounds of the error of the linear part (forward, inverse) from UsdSkel's half-precision
        scale lerp.
    path_off : (M + 1,) int64
        CSR offsets: pair ``k``'s chain is ``path_j[path_off[k]:path_off[k + 1]]``.
    path_j : (S,) int64
        The joint of each factor, innermost first: from the pair's joint ``b`` up to the common
        ancestor, then down to the part's joint ``J``.
    path_dir : (S,) int64
        +1 where the factor is the joint's local transform (going up), -1 its inverse (going down).
    pj_center : (M, 3) float64, pj_radius : (M,) float64
        Pair ``k``'s ball, in joint ``b``'s bind space, holding the part's vertices ``b`` influences.
    pair_part : (M,) int64
        The part of each pair.
    part_centers : (P, 3) float64
        Each part's sphere centre ``c_P``, in its joint ``J``'s space.
    e0, e1, delta, lam, pert : (I, M) float64, out
        ``|A(0) c - c_P|`` and ``|A(1) c - c_P|`` (the ball's centre moved into ``J``'s space at
        both samples); ``delta`` the largest distance of a point of the moving ball from its chord
        at any ``tau``; ``lam`` a bound of the norm of ``A``'s linear part; ``pert`` the bound of
        how far the half-precision scale rounding moves the point off the smooth path.
    compiled : bool, optional
        True: the kernel; False: the numpy recursion; default by size.
    """
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
@njit(cache=True, fastmath=FASTMATH_OFF)
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


@njit(cache=True, fastmath=FASTMATH_OFF)
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
FACTOR_KERNEL_MIN = 900


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
