"""The certificate that every part sphere holds its skinned vertices: at sampled poses (tiers K,
D, exact) and for every time between the samples of a clip as UsdSkel interpolates it.

Used by the frame proof (:mod:`validators.frameproof`) and by the import's spheres stage
(:mod:`pipeline.stages.spheres`, which grows each sphere just enough for the certificate); it
sits in the runtime because both need it and the runtime is the lowest layer.  Numba kernels are
in :mod:`runtime.kernels.bounds`, :mod:`runtime.kernels.interval`, :mod:`runtime.kernels.skin`,
:mod:`runtime.kernels.farthest` (the exact tier by chunks) and :mod:`runtime.kernels.subdivide`
(levels B and C batched); the bounds and their soundness arguments are written in those modules'
docstrings and in :func:`continuous` below.

Matrices are column-vector float64 (``p' = M @ p``).  ``world`` is the skeleton prim's
local-to-world transform (stage space); a clip is a :class:`runtime.schema.Clip`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import kernels as B  # the bounds: at a pose (kernels.bounds) and between samples (kernels.interval)
from .kernels import pose as PK
from .kernels import skin as SK
from .kernels import farthest as FA
from .kernels import subdivide as SD
from .schema import parents_first

#: Subdivision depth of one sample interval before the certificate gives up (2^8 sub-steps).
MAX_DEPTH = 8
#: A sample interval that really fails is sampled at this many sub-steps to report its worst excess.
FAIL_SAMPLES = 16
#: Levels B and C by the compiled, batched kernels (:func:`_refine_batched`, one kernel call per
#: subdivision level over every open node); False: the reference loop (:func:`_refine`, one
#: numpy call per node, kept as the benchmark's baseline and the tests' reference).
BATCHED = True
#: Until this process has refined this many open (interval, part) pairs the reference loop runs
#: instead (the same decisions): a demo-sized asset's few pairs take milliseconds so, and a new
#: user's first import or validation of it does not compile the batched kernels (~2 s once per
#: machine); a real character's clips pass it within the first clips.
BATCHED_MIN_PAIRS = 128
_refined_pairs = 0
#: The sampled proof's exact tier by the chunk search (:func:`runtime.kernels.farthest.farthest`:
#: chunk bounds first, then exact skinning of the chunks that can hold the farthest vertex,
#: threaded) instead of every vertex of the part (:func:`runtime.kernels.skin.part_farthest`).
#: The same distances and vertices either way.  Off: on the corpus characters' tight spheres most
#: chunks lie near the sphere (8-vertex chunks still skin 59 % of the vertex-poses on the Godot
#: mannequin, 16-vertex ones 76 %) and the search skinned ~20 % slower per vertex, so it measured
#: 0.7-0.9x the whole-part kernel (issue 22 item 3, open).
CHUNKED = False
#: :func:`_refine_batched` computes the joint transforms of at most about this many bytes of
#: times at once (the nodes of a level are processed in chunks).
BATCH_BYTES = 16 << 20
#: Rotation speed and acceleration margins over the interval's angle (GfSlerp's linear branch
#: and float32 quaternions; see :func:`factor_bounds`).
OMEGA_MARGIN = 1.001
ALPHA_MARGIN = 1.01


def _inv_or_nan(m):
    """``inv(m)`` of (F, 4, 4) poses, NaN for a singular one: a joint squashed to nothing has no
    space to measure a part in, so nothing there is ever certified (the validator refuses such
    a pose first, COL518; this is the guard for what gets past it)."""
    try:
        return np.linalg.inv(m)
    except np.linalg.LinAlgError:
        out = np.full_like(m, np.nan, dtype=np.float64)
        for k in range(len(m)):
            try:
                out[k] = np.linalg.inv(m[k])
            except np.linalg.LinAlgError:
                pass
        return out


@dataclass
class Rig:
    """What the certificate reads of an asset (arrays; see :class:`runtime.asset.ColliderData`).

    points (V, 3) float32 mesh space; joint_indices / joint_weights (V, k); geom_bind (4, 4);
    bind, rest_local (J, 4, 4); parents (J,) int (-1 for roots, parents first); part_joint (P,);
    part_centers (P, 3) / part_radii (P,) in joint space; vert_offsets (P + 1,) / verts: the CSR
    of each part's vertices; world (4, 4) skeleton -> stage.
    """

    points: np.ndarray
    joint_indices: np.ndarray
    joint_weights: np.ndarray
    geom_bind: np.ndarray
    bind: np.ndarray
    rest_local: np.ndarray
    parents: np.ndarray
    part_joint: np.ndarray
    part_centers: np.ndarray
    part_radii: np.ndarray
    vert_offsets: np.ndarray
    verts: np.ndarray
    world: np.ndarray = field(default_factory=lambda: np.eye(4))
    bounds: B.BoundData | None = None
    #: "classicLinear" or "dualQuaternion" (the mesh's ``primvars:skel:skinningMethod``): a
    #: dual-quaternion rig is certified by :mod:`runtime.certify_dq` (exact skinning at samples)
    skinning_method: str = SK.CLASSIC_LINEAR
    #: the mesh's blend shapes (:class:`runtime.kernels.skin.Shapes`) or None: :func:`sampled`
    #: skins the displaced points at poses given shape weights; between samples
    #: :mod:`runtime.certify_shapes` certifies them
    shapes: object = None

    def __post_init__(self):
        J = len(self.bind)
        self.points, self.joint_indices, self.joint_weights = SK.check_skin_inputs(
            self.points, self.joint_indices, self.joint_weights, J)
        self.bind = np.ascontiguousarray(self.bind, dtype=np.float64)
        self.inv_bind = np.linalg.inv(self.bind)
        self.geom_bind = np.ascontiguousarray(self.geom_bind, dtype=np.float64)
        self.rest_local = np.ascontiguousarray(self.rest_local, dtype=np.float64)
        self.parents = np.asarray(self.parents, dtype=np.int64)
        self.topo = parents_first(self.parents)
        self.part_joint = np.asarray(self.part_joint, dtype=np.int64)
        self.part_centers = np.ascontiguousarray(self.part_centers, dtype=np.float64).reshape(-1, 3)
        self.part_radii = np.ascontiguousarray(self.part_radii, dtype=np.float64)
        self.vert_offsets = np.ascontiguousarray(self.vert_offsets, dtype=np.int64)
        self.verts = np.ascontiguousarray(self.verts, dtype=np.int32)
        self.world = np.ascontiguousarray(self.world, dtype=np.float64)
        if self.bounds is None:
            self.bounds = B.bound_data(self.points, self.joint_indices, self.joint_weights, self.geom_bind,
                                       self.bind, self.part_joint, self.part_centers, self.part_radii,
                                       self.vert_offsets, self.verts)
        self._paths = None
        self._chunks = None
        self._ibg = None

    @property
    def chunks(self):
        """The parts' vertex chunks of the exact tier (:func:`runtime.kernels.farthest.chunk_data`)."""
        if self._chunks is None:
            self._chunks = FA.chunk_data(self.points, self.joint_indices, self.joint_weights, self.vert_offsets,
                                         self.verts)
        return self._chunks

    @property
    def P(self) -> int:
        return len(self.part_joint)

    def skin_mats(self, skel) -> np.ndarray:
        """(F, J, 12) folded stage-space skinning transforms ``world @ skel @ inv_bind @ geom_bind``
        (a dual-quaternion rig: the (F, J, 1, DQ_WIDTH) layout of :func:`runtime.kernels.skin.fold_dq`)."""
        if self.skinning_method != SK.CLASSIC_LINEAR:
            return SK.fold_method(self.skinning_method, skel @ self.inv_bind, self.geom_bind, self.world)
        return SK.fold(self.world @ skel @ self.inv_bind @ self.geom_bind)

    def joint_space_mats(self, skel, joint) -> np.ndarray:
        """(F, J, 12) folded skinning transforms into joint ``joint``'s space at poses ``skel``."""
        return SK.fold(_inv_or_nan(skel[:, joint])[:, None] @ skel @ self.inv_bind @ self.geom_bind)

    def paths(self):
        """Per (part, joint) pair of the bounds: the chain of local transforms from the joint's
        space to the part joint's space, innermost first (CSR ``off``, ``joint``, ``dir``: +1 a
        forward local transform, -1 an inverse one)."""
        if self._paths is None:
            bd = self.bounds
            pair_part = np.repeat(np.arange(self.P), np.diff(bd.pj_offsets))
            off, pj, pd = [0], [], []
            for k, b in enumerate(bd.pj_joint):
                J = int(self.part_joint[pair_part[k]])
                up_b, up_J = _ancestors(self.parents, int(b)), _ancestors(self.parents, J)
                common = set(up_b) & set(up_J)
                fwd = [x for x in up_b if x not in common]
                inv = [x for x in up_J if x not in common][::-1]
                pj += fwd + inv
                pd += [1] * len(fwd) + [-1] * len(inv)
                off.append(len(pj))
            self._paths = (np.array(off, dtype=np.int64), np.array(pj, dtype=np.int64),
                           np.array(pd, dtype=np.int64), pair_part.astype(np.int64))
        return self._paths


