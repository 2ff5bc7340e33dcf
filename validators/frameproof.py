"""The frame proof: skin every frame of every clip and test every vertex of every part against
the part's sphere moved by its joint.

Compiled numba kernels (``_``-prefixed, ``@njit(parallel=True, cache=True)``) sit behind
validating public wrappers.  Geometry is ``float32``; transforms are ``float64`` (arithmetic in
``float64``).  The proof never holds skinned points: each (frame, part) task skins its part's
vertices on the fly and keeps only the farthest one, and frames are processed in chunks whose
per-frame joint matrices stay under :data:`validators.tolerances.CHUNK_BYTES`, so memory is
``O(vertices + chunk x joints)`` whatever the frame count.

Public functions
----------------
skinning_transforms(skel, inv_bind, geom_bind=None, world=None) -> (f, b, 4, 4) float64
skin_frames(points, joint_indices, joint_weights, skin_xforms, out=None) -> (f, n, 3) float32
part_farthest(points, joint_indices, joint_weights, skin_xforms, part_offsets, part_vertices,
              centers) -> (distance (f, P) float64, vertex (f, P) int32)
world_spheres(joint_xforms, part_joints, centers, radii) -> (centers (f, P, 3), radii (f, P), scale (f, P))
prove(asset, subframes=0, ...) -> Proof
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from . import tolerances as tol


# --------------------------------------------------------------------------------- kernels
@njit(cache=True, parallel=True)
def _skin_kernel(points, jidx, jw, mats, out):
    F, n, k = mats.shape[0], points.shape[0], jidx.shape[1]
    for f in range(F):
        for v in prange(n):
            x = np.float64(points[v, 0])
            y = np.float64(points[v, 1])
            z = np.float64(points[v, 2])
            ax = 0.0
            ay = 0.0
            az = 0.0
            for i in range(k):
                w = np.float64(jw[v, i])
                if w == 0.0:
                    continue
                m = mats[f, jidx[v, i]]
                ax += w * (m[0, 0] * x + m[0, 1] * y + m[0, 2] * z + m[0, 3])
                ay += w * (m[1, 0] * x + m[1, 1] * y + m[1, 2] * z + m[1, 3])
                az += w * (m[2, 0] * x + m[2, 1] * y + m[2, 2] * z + m[2, 3])
            out[f, v, 0] = ax
            out[f, v, 1] = ay
            out[f, v, 2] = az


#: Frames per task of the containment kernel: each vertex is loaded once per block of frames.
_FRAME_BLOCK = 8


@njit(cache=True, parallel=True, fastmath={"contract", "reassoc", "arcp", "nsz"})
def _farthest_kernel(points, jidx, jw, mats, poff, pverts, centers, out_d, out_v):
    """Tasks are (part, block of frames): a vertex is read once and skinned for every frame of
    the block; per (frame, part) the largest squared distance to the centre is kept."""
    F, P, k = mats.shape[0], poff.shape[0] - 1, jidx.shape[1]
    nb = (F + _FRAME_BLOCK - 1) // _FRAME_BLOCK
    for task in prange(P * nb):
        p = task // nb
        f0 = (task % nb) * _FRAME_BLOCK
        f1 = min(F, f0 + _FRAME_BLOCK)
        best = np.full(_FRAME_BLOCK, -1.0)
        bestv = np.full(_FRAME_BLOCK, -1, dtype=np.int32)
        for s in range(poff[p], poff[p + 1]):
            v = pverts[s]
            x = np.float64(points[v, 0])
            y = np.float64(points[v, 1])
            z = np.float64(points[v, 2])
            for f in range(f0, f1):
                ax = 0.0
                ay = 0.0
                az = 0.0
                for i in range(k):
                    w = np.float64(jw[v, i])
                    j = jidx[v, i]
                    ax += w * (mats[f, j, 0, 0] * x + mats[f, j, 0, 1] * y + mats[f, j, 0, 2] * z + mats[f, j, 0, 3])
                    ay += w * (mats[f, j, 1, 0] * x + mats[f, j, 1, 1] * y + mats[f, j, 1, 2] * z + mats[f, j, 1, 3])
                    az += w * (mats[f, j, 2, 0] * x + mats[f, j, 2, 1] * y + mats[f, j, 2, 2] * z + mats[f, j, 2, 3])
                dx = ax - centers[f, p, 0]
                dy = ay - centers[f, p, 1]
                dz = az - centers[f, p, 2]
                d2 = dx * dx + dy * dy + dz * dz
                if not (d2 <= 1e300):  # NaN or inf: as far as it gets
                    d2 = np.inf
                if d2 > best[f - f0]:
                    best[f - f0] = d2
                    bestv[f - f0] = v
        for f in range(f0, f1):
            out_d[f, p] = np.sqrt(best[f - f0]) if best[f - f0] >= 0.0 else 0.0
            out_v[f, p] = bestv[f - f0]


# ------------------------------------------------------------------------ public wrappers
def _check_skin_inputs(points, joint_indices, joint_weights, skin_xforms):
    points = np.ascontiguousarray(points, dtype=np.float32)
    ji = np.ascontiguousarray(joint_indices, dtype=np.int32)
    jw = np.ascontiguousarray(joint_weights, dtype=np.float32)
    x = np.asarray(skin_xforms, dtype=np.float64)
    if x.ndim == 3:
        x = x[None]
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points: expected (n, 3), got {points.shape}")
    n = len(points)
    if ji.ndim != 2 or ji.shape[0] != n:
        raise ValueError(f"joint_indices: expected ({n}, k), got {ji.shape}")
    if jw.shape != ji.shape:
        raise ValueError(f"joint_weights: expected {ji.shape}, got {jw.shape}")
    if x.ndim != 4 or x.shape[2:] != (4, 4):
        raise ValueError(f"skin_xforms: expected (f, b, 4, 4), got {x.shape}")
    if ji.size and (ji.min() < 0 or ji.max() >= x.shape[1]):
        raise ValueError(f"joint_indices: expected values in [0, {x.shape[1]}), got [{ji.min()}, {ji.max()}]")
    mats = np.ascontiguousarray(x[:, :, :3, :])
    return points, ji, jw, mats


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


def skin_frames(points, joint_indices, joint_weights, skin_xforms, out=None) -> np.ndarray:
    """Linear-blend skinning of ``f`` frames (compiled, parallel over vertices).

    Parameters
    ----------
    points : (n, 3) float32                  mesh-space points
    joint_indices : (n, k) int               influencing joints (weight-0 entries are padding)
    joint_weights : (n, k) float32
    skin_xforms : (f, b, 4, 4) float64       from :func:`skinning_transforms`
    out : (f, n, 3) float32, optional

    Returns
    -------
    (f, n, 3) float32 skinned points: ``sum_k w[v,k] * skin_xforms[f, j[v,k]] @ p[v]``.
    """
    points, ji, jw, mats = _check_skin_inputs(points, joint_indices, joint_weights, skin_xforms)
    shape = (mats.shape[0], len(points), 3)
    if out is None:
        out = np.empty(shape, dtype=np.float32)
    elif out.shape != shape or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ValueError(f"out: expected C-contiguous float32 {shape}, got {out.dtype} {out.shape}")
    _skin_kernel(points, ji, jw, mats, out)
    return out


def part_farthest(points, joint_indices, joint_weights, skin_xforms, part_offsets, part_vertices,
                  centers):
    """For every frame and part, the skinned vertex of the part farthest from ``centers``.

    Parameters
    ----------
    points, joint_indices, joint_weights, skin_xforms : as :func:`skin_frames`
    part_offsets : (P + 1,) int, part_vertices : (sum,) int
        CSR: vertices of part ``p`` are ``part_vertices[part_offsets[p]:part_offsets[p + 1]]``.
    centers : (f, P, 3) float64              sphere centres at each frame, same space as the skin

    Returns
    -------
    distance : (f, P) float64   distance of the farthest vertex (inf if a skinned point is NaN;
                                0 for an empty part)
    vertex : (f, P) int32       its index (-1 for an empty part)
    """
    points, ji, jw, mats = _check_skin_inputs(points, joint_indices, joint_weights, skin_xforms)
    poff = np.ascontiguousarray(part_offsets, dtype=np.int64)
    pv = np.ascontiguousarray(part_vertices, dtype=np.int32)
    F, P = mats.shape[0], len(poff) - 1
    c = np.ascontiguousarray(centers, dtype=np.float64)
    if c.shape != (F, P, 3):
        raise ValueError(f"centers: expected ({F}, {P}, 3), got {c.shape}")
    if P >= 0 and (poff[0] != 0 or poff[-1] != len(pv) or np.any(np.diff(poff) < 0)):
        raise ValueError("part_offsets: expected non-decreasing from 0 to len(part_vertices)")
    if pv.size and (pv.min() < 0 or pv.max() >= len(points)):
        raise ValueError(f"part_vertices: expected values in [0, {len(points)})")
    d = np.empty((F, P), dtype=np.float64)
    v = np.empty((F, P), dtype=np.int32)
    _farthest_kernel(points, ji, jw, mats, poff, pv, c, d, v)
    return d, v


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
@dataclass
class PartResult:
    """Worst case of one part over one clip (times checked: frames plus subframes)."""

    clip: str
    part: int
    excess: float = -np.inf     # stage units, max over times of farthest distance - radius
    fraction: float = 0.0       # excess / world radius at that time
    time: float = 0.0
    frame: int = 0              # index of the frame at or before ``time`` in the clip
    vertex: int = -1
    failing_times: int = 0
    first_fail_time: float | None = None


@dataclass
class Proof:
    """Result of :func:`prove`.

    ``results``: one :class:`PartResult` per (clip, part).  ``tightest``: (P,) the largest
    joint-space farthest-vertex distance over every checked time (what the radius must be at
    least).  ``checked`` / ``not_checked``: plain-language lists for the report.
    """

    results: list = field(default_factory=list)
    tightest: np.ndarray = None
    tolerance: float = 0.0
    frames: int = 0
    subframe_times: int = 0
    vertex_frames: int = 0
    seconds: float = 0.0
    checked: list = field(default_factory=list)
    not_checked: list = field(default_factory=list)

    def stats(self) -> dict:
        return {"frames": self.frames, "subframe_times": self.subframe_times,
                "vertex_frames": self.vertex_frames, "seconds": round(self.seconds, 4),
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


def prove(asset, subframes: int = 0, chunk_frames: int | None = None, clips=None) -> Proof:
    """Run the frame proof on a :class:`validators.asset.LoadedAsset` whose ``ready("proof")``.

    For every clip and every checked time: joint local transforms from ``UsdSkel.AnimQuery``
    (its own interpolation at in-between times), composed to skeleton space, skinned and tested
    in compiled code, one chunk of times at a time.

    ``clips``: names of the clips to prove (default all).  Clips are independent, so proofs of
    disjoint clip sets combine with :func:`merge_proofs` into exactly the proof of them all
    (how ``colossus validate`` splits a very large asset across workers).
    """
    t0 = _time.perf_counter()
    P = len(asset.part_joints)
    poff, pverts = asset.part_vertices
    pj = asset.part_joint_ids
    tolerance = tol.CONTAIN_RELATIVE * asset.model_size
    proof = Proof(tightest=np.zeros(P), tolerance=tolerance)
    chunk = chunk_frames or chunk_size(len(asset.joints), P)
    inv_bind = asset.inv_bind
    for clip in asset.clips:
        if clips is not None and clip.name not in clips:
            continue
        if len(clip.times) == 0:
            continue
        times, fidx, is_sub = clip_times(clip.times, subframes)
        res = [PartResult(clip.name, p) for p in range(P)]
        for lo in range(0, len(times), chunk):
            t = times[lo:lo + chunk]
            skel = asset.skel_transforms(asset.anim_local(clip, t))
            joint_world = asset.skel_world @ skel
            sk = skinning_transforms(skel, inv_bind, asset.geom_bind, asset.skel_world)
            wc, wr, scale = world_spheres(joint_world, pj, asset.part_centers, asset.part_radii)
            d, v = part_farthest(asset.points, asset.jidx, asset.jw, sk, poff, pverts, wc)
            proof.tightest = np.maximum(proof.tightest, np.max(d / scale, axis=0))
            excess = d - wr
            fail = excess > tolerance + tol.CONTAIN_RADIUS * wr
            worst = np.argmax(excess, axis=0)
            for p in np.nonzero(fail.any(axis=0) | (excess[worst, np.arange(P)] > [r.excess for r in res]))[0]:
                r, i = res[p], worst[p]
                if excess[i, p] > r.excess:
                    r.excess, r.fraction = float(excess[i, p]), float(excess[i, p] / wr[i, p])
                    r.time, r.frame, r.vertex = float(t[i]), int(fidx[lo + i]), int(v[i, p])
                nf = int(fail[:, p].sum())
                if nf:
                    if r.first_fail_time is None:
                        r.first_fail_time = float(t[np.argmax(fail[:, p])])
                    r.failing_times += nf
        proof.results.extend(res)
        proof.frames += len(clip.times)
        proof.subframe_times += int(is_sub.sum())
        proof.vertex_frames += len(times) * len(pverts)
    proof.seconds = _time.perf_counter() - t0
    _describe(proof, asset, subframes)
    return proof


def merge_proofs(asset, proofs, subframes: int = 0) -> Proof:
    """Combine proofs of disjoint clip sets of ``asset`` (from ``prove(..., clips=...)``) into the
    proof :func:`prove` gives for all of them: results in the asset's clip order, ``tightest``
    the elementwise maximum, counts and seconds summed."""
    order = {c.name: i for i, c in enumerate(asset.clips)}
    out = Proof(tightest=np.zeros(len(asset.part_joints)), tolerance=tol.CONTAIN_RELATIVE * asset.model_size)
    for p in proofs:
        out.results.extend(p.results)
        out.tightest = np.maximum(out.tightest, p.tightest)
        out.frames += p.frames
        out.subframe_times += p.subframe_times
        out.vertex_frames += p.vertex_frames
        out.seconds += p.seconds
    out.results.sort(key=lambda r: (order.get(r.clip, len(order)), r.part))
    _describe(out, asset, subframes)
    return out


def _describe(proof, asset, subframes):
    names = ", ".join(f"{c.name} ({len(c.times)})" for c in asset.clips)
    proof.checked = [f"every vertex of every part on all {proof.frames} frames of every clip: {names}"]
    if subframes:
        proof.checked.append(f"{subframes} in-between time(s) per frame interval ({proof.subframe_times} times)")
        proof.not_checked = ["times between the checked in-between times (motion is a curve; "
                             "raise --subframes to sample it more finely)"]
    else:
        proof.not_checked = ["in-between times (motion between frames is a curve); use --subframes K"]
    proof.checked.append("triangles between the vertices (a sphere is convex: holding a triangle's corners holds it)")
    return proof
