"""The continuous certificate for dual-quaternion skinning (``primvars:skel:skinningMethod =
"dualQuaternion"``): every vertex of every part inside its sphere at every time between two
samples of a clip, as UsdSkel interpolates the joints and skins them (``_SkinPointsDQS``,
:func:`runtime.kernels.skin.dq_parts`).  :func:`certificate` dispatches here for a
dual-quaternion :class:`runtime.certify.Rig` (and to :func:`runtime.certify.continuous` for a
linear one); at the samples themselves
:func:`runtime.certify.sampled` skins every dual-quaternion part exactly (tests K and D bound
linear blends only: a DQS vertex is not a convex combination of its joints' transforms).

The bound (a Lipschitz bound in time, with subdivision)
-------------------------------------------------------
Notation.  Over one sample interval, time is normalised to ``u in [0, 1]``; a sub-interval
``[a, b]`` has length ``l = b - a`` in those units.  Joint ``j``'s skinning transform is
``M_j(u) = K_j(u) B_j^-1`` (``K_j`` its skeleton-space transform, ``B_j`` its bind), with linear
part ``A_j = R_j S_j`` (UsdSkel's split: ``R_j`` a proper rotation, ``S_j = R_j^T A_j``) and
translation ``t_j``; ``q_j`` the unit quaternion of ``R_j``.  A vertex has non-negative weights
``w_j`` (its pivot, the first of the largest weight ``w_max``) and bind position ``p = G p_mesh``
(skeleton space).  UsdSkel's skinned point is ``x = R(b^) s + T(b, c)`` with ``b = sum s_j w_j
q_j``, ``c = sum s_j w_j (0, t_j / 2) q_j`` (``s_j = -1`` where ``q_j . q_piv < 0``), ``b^ =
b / |b|``, ``T(b, c) = 2 Im(c b*) / |b|^2`` and ``s = sum w_j S_j p`` (or ``p`` when no joint of
the pose has a scale).  Part ``P`` of joint ``J`` has the fixed joint-space ball ``(c_P, r_P)``;
its skeleton-space centre is ``C(u) = K_J(u) c_P`` and ``o = B_J c_P`` is that centre at bind.

Per-joint bounds over the interval (from :func:`runtime.certify.factor_bounds`: ``n0, n1`` of
each local factor and of its inverse, the translation change ``dt``), by the product rule along
the root path: ``||A_j|| <= N_j = nK_j ||B_j^-1||``, ``sigma_min(A_j) >= m_j = lK_j
sigma_min(B_j^-1)`` and ``||A_j'|| <= dK_j ||B_j^-1||`` with ``nK_j = nK_par n0_j``, ``lK_j =
lK_par / n0inv_j``, ``dK_j = dK_par n0_j + nK_par n1_j``.  Then

1. ``eta_j = max(N_j - 1, 1 - m_j)`` bounds ``||S_j - I||`` (the eigenvalues of ``S_j`` are
   ``A_j``'s singular values where ``det A_j > 0``, checked at every sample: it cannot change
   sign in between while ``m_j > 0``).  Every animated local factor's ``n0``, ``n1`` and
   ``1 / n0inv`` are corrected by :func:`quat_pads`: UsdSkel's rotation matrix of a quaternion
   that is not exactly unit (float32 storage, GfSlerp's unnormalised linear branch) is not
   quite a rotation.
2. ``omega_j = ||A_j'|| / sigma_min(A_j)`` bounds the angular speed of ``R_j``: with ``R^T R' =
   W`` skew, ``R^T A' - A'^T R = W S + S W``; in ``S``'s eigenbasis ``W_ik (s_i + s_k) = K_ik``,
   and ``|w|^2 = sum_{i<k} W_ik^2 <= sum K_ik^2 / (2 s_min)^2 = ||K||_2^2 / (2 s_min)^2 <=
   ||A'||^2 / s_min^2``.  So ``|q_j'| <= omega_j / 2``.
3. No hemisphere flip: ``|q_j . q_piv|`` is Lipschitz with constant ``(omega_j + omega_piv) / 2``;
   where ``|q_j . q_piv|(a) + |q_j . q_piv|(b) > l (omega_j + omega_piv) / 2`` for every
   (joint, pivot) pair of the part it never reaches 0 on ``[a, b]``, so every ``s_j`` is constant
   and ``x(u)`` is continuous there (where it may flip, UsdSkel's DQS jumps: the sub-interval is
   subdivided and, at the depth limit, left undecided).
4. ``|b| >= w_max``: ``b . q_piv = sum w_j |q_j . q_piv| >= w_max`` (every flipped term has a
   non-negative dot; needs non-negative weights, else the interval is undecided).  So UsdSkel
   never takes its identity branch (``|b| < 1e-10``).
5. Right equivariance (rigid ``D = translate(o)``: DQ(M D) = DQ(M) DQ(D), the flips and norms
   unchanged): with ``x° = R(b^) p + T(b, c)`` (the point if every ``S_j`` were ``I``),
   ``x° - C = R(b^)(p - o) + T(b, c_D) - T(b, c_e)``, where ``c_D``, ``c_e`` are the blends of
   the translations ``D_j = M_j(o) - M_J(o) = Lin(K_J)(Y_j(o) - c_P)`` (``Y_j = K_J^-1 K_j B_j^-1``,
   the relative transform; ``M_J(o) = C``) and ``e_j = R_j (S_j - I) o``, because ``T`` is linear
   in the translations, ``T(b, (0, C/2) b) = C``, and ``R_j o + t_j = M_j(o) - e_j``.
6. Constants: ``|x - x°| = |s - p| <= (sum w_j eta_j + |sum w_j - 1|) |p|`` (0 without a scale
   flag) and ``|T(b, c_e)| <= 2 |c_e| / |b| <= sum w_j eta_j |o| / w_max``; their sum is
   ``eps_v``.
7. Lipschitz, in the blend's own frame: ``h(u) = R(b^)(p - o) + T(b, c_D)`` has ``|h| = |k|``
   with ``k(u) = R(b^)^T h = (p - o) + 2 Im(b* c_D) / |b|^2`` (``R(b^)^T 2 Im(c b*) / |b|^2 =
   2 Im(b* c) / |b|^2``: conjugating by the unit ``b^`` moves the vector part and keeps the real
   one), whose first term is constant: ``|k'| <= L_v = 2 |c_D'| / w_max + 6 |c_D| |b'| / w_max^2``
   (the quotient rule, ``|b| >= w_max``), with ``|b'| <= sum w_j omega_j / 2``, ``|c_D| <= sum w_j
   Dm_j / 2``, ``|c_D'| <= sum w_j (Dv_j + Dm_j omega_j / 2) / 2`` (``d_j = (0, D_j/2) q_j``), and
   ``|D_j| <= Dm_j = nK_J E_j``, ``|D_j'| <= Dv_j = dK_J E_j + nK_J V_j``.  ``E_j`` bounds
   ``|Y_j(o) - c_P|`` on the interval (the end distances plus the chord deviation of
   :func:`runtime.kernels.interval.chain_bounds`, run on the points ``B_j^-1 o`` with radius 0),
   ``V_j`` the speed of ``Y_j(o)``: along the chain of local factors from ``j`` to ``J``
   (innermost first) a point ``z`` moved by a forward factor ``F z + t`` gains ``|(Fz + t)'| <=
   n0 |z'| + n1 |z|max + dt`` and by an inverse one ``|(F^-1 (z - t))'| <= n0inv |z'| + n1inv
   (|z|max + |t|max) + n0inv dt``.
8. Hence on ``[a, b]``, for every vertex (``|k|`` is ``L_v``-Lipschitz), ``|x(u) - C(u)| <= |h(u)|
   + eps_v <= (|h(a)| + |h(b)|) / 2 + L_v l / 2 + eps_v <= (g(a) + g(b)) / 2 + L_v l / 2 + 2 eps_v``
   with ``g = |x - C|``
   skinned exactly at the ends (the runtime's kernel); per part, ``U = (G(a) + G(b)) / 2 +
   max_v (L_v l / 2 + 2 eps_v)`` with ``G`` the part's exact farthest distance.  In ``J``'s space
   ``|y - c_P| <= |x - C| / sigma_min(K_J) <= U / lK_J``, held to the same radius ``rho`` as the
   linear certificate (:func:`runtime.certify.continuous`: the stage sphere then holds).
9. Across a hemisphere flip (where item 3 cannot exclude one, UsdSkel's DQS jumps and item 8's
   Lipschitz argument does not apply) a static bound still holds at every ``u``: item 4 needs no
   continuity (``b . q_piv = sum w_j |q_j . q_piv|`` whichever signs UsdSkel picks), so by item 5
   ``|x - C| <= |p - o| + |T(b, c_D)| + eps_v <= |p - o| + sum w_j Dm_j / w_max + eps_v``
   (``|T(b, c)| <= 2 |c| / |b|``, ``|d_j| = |D_j| / 2``).  ``U`` is the smaller of the two bounds
   where there is no flip and this one where there may be; with it a flip no longer leaves an
   interval undecided at the depth limit.

Item 8's hypotheses fail where scales change over the interval (UsdSkel rounds their lerp to half
precision, a step function) or a skinning transform is far from rigid (``eta_j > ETA_MAX``): there
only item 9's bound applies, with every factor's norms padded by its half-precision ``eps``
(:func:`runtime.certify.factor_bounds`), so ``eta_j`` and ``E_j`` hold at every time of the
interval.  Where item 9's fail too (a mirrored skinning transform, negative weights) it never
certifies (status 4, undecided, reported as a failure; the spheres stage refuses to write such an
asset).  Subdivision halves ``l`` (the bounds above hold on the whole interval, so on every part
of it) up to ``max_depth`` times.
"""

