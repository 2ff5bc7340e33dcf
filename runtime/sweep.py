"""The body's own motion between two poses, swept: a continuous contact query for a moving sphere.

>>> hit = sweep_sphere(pose_prev, pose_next, c0, c1, radius)
>>> if hit is not None:
...     hit.time, hit.triangle, hit.barycentric, hit.point, hit.normal, hit.velocity

A sphere of ``radius`` moves from ``c0`` to ``c1`` while the body moves from ``pose_prev`` to
``pose_next``; the query returns the first time of contact (a fraction of the step) and the
contact, or None.  It is conservative: it may report a contact slightly early, never miss one.

**The body's motion between the two poses** (:class:`BodyMotion`).  Two poses of one clip
(``col.pose(clip, t)``) move as UsdSkel interpolates the clip from ``t_prev`` to ``t_next`` (either
direction, when they are at most half the clip's duration apart): the step is cut at the clip's samples in between into *segments*, on each of which every
animated joint's local transform is ``T R S`` with the translation and scale lerped and the rotation
slerped between the segment's ends (a sub-interval of a UsdSkel interval is again one).  Any other
pair (:meth:`Collider.pose_from_joints` results, the rest pose, two clips, the skeleton's
transform animated, or two times of a clip further apart: a looping clip that wrapped around, a
jump) is one segment of the same joint-space interpolation between the two poses'
joint-local transforms, each decomposed as ``T R S`` (scale = column norms; a negative determinant
flips the first axis; shear is refused with ``ValueError``), rotations on the shortest arc.  The
player is at ``c0 + f (c1 - c0)`` at step fraction ``f``; a clip segment from time ``a`` to ``b``
spans the fractions ``(a - t_prev) / (t_next - t_prev)`` to ``(b - t_prev) / (t_next - t_prev)``.

**The bound** (per segment and part ``P``: ``D_P``, :attr:`BodyMotion.deviation`).  On a segment
(normalised time ``tau`` in [0, 1]) every skinned vertex of part ``P`` stays within ``D_P`` of its
chord ``(1 - tau) x_v(0) + tau x_v(1)``, where

    ``D_P = ||L(W)|| min(a_P max_b (delta_b + pert_b), sum_b wmax_b (delta_b + pert_b))``

over the part's (part, joint) pairs ``b`` (:class:`~runtime.kernels.bounds.BoundData`: the ball
``(c_b, r_b)`` of the part's vertices in ``b``'s bind space, ``wmax_b`` the largest weight of ``b`` in
the part, ``a_P`` the largest ``sum_b |w_b(v)|``), ``W`` the skeleton prim's transform, and
``delta_b``, ``pert_b`` the outputs of the continuous certificate's chain recursion
(:func:`runtime.kernels.interval.chain_bounds`, reused as is) run on the chain from ``b`` up to the
root, i.e. on ``G_b(tau) = L_root(tau) ... L_b(tau)`` (joint ``b`` -> skeleton space), with the factor
bounds of :func:`runtime.kernels.interval.factor_terms` for the segment (:func:`runtime.certify.factor_bounds`
derives them, margins included).

Soundness.  (1) ``chain_bounds`` proves, for every point ``u`` of the ball and every ``tau``,
``|G_b(tau) u - chord| <= delta_b + pert_b`` (``delta_b = sup|p''| / 8``, the vector form of linear
interpolation's error, ``pert_b`` UsdSkel's half-precision scale lerp); its recursion needs only that
each factor's path is ``T R S`` lerped / slerped between the ends, which holds on every segment (a
clip's sub-interval, or the joint-space interpolation by definition).  Its argument does not depend on
which chain it is given: the certificate runs it on ``G_J^-1 G_b`` (part joint space), this module on
``G_b`` (skeleton space); so the bound is the certificate's own, not a re-derived one.  (2) LBS is
linear in the joint transforms: ``x_v(tau) = W sum_b w_b(v) G_b(tau) u_b(v)``, and so is the chord, so
``|x_v(tau) - chord_v(tau)| <= ||L(W)|| sum_b |w_b(v)| (delta_b + pert_b)``, which is at most both
terms of the ``min`` (``sum_b |w_b(v)| <= a_P``; ``|w_b(v)| <= wmax_b``).  When ``W`` differs between
the ends (an animated skeleton transform; taken to move as the lerp of its two matrices) the deviation
gains ``|tau (1 - tau) (W0 - W1) (s_0 - s_1)| <= ||L(W0 - W1)|| S / 4`` (``s`` the skeleton-space
point, ``S`` a bound of its travel from the part spheres) and the ``||L(W)||`` factor is the larger of
the two.  (3) Float rounding: ``D`` is padded by ``1e-9`` relative, and by ``1e-5 D + 2e-6 (|C| + R)
+ 1e-9`` for the float32 posed corners the query reads (the culling spheres' padding).

**The query** (:func:`sweep_sphere`).  Per segment, per part: the part's points at the segment's
ends lie in its culling spheres ``(C_a, R_a)``, ``(C_b, R_b)`` (:attr:`Pose.cull`, provable), so at
``tau`` every vertex is within ``(1 - tau) R_a + tau R_b + D_P`` of ``(1 - tau) C_a + tau C_b``; the
part is skipped when the sphere's path relative to that centre (a segment) stays farther than
``max(R_a, R_b) + D_P + radius`` from it.  The remaining parts' triangles (skinned at the two ends
only) go to the conservative-advancement kernel (:mod:`runtime.kernels.swept`), each inflated by its
part's ``D_P``: every true triangle point is within ``D_P`` of the chord triangle's.  The segments are
searched in order; the first contact ends the search.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import kernels as B
from .certify import ALPHA_MARGIN, OMEGA_MARGIN
from .collider import Pose
from .kernels import interval as IK
from .kernels import pose as PK
from .kernels.swept import _part_deviation, _sweep_segment

#: Conservative advancement stops this close (x radius) to a contact, or after MAX_ITER steps.
TOLERANCE = 1e-3
MAX_ITER = 64
#: Largest deviation of a decomposed joint-local rotation from orthonormal (else: shear, refused).
SHEAR = 1e-6


@dataclass(frozen=True)
class SweptContact:
    """The first contact of :func:`sweep_sphere` (arrays are copies).

    time : float, fraction of the step in [0, 1] (``pose_prev`` = 0, ``pose_next`` = 1)
    triangle : int; part : int, the part whose triangles it was found among
    barycentric : (3,) float64, on the chord triangle at that time
    point : (3,) float64, that point (stage space); normal : (3,) unit normal of the chord triangle
        there (counter-clockwise = outward)
    velocity : (3,) float64, the point's velocity along the segment, stage units per step
    centre : (3,) float64, the sphere's centre at that time
    segment : int, the body-motion segment it was found on
    """

    time: float
    triangle: int
    part: int
    barycentric: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    velocity: np.ndarray
    centre: np.ndarray
    segment: int


def _root_paths(data):
    """(off, joint, dir, pair_part): per (part, joint) pair of the bounds, the chain of local
    transforms from the pair's joint up to the root (innermost first, every one forward)."""
    bd = data.bounds
    got = getattr(bd, "_sweep_root_paths", None)
    if got is None:
        pair_part = np.repeat(np.arange(len(bd.part_joint)), np.diff(bd.pj_offsets)).astype(np.int64)
        off, pj = [0], []
        for b in bd.pj_joint:
            j = int(b)
            while j >= 0:
                pj.append(j)
                j = int(data.parents[j])
            off.append(len(pj))
        got = (np.array(off, np.int64), np.array(pj, np.int64), np.ones(len(pj), np.int64), pair_part)
        bd._sweep_root_paths = got
    return got


