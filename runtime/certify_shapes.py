"""The continuous certificate under blend shapes: every vertex of every part inside its sphere at
every time between two samples of a clip, as UsdSkel interpolates the joints and the blend-shape
weights, applies the shapes and then skins (linear blend or dual quaternion).

The bound (written before the code)
-----------------------------------
Notation.  A vertex has rest point ``p`` (mesh space).  Shape ``s`` has knots ``k_0 < ... <
k_m`` (the rest at 0, the in-betweens, the primary at 1) with offsets ``o_0 = 0, ..., o_m`` at
the vertex; UsdSkel moves the vertex by ``D_s(w)``, the piecewise-linear interpolation of the
knots, extrapolated by the end segments (:class:`runtime.kernels.skin.Shapes`).  Over one sample
interval time is ``u in [0, 1]`` and UsdSkel interpolates the weights linearly: ``w_s(u) = (1 -
u) w_s(0) + u w_s(1)``.  The displaced rest point is ``p(u) = p + d(u)``, ``d(u) = sum_s
D_s(w_s(u))``, and the skinned point is ``x(u) = Skin_u(p(u))``.

1. Size: the vertex moves by ``|d(u)| <= sum_s |D_s(w_s(u))|``, which for a shape without
   in-betweens is ``|w_s(u)| |o|`` (with in-betweens, the interpolated knot offsets).  This
   crude bound is not what is certified: items 2-4 keep the shapes exact.
2. Path of the displacement: ``u -> w_s(u)`` is affine, so ``u -> D_s(w_s(u))`` is piecewise
   linear in ``u`` with breakpoints where ``w_s(u)`` crosses a knot ``k`` strictly between
   ``w_s(0)`` and ``w_s(1)``: ``u = (k - w_s(0)) / (w_s(1) - w_s(0))``.  The sum ``d(u)`` is
   piecewise linear with breakpoints ``0 = u_0 < u_1 < ... < u_q = 1`` (the union over shapes),
   so on each piece it is the chord of its ends and ``d(u)`` lies in the convex hull of
   ``{d(u_0), ..., d(u_q)}`` for every ``u`` in ``[0, 1]``.  With no in-between and weights of one
   sign (the usual case) ``q = 1``: the hull is the segment between the displacements at the two
   samples.
3. Skinning is affine in the rest point at a fixed time: linear blend ``x = sum_k w_k M_k(u)
   (G p, 1)``; UsdSkel's dual-quaternion skinning ``x = R(b^) s + T(b, c)`` with ``s = sum_j w_j
   S_j G p`` (or ``G p``), where the blended dual quaternion ``(b, c)``, the pivot and the
   hemisphere flips depend on the joints and the weights, never on the point.  So at fixed ``u``
   the map ``q -> |Skin_u(q) - C(u)|`` (``C(u)`` the part's sphere centre, and likewise in the part
   joint's space) is a norm of an affine map: convex.  A convex function on the hull takes its
   maximum at one of the hull's generators, so
   ``|x(u) - C(u)| <= max_k |Skin_u(p + d(u_k)) - C(u)|`` for every ``u`` of the interval.
4. Each ``p + d(u_k)`` is a fixed rest point (a "virtual vertex"): the certificates for fixed rest
   points (:func:`runtime.certify.continuous` for linear blend, :func:`runtime.certify_dq.continuous`
   for dual quaternion, with their own bounds and subdivision) applied to the rig whose points
   are the virtual vertices of every vertex, with the vertex's influences, bound the real vertex
   at every ``u``.  Nothing is loosened beyond those certificates for the displacement: the
   virtual vertices at ``u_0`` and ``u_q`` are the real displaced points at the two samples; the
   only conservatism is that each virtual vertex is followed over the whole interval (a vertex
   that only exists at ``u = 1`` is also checked at ``u = 0``).

Verdicts: an interval certified for the virtual vertices is certified (2-4 above).  Where the
virtual certificate finds a time at which a virtual vertex is outside, the real vertex is skinned
exactly at that time and at :data:`runtime.certify.FAIL_SAMPLES` sub-steps (weights and joints as
UsdSkel interpolates them): a real excess beyond the tolerance is a definite failure (status 3)
with its time; otherwise the interval is undecided (status 4), which the proof reports as a
failure: never a certificate the argument does not give.  Intervals whose weights are 0 at both
ends have ``d = 0`` throughout and go to the fixed-point certificate as they are.
"""

