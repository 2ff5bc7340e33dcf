"""Frame-proof benchmark (not a timed test): ``run_bench() -> dict``.

A synthetic 20,000-vertex, 40-joint, 4-influence skinned mesh with 500 frames.  Measures, in the
same run and on the same data:

* ``proof``: the whole frame proof as :func:`validators.frameproof.prove` runs it per chunk of
  frames (skinning transforms, moved spheres, compiled skinning + containment of every vertex of
  every part), in vertex-frames per second;
* ``usd_lbs_serial`` / ``usd_lbs_parallel``: ``UsdSkel.SkinPointsLBS`` skinning alone (usd-core's
  C++), one call per frame, ``inSerial=True`` (its default) and ``False``.

Joint transforms are given (the USD reading of clips, ``UsdSkel.AnimQuery``, is not part of
either side).  Numba compilation is done before timing.
"""

from __future__ import annotations

import time

import numpy as np

from . import frameproof as fp


def synthetic_rig(n=20000, b=40, k=4, frames=500, seed=0):
    """A chain of ``b`` joints along Y, a tube of ``n`` points around it, smooth ``k``-joint
    weights, ``frames`` frames of bending.  Returns a dict of arrays (column-vector matrices)."""
    rng = np.random.default_rng(seed)
    y = rng.random(n) * b
    th = rng.random(n) * 2 * np.pi
    pts = np.stack([0.3 * np.cos(th), y, 0.3 * np.sin(th)], 1).astype(np.float32)
    centers = np.arange(b) + 0.5
    d = np.abs(y[:, None] - centers[None])
    ji = np.argsort(d, axis=1)[:, :k].astype(np.int32)
    w = np.maximum(1e-3, 1.5 - np.take_along_axis(d, ji, 1))
    jw = (w / w.sum(1, keepdims=True)).astype(np.float32)
    bind = np.repeat(np.eye(4)[None], b, 0)
    bind[:, 1, 3] = np.arange(b)
    t = np.arange(frames)[:, None] * 0.05 + np.arange(b)[None] * 0.3
    ang = 0.15 * np.sin(t)  # (f, b) bend per joint about Z
    local = np.repeat(np.repeat(np.eye(4)[None, None], frames, 0), b, 1)
    c, s = np.cos(ang), np.sin(ang)
    local[..., 0, 0], local[..., 0, 1], local[..., 1, 0], local[..., 1, 1] = c, -s, s, c
    local[:, 1:, 1, 3] = 1.0
    skel = np.empty_like(local)
    skel[:, 0] = local[:, 0]
    for j in range(1, b):
        skel[:, j] = skel[:, j - 1] @ local[:, j]
    owner = ji[:, 0]
    order = np.argsort(owner, kind="stable")
    poff = np.searchsorted(owner[order], np.arange(b + 1)).astype(np.int64)
    return {"points": pts, "jidx": ji, "jw": jw, "bind": bind, "skel": skel, "part_joints": np.arange(b),
            "part_offsets": poff, "part_vertices": order.astype(np.int32),
            "centers": np.tile([0.0, 0.5, 0.0], (b, 1)), "radii": np.full(b, 2.0)}


def _proof(r, chunk):
    inv_bind = np.linalg.inv(r["bind"])
    world = np.eye(4)
    F = len(r["skel"])
    worst = -np.inf
    for lo in range(0, F, chunk):
        skel = r["skel"][lo:lo + chunk]
        sk = fp.skinning_transforms(skel, inv_bind, None, world)
        wc, wr, _ = fp.world_spheres(world @ skel, r["part_joints"], r["centers"], r["radii"])
        d, _ = fp.part_farthest(r["points"], r["jidx"], r["jw"], sk, r["part_offsets"], r["part_vertices"], wc)
        worst = max(worst, float((d - wr).max()))
    return worst


def _usd_lbs(r, serial):
    from pxr import Gf, UsdSkel, Vt
    inv_bind = np.linalg.inv(r["bind"])
    ji = Vt.IntArray.FromNumpy(r["jidx"].ravel())
    jw = Vt.FloatArray.FromNumpy(r["jw"].ravel())
    k = r["jidx"].shape[1]
    gb = Gf.Matrix4d(1)
    xforms = np.ascontiguousarray((r["skel"] @ inv_bind).transpose(0, 1, 3, 2))  # row-vector for Gf
    src = Vt.Vec3fArray.FromNumpy(r["points"])
    t0 = time.perf_counter()
    for f in range(len(xforms)):
        p = Vt.Vec3fArray(src)
        UsdSkel.SkinPointsLBS(gb, Vt.Matrix4dArray.FromNumpy(xforms[f]), ji, jw, k, p, serial)
    return time.perf_counter() - t0


def run_bench(n=20000, joints=40, influences=4, frames=500, repeat=3) -> dict:
    """Run the benchmark; returns timings, vertex-frames per second and the speed-up ratios."""
    r = synthetic_rig(n, joints, influences, frames)
    chunk = fp.chunk_size(joints, joints)
    small = synthetic_rig(200, joints, influences, 3)
    _proof(small, chunk)  # compile / load the numba cache outside the timing
    vf = n * frames
    t_proof = min(_timed(lambda: _proof(r, chunk)) for _ in range(repeat))
    t_ser = min(_usd_lbs(r, True) for _ in range(repeat))
    t_par = min(_usd_lbs(r, False) for _ in range(repeat))
    import numba
    out = {
        "vertices": n, "joints": joints, "influences": influences, "frames": frames,
        "vertex_frames": vf, "threads": numba.get_num_threads(), "chunk_frames": chunk,
        "proof_seconds": t_proof, "proof_vertex_frames_per_s": vf / t_proof,
        "usd_lbs_serial_seconds": t_ser, "usd_lbs_serial_vertex_frames_per_s": vf / t_ser,
        "usd_lbs_parallel_seconds": t_par, "usd_lbs_parallel_vertex_frames_per_s": vf / t_par,
        "speedup_vs_usd_serial": t_ser / t_proof, "speedup_vs_usd_parallel": t_par / t_proof,
    }
    return out


def _timed(fn):
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def format_bench(res: dict) -> str:
    m = 1e6
    return (f"frame proof: {res['vertices']} vertices x {res['frames']} frames, {res['joints']} joints, "
            f"{res['influences']} influences, {res['threads']} threads\n"
            f"  whole proof (skin + containment): {res['proof_seconds']:.3f} s  "
            f"{res['proof_vertex_frames_per_s'] / m:.1f} M vertex-frames/s\n"
            f"  UsdSkel.SkinPointsLBS serial:      {res['usd_lbs_serial_seconds']:.3f} s  "
            f"{res['usd_lbs_serial_vertex_frames_per_s'] / m:.1f} M vertex-frames/s  "
            f"(proof is {res['speedup_vs_usd_serial']:.2f}x faster)\n"
            f"  UsdSkel.SkinPointsLBS parallel:    {res['usd_lbs_parallel_seconds']:.3f} s  "
            f"{res['usd_lbs_parallel_vertex_frames_per_s'] / m:.1f} M vertex-frames/s  "
            f"(proof is {res['speedup_vs_usd_parallel']:.2f}x faster)")


if __name__ == "__main__":  # pragma: no cover
    print(format_bench(run_bench()))