def _factor_terms(d, L, t, q, s, anim):
    """:func:`runtime.kernels.interval.factor_terms` (its kernel, the same numbers), with the
    constant joints' rows (an SVD of the rest transforms) computed once per asset."""
    bd = d.bounds
    rows = getattr(bd, "_sweep_rest_rows", None)
    if rows is None:
        sv = np.linalg.svd(d.rest_local[:, :3, :3], compute_uv=False)
        with np.errstate(divide="ignore"):
            inv = np.where(sv[:, -1] > 0, 1.0 / sv[:, -1], np.inf)
        rows = bd._sweep_rest_rows = (sv[:, 0] * (1 + 1e-12), inv * (1 + 1e-12),
                                      sv[:, 0] - sv[:, -1] <= 1e-12 * sv[:, 0])
    L = np.ascontiguousarray(L, dtype=np.float64)
    T, J = L.shape[:2]
    I = T - 1
    fw, iv = np.zeros((I, J, 3)), np.zeros((I, J, 3))
    fw[:, :, 0] = rows[0][None]
    iv[:, :, 0] = rows[1][None]
    iso = np.repeat(rows[2][None], I, 0)
    dt, eps = np.zeros((I, J)), np.zeros((I, J, 2))
    Li = np.empty_like(L)
    f64 = (lambda a: np.ascontiguousarray(a, dtype=np.float64))
    IK._factor_terms(L, f64(t), f64(q), f64(s), np.ascontiguousarray(anim, dtype=np.int64), float(OMEGA_MARGIN),
                     float(ALPHA_MARGIN), IK.HALF_LERP_REL, Li, fw, iv, dt, eps, iso)
    return Li, fw, iv, dt, eps