from __future__ import annotations

import numpy as np

from . import certify as C
from . import certify_dq as CDQ
from .kernels import bounds as B
from .kernels import pose as PK
from .kernels import skin as SK


def breakpoints(shapes: SK.Shapes, w0, w1) -> np.ndarray:
    """Sorted ``u`` in ``[0, 1]`` (0 and 1 included) where some shape's weight, linear from ``w0``
    (S,) to ``w1`` (S,), crosses one of its knots strictly inside (item 2)."""
    u = [0.0, 1.0]
    for s in range(len(shapes)):
        a, b = float(w0[s]), float(w1[s])
        if a == b:
            continue
        k = shapes.knots[s]
        inside = k[(k > min(a, b)) & (k < max(a, b))]
        u.extend(((inside - a) / (b - a)).tolist())
    return np.unique(np.clip(np.asarray(u), 0.0, 1.0))


def breakpoint_weights(shapes: SK.Shapes, clip, a: float, b: float, wa, wb) -> np.ndarray:
    """(q + 1, S) the weights at the breakpoints of ``[a, b]`` (item 2): the ends (``wa``, ``wb``
    exactly), every ``blendShapeWeights`` sample time strictly inside (a foreign asset may sample
    its weights at times its joints are not: UsdSkel's weights are linear only between their own
    samples), and every knot crossing of the linear pieces between those."""
    tw = np.asarray(getattr(clip, "tw", np.zeros(0)), dtype=np.float64)
    inner = tw[(tw > a) & (tw < b)]
    ts = np.r_[a, inner, b]
    W = np.concatenate([np.asarray(wa, float)[None], clip.shape_weights(inner, len(shapes)),
                        np.asarray(wb, float)[None]]) if len(inner) else np.stack([np.asarray(wa, float),
                                                                                    np.asarray(wb, float)])
    rows = [W[0]]
    for k in range(len(ts) - 1):
        u = breakpoints(shapes, W[k], W[k + 1])[1:-1]
        rows += [W[k] + x * (W[k + 1] - W[k]) for x in u]
        rows.append(W[k + 1])
    return np.array(rows)


def virtual_rig(rig: C.Rig, points) -> C.Rig:
    """The rig whose rest points are ``points`` (m, n, 3) (m copies of the vertex set: the virtual
    vertices of item 4), each copy with the vertex's influences and in the vertex's parts."""
    m, n = points.shape[0], points.shape[1]
    voff = np.asarray(rig.vert_offsets, dtype=np.int64)
    counts = np.diff(voff)
    verts = np.concatenate([np.concatenate([rig.verts[voff[p]:voff[p + 1]] + c * n for c in range(m)])
                            if counts[p] else np.zeros(0, np.int64) for p in range(len(counts))]) \
        if len(counts) else np.zeros(0, np.int64)
    return C.Rig(points.reshape(m * n, 3), np.tile(rig.joint_indices, (m, 1)), np.tile(rig.joint_weights, (m, 1)),
                 rig.geom_bind, rig.bind, rig.rest_local, rig.parents, rig.part_joint, rig.part_centers,
                 rig.part_radii, np.r_[0, np.cumsum(counts * m)], verts, world=rig.world,
                 skinning_method=rig.skinning_method)


def skel_at(rig: C.Rig, clip, times) -> np.ndarray:
    """(T, J, 4, 4) skeleton-space joint transforms of ``clip`` at ``times``, as UsdSkel interpolates."""
    return PK.compose(PK.locals_at(clip, np.atleast_1d(times), rig.rest_local), rig.parents, rig.topo)


