"""The frame proof: every vertex of every part inside the part's moving sphere, on every
frame of every clip (tiers K, D, exact) and for every time between the frames (the continuous
certificate).

The machinery is :mod:`runtime.certify` (shared with the import's spheres stage) on the one
skinning kernel :mod:`runtime.kernels.skin`; the bounds and their soundness arguments are in the
docstrings of :mod:`runtime.kernels.bounds`, :mod:`runtime.kernels.interval` and
:func:`runtime.certify.continuous`.  This module runs it on a
:class:`validators.asset.LoadedAsset`, one clip and one chunk of frames at a time (memory
``O(vertices + chunk x joints)``), and turns the results into per-part records.

Sampled frames: joint transforms from ``UsdSkel.AnimQuery`` (usd-core itself).  Per (frame,
part): test K, else test D, else the part is skinned exactly; the verdict is the exact one, and a
failure names clip, frame, part, joint, vertex and excess.  Between frames: UsdSkel's own
interpolation (lerp translations and scales, GfSlerp rotations) as the runtime's port computes it.

Public functions
----------------
skinning_transforms(skel, inv_bind, geom_bind=None, world=None) -> (f, b, 4, 4) float64
skin_frames / part_farthest: :mod:`runtime.kernels.skin` (re-exported)
world_spheres(joint_xforms, part_joints, centers, radii) -> (centers (f, P, 3), radii (f, P), scale (f, P))
prove(asset, subframes=0, ..., continuous=True) -> Proof;  merge_proofs(asset, proofs) -> Proof
tightest(asset, proof) -> (P,) exact tightest radii (for the slack rule)
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np

from colossus.runtime import certify as C
from colossus.runtime.certify_dq import certificate  # the skinning method's continuous certificate
from colossus.runtime.kernels.skin import part_farthest, skin_frames  # noqa: F401  (the one skinning kernel)

from . import tolerances as tol


def skinning_transforms(skel, inv_bind, geom_bind=None, world=None) -> np.ndarray:
    """Per-joint skinning transforms ``world @ skel @ inv_bind @ geom_bind``.

    Parameters
    ----------
    skel : (f, b, 4, 4) or (b, 4, 4) float64  joint skeleton-space transforms (column-vector)
    inv_bind : (b, 4, 4) float64              inverse bind transforms
    geom_bind : (4, 4) float64, optional      mesh space -> skeleton space at bind time
    world : (4, 4) float64, optional          the skeleton's local-to-world transform

    Returns
    -------
    (f, b, 4, 4) float64
    """
    skel = np.asarray(skel, dtype=np.float64)
    if skel.ndim == 3:
        skel = skel[None]
    m = skel @ np.asarray(inv_bind, dtype=np.float64)
    if geom_bind is not None:
        m = m @ np.asarray(geom_bind, dtype=np.float64)
    if world is not None:
        m = np.asarray(world, dtype=np.float64) @ m
    return m


def skin_layout(skel, inv_bind, geom_bind=None, world=None, method: str = "classicLinear") -> np.ndarray:
    """The one kernel's folded transforms for skinning by ``method`` (the asset's
    ``primvars:skel:skinningMethod``): :func:`skinning_transforms` folded for linear blend; the
    dual-quaternion layout (:func:`runtime.kernels.skin.fold_dq`: skinning in skeleton space,
    ``geom_bind`` before and ``world`` after) otherwise."""
    from colossus.runtime.kernels.skin import fold_method
    skel = np.asarray(skel, dtype=np.float64)
    if skel.ndim == 3:
        skel = skel[None]
    return fold_method(method, skel @ np.asarray(inv_bind, dtype=np.float64), geom_bind, world)


def world_spheres(joint_xforms, part_joints, centers, radii):
    """Part spheres moved by their joints.

    Parameters
    ----------
    joint_xforms : (f, b, 4, 4) float64   joint -> stage space (world @ skel transform)
    part_joints : (P,) int; centers : (P, 3) joint-space centres; radii : (P,)

    Returns
    -------
    centers : (f, P, 3) float64, radii : (f, P) float64, scale : (f, P) float64
        ``scale`` is the largest axis scale of each part's joint transform (radius multiplier).
    """
    m = np.asarray(joint_xforms, dtype=np.float64)[:, np.asarray(part_joints)]  # (f, P, 4, 4)
    c = np.asarray(centers, dtype=np.float64)
    wc = np.einsum("fpij,pj->fpi", m[..., :3, :3], c) + m[..., :3, 3]
    scale = np.linalg.norm(m[..., :3, :3], axis=-2).max(-1)
    return wc, scale * np.asarray(radii, dtype=np.float64), scale


# ------------------------------------------------------------------------------ the proof
TIER_NAMES = ("K", "D", "exact")
#: Names of :class:`runtime.certify.Continuous` statuses in the stats.
INTERVAL_NAMES = ("chord", "vertex_chord", "subdivided", "failed", "undecided", "not_checked")


@dataclass
class PartResult:
    """Worst case of one part over one clip at the checked times (frames plus subframes), from
    the times where the part was skinned exactly (a time the bounds settled is inside)."""

    clip: str
    part: int
    excess: float = -np.inf     # stage units, max over exactly checked times of farthest - radius
    fraction: float = 0.0       # excess / world radius at that time
    time: float = 0.0
    frame: int = 0              # index of the frame at or before ``time`` in the clip
    vertex: int = -1
    failing_times: int = 0
    first_fail_time: float | None = None


@dataclass
class Proof:
    """Result of :func:`prove`.

    ``results``: one :class:`PartResult` per (clip, part).  ``tight_lo`` / ``tight_hi``: (P,)
    a lower and an upper bound of the largest joint-space farthest-vertex distance over every
    checked time (:func:`tightest` makes it exact when the slack rule needs it).  ``tiers``: how
    many (part, time) pairs tests K, D and exact skinning settled.  ``between``: the intervals
    the continuous certificate could not certify (dicts: clip, part, t0, t1, time, vertex,
    excess, definite); ``intervals``: how many (part, interval) pairs each level settled.
    ``checked`` / ``not_checked``: plain-language lists for the report.
    """

    results: list = field(default_factory=list)
    tight_lo: np.ndarray = None
    tight_hi: np.ndarray = None
    tolerance: float = 0.0
    frames: int = 0
    subframe_times: int = 0
    subframes: int = 0
    vertex_frames: int = 0
    skinned_vertex_frames: int = 0
    tiers: dict = field(default_factory=lambda: dict.fromkeys(TIER_NAMES, 0))
    continuous: bool = True
    intervals: dict = field(default_factory=lambda: dict.fromkeys(INTERVAL_NAMES, 0))
    between: list = field(default_factory=list)
    clip_ranges: dict = field(default_factory=dict)
    seconds: float = 0.0
    continuous_seconds: float = 0.0
    checked: list = field(default_factory=list)
    not_checked: list = field(default_factory=list)
    _tightest: np.ndarray = None

    @property
    def tightest(self) -> np.ndarray:
        """(P,) the exact tightest radii when :func:`tightest` has run, else the upper bound."""
        return self._tightest if self._tightest is not None else self.tight_hi

    def stats(self) -> dict:
        return {"frames": self.frames, "subframe_times": self.subframe_times,
                "vertex_frames": self.vertex_frames, "skinned_vertex_frames": self.skinned_vertex_frames,
                "tiers": dict(self.tiers), "continuous": self.continuous,
                "intervals": dict(self.intervals) if self.continuous else {},
                "seconds": round(self.seconds, 4),
                "tolerance": self.tolerance, "checked": self.checked, "not_checked": self.not_checked}


def clip_times(frames: np.ndarray, subframes: int):
    """Times to check: the frames, plus ``subframes`` evenly spaced times inside each interval.

    Returns ``(times (t,), frame_index (t,) int, is_sub (t,) bool)``.
    """
    frames = np.asarray(frames, dtype=np.float64)
    idx = np.arange(len(frames))
    if subframes <= 0 or len(frames) < 2:
        return frames, idx, np.zeros(len(frames), bool)
    s = np.arange(1, subframes + 1) / (subframes + 1)
    sub = (frames[:-1, None] + np.diff(frames)[:, None] * s).ravel()
    times = np.concatenate([frames, sub])
    fidx = np.concatenate([idx, np.repeat(idx[:-1], subframes)])
    is_sub = np.concatenate([np.zeros(len(frames), bool), np.ones(len(sub), bool)])
    order = np.argsort(times, kind="stable")
    return times[order], fidx[order], is_sub[order]


def chunk_size(joint_count: int, part_count: int = 0) -> int:
    per_frame = joint_count * 16 * 8 * 3 + part_count * 8 * 8
    return int(max(1, min(tol.CHUNK_FRAMES, tol.CHUNK_BYTES // max(per_frame, 1))))


def prove(asset, subframes: int = 0, chunk_frames: int | None = None, clips=None, continuous: bool = True) -> Proof:
    """Run the proof on a :class:`validators.asset.LoadedAsset` whose ``ready("proof")``.

    For every clip and every checked time: joint local transforms from ``UsdSkel.AnimQuery``,
    composed to skeleton space, certified by :func:`runtime.certify.sampled` (tiers K, D, exact),
    one chunk of times at a time.  Then, with ``continuous``, every interval between consecutive
    frames by :func:`runtime.certify.continuous`.

    ``clips``: names of the clips to prove (default all).  Clips are independent, so proofs of
    disjoint clip sets combine with :func:`merge_proofs` into exactly the proof of them all
    (how ``colossus validate`` splits a very large asset across workers).
    """
    t0 = _time.perf_counter()
    P = len(asset.part_joints)
    poff, pverts = asset.part_vertices
    tolerance = tol.CONTAIN_RELATIVE * asset.model_size
    proof = Proof(tight_lo=np.zeros(P), tight_hi=np.zeros(P), tolerance=tolerance, continuous=continuous,
                  subframes=subframes)
    chunk = chunk_frames or chunk_size(len(asset.joints), P)
    rig = asset.rig
    radii = np.asarray(asset.part_radii, dtype=np.float64)
    for clip in asset.clips:
        if clips is not None and clip.name not in clips:
            continue
        if len(clip.times) == 0:
            continue
        times, fidx, is_sub = clip_times(clip.times, subframes)
        res = [PartResult(clip.name, p) for p in range(P)]
        fbound = np.zeros((len(clip.times), P))
        fok = np.ones((len(clip.times), P), bool)
        for lo in range(0, len(times), chunk):
            t = times[lo:lo + chunk]
            skel = asset.skel_transforms(asset.anim_local(clip, t))
            s = C.sampled(rig, skel, tolerance, tol.CONTAIN_RADIUS)
            for k, name in enumerate(TIER_NAMES):
                proof.tiers[name] += int((s.tier == k).sum())
            exact = s.tier == 2
            proof.skinned_vertex_frames += int((exact * np.diff(poff)[None]).sum())
            wr = s.spheres[..., 3]
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):  # a corrupt asset's 0 / inf radii
                scale = wr / np.where(radii > 0, radii, 1.0)[None]
                proof.tight_hi = np.maximum(proof.tight_hi, np.max(s.bound / scale, axis=0))
            with np.errstate(invalid="ignore", divide="ignore"):
                proof.tight_lo = np.maximum(proof.tight_lo, np.nanmax(np.where(exact, s.dist / scale, 0.0), axis=0))
                excess = np.where(exact, s.dist - wr, -np.inf)
            fail = excess > tolerance + tol.CONTAIN_RADIUS * wr
            frames_here = ~is_sub[lo:lo + chunk]
            fbound[fidx[lo:lo + chunk][frames_here]] = s.bound[frames_here]
            fok[fidx[lo:lo + chunk][frames_here]] = ~fail[frames_here]
            worst = np.argmax(excess, axis=0)
            for p in range(P):
                r, i = res[p], worst[p]
                if excess[i, p] > r.excess:
                    with np.errstate(invalid="ignore", divide="ignore"):
                        r.excess, r.fraction = float(excess[i, p]), float(excess[i, p] / wr[i, p])
                    r.time, r.frame, r.vertex = float(t[i]), int(fidx[lo + i]), int(s.vertex[i, p])
                nf = int(fail[:, p].sum())
                if nf:
                    if r.first_fail_time is None:
                        r.first_fail_time = float(t[np.argmax(fail[:, p])])
                    r.failing_times += nf
        proof.results.extend(res)
        proof.frames += len(clip.times)
        proof.subframe_times += int(is_sub.sum())
        proof.vertex_frames += len(times) * len(pverts)
        proof.clip_ranges[clip.name] = (float(clip.times[0]), float(clip.times[-1]))
        if continuous and len(clip.times) > 1:
            tc = _time.perf_counter()
            c = certificate(rig, asset.clip_data(clip), clip.times, fbound, fok, tolerance, tol.CONTAIN_RADIUS)
            for k, name in enumerate(INTERVAL_NAMES):
                proof.intervals[name] += int((c.status == k).sum())
            for f in c.failures:
                proof.between.append({"clip": clip.name, **f})
            proof.continuous_seconds += _time.perf_counter() - tc
    proof.seconds = _time.perf_counter() - t0
    _describe(proof, asset, subframes)
    return proof


def merge_proofs(asset, proofs, subframes: int = 0) -> Proof:
    """Combine proofs of disjoint clip sets of ``asset`` (from ``prove(..., clips=...)``) into the
    proof :func:`prove` gives for all of them: results and interval failures in the asset's clip
    order, tight bounds the elementwise maximum, counts and seconds summed."""
    order = {c.name: i for i, c in enumerate(asset.clips)}
    P = len(asset.part_joints)
    cont = all(p.continuous for p in proofs) if proofs else True
    out = Proof(tight_lo=np.zeros(P), tight_hi=np.zeros(P), tolerance=tol.CONTAIN_RELATIVE * asset.model_size,
                continuous=cont, subframes=subframes)
    for p in proofs:
        out.results.extend(p.results)
        out.between.extend(p.between)
        out.tight_lo = np.maximum(out.tight_lo, p.tight_lo)
        out.tight_hi = np.maximum(out.tight_hi, p.tight_hi)
        out.frames += p.frames
        out.subframe_times += p.subframe_times
        out.vertex_frames += p.vertex_frames
        out.skinned_vertex_frames += p.skinned_vertex_frames
        for k in TIER_NAMES:
            out.tiers[k] += p.tiers[k]
        for k in INTERVAL_NAMES:
            out.intervals[k] += p.intervals[k]
        out.clip_ranges.update(p.clip_ranges)
        out.seconds += p.seconds
        out.continuous_seconds += p.continuous_seconds
    out.results.sort(key=lambda r: (order.get(r.clip, len(order)), r.part))
    out.between.sort(key=lambda f: (order.get(f["clip"], len(order)), f["interval"], f["part"]))
    _describe(out, asset, subframes)
    return out


def tightest(asset, proof: Proof, slack_ratio: float) -> np.ndarray:
    """(P,) the largest joint-space distance of each part's farthest skinned vertex over every
    checked time, exact for every part that might be slack (radius > ``slack_ratio`` x it): the
    bound tiers give only a lower bound (the exactly skinned times) and an upper bound, so a
    part whose lower bound leaves room for slack is skinned exactly at every checked time here.
    The same for a whole proof and a merged per-clip one (it runs after the merge)."""
    if proof._tightest is not None:
        return proof._tightest
    r = np.asarray(asset.part_radii, dtype=np.float64)
    out = proof.tight_lo.copy()
    need = ~(r <= slack_ratio * proof.tight_lo)
    if need.any():
        rig = asset.rig
        exact = np.zeros(len(r), bool)
        exact[need] = True
        out[need] = 0.0
        for clip in asset.clips:
            if len(clip.times) == 0:
                continue
            times = clip_times(clip.times, proof.subframes)[0]
            for lo in range(0, len(times), tol.CHUNK_FRAMES):
                skel = asset.skel_transforms(asset.anim_local(clip, times[lo:lo + tol.CHUNK_FRAMES]))
                s = C.sampled(rig, skel, 0.0, 0.0, exact=np.broadcast_to(exact, (len(skel), len(r))))
                with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                    scale = s.spheres[..., 3] / np.where(r > 0, r, 1.0)[None]
                    out[need] = np.maximum(out[need], np.max(s.dist[:, need] / scale[:, need], axis=0))
    proof._tightest = out
    return out


def _describe(proof, asset, subframes):
    names = ", ".join(f"{c.name} ({len(c.times)})" for c in asset.clips)
    t = proof.tiers
    proof.checked = [f"every vertex of every part on all {proof.frames} frames of every clip: {names}",
                     f"(part, time) pairs settled by test K {t['K']}, by test D {t['D']}, by exact skinning {t['exact']}"]
    proof.not_checked = []
    if subframes:
        proof.checked.append(f"{subframes} in-between time(s) per frame interval ({proof.subframe_times} times)")
    if proof.continuous:
        n = proof.intervals
        how = (f"(part, interval) pairs: chord bound {n['chord']}, per-vertex chord {n['vertex_chord']}, "
               f"subdivided {n['subdivided']}")
        if not proof.between and not n["not_checked"]:
            proof.checked.append("certified for every time in [first, last] of every clip, as UsdSkel interpolates "
                                 f"(lerp translations and scales, slerp rotations); {how}")
        else:
            bad = sorted({(f["clip"], f["part"]) for f in proof.between})
            proof.checked.append(f"every time between frames, as UsdSkel interpolates: {how}; "
                                 f"{len(proof.between)} interval(s) NOT certified"
                                 + (f" (first: clip {bad[0][0]!r} part {bad[0][1]})" if bad else ""))
            if n["not_checked"]:
                proof.not_checked.append(f"{n['not_checked']} (part, interval) pairs next to a failing frame")
    else:
        proof.not_checked = ["in-between times (motion between frames is a curve); the continuous certificate is off"]
    proof.checked.append("triangles between the vertices (a sphere is convex: holding a triangle's corners holds it)")
    return proof