from __future__ import annotations

import numpy as np

from . import certify as C
from .kernels import bounds as B
from .kernels import interval as IV
from .kernels import pose as PK
from .kernels import skin as SK

#: Subdivision depth before an interval is left undecided (as the linear certificate's).
MAX_DEPTH = 8
#: A failing interval is sampled at this many sub-steps for its worst excess.
FAIL_SAMPLES = 16

#: Largest ``||S_j - I||`` (stretch of a skinning transform) the Lipschitz bound accepts.
ETA_MAX = 1e-3
#: Relative padding of every bound (float64 rounding).
ROUND = 1e-9


def quat_pads(clip, times, rest_local, J):
    """(up, down, dadd): (I, J) arrays correcting each local factor's bounds for UsdSkel's
    rotation matrix of a quaternion that is not exactly unit (item 1).

    UsdSkel builds the matrix of ``q = lam q^`` with the unit-quaternion formula, which gives
    ``M = (1 - lam^2) I + lam^2 R`` (``R`` the rotation of ``q^``, angle ``th``): along the axis
    ``M`` is 1, in the plane it is ``(1 - lam^2) + lam^2 e^{i th}`` of modulus ``sqrt(1 - 2 lam^2
    (1 - lam^2)(1 - cos th))``; so its singular values lie in ``[1 - 2 e- (1 - cos th), 1 + 2 e+
    (1 - cos th)]`` with ``e+- >= max(0, +-(lam^2 - 1))`` (``up``, ``down``), and ``||M'|| <=
    ||R'|| (1 + e+) + 2 |(lam^2)'|`` (``dadd``, times the factor's largest scale).  Over an
    interval: ``|1 - lam^2| <= 2 dev + lin + 1e-7`` with ``dev`` the end samples' own
    ``|1 - |q|^2|`` (float32 storage; GfSlerp's weights sum to at most sqrt 2) and ``lin = (1 -
    cos) / 2`` on GfSlerp's linear branch (``1 - cos <= 1e-5``: ``|q|^2 = 1 - 2u(1-u)(1 - cos)``,
    so ``|(lam^2)'| <= 2 (1 - cos)`` there, and ``<= 8 dev`` on the slerp branch); ``th`` at most
    the smaller end's angle plus the interval's (``1 - cos th <= 2``).  Joints the clip does not
    animate: their rest matrices, exact (1, 1, 0)."""
    from .kernels import pose as _pk
    _, _, q, sc = _pk.locals_at(clip, times, rest_local, trs=True)  # (T, A, 4) (x, y, z, w)
    I = len(times) - 1
    up, down, dadd = np.ones((I, J)), np.ones((I, J)), np.zeros((I, J))
    if q.shape[1] == 0 or I < 1:
        return up, down, dadd
    f32 = q.astype(np.float32)
    cos = np.minimum(np.abs((f32[:-1] * f32[1:]).sum(-1, dtype=np.float32)).astype(np.float64), 1.0)
    n2 = (q * q).sum(-1)
    lin = 1.0 - cos <= 1e-5
    e_up = 2.0 * np.maximum(np.maximum(n2[:-1] - 1.0, n2[1:] - 1.0), 0.0) + 1e-7
    e_dn = 2.0 * np.maximum(np.maximum(1.0 - n2[:-1], 1.0 - n2[1:]), 0.0) + np.where(lin, (1.0 - cos) / 2.0, 0.0) + 1e-7
    ang = 2.0 * np.arccos(np.minimum(np.abs(q[..., 3]) / np.sqrt(n2), 1.0))  # each sample's rotation angle
    th = np.minimum(np.minimum(ang[:-1], ang[1:]) + 2.0 * np.arccos(cos) * 1.001 + 1e-6, np.pi)
    omc = 1.0 - np.cos(th)
    smax = np.maximum(np.abs(sc[:-1]).max(-1), np.abs(sc[1:]).max(-1))
    dev = np.maximum(np.abs(1.0 - n2[:-1]), np.abs(1.0 - n2[1:]))
    a = clip.anim_to_skel
    up[:, a] = 1.0 + 2.0 * e_up * omc
    down[:, a] = np.maximum(1.0 - 2.0 * e_dn * omc, 0.0)
    dadd[:, a] = 2.0 * np.where(lin, 2.0 * (1.0 - cos), 8.0 * dev + 1e-7) * smax
    return up, down, dadd