def real_excess(rig: C.Rig, clip, times, p: int):
    """``(excess (T,), vertex (T,), radius (T,))`` of part ``p``'s real farthest vertex beyond its
    sphere at ``times``: weights and joints interpolated as UsdSkel does, shapes applied, skinned
    exactly (stage space)."""
    times = np.atleast_1d(np.asarray(times, dtype=np.float64))
    skel = skel_at(rig, clip, times)
    sph, _, _ = B.pose_bounds(rig.world @ skel, rig.bounds)
    pts = SK.shape_points(rig.points, rig.shapes, clip.shape_weights(times, len(rig.shapes)))
    todo = np.zeros(sph.shape[:2], bool)
    todo[:, p] = True
    d, v = SK.part_farthest(pts, rig.joint_indices, rig.joint_weights, rig.skin_mats(skel), rig.vert_offsets,
                            rig.verts, sph[..., :3], todo=todo)
    return d[:, p] - sph[:, p, 3], v[:, p], sph[:, p, 3]


def certificate(rig: C.Rig, clip, times, frame_bound, frame_ok, tol_abs: float, tol_rel: float, rho=None,
                growth: bool = False, max_depth: int = C.MAX_DEPTH, frame_bound_space: str = "stage") -> C.Continuous:
    """The continuous certificate of a rig with blend shapes (the module docstring's argument);
    without shapes, or on intervals whose weights are 0 at both ends, the fixed-point certificate
    of the rig's skinning method (:func:`runtime.certify_dq.certificate`).  Arguments as there;
    ``clip.shape_weights`` gives the weights (:class:`runtime.schema.Clip`)."""
    kw = dict(rho=rho, growth=growth, max_depth=max_depth, frame_bound_space=frame_bound_space)
    base = CDQ.certificate(rig, clip, times, frame_bound, frame_ok, tol_abs, tol_rel, **kw)
    S = 0 if rig.shapes is None else len(rig.shapes)
    times = np.asarray(times, dtype=np.float64)
    if S == 0 or len(times) < 2:
        return base
    W = clip.shape_weights(times, S)
    live = (W[:-1] != 0).any(1) | (W[1:] != 0).any(1)
    tw, vw = np.asarray(clip.tw, dtype=np.float64), np.asarray(clip.vw, dtype=np.float64)
    if len(tw):  # a weight sample strictly inside an interval whose ends are at 0
        k = np.searchsorted(times, tw[(vw != 0).any(1)], side="right") - 1
        inside = (k >= 0) & (k < len(times) - 1)
        live[k[inside]] |= ~np.isin(tw[(vw != 0).any(1)][inside], times)
    shaped = np.flatnonzero(live)
    if not len(shaped):
        return base
    ok = np.asarray(frame_ok, dtype=bool)
    rho_all = None if rho is None else np.broadcast_to(np.asarray(rho, dtype=np.float64),
                                                       (len(times) - 1, rig.P))
    base.failures = [f for f in base.failures if f["interval"] not in set(shaped.tolist())]
    for i in shaped:
        t0, t1 = float(times[i]), float(times[i + 1])
        status, bound, rho_i, ratio, found = _interval(rig, clip, t0, t1, W[i], W[i + 1], ok[i:i + 2], tol_abs,
                                                       tol_rel, kw, None if rho_all is None else rho_all[i])
        base.status[i], base.bound[i], base.rho[i] = status, bound, rho_i
        if base.ratio is not None:
            base.ratio[i] = ratio
        for p, f in found.items():
            if status[p] == 5:
                base.failures.append(dict(f, interval=int(i), t0=t0, t1=t1))
                continue
            sub = t0 + (t1 - t0) * np.arange(1, C.FAIL_SAMPLES) / C.FAIL_SAMPLES
            tt = np.unique(np.r_[sub, float(f["time"])])
            ex, vv, rr = real_excess(rig, clip, tt, p)
            k = int(np.argmax(ex))
            real = ex[k] > tol_abs + tol_rel * rr[k]
            base.status[i, p] = 3 if real else 4
            base.failures.append(dict(f, interval=int(i), t0=t0, t1=t1, time=float(tt[k]), vertex=int(vv[k]),
                                      excess=float(ex[k]), radius=float(rr[k]), definite=bool(real),
                                      reason=None if real else (
                                          "blend shapes: a virtual vertex (the displaced point at a breakpoint of "
                                          "the weights, followed over a sub-interval) leaves the sphere at "
                                          f"{SHAPE_DEPTH} halvings; the real vertex did not at the sampled "
                                          "sub-steps: not certified")))
    return base