def _ancestors(parents, j):
    out = []
    while j >= 0:
        out.append(j)
        j = int(parents[j])
    return out


# ------------------------------------------------------------------------- sampled poses
@dataclass
class Sampled:
    """The certificate at F sampled poses of P parts.

    tier (F, P) int8: 0 test K proved it, 1 test D, 2 the part was skinned exactly; bound (F, P):
    an upper bound of the stage distance of the part's farthest vertex from its centre (exact for
    tier 2); dist / vertex (F, P): the exact farthest distance and vertex (NaN / -1 where not
    skinned); spheres (F, P, 4) the moved spheres (stage space)."""

    tier: np.ndarray
    bound: np.ndarray
    dist: np.ndarray
    vertex: np.ndarray
    spheres: np.ndarray


def sampled(rig: Rig, skel, tol_abs: float, tol_rel: float, exact=None, shape_weights=None) -> Sampled:
    """Certify the part spheres at poses ``skel`` (F, J, 4, 4) (skeleton space), with the
    rig's blend shapes at ``shape_weights`` (F, S) (none: every shape at 0).

    A (pose, part) passes a bound tier when the bound is at most ``R (1 + tol_rel) + tol_abs``
    (the proof's verdict threshold); otherwise the part's vertices are skinned exactly
    (:func:`runtime.kernels.skin.part_farthest`), which decides.  Since the tiers only pass what
    the exact test would pass, the verdict is the exact one.  ``exact`` (F, P) bool forces the
    exact tier for some pairs."""
    skel = np.asarray(skel, dtype=np.float64)
    world = rig.world @ skel
    sph, kb, db = B.pose_bounds(world, rig.bounds)
    R = sph[..., 3]
    limit = R * (1.0 + tol_rel) + tol_abs
    tier = np.full(R.shape, 2, dtype=np.int8)
    if rig.skinning_method == SK.CLASSIC_LINEAR:  # tests K and D bound linear blends only
        tier[kb <= limit] = 0
        tier[(tier == 2) & (db <= limit)] = 1
    else:  # dual quaternion: every part skinned exactly (runtime.certify_dq)
        kb = db = np.full(R.shape, np.inf)
    points = rig.points
    if shape_weights is not None and rig.shapes is not None and len(rig.shapes):
        W = np.asarray(shape_weights, dtype=np.float64).reshape(len(skel), len(rig.shapes))
        shaped = (W != 0).any(1)
        if shaped.any():  # tests K and D bound the rest points: a pose under shapes is skinned exactly,
            tier[shaped] = 2  # its displaced points (the one kernel's pre-pass), which is sampled exactly
            kb, db = kb.copy(), db.copy()
            kb[shaped] = np.inf
            db[shaped] = np.inf
            points = SK.shape_points(rig.points, rig.shapes, W)
    todo = tier == 2
    if exact is not None:
        todo = todo | exact
    if points is not rig.points:
        d, v = SK.part_farthest(points, rig.joint_indices, rig.joint_weights, rig.skin_mats(skel),
                                rig.vert_offsets, rig.verts, sph[..., :3], todo=todo)
    elif CHUNKED:
        d, v, _ = FA.farthest(rig.points, rig.joint_indices, rig.joint_weights, rig.skin_mats(skel), rig.vert_offsets,
                              rig.verts, rig.part_joint, sph[..., :3], todo, rig.chunks)
    else:
        d, v = SK.part_farthest(rig.points, rig.joint_indices, rig.joint_weights, rig.skin_mats(skel),
                                rig.vert_offsets, rig.verts, sph[..., :3], todo=todo)
    bound = np.where(todo, d, np.minimum(kb, db))
    return Sampled(tier, bound, d, v, sph)