def _joint_bounds(rig, fac, pads):
    """Per (interval, joint): nK, lK, dK (skeleton-space linear part norm, smallest singular
    value, derivative norm) and, for the skinning transform, eta, omega (items 1-2); ``pads``
    from :func:`quat_pads`."""
    fw, iv = fac["fw"], fac["iv"]
    up, down, dadd = pads
    I, Jn = fw.shape[:2]
    nK, lK, dK = np.empty((I, Jn)), np.empty((I, Jn)), np.empty((I, Jn))
    with np.errstate(all="ignore"):
        for j in rig.topo:
            p = rig.parents[j]
            n0 = fw[:, j, 0] * up[:, j]
            l0 = down[:, j] / iv[:, j, 0]
            n1 = fw[:, j, 1] * up[:, j] + dadd[:, j]
            if p < 0:
                nK[:, j], lK[:, j], dK[:, j] = n0, l0, n1
            else:
                nK[:, j] = nK[:, p] * n0
                lK[:, j] = lK[:, p] * l0
                dK[:, j] = dK[:, p] * n0 + nK[:, p] * n1
        sv = np.linalg.svd(rig.inv_bind[:, :3, :3], compute_uv=False)
        Bn, Bs = sv[:, 0] * (1 + 1e-12), sv[:, -1] * (1 - 1e-12)
        N, m = nK * Bn, lK * Bs
        eta = np.maximum(N - 1.0, 1.0 - m) * (1 + ROUND) + 1e-12
        omega = dK * Bn / m * (1 + ROUND)
    return nK, lK, dK, eta, omega