# -- joint-space interpolation of arbitrary poses ---------------------------------------------------


def decompose(local):
    """(t (J, 3), q (J, 4) (x, y, z, w), s (J, 3)) of column-vector joint-local transforms
    (J, 4, 4) as ``T R S``; ValueError on shear."""
    local = np.asarray(local, dtype=np.float64)
    t = local[:, :3, 3].copy()
    lin = local[:, :3, :3]
    s = np.linalg.norm(lin, axis=1)  # column norms
    if not (s > 0).all():
        raise ValueError("a joint-local transform has a zero scale: no rotation to interpolate")
    R = lin / s[:, None, :]
    neg = np.linalg.det(R) < 0
    s[neg, 0] *= -1
    R[neg, :, 0] *= -1
    if np.abs(np.einsum("jki,jkl->jil", R, R) - np.eye(3)).max(initial=0.0) > SHEAR:
        raise ValueError("a joint-local transform has shear: it has no T R S interpolation")
    return t, _quat(R), s


def _quat(R):
    """(J, 4) (x, y, z, w) unit quaternions of rotation matrices (J, 3, 3) (Shepperd's method)."""
    J = len(R)
    q = np.empty((J, 4))
    tr = np.trace(R, axis1=1, axis2=2)
    for j in range(J):
        m = R[j]
        k = int(np.argmax([tr[j], m[0, 0], m[1, 1], m[2, 2]]))
        if k == 0:
            r = math.sqrt(max(1.0 + tr[j], 0.0)) * 2
            q[j] = [(m[2, 1] - m[1, 2]) / r, (m[0, 2] - m[2, 0]) / r, (m[1, 0] - m[0, 1]) / r, 0.25 * r]
        elif k == 1:
            r = math.sqrt(max(1.0 + m[0, 0] - m[1, 1] - m[2, 2], 0.0)) * 2
            q[j] = [0.25 * r, (m[0, 1] + m[1, 0]) / r, (m[0, 2] + m[2, 0]) / r, (m[2, 1] - m[1, 2]) / r]
        elif k == 2:
            r = math.sqrt(max(1.0 + m[1, 1] - m[0, 0] - m[2, 2], 0.0)) * 2
            q[j] = [(m[0, 1] + m[1, 0]) / r, 0.25 * r, (m[1, 2] + m[2, 1]) / r, (m[0, 2] - m[2, 0]) / r]
        else:
            r = math.sqrt(max(1.0 + m[2, 2] - m[0, 0] - m[1, 1], 0.0)) * 2
            q[j] = [(m[0, 2] + m[2, 0]) / r, (m[1, 2] + m[2, 1]) / r, 0.25 * r, (m[1, 0] - m[0, 1]) / r]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def interpolate_locals(local0, local1, alpha):
    """(J, 4, 4) the joint-space interpolation at ``alpha`` in [0, 1] between two joint-local
    poses: translations and scales lerped, rotations slerped on the shortest arc (the motion
    :func:`sweep_sphere` assumes between two poses that are not two times of one clip)."""
    t0, q0, s0 = decompose(local0)
    t1, q1, s1 = decompose(local1)
    return _interpolate_trs(t0, q0, s0, t1, q1, s1, alpha)