# -------------------------------------------------------------------- continuous time
def factor_bounds(clip, times, rest_local):
    """Per sample interval and joint: the local transforms at both ends and the bounds the chain
    recursion (:func:`runtime.kernels.interval.chain_bounds`) needs.

    For a joint the clip animates, over an interval with ends ``(t0, q0, s0)``, ``(t1, q1, s1)``
    (time normalised to [0, 1]): the translation moves by ``dt = |t1 - t0|`` at constant speed;
    the rotation turns by ``theta = 2 angle(q0, +-q1)`` (GfSlerp's shortest arc) about a fixed
    axis, so ``|R'| <= omega = theta`` and ``|R''| <= theta^2`` for a true slerp.  GfSlerp's
    linear branch (``1 - |q0.q1| <= 1e-5``, theta < 0.009) normalises a lerp instead: there the
    angular speed is at most ``theta / cos^2(theta / 4)`` and the angular acceleration at most
    ``0.003 theta^2`` more than ``omega^2``; :data:`OMEGA_MARGIN` and :data:`ALPHA_MARGIN` cover
    both, and float32 quaternions that are not exactly unit.  Scales lerp: ``s_max``, ``s_min``
    the extreme |scale| components at the ends (a sign change makes the inverse unbounded),
    ``ds`` the largest change.  Forward factor ``F = R S``: ``n0 = s_max``,
    ``n1 = omega s_max + ds``, ``n2 = alpha s_max + 2 omega ds``.  Inverse ``F^-1 = S^-1 R^T``:
    ``n0 = 1 / s_min``, ``n1 = ds / s_min^2 + omega / s_min``,
    ``n2 = 2 ds^2 / s_min^3 + 2 omega ds / s_min^2 + alpha / s_min`` (product rule; ``(1/s)' =
    -s'/s^2``, ``(1/s)'' = 2 s'^2 / s^3``).  A joint the clip does not animate is a constant
    factor: ``n0`` its linear part's norm (or its inverse's), ``n1 = n2 = dt = 0``.

    UsdSkel lerps ``half3`` scales in half precision (three roundings, each within 2^-11 of a
    value at most ``s_max``), so between samples the true scale is within ``e = 3 * 2^-11 s_max``
    of the smooth lerp when the scale changes over the interval: ``eps`` (I, J, 2) bounds the
    resulting error of the linear part, ``e`` forward and ``e / (s_min (s_min - e))`` inverse.

    Returns a dict of (I, J, ...) float64 arrays: L0, L1, Li0, Li1, fw, iv, dt, eps (and iso,
    locals).  Computed by the compiled :func:`runtime.kernels.interval.factor_terms` (one pass over
    the (interval, joint) pairs; it runs on every clip the proof checks)."""
    times = np.asarray(times, dtype=np.float64)
    L, t, q, s = PK.locals_at(clip, times, rest_local, trs=True)
    Li, fw, iv, dt, eps, iso = B.factor_terms(L, t, q, s, clip.anim_to_skel, rest_local, OMEGA_MARGIN, ALPHA_MARGIN)
    return dict(L0=L[:-1], L1=L[1:], Li0=Li[:-1], Li1=Li[1:], fw=fw, iv=iv, dt=dt, eps=eps, iso=iso, locals=L)