def _path_speeds(rig, fac, pj_point, pads):
    """(I, M) speed bound ``V`` of ``Y_b(z0)`` for every (part, joint) pair (item 7), ``z0 =
    pj_point`` in the joint's own space; the factors' bounds corrected by ``pads``
    (:func:`quat_pads`; an inverse factor's derivative by ``||(M^-1)'|| <= ||M^-1||^2 ||M'||``)."""
    off, pj, pd, _ = rig.paths()
    up, down, dadd = pads
    fw, iv, dt = fac["fw"].copy(), fac["iv"].copy(), fac["dt"]
    with np.errstate(all="ignore"):
        fw[..., 0] *= up
        fw[..., 1] = fw[..., 1] * up + dadd
        iv[..., 0] /= down
        iv[..., 1] = np.maximum(iv[..., 1] / down ** 2, iv[..., 0] ** 2 * fw[..., 1])
    tmax = np.maximum(np.linalg.norm(fac["L0"][..., :3, 3], axis=-1), np.linalg.norm(fac["L1"][..., :3, 3], axis=-1))
    I, M = fw.shape[0], len(off) - 1
    V = np.zeros((I, M))
    with np.errstate(all="ignore"):
        for k in range(M):
            z = np.full(I, np.linalg.norm(pj_point[k]))
            v = np.zeros(I)
            for e in range(off[k], off[k + 1]):
                j, d = pj[e], pd[e]
                if d > 0:
                    v = fw[:, j, 0] * v + fw[:, j, 1] * z + dt[:, j]
                    z = fw[:, j, 0] * z + tmax[:, j]
                else:
                    v = iv[:, j, 0] * v + iv[:, j, 1] * (z + tmax[:, j]) + iv[:, j, 0] * dt[:, j]
                    z = iv[:, j, 0] * (z + tmax[:, j])
            V[:, k] = v * (1 + ROUND)
    return V