def _interpolate_trs(t0, q0, s0, t1, q1, s1, alpha):
    a = float(alpha)
    q0 = q0 / np.linalg.norm(q0, axis=1, keepdims=True)
    q1 = q1 / np.linalg.norm(q1, axis=1, keepdims=True)
    d = np.einsum("jk,jk->j", q0, q1)
    q1 = np.where(d[:, None] < 0, -q1, q1)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    st = np.sin(theta)
    small = st < 1e-9
    with np.errstate(invalid="ignore", divide="ignore"):
        w0 = np.where(small, 1 - a, np.sin((1 - a) * theta) / np.where(small, 1, st))
        w1 = np.where(small, a, np.sin(a * theta) / np.where(small, 1, st))
    q = w0[:, None] * q0 + w1[:, None] * q1
    return PK.trs_matrices(t0 + a * (t1 - t0), q, s0 + a * (s1 - s0))


# -- the body's motion ----------------------------------------------------------------------------


class BodyMotion:
    """The body's motion from ``pose_prev`` to ``pose_next`` (module docstring), cut into segments.

    Attributes
    ----------
    poses : list of Pose, the segments' ends (``poses[0]`` is ``pose_prev``, ``poses[-1]``
        ``pose_next``; the ones between are clip samples, posed here, skinned lazily)
    fractions : (I + 1,) float64, the step fraction of each end
    deviation : (I, P) float64, ``D_P`` per segment and part (stage units)
    clip : str or None, the clip both poses are of (None: joint-space interpolation)
    """

    def __init__(self, pose_prev: Pose, pose_next: Pose):
        col = pose_prev.collider
        if pose_next.collider is not col:
            raise ValueError("the poses belong to different colliders")
        d = col.data
        self.collider = col
        clip = None
        if pose_prev.clip is not None and pose_prev.clip == pose_next.clip and d.static_local_to_world is not None:
            clip = col._clip(pose_prev.clip)
            span = float(clip.times[-1] - clip.times[0]) if len(clip.times) else 0.0
            if abs(float(pose_next.time) - float(pose_prev.time)) > 0.5 * span:
                clip = None  # a jump (a looping clip wrapped around): the joint-space path
        if clip is not None:
            ta, tb = float(pose_prev.time), float(pose_next.time)
            lo, hi = min(ta, tb), max(ta, tb)
            inner = clip.times[(clip.times > lo) & (clip.times < hi)]
            if tb < ta:
                inner = inner[::-1]
            times = np.concatenate([[ta], inner, [tb]])
            ka, kb = pose_prev._trs.get(clip.name), pose_next._trs.get(clip.name)
            if not len(inner) and ka is not None and kb is not None:  # the poses' own T R S (no recompute)
                L = np.stack([pose_prev._local, pose_next._local])
                v = np.concatenate([ka, kb])
                t, q, s = v[..., :3], v[..., 3:7], v[..., 7:]
            else:
                L, t, q, s = PK.locals_at(clip, times, d.rest_local, trs=True, compiled=True)
            anim = clip.anim_to_skel
            self.clip = clip.name
            self.poses = [pose_prev] + [col.pose(clip.name, float(x)) for x in inner] + [pose_next]
            span = tb - ta
            self.fractions = (times - ta) / span if span != 0 else np.linspace(0.0, 1.0, len(times))
        else:
            L = np.stack([pose_prev._local, pose_next._local])
            if pose_prev.clip is not None and pose_prev.clip == pose_next.clip:
                # two times of one clip: the clip's own T R S at both (float32 quaternions are not
                # exactly unit, so the matrices are not decomposed)
                c = col._clip(pose_prev.clip)
                L, t, q, s = PK.locals_at(c, [pose_prev.time, pose_next.time], d.rest_local, trs=True,
                                          compiled=True)
                anim = np.ascontiguousarray(c.anim_to_skel, dtype=np.int64)
            else:
                dec = [decompose(x) for x in L]
                t, q, s = (np.stack([x[i] for x in dec]) for i in range(3))
                anim = np.arange(len(d.joints), dtype=np.int64)
            self._trs = (t, q, s, anim)
            self.clip = None
            self.poses = [pose_prev, pose_next]
            self.fractions = np.array([0.0, 1.0])
        self._locals = L
        self.deviation = self._deviation(L, t, q, s, anim)

    def _deviation(self, L, t, q, s, anim):
        d = self.collider.data
        bd = d.bounds
        I = len(L) - 1
        P = len(bd.part_joint)
        Li, fw, iv, dt, eps = _factor_terms(d, L, t, q, s, anim)
        off, pj, pd, pair_part = _root_paths(d)
        M = len(bd.pj_joint)
        e0, e1, delta, lam, pert = (np.zeros((I, M)) for _ in range(5))
        if M:
            c = np.ascontiguousarray
            B.chain_bounds(c(L[:-1]), c(L[1:]), c(Li[:-1]), c(Li[1:]), fw, iv, dt, eps, off, pj, pd,
                           bd.pj_center, bd.pj_radius, pair_part, np.zeros((P, 3)), e0, e1, delta, lam, pert,
                           compiled=True)
        W0, W1 = self.poses[0].local_to_world, self.poses[-1].local_to_world
        if W0 is W1 and W0 is d.static_local_to_world:  # the usual case: computed once per asset
            w = getattr(bd, "_sweep_world_norm", None)
            if w is None:
                w = bd._sweep_world_norm = _norm2(W0[:3, :3])
        else:
            w = max(_norm2(W0[:3, :3]), _norm2(W1[:3, :3]))
        dev = np.empty((I, P))
        _part_deviation(delta, pert, bd.pj_offsets, bd.pj_wmax, bd.part_wabs, w, dev)
        if not np.array_equal(W0, W1):  # one segment; the travel term of the lerped world matrix
            c0, c1 = self.poses[0].cull, self.poses[-1].cull
            s0 = np.c_[c0[:, :3], np.ones(P)] @ np.linalg.inv(W0).T
            s1 = np.c_[c1[:, :3], np.ones(P)] @ np.linalg.inv(W1).T
            travel = (np.linalg.norm(s0[:, :3] - s1[:, :3], axis=1) + c0[:, 3] / _sigma_min(W0[:3, :3])
                      + c1[:, 3] / _sigma_min(W1[:3, :3]))
            dev = (dev + 0.25 * _norm2(W0[:3, :3] - W1[:3, :3]) * travel[None]) * (1.0 + 1e-9)
        return dev

    @property
    def segments(self) -> int:
        return len(self.poses) - 1

    def pose_at(self, fraction: float, out: Pose | None = None) -> Pose:
        """The body at step ``fraction`` in [0, 1] along this motion (a clip pose at the
        interpolated time, or :meth:`Collider.pose_from_joints` of the joint-space interpolation)."""
        f = float(fraction)
        col = self.collider
        if self.clip is not None:
            ta, tb = self.poses[0].time, self.poses[-1].time
            return col.pose(self.clip, ta + f * (tb - ta), out=out)
        t, q, s, anim = self._trs
        local = col.data.rest_local.copy()
        local[anim] = _interpolate_trs(t[0], q[0], s[0], t[1], q[1], s[1], f)
        return col.pose_from_joints(local, out=out)