def _norm2(lin):
    """Spectral norms of (..., 3, 3) (exact, by SVD; outside the kernels)."""
    return np.linalg.svd(lin, compute_uv=False)[..., 0] * (1 + 1e-12)


def _sigma_min(lin):
    return np.linalg.svd(lin, compute_uv=False)[..., -1] * (1 - 1e-12)


@dataclass
class Continuous:
    """The continuous certificate of one clip (I = frames - 1 intervals, P parts).

    status (I, P) int8: 0 the chord bound (level A) certified the interval, 1 the per-vertex chord
    bound (B), 2 subdivision (C), 3 it fails (a time in it has a vertex outside the sphere beyond
    the tolerance), 4 undecided at :data:`MAX_DEPTH` (reported as a failure), 5 not checked (a
    sample at one of its ends already fails the sampled proof); bound (I, P): a J-space upper bound
    of the part's farthest vertex over the interval (for the spheres stage); rho (I, P): the
    J-space radius the bound was held to; failures: list of dicts (interval, part, t0, t1, time,
    vertex, excess, definite); ratio (I, P): the scale ratio ``s_lo / s_hi`` of each part joint's
    transform over the interval (1 where it is a similarity throughout): a J-space bound ``U``
    certifies a radius ``r`` when ``U <= r * ratio``."""

    status: np.ndarray
    bound: np.ndarray
    rho: np.ndarray
    failures: list = field(default_factory=list)
    ratio: np.ndarray | None = None
    subdivided: int = 0