class _Times:
    """Skeleton transforms, exact part distances and joint quaternions at any time of the clip,
    computed on demand (only for the parts asked) and kept."""

    def __init__(self, rig, clip, times, fac):
        self.rig, self.clip = rig, clip
        self.frame = {float(t): i for i, t in enumerate(times)}
        self.locals = fac["locals"]
        self.skel = {}
        self.dist = {}   # (t, part) -> skeleton-space farthest |x - C|
        self.quat = {}   # t -> (J, 4) UsdSkel's joint quaternions (w, x, y, z)

    def skel_at(self, t):
        """(J, 4, 4) skeleton-space joint transforms at time ``t`` (UsdSkel's interpolation)."""
        t = float(t)
        if t not in self.skel:
            i = self.frame.get(t)
            local = self.locals[i] if i is not None else PK.locals_at(self.clip, [t], self.rig.rest_local)[0]
            self.skel[t] = PK.compose(local, self.rig.parents, self.rig.topo)
        return self.skel[t]

    def fill(self, requests):
        """Skin what ``requests`` ((time, part) pairs) needs and is not known yet."""
        rig = self.rig
        need = sorted({(float(t), int(p)) for t, p in requests if (float(t), int(p)) not in self.dist})
        if not need:
            return
        ts = sorted({t for t, _ in need})
        row = {t: n for n, t in enumerate(ts)}
        todo = np.zeros((len(ts), rig.P), bool)
        for t, p in need:
            todo[row[t], p] = True
        skel = np.stack([self.skel_at(t) for t in ts])  # (T, J, 4, 4)
        skin = skel @ rig.inv_bind
        real, _, _, _ = SK.dq_parts(skin)
        KJ = skel[:, rig.part_joint]
        cen = np.einsum("tpij,pj->tpi", KJ[..., :3, :3], rig.part_centers) + KJ[..., :3, 3]
        d, _ = SK.part_farthest(rig.points, rig.joint_indices, rig.joint_weights,
                                SK.fold_dq(skin, rig.geom_bind), rig.vert_offsets, rig.verts, cen, todo=todo)
        for t, p in need:
            self.dist[(t, p)] = d[row[t], p]
        for n, t in enumerate(ts):
            self.quat.setdefault(t, real[n])


def certificate(rig, clip, times, frame_bound, frame_ok, tol_abs: float, tol_rel: float, **kw) -> C.Continuous:
    """The continuous certificate of ``rig``'s own skinning method: :func:`continuous` for a
    dual-quaternion rig, :func:`runtime.certify.continuous` for a linear one (the one entry the
    frame proof and the spheres stage call)."""
    if rig.skinning_method == SK.CLASSIC_LINEAR:
        return C.continuous(rig, clip, times, frame_bound, frame_ok, tol_abs, tol_rel, **kw)
    if rig.skinning_method != SK.DUAL_QUATERNION:
        raise ValueError(f"skinning method {rig.skinning_method!r}: expected one of {SK.METHODS}")
    return continuous(rig, clip, times, frame_bound, frame_ok, tol_abs, tol_rel, **kw)