#: Halvings of a sample interval under changing shape weights before the virtual vertices'
#: certificate gives up on a part (each halving shrinks the hull of item 2 toward the real path).
SHAPE_DEPTH = 4


def _interval(rig, clip, t0, t1, w0, w1, ok_ends, tol_abs, tol_rel, kw, rho):
    """One sample interval under shapes: the virtual-vertex certificate on ``[t0, t1]``, halved
    (up to :data:`SHAPE_DEPTH`) for the parts it does not certify.  A sub-interval of a sample
    interval is itself an interval of UsdSkel's interpolation (slerp, lerp and the weights' lerp
    restricted to it are the same interpolation between its ends), so the fixed-point
    certificates apply to it as to a sample interval.  Returns per part the worst status of the
    leaves it needed, the largest bound, the radius held to, the smallest ratio and the first
    failure (a dict) of the parts that were not certified."""
    P = rig.P
    status = np.zeros(P, np.int8)
    bound = np.zeros(P)
    rho_out = np.full(P, np.inf)
    ratio = np.ones(P)
    found = {}
    todo = [(t0, t1, np.asarray(w0, float), np.asarray(w1, float), 0, np.ones(P, bool))]
    while todo:
        a, b, wa, wb, depth, parts = todo.pop()
        Wk = breakpoint_weights(rig.shapes, clip, a, b, wa, wb)
        vr = virtual_rig(rig, SK.shape_points(rig.points, rig.shapes, Wk))
        t2 = np.array([a, b])
        skel = skel_at(rig, clip, t2)
        s = C.sampled(vr, skel, tol_abs, tol_rel)  # the virtual vertices at both ends (stage space)
        fb = s.bound if kw["frame_bound_space"] == "stage" else _joint_space(vr, skel, s.bound)
        oke = np.array([ok_ends[0] if a == t0 else np.ones(P, bool), ok_ends[1] if b == t1 else np.ones(P, bool)])
        c = CDQ.certificate(vr, clip, t2, fb, oke, tol_abs, tol_rel, **dict(kw, rho=rho))
        good = (c.status[0] <= 2) & parts
        bound[good] = np.maximum(bound[good], c.bound[0, good])
        status[good] = np.maximum(status[good], c.status[0, good])
        rho_out[parts] = np.minimum(rho_out[parts], c.rho[0, parts])
        if c.ratio is not None:
            ratio[parts] = np.minimum(ratio[parts], c.ratio[0, parts])
        left = parts & ~good
        if not left.any():
            continue
        if depth < SHAPE_DEPTH and not (c.status[0, left] == 5).all():
            m = 0.5 * (a + b)
            f = (m - t0) / (t1 - t0)
            wm = np.asarray(w0, float) + f * (np.asarray(w1, float) - np.asarray(w0, float))
            todo.append((a, m, wa, wm, depth + 1, left))
            todo.append((m, b, wm, wb, depth + 1, left))
            continue
        for p in np.flatnonzero(left):
            status[p] = max(int(status[p]), int(c.status[0, p]) if c.status[0, p] >= 3 else 4)
            bound[p] = max(bound[p], c.bound[0, p])
            if p not in found:
                hit = [x for x in c.failures if int(x["part"]) == p]
                found[int(p)] = hit[0] if hit else {"part": int(p), "time": 0.5 * (a + b), "vertex": -1,
                                                     "excess": float("nan"), "definite": False,
                                                     "bound": float(c.bound[0, p])}
    rho_out[~np.isfinite(rho_out)] = 0.0
    return status, bound, rho_out, ratio, found


def _joint_space(vr: C.Rig, skel, stage_bound):
    """Stage-space frame bounds made part-joint-space ones (over the joint's smallest singular
    value at each end: ``|y - c| <= |x - C| / sigma_min``)."""
    lin = (vr.world @ skel)[:, vr.part_joint, :3, :3]
    smin = np.linalg.svd(lin, compute_uv=False)[..., -1]
    return stage_bound / smin