def continuous(rig: Rig, clip, times, frame_bound, frame_ok, tol_abs: float, tol_rel: float, rho=None,
               growth: bool = False, max_depth: int = MAX_DEPTH, frame_bound_space: str = "stage") -> Continuous:
    """Certify every time in every interval between consecutive samples ``times`` of ``clip``.

    Soundness (every bound is an upper bound of ``|y_v(tau) - c_P|`` over the interval, ``y_v``
    the vertex in its part joint J's space, where the part's sphere is the fixed ball ``(c_P,
    r_P)``; see :mod:`runtime.kernels.bounds` for the notation):

    * J space: ``y_v(tau) = sum_b w_b A_b(tau) u_b(v)`` with ``A_b = G_J^-1 G_b`` (the skeleton's
      root motion and the stage transform cancel).  Containment in stage space follows from
      ``|y_v - c_P| <= rho``: ``|x - C| <= ||L(N_J)|| |y - c|`` and ``R = r mu(N_J) >= r
      sigma_min(N_J)``, so ``rho = r (1 + tol_rel) s_lo / s_hi + tol_abs / s_hi`` with ``s_hi, s_lo``
      bounds of the largest / smallest singular value of N_J's linear part over the interval
      (products along J's root path of the factors' ``n0`` and ``1 / n0`` of the inverse, times
      the world transform's).  When every factor on the path is a rotation times a uniform scale
      at all times (a uniform scale stays uniform under lerp and half rounding) and so is the
      world transform, N_J is a similarity at each time and the ratio ``s_lo / s_hi`` is exactly 1.
      Non-uniform scales on the path make the certificate conservative (it may then report an
      interval as undecided).
    * Chord deviation of a ball's copy: ``delta_b`` of :func:`runtime.kernels.interval.chain_bounds`.
    * Level A1 (continuous test K): ``|y_v(tau) - c| <= a_P max_b (max(e0_b, e1_b) + delta_b +
      lam_b r_b) + eps_P |c_P|`` (the ball's centre is within ``delta_b`` of its chord, whose points
      are within the larger end distance; the ball's points within ``lam_b r_b`` of it).
    * Level A2 (chords): LBS is linear in the ``A_b``, so ``y_v(tau)`` strays from the chord
      between ``y_v(0)`` and ``y_v(1)`` by at most ``sum_b |w_b(v)| delta_b`` (the part joint's own
      term is 0: ``A_J`` is constant); the chord lies in the ball of radius ``max(D0, D1)`` (the
      sampled proof's bounds of the farthest vertex at both ends, in J space), so the bound is
      ``max(D0, D1) + min(a_P max_b delta_b, sum_b wmax_b delta_b)``.
    * Level B: the same per vertex, with both ends skinned exactly
      (:func:`runtime.kernels.subdivide.chord_nodes`, batched over every open node of a level;
      its numpy reference :func:`runtime.kernels.interval.chord_tasks`).
    * Level C: halve the interval (UsdSkel's interpolation evaluated at the midpoint by the
      runtime's port, :mod:`runtime.kernels.pose`); on a sub-interval of fraction f the
      recursion's velocities scale by f and accelerations by f^2 (the magnitudes bounded on the
      whole interval stay valid), so ``delta`` becomes ``f^2 delta`` (``pert``, the half-precision
      scale rounding, stays).  Up to ``max_depth`` halvings.

    An interval fails when a sub-sample time has a vertex outside the sphere by more than the
    tolerance (skinned exactly in stage space); it is then sampled at :data:`FAIL_SAMPLES`
    sub-steps for its worst excess.  ``growth``: never stop at a failure, subdivide to
    ``max_depth`` and return the bound (the spheres stage's mode, with ``rho`` the target radii).

    Parameters
    ----------
    rig : Rig; clip : schema.Clip; times : (F,) the clip's samples
    frame_bound : (F, P) upper bounds of the farthest vertex at the samples (stage space, or the
        part joint's space with ``frame_bound_space="joint"``); frame_ok : (F, P) bool the
        sampled verdicts (intervals next to a failing sample are not checked: status 5)
    rho : (P,) or (I, P), optional: radii to hold the bounds to, times the interval's scale ratio as
        for the spheres' own radii (default: the spheres' radii with the tolerance)
    """
    if rig.skinning_method != SK.CLASSIC_LINEAR:  # the chord bounds are LBS's: runtime.certify_dq.certificate
        raise ValueError(f"continuous: a {rig.skinning_method!r} rig is certified by runtime.certify_dq")
    times = np.asarray(times, dtype=np.float64)
    F, P = len(times), rig.P
    I = F - 1
    if I <= 0 or P == 0:
        z = np.zeros((max(I, 0), P))
        return Continuous(z.astype(np.int8), z, z)
    bd = rig.bounds
    fac = factor_bounds(clip, times, rig.rest_local)
    off, pj, pd, pair_part = rig.paths()
    M = len(bd.pj_joint)
    e0, e1, delta, lam, pert = (np.zeros((I, M)) for _ in range(5))
    if M:
        B.chain_bounds(fac["L0"], fac["L1"], fac["Li0"], fac["Li1"], fac["fw"], fac["iv"], fac["dt"], fac["eps"],
                        off, pj, pd, bd.pj_center, bd.pj_radius, pair_part, bd.part_centers, e0, e1, delta, lam, pert)
    # scale bounds of N_J over each interval (products along the root path, parents first)
    Jn = len(rig.bind)
    s_hi = np.empty((I, Jn))
    s_lo = np.empty((I, Jn))
    iso = np.empty((I, Jn), bool)
    # a degenerate interval (a scale through zero in a corrupt asset) gives an infinite or NaN
    # bound here: never certified (it compares false), so no warning is worth raising
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for j in rig.topo:
            p = rig.parents[j]
            s_hi[:, j] = fac["fw"][:, j, 0] * (s_hi[:, p] if p >= 0 else 1.0)
            s_lo[:, j] = (s_lo[:, p] if p >= 0 else 1.0) / fac["iv"][:, j, 0]
            iso[:, j] = fac["iso"][:, j] & (iso[:, p] if p >= 0 else True)
        wl = rig.world[:3, :3]
        s_hi *= _norm2(wl)
        s_lo *= _sigma_min(wl)
        J = rig.part_joint
        r = rig.part_radii
        # where every factor of J's root path (and the world transform) is a rotation times a uniform
        # scale at every time, N_J is a similarity: mu(N_J) = ||L(N_J)|| at each time, ratio 1
        sw = np.linalg.svd(wl, compute_uv=False)
        iso &= bool(sw[0] - sw[-1] <= 1e-12 * sw[0])
        ratio = np.where(iso, 1.0, s_lo / s_hi)
        if rho is None:
            rho = (r[None] * (1.0 + tol_rel) * ratio[:, J] * (1 - 1e-12) + tol_abs / s_hi[:, J])
        else:
            # radii given (the spheres stage's targets): held as the default holds the spheres' own
            # radii, times the interval's scale ratio, so what passes here passes the validator
            rho = np.asarray(rho, dtype=np.float64) * ratio[:, J] * (1 - 1e-12)
        rho = np.broadcast_to(np.asarray(rho, dtype=np.float64), (I, P)).copy()
        # level A1: the continuous test K
        kc = np.maximum(e0, e1) + delta + pert + lam * bd.pj_radius[None]
        starts = bd.pj_offsets[:-1]
        nonempty = np.diff(bd.pj_offsets) > 0
        K1 = np.full((I, P), np.inf)
        if M:
            K1[:, nonempty] = np.maximum.reduceat(kc, starts[nonempty], axis=1)
        with np.errstate(invalid="ignore"):
            K1 = np.where(nonempty[None], bd.part_wabs[None] * K1, 0.0)
        K1 = K1 \
            + bd.part_wdev[None] * np.linalg.norm(bd.part_centers, axis=1)[None]  # an empty part holds trivially
        # level A2: chords of the sampled bounds
        own = bd.pj_joint == J[pair_part] if M else np.zeros(0, bool)
        dl = np.where(own[None], 0.0, delta + pert)
        dev_max = np.zeros((I, P))
        dev_sum = np.zeros((I, P))
        if M:
            dev_max[:, nonempty] = np.maximum.reduceat(dl, starts[nonempty], axis=1)
            dev_sum[:, nonempty] = np.add.reduceat(dl * bd.pj_wmax[None], starts[nonempty], axis=1)
        dev = np.minimum(bd.part_wabs[None] * dev_max, dev_sum)
        fb = np.asarray(frame_bound, dtype=np.float64)
        fb = np.maximum(fb[:-1], fb[1:])
        if frame_bound_space == "stage":
            fb = fb / s_lo[:, J]
    U = np.minimum(K1, fb + dev)
    ok = np.asarray(frame_ok, dtype=bool)
    ends_ok = ok[:-1] & ok[1:]
    status = np.full((I, P), -1, dtype=np.int8)
    status[U <= rho] = 0
    status[~ends_ok] = 5
    bound = np.where(status == 0, U, np.inf)
    if growth:
        status[:] = np.where(U <= rho, 0, -1)
    out = Continuous(status, bound, rho, ratio=ratio[:, J].copy())
    todo = np.argwhere(status == -1)
    if len(todo):
        global _refined_pairs
        _refined_pairs += len(todo)
        batched = BATCHED and _refined_pairs >= BATCHED_MIN_PAIRS
        (_refine_batched if batched else _refine)(rig, clip, times, fac, delta, pert, own, pair_part, todo, out,
                                                  tol_abs, tol_rel, growth, max_depth)
    return out