def continuous(rig, clip, times, frame_bound, frame_ok, tol_abs: float, tol_rel: float, rho=None,
               growth: bool = False, max_depth: int = MAX_DEPTH, frame_bound_space: str = "stage") -> C.Continuous:
    """:func:`runtime.certify.continuous` for a dual-quaternion rig (the bound: module docstring).

    Same parameters and result; ``frame_bound`` is not used (the ends of every sub-interval are
    skinned exactly).  Status 1: certified on the whole interval; 2: after subdivision; 3: a
    sub-interval end is outside (a definite failure); 4: undecided (the hypotheses fail, or the
    depth limit); 5: a sample at an end already fails."""
    times = np.asarray(times, dtype=np.float64)
    F, P = len(times), rig.P
    I = F - 1
    if I <= 0 or P == 0:
        z = np.zeros((max(I, 0), P))
        return C.Continuous(z.astype(np.int8), z, z)
    bd = rig.bounds
    fac = C.factor_bounds(clip, times, rig.rest_local)
    pads = quat_pads(clip, times, rig.rest_local, len(rig.bind))
    nK, lK, dK, eta, omega = _joint_bounds(rig, fac, pads)
    # item 9's static bound holds across half-precision scale steps too: the factors' norms padded by eps
    fac_s = dict(fac, fw=fac["fw"].copy(), iv=fac["iv"].copy())
    fac_s["fw"][..., 0] += fac["eps"][..., 0]
    fac_s["iv"][..., 0] += fac["eps"][..., 1]
    nKs, lKs, _, etas, _ = _joint_bounds(rig, fac_s, pads)
    Jp = rig.part_joint

    # -- the radius held (as runtime.certify.continuous): scale bounds of N_J = world @ K_J
    with np.errstate(all="ignore"):
        sw = np.linalg.svd(rig.world[:3, :3], compute_uv=False)
        s_hi = nK * sw[0] * (1 + 1e-12)
        s_lo = lK * sw[-1] * (1 - 1e-12)
        iso = fac["iso"].copy()
        for j in rig.topo:
            p = rig.parents[j]
            if p >= 0:
                iso[:, j] &= iso[:, p]
        iso &= bool(sw[0] - sw[-1] <= 1e-12 * sw[0])
        ratio = np.where(iso, 1.0, s_lo / s_hi)
        r = rig.part_radii
        if rho is None:
            rho = r[None] * (1.0 + tol_rel) * ratio[:, Jp] * (1 - 1e-12) + tol_abs / s_hi[:, Jp]
        else:
            rho = np.asarray(rho, dtype=np.float64) * ratio[:, Jp] * (1 - 1e-12)
    rho = np.broadcast_to(np.asarray(rho, dtype=np.float64), (I, P)).copy()

    # -- hypotheses per interval (smooth, near-rigid skinning transforms, non-negative weights)
    smooth = ~(fac["eps"] > 0).any(axis=(1, 2))
    ji, jw = rig.joint_indices, rig.joint_weights.astype(np.float64)
    used = np.unique(ji[jw != 0])
    rigid = (eta[:, used] <= ETA_MAX).all(axis=1) if len(used) else np.ones(I, bool)
    nonneg = bool((jw >= 0).all())
    tm = _Times(rig, clip, times, fac)
    # det A_j > 0 at every sample (then on the whole interval: sigma_min(A_j) >= m_j > 0 there), so
    # S_j is positive definite and eta bounds ||S_j - I|| (a mirrored joint has S_j near -I)
    dets = np.array([np.linalg.det((tm.skel_at(t) @ rig.inv_bind)[used, :3, :3]) for t in times]) if len(used) \
        else np.ones((F, 0))
    proper = (dets > 0).all(axis=1)
    rigid &= proper[:-1] & proper[1:]
    # item 9 needs no smoothness nor near-rigidity: proper at the samples, sigma_min > 0 between, weights >= 0
    static_ok = proper[:-1] & proper[1:] & nonneg & ((lKs[:, used] > 0).all(axis=1) if len(used) else True)

    # -- per (part, joint) pair: E (bound on |Y_b(o) - c_P|) and V (its speed) (item 7)
    pair_part = np.repeat(np.arange(P), np.diff(bd.pj_offsets))
    o_bind = np.einsum("pij,pj->pi", rig.bind[Jp][:, :3, :3], rig.part_centers) + rig.bind[Jp][:, :3, 3]
    M = len(bd.pj_joint)
    z0 = np.zeros((M, 3))
    if M:
        ib = rig.inv_bind[bd.pj_joint]
        z0 = np.einsum("mij,mj->mi", ib[:, :3, :3], o_bind[pair_part]) + ib[:, :3, 3]
    e0, e1, delta, lam, pert = (np.zeros((I, M)) for _ in range(5))
    if M:
        off, pj, pd, _ = rig.paths()
        IV.chain_bounds(fac["L0"], fac["L1"], fac["Li0"], fac["Li1"], fac["fw"], fac["iv"], fac["dt"], fac["eps"],
                        off, pj, pd, np.ascontiguousarray(z0), np.zeros(M), pair_part, bd.part_centers,
                        e0, e1, delta, lam, pert)
    E = (np.maximum(e0, e1) + delta + pert) * (1 + ROUND)
    V = _path_speeds(rig, fac, z0, pads) if M else np.zeros((I, 0))
    Dm = nK[:, Jp[pair_part]] * E
    Dms = nKs[:, Jp[pair_part]] * E
    Dv = dK[:, Jp[pair_part]] * E + nK[:, Jp[pair_part]] * V

    # -- per part: Lipschitz constant L and constant eps (items 4-7), per interval
    G = rig.geom_bind
    pbind = rig.points.astype(np.float64) @ G[:3, :3].T + G[:3, 3]
    Lp = np.full((I, P), np.inf)
    Ep = np.full((I, P), np.inf)
    Sp = np.full((I, P), np.inf)
    pairs = []  # per part: (joint, pivot) index arrays for the flip test
    with np.errstate(all="ignore"):
        for p in range(P):
            vs = rig.verts[rig.vert_offsets[p]:rig.vert_offsets[p + 1]]
            if len(vs) == 0:
                Lp[:, p] = 0.0
                Ep[:, p] = 0.0
                Sp[:, p] = 0.0
                pairs.append((np.zeros(0, np.int64), np.zeros(0, np.int64)))
                continue
            lo, hi = bd.pj_offsets[p], bd.pj_offsets[p + 1]
            col = np.full(len(rig.bind), lo, dtype=np.int64)  # joint -> its pair index in the part
            col[bd.pj_joint[lo:hi]] = np.arange(lo, hi)
            w = np.abs(jw[vs])
            jj = ji[vs]
            live = w != 0
            k = np.where(live, col[jj], lo)
            piv = jj[np.arange(len(vs)), np.argmax(jw[vs], axis=1)]
            wmax = w.max(1)
            om = np.where(live[None], omega[:, jj], 0.0)  # (I, n, k); padding never read
            et = np.where(live[None], eta[:, jj], 0.0)
            sw_ = (w[None] * et).sum(2)
            bdot = 0.5 * (w[None] * om).sum(2)
            dm = np.where(live[None], Dm[:, k], 0.0)
            dv = np.where(live[None], Dv[:, k], 0.0)
            cD = 0.5 * (w[None] * dm).sum(2)
            ets = np.where(live[None], etas[:, jj], 0.0)
            dms = np.where(live[None], Dms[:, k], 0.0)
            cDd = 0.5 * (w[None] * (dv + dm * om / 2)).sum(2)
            L = 2.0 * cDd / wmax[None] + 6.0 * cD * bdot / wmax[None] ** 2
            eps_v = (sw_ + np.abs(jw[vs].sum(1) - 1.0)[None]) * np.linalg.norm(pbind[vs], axis=1)[None] \
                + sw_ * np.linalg.norm(o_bind[p]) / wmax[None]
            Lp[:, p] = np.max(L, axis=1) * (1 + ROUND)
            Ep[:, p] = np.max(eps_v, axis=1) * (1 + ROUND)
            # item 9: the flip-free static bound |p - o| + sum w_j Dm_j / w_max + eps_v
            sws = (w[None] * ets).sum(2)
            eps_s = (sws + np.abs(jw[vs].sum(1) - 1.0)[None]) * np.linalg.norm(pbind[vs], axis=1)[None] \
                + sws * np.linalg.norm(o_bind[p]) / wmax[None]
            Sp[:, p] = np.max(np.linalg.norm(pbind[vs] - o_bind[p], axis=1)[None]
                              + (w[None] * dms).sum(2) / wmax[None] + eps_s, axis=1) * (1 + ROUND)
            a, b = np.broadcast_to(piv[:, None], jj.shape)[live], jj[live]
            u = np.unique(np.c_[a, b][a != b], axis=0)
            pairs.append((u[:, 1].astype(np.int64), u[:, 0].astype(np.int64)))
    ok_int = smooth & rigid & nonneg
    Lp[~np.isfinite(Lp)] = np.inf
    Sp[~np.isfinite(Sp)] = np.inf

    ok = np.asarray(frame_ok, dtype=bool)
    ends_ok = ok[:-1] & ok[1:]
    status = np.full((I, P), -1, dtype=np.int8)
    status[~ends_ok] = 5
    if growth:
        status[:] = -1
    out = C.Continuous(status, np.full((I, P), np.inf), rho, ratio=ratio[:, Jp].copy())
    nodes = [(int(i), int(p), float(times[i]), float(times[i + 1]), 0) for i, p in np.argwhere(status == -1)]
    worst, deepest, found = {}, {}, {}
    bad_hyp = set()
    while nodes:
        tm.fill([(x, n[1]) for n in nodes for x in (n[2], n[3])])
        nxt = []
        for i, p, a, b, depth in nodes:
            key = (i, p)
            if out.status[i, p] in (3, 4) and not growth:
                continue
            if not ok_int[i]:  # only item 9's static bound applies here
                Us = Sp[i, p] * (1 + ROUND) / (lKs[i, Jp[p]] * (1 - 1e-12)) if static_ok[i] else np.inf
                if Us <= rho[i, p] or (growth and np.isfinite(Us)):
                    worst[key] = max(worst.get(key, -np.inf), Us)
                    continue
                bad_hyp.add(key)
                out.status[i, p] = 4
                continue
            l = (b - a) / (times[i + 1] - times[i])
            jA, jP = pairs[p]
            qa, qb = tm.quat[a], tm.quat[b]
            if len(jA):
                da = np.abs((qa[jA] * qa[jP]).sum(1))
                db = np.abs((qb[jA] * qb[jP]).sum(1))
                no_flip = bool(np.all(da + db > 0.5 * l * (omega[i, jA] + omega[i, jP]) * (1 + ROUND)))
            else:
                no_flip = True
            Ga, Gb = tm.dist[(a, p)], tm.dist[(b, p)]
            U = ((Ga + Gb) / 2 + Lp[i, p] * l / 2 + 2 * Ep[i, p]) * (1 + ROUND) / (lK[i, Jp[p]] * (1 - 1e-12))
            Us = Sp[i, p] * (1 + ROUND) / (lKs[i, Jp[p]] * (1 - 1e-12))  # item 9: holds across flips
            U = min(U, Us) if no_flip else Us
            no_flip = no_flip or bool(np.isfinite(Us))
            if no_flip and U <= rho[i, p]:
                worst[key] = max(worst.get(key, -np.inf), U)
                deepest[key] = max(deepest.get(key, 0), depth)
                continue
            if not growth and depth > 0 and max(Ga, Gb) / lK[i, Jp[p]] > rho[i, p]:
                t_end = a if Ga >= Gb else b
                d, R, v = _exact(rig, tm.skel_at(t_end)[None], p)
                if d[0] - R[0] * (1 + tol_rel) - tol_abs > 0:
                    out.status[i, p] = 3
                    found[key] = (t_end, int(v[0]), float(d[0] - R[0]), float(R[0]))
                    continue
            if depth >= max_depth:
                worst[key] = max(worst.get(key, -np.inf), U if no_flip else np.inf)
                deepest[key] = depth
                if not growth:
                    out.status[i, p] = 4
                continue
            m = 0.5 * (a + b)
            nxt += [(i, p, a, m, depth + 1), (i, p, m, b, depth + 1)]
            out.subdivided += 1
        nodes = nxt
    for i, p in np.argwhere(out.status != 5):
        key = (int(i), int(p))
        if key in bad_hyp:
            out.status[i, p] = 4
            out.bound[i, p] = np.inf
            continue
        if out.status[i, p] == -1:
            out.status[i, p] = 1 if deepest.get(key, 0) == 0 else 2
        out.bound[i, p] = worst.get(key, np.inf) if out.status[i, p] != 3 else np.inf
    for i, p in np.argwhere((out.status == 3) | (out.status == 4)):
        f = _describe_failure(rig, times, int(i), int(p), out, tm, found.get((int(i), int(p))))
        if (int(i), int(p)) in bad_hyp:
            f["reason"] = ("the dual-quaternion bound's hypotheses fail on this interval (a mirrored skinning "
                           "transform or negative weights), or with animated scales or a stretched skinning "
                           "transform its static bound (item 9) exceeds the radius: not certified"
                           if static_ok[int(i)] and not ok_int[int(i)] else
                           "the dual-quaternion bound's hypotheses fail on this interval (a mirrored skinning "
                           "transform or negative weights): not certified")
        out.failures.append(f)
    return out