def _norm2(m):
    return float(np.linalg.norm(m, 2)) * (1 + 1e-12)


def _sigma_min(m):
    return float(np.linalg.svd(m, compute_uv=False)[-1]) * (1 - 1e-12)


# -- the query --------------------------------------------------------------------------------------


def sweep_sphere(pose_prev: Pose, pose_next: Pose, c0, c1, radius, *, ignore=None, motion: BodyMotion | None = None,
                 reach=None) -> SweptContact | None:
    """First contact of a sphere moving ``c0`` -> ``c1`` (3,) with the body moving ``pose_prev``
    -> ``pose_next`` (module docstring), or None.  Conservative: a contact may be reported up to
    :data:`TOLERANCE` x radius early (or, on a grazing approach, after :data:`MAX_ITER` steps,
    earlier), never missed.

    ignore : optional triangle indices left out (e.g. a carried player's own contacts).
    motion : a :class:`BodyMotion` of the same two poses, to reuse.
    reach : optional (I,) float64 array filled with, per segment, a bound of how far any point of
        the triangles that can come near the sphere moves relative to its centre over the segment
        (0 where none can); segments after the contact's are left at 0.
    """
    c0 = _vec(c0, "c0")
    c1 = _vec(c1, "c1")
    r = float(radius)
    if not (r >= 0 and math.isfinite(r)):
        raise ValueError(f"radius must be finite and >= 0, got {radius!r}")
    m = motion if motion is not None else BodyMotion(pose_prev, pose_next)
    if m.poses[0] is not pose_prev or m.poses[-1] is not pose_next:
        raise ValueError("motion is of other poses")
    skip = np.zeros(len(pose_prev.collider.data.triangles), bool)
    if ignore is not None:
        skip[np.asarray(ignore, dtype=np.int64).ravel()] = True
    out = np.empty(11)
    T = pose_prev.collider.data.triangles
    for i in range(m.segments):
        f, p, ca, cb = _segment(m, i, c0, c1, r, skip, out, 1.0)
        if reach is not None:
            reach[i] = out[10]
        if f >= 0:
            fr = m.fractions
            tau = float(out[0])
            span = fr[i + 1] - fr[i]
            bary = out[1:4].copy()
            xa = m.poses[i]._points[T[f]].astype(np.float64)
            xb = m.poses[i + 1]._points[T[f]].astype(np.float64)
            vel = bary @ (xb - xa) / span if span > 0 else np.zeros(3)
            return SweptContact(time=float(fr[i] + tau * span), triangle=int(f), part=int(p),
                                barycentric=bary, point=out[4:7].copy(), normal=out[7:10].copy(), velocity=vel,
                                centre=ca + tau * (cb - ca), segment=i)
    return None