class _Mats:
    """J-space skinning transforms at given times, computed on demand and stacked for the
    kernels: index (time, joint) -> row of a (T, J, 12) array."""

    def __init__(self, rig, clip, times, fac):
        self.rig, self.clip = rig, clip
        self.frame = {float(t): i for i, t in enumerate(times)}
        self.locals = fac["locals"]
        self.skel = {}
        self.index = {}
        self.rows = []

    def skel_at(self, t):
        t = float(t)
        if t not in self.skel:  # a sample's local transforms are known; others are interpolated
            i = self.frame.get(t)
            local = self.locals[i] if i is not None else PK.locals_at(self.clip, [t], self.rig.rest_local)[0]
            self.skel[t] = PK.compose(local, self.rig.parents, self.rig.topo)
        return self.skel[t]

    def get(self, t, joint):
        key = (float(t), int(joint))
        if key not in self.index:
            s = self.skel_at(t)[None]
            self.index[key] = len(self.rows)
            self.rows.append(self.rig.joint_space_mats(s, int(joint))[0])
        return self.index[key]

    def array(self):
        return np.ascontiguousarray(np.stack(self.rows)) if self.rows else np.zeros((0, len(self.rig.bind), 12))


def _refine(rig, clip, times, fac, delta, pert, own, pair_part, todo, out, tol_abs, tol_rel, growth, max_depth):
    """Levels B and C of :func:`continuous` for the (interval, part) pairs ``todo``."""
    bd = rig.bounds
    P, Jn = rig.P, len(rig.bind)
    mats = _Mats(rig, clip, times, fac)
    # dense per (interval, part) deviation rows, by joint
    rows = {}
    drow, prow = [], []
    for i, p in todo:
        rows[(i, p)] = len(drow)
        d = np.zeros(Jn)
        e = np.zeros(Jn)
        lo, hi = bd.pj_offsets[p], bd.pj_offsets[p + 1]
        d[bd.pj_joint[lo:hi]] = np.where(own[lo:hi], 0.0, delta[i, lo:hi])
        e[bd.pj_joint[lo:hi]] = np.where(own[lo:hi], 0.0, pert[i, lo:hi])
        drow.append(d)
        prow.append(e)
    drow = np.ascontiguousarray(np.array(drow))
    prow = np.ascontiguousarray(np.array(prow))
    # nodes: (i, p, ta, tb, depth); depth 0 is the whole interval (level B)
    nodes = [(int(i), int(p), float(times[i]), float(times[i + 1]), 0) for i, p in todo]
    worst = {}
    deepest = {}
    found = {}
    while nodes:
        tp, ta, tb, tr, ts = [], [], [], [], []
        for i, p, a, b, depth in nodes:
            J = rig.part_joint[p]
            frac = (b - a) / (times[i + 1] - times[i])
            tp.append(p)
            ta.append(mats.get(a, J))
            tb.append(mats.get(b, J))
            tr.append(rows[(i, p)])
            ts.append(frac * frac)
        u, vu, d0, v0, d1, v1 = B.chord_tasks(
            rig.points, rig.joint_indices, rig.joint_weights, mats.array(), rig.vert_offsets, rig.verts,
            bd.part_centers, np.array(tp, np.int64), np.array(ta, np.int64), np.array(tb, np.int64),
            np.array(tr, np.int64), np.array(ts), drow, prow)
        nxt = []
        for n_, (i, p, a, b, depth) in enumerate(nodes):
            key = (i, p)
            if out.status[i, p] == 3:
                continue
            rho = out.rho[i, p]
            if u[n_] <= rho:
                worst[key] = max(worst.get(key, -np.inf), u[n_])
                deepest[key] = max(deepest.get(key, 0), depth)
                continue
            if not growth and depth > 0 and max(d0[n_], d1[n_]) > rho:
                # an end of this sub-interval may be a real failure: decide in stage space
                t_end = a if d0[n_] >= d1[n_] else b
                d, R, v = sampled_exact(rig, mats.skel_at(t_end)[None], [p])
                if d[0] - R[0] * (1 + tol_rel) - tol_abs > 0:
                    out.status[i, p] = 3
                    found[key] = (t_end, int(v[0]), float(d[0] - R[0]), float(R[0]))
                    continue
            if depth >= max_depth:
                worst[key] = max(worst.get(key, -np.inf), u[n_])
                deepest[key] = depth
                if not growth:
                    out.status[i, p] = 4
                continue
            m = 0.5 * (a + b)
            nxt += [(i, p, a, m, depth + 1), (i, p, m, b, depth + 1)]
            out.subdivided += 1
        nodes = nxt
    for i, p in todo:
        key = (int(i), int(p))
        if out.status[i, p] == -1:
            out.status[i, p] = 1 if deepest.get(key, 0) == 0 else 2
        out.bound[i, p] = worst.get(key, np.inf) if out.status[i, p] != 3 else np.inf
    for i, p in np.argwhere((out.status == 3) | (out.status == 4)):
        out.failures.append(_describe_failure(rig, clip, times, int(i), int(p), out, mats, found.get((int(i), int(p)))))