def _exact(rig, skel, p):
    """Stage-space farthest distance, radius and vertex of part ``p`` at poses ``skel`` (F, J, 4, 4)."""
    sph, _, _ = B.pose_bounds(rig.world @ skel, rig.bounds)
    todo = np.zeros(sph.shape[:2], bool)
    todo[:, p] = True
    d, v = SK.part_farthest(rig.points, rig.joint_indices, rig.joint_weights,
                            SK.fold_dq(skel @ rig.inv_bind, rig.geom_bind, rig.world), rig.vert_offsets, rig.verts,
                            sph[..., :3], todo=todo)
    return d[:, p], sph[:, p, 3], v[:, p]


def _describe_failure(rig, times, i, p, out, tm, found):
    """The worst excess of part ``p`` over interval ``i``: the time the subdivision found outside
    and :data:`FAIL_SAMPLES` evenly spaced sub-steps, all skinned exactly in stage space."""
    t0, t1 = float(times[i]), float(times[i + 1])
    sub = t0 + (t1 - t0) * np.arange(1, FAIL_SAMPLES) / FAIL_SAMPLES
    d, R, v = _exact(rig, np.stack([tm.skel_at(t) for t in sub]), p)
    k = int(np.argmax(d - R))
    time, vertex, excess, radius = float(sub[k]), int(v[k]), float(d[k] - R[k]), float(R[k])
    if found is not None and found[2] > excess:
        time, vertex, excess, radius = found
    return {"interval": i, "part": p, "t0": t0, "t1": t1, "time": time, "vertex": vertex, "excess": excess,
            "radius": radius, "definite": bool(out.status[i, p] == 3), "bound": float(out.bound[i, p])}