def segment_reach(motion: BodyMotion, i: int, c0, c1, radius, ignore=None) -> float:
    """A bound of how far any point of the triangles that can come within ``radius`` of the
    sphere's path moves relative to its centre over segment ``i`` of ``motion`` (0 when none
    can): a sub-step of the segment of fraction ``g`` moves them at most ``g`` times it."""
    skip = np.zeros(len(motion.collider.data.triangles), bool)
    if ignore is not None:
        skip[np.asarray(ignore, dtype=np.int64).ravel()] = True
    out = np.empty(11)
    _segment(motion, i, _vec(c0, "c0"), _vec(c1, "c1"), float(radius), skip, out, 0.0)
    return float(out[10])


def _segment(m, i, c0, c1, r, skip, out, limit):
    """Segment ``i`` of the query: cull the parts, run the kernel on the rest (contacts before
    ``limit`` in the segment's tau).  Returns (face, part, ca, cb); ``out[10]`` the reach."""
    d = m.collider.data
    fr = m.fractions
    out[10] = 0.0
    pa, pb = m.poses[i], m.poses[i + 1]
    ca = c0 + fr[i] * (c1 - c0)
    cb = c0 + fr[i + 1] * (c1 - c0)
    A, Bc = pa.cull, pb.cull
    dev = m.deviation[i]
    # the sphere's path relative to each part's lerped centre: a segment from u0 to u1
    u0 = ca[None] - A[:, :3]
    u1 = cb[None] - Bc[:, :3]
    du = u1 - u0
    dd = np.einsum("pk,pk->p", du, du)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.clip(np.where(dd > 0, -np.einsum("pk,pk->p", u0, du) / dd, 0.0), 0.0, 1.0)
    gap = np.linalg.norm(u0 + s[:, None] * du, axis=1)
    mag = np.maximum(np.abs(A[:, :3]).sum(1), np.abs(Bc[:, :3]).sum(1)) + np.maximum(A[:, 3], Bc[:, 3])
    pad = dev * (1 + 1e-5) + 2e-6 * mag + 1e-9
    near = np.flatnonzero(gap <= np.maximum(A[:, 3], Bc[:, 3]) + pad + r)
    if not len(near):
        return -1, -1, ca, cb
    fo = d.face_offsets
    faces = d.faces[fo[near[0]]:fo[near[0] + 1]] if len(near) == 1 else \
        np.concatenate([d.faces[fo[p]:fo[p + 1]] for p in near])
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    pa._ready_faces(faces)
    pb._ready_faces(faces)
    f, p = _sweep_segment(pa._points, pb._points, d.triangles, d.faces, d.chunk_offsets, d.part_chunks,
                          d.chunk_vert_offsets, d.chunk_verts, near.astype(np.int64), pad, skip, ca, cb, r,
                          TOLERANCE * r, MAX_ITER, limit, out)
    return f, p, ca, cb


def _vec(a, name):
    v = np.ascontiguousarray(np.asarray(a, dtype=np.float64).reshape(-1))
    if v.shape != (3,) or not np.isfinite(v).all():
        raise ValueError(f"{name} must be 3 finite numbers, got {a!r}")
    return v