def _dev_rows(rig, delta, pert, own, todo):
    """Dense per (interval, part) rows, by joint, of the chord deviation ``delta`` and the
    half-precision rounding ``pert`` of the pairs ``todo`` (0 for the part's own joint and for
    joints outside the part): (len(todo), J) each."""
    bd = rig.bounds
    Jn = len(rig.bind)
    drow = np.zeros((len(todo), Jn))
    prow = np.zeros((len(todo), Jn))
    for p in np.unique(todo[:, 1]):
        rows = np.flatnonzero(todo[:, 1] == p)
        lo, hi = bd.pj_offsets[p], bd.pj_offsets[p + 1]
        if hi == lo:
            continue
        cols = bd.pj_joint[lo:hi]
        i = todo[rows, 0]
        drow[rows[:, None], cols[None]] = np.where(own[None, lo:hi], 0.0, delta[i, lo:hi])
        prow[rows[:, None], cols[None]] = np.where(own[None, lo:hi], 0.0, pert[i, lo:hi])
    return drow, prow


def _refine_batched(rig, clip, times, fac, delta, pert, own, pair_part, todo, out, tol_abs, tol_rel, growth,
                    max_depth):
    """Levels B and C of :func:`continuous` for the (interval, part) pairs ``todo``: the decisions
    of :func:`_refine`, node for node and in its order, with each subdivision level's per-vertex
    chord bounds computed by one batched kernel (:func:`runtime.kernels.subdivide.chord_nodes`) over
    all its open nodes, the joint transforms of the level's times by one interpolation and one
    composition call (:func:`runtime.kernels.subdivide.pose_at`), and ``inv_bind @ geom_bind``
    once per rig."""
    bd = rig.bounds
    P = rig.P
    if rig._ibg is None:
        rig._ibg = np.ascontiguousarray(rig.inv_bind @ rig.geom_bind)
    todo = np.asarray(todo, dtype=np.int64)
    drow, prow = _dev_rows(rig, delta, pert, own, todo)
    flat_status = out.status.reshape(-1)  # a view: writes land in out.status
    worst = np.full(flat_status.shape, -np.inf)
    deepest = np.zeros(flat_status.shape, np.int64)
    found = {}
    mats = None  # the reference's per-time cache, for the rare exact checks and failure reports
    # nodes of the current level, in the reference's order
    n_i, n_p = todo[:, 0].copy(), todo[:, 1].copy()
    n_a, n_b = times[n_i].astype(np.float64), times[n_i + 1].astype(np.float64)
    n_row = np.arange(len(todo), dtype=np.int64)
    depth = 0
    Jn = len(rig.bind)
    chunk = max(64, BATCH_BYTES // (2 * 2 * Jn * 16 * 8))
    while len(n_i):
        key = n_i * P + n_p
        frac = (n_b - n_a) / (times[n_i + 1] - times[n_i])
        N = len(n_i)
        u, d0, d1 = np.empty(N), np.empty(N), np.empty(N)
        for lo in range(0, N, chunk):
            s = slice(lo, lo + chunk)
            ts, inv = np.unique(np.r_[n_a[s], n_b[s]], return_inverse=True)
            skel, skin = SD.pose_at(clip, ts, rig.rest_local, rig.parents, rig.topo, rig._ibg)
            k = len(n_a[s])
            r = SD.chord_nodes(rig.points, rig.joint_indices, rig.joint_weights, rig.vert_offsets, rig.verts,
                               bd.part_joint, bd.pj_offsets, bd.pj_joint, bd.part_centers, skel, skin,
                               n_p[s], inv[:k].astype(np.int64), inv[k:].astype(np.int64), n_row[s],
                               frac[s] * frac[s], drow, prow)
            u[s], d0[s], d1[s] = r[0], r[2], r[4]
        rho = out.rho[n_i, n_p]
        alive = flat_status[key] != 3
        ok = u <= rho
        first_fail = {}
        if not growth and depth > 0:
            for n in np.flatnonzero(alive & ~ok & (np.maximum(d0, d1) > rho)):
                kk = int(key[n])
                if flat_status[kk] == 3:
                    continue
                # an end of this sub-interval may be a real failure: decide in stage space
                if mats is None:
                    mats = _Mats(rig, clip, times, fac)
                p = int(n_p[n])
                t_end = float(n_a[n]) if d0[n] >= d1[n] else float(n_b[n])
                d, R, v = sampled_exact(rig, mats.skel_at(t_end)[None], [p])
                if d[0] - R[0] * (1 + tol_rel) - tol_abs > 0:
                    flat_status[kk] = 3
                    found[(int(n_i[n]), p)] = (t_end, int(v[0]), float(d[0] - R[0]), float(R[0]))
                    first_fail[kk] = n
        proc = alive
        if first_fail:  # the nodes of a key after its first failure in this level are skipped
            ff = np.array([first_fail.get(int(k_), N) for k_ in key], np.int64)
            proc = alive & (np.arange(N) < ff)
        done = proc & ok
        np.maximum.at(worst, key[done], u[done])
        np.maximum.at(deepest, key[done], depth)
        rest = proc & ~ok
        if depth >= max_depth:
            np.maximum.at(worst, key[rest], u[rest])
            np.maximum.at(deepest, key[rest], depth)
            if not growth:
                kr = key[rest]
                flat_status[kr[flat_status[kr] != 3]] = 4
            break
        sub = np.flatnonzero(rest)
        out.subdivided += len(sub)
        m = 0.5 * (n_a[sub] + n_b[sub])
        n_i, n_p, n_row = np.repeat(n_i[sub], 2), np.repeat(n_p[sub], 2), np.repeat(n_row[sub], 2)
        a2, b2 = np.empty(2 * len(sub)), np.empty(2 * len(sub))
        a2[0::2], b2[0::2] = n_a[sub], m
        a2[1::2], b2[1::2] = m, n_b[sub]
        n_a, n_b = a2, b2
        depth += 1
    i, p = todo[:, 0], todo[:, 1]
    key = i * P + p
    st = out.status[i, p]
    open_ = st == -1
    out.status[i[open_], p[open_]] = np.where(deepest[key[open_]] == 0, 1, 2)
    out.bound[i, p] = np.where((out.status[i, p] != 3) & (worst[key] > -np.inf), worst[key], np.inf)
    fails = np.argwhere((out.status == 3) | (out.status == 4))
    if len(fails) and mats is None:
        mats = _Mats(rig, clip, times, fac)
    for i, p in fails:
        out.failures.append(_describe_failure(rig, clip, times, int(i), int(p), out, mats, found.get((int(i), int(p)))))


def sampled_exact(rig, skel, parts):
    """Exact farthest distance (F,), sphere radius (F,) and farthest vertex (F,) of part
    ``parts[0]`` at poses ``skel`` (F, J, 4, 4), stage space."""
    skel = np.asarray(skel, dtype=np.float64)
    world = rig.world @ skel
    sph, _, _ = B.pose_bounds(world, rig.bounds)
    todo = np.zeros(sph.shape[:2], bool)
    todo[:, parts] = True
    d, v = SK.part_farthest(rig.points, rig.joint_indices, rig.joint_weights, rig.skin_mats(skel),
                            rig.vert_offsets, rig.verts, sph[..., :3], todo=todo)
    return d[:, parts][:, 0], sph[:, parts, 3][:, 0], v[:, parts][:, 0]


def _describe_failure(rig, clip, times, i, p, out, mats, found):
    """The worst excess of part ``p`` over interval ``i``: the time the subdivision found outside
    and :data:`FAIL_SAMPLES` evenly spaced sub-steps, all skinned exactly in stage space."""
    t0, t1 = float(times[i]), float(times[i + 1])
    sub = t0 + (t1 - t0) * np.arange(1, FAIL_SAMPLES) / FAIL_SAMPLES
    skel = np.stack([mats.skel_at(t) for t in sub])
    world = rig.world @ skel
    sph, _, _ = B.pose_bounds(world, rig.bounds)
    todo = np.zeros(sph.shape[:2], bool)
    todo[:, p] = True
    d, v = SK.part_farthest(rig.points, rig.joint_indices, rig.joint_weights, rig.skin_mats(skel),
                            rig.vert_offsets, rig.verts, sph[..., :3], todo=todo)
    ex = d[:, p] - sph[:, p, 3]
    k = int(np.argmax(ex))
    time, vertex, excess, radius = float(sub[k]), int(v[k, p]), float(ex[k]), float(sph[k, p, 3])
    if found is not None and found[2] > excess:
        time, vertex, excess, radius = found
    return {"interval": i, "part": p, "t0": t0, "t1": t1, "time": time, "vertex": vertex, "excess": excess,
            "radius": radius, "definite": bool(out.status[i, p] == 3), "bound": float(out.bound[i, p])}
