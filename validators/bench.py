"""The validator's benchmarks (not timed tests): the frame proof (``run_bench() -> dict``) and
the many-assets scale run (``run_scale_bench() -> dict``, ``colossus bench --only scale``).

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

import os
import time

import numpy as np

from runtime import schema

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


# ------------------------------------------------------------------------- scale benchmark
def make_library(directory, count=200, triangles=3000, bones=12, clips=3, frames=24, seed=0):
    """``count`` collider assets for benchmarks and tests: one synthetic ``.glb`` imported once,
    then its USD text copied with every part radius scaled by a random factor in [0.97, 1.3)
    (some assets fail the frame proof, most pass, as in a real library).  Returns the paths."""
    from pipeline.run import import_asset
    from pipeline.synth.glb import write_glb
    os.makedirs(directory, exist_ok=True)
    src = os.path.join(directory, "_source.glb")
    write_glb(src, triangles, bones, clips, frames)
    base = os.path.join(directory, "_base.usda")
    import_asset(src, base)
    from pxr import Sdf
    layer = Sdf.Layer.FindOrOpen(base)
    attr = next(s for s in _walk_attrs(layer) if s.name == schema.PARTS_RADII)
    radii = np.array(attr.default, dtype=np.float64)
    rng = np.random.default_rng(seed)
    paths = []
    for i in range(count):
        attr.default = [float(r) for r in radii * rng.uniform(0.97, 1.3)]
        p = os.path.join(directory, f"asset{i:04d}.usda")
        layer.Export(p)
        paths.append(p)
    os.unlink(src)
    os.unlink(base)
    return paths


def _walk_attrs(layer):
    out = []

    def visit(path):
        spec = layer.GetObjectAtPath(path)
        if hasattr(spec, "attributes"):
            out.extend(spec.attributes)
    layer.Traverse("/", visit)
    return out


def run_scale_bench(count=200, triangles=6000, frames=48, echo=print):
    """Validate ``count`` generated assets (a few thousand vertices, 3 clips each) with
    ``--jobs 1``, ``--jobs 2`` and a 2-worker ``LocalCluster``; check the three reports are the
    same; return wall times, speed-ups and the cluster path's per-asset overhead."""
    import tempfile

    from pipeline.engine import local_cluster

    from .parallel import check_many, comparable

    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        paths = make_library(tmp, count=count, triangles=triangles, frames=frames)
        t_gen = time.perf_counter() - t0
        check_many(paths[:1])  # warm numba's on-disk cache in this process
        cores = os.cpu_count() or 1
        runs = [("--jobs 1", dict(jobs=1)), ("--jobs 2", dict(jobs=2))]
        try:
            import distributed  # noqa: F401
            runs.append(("LocalCluster(2)", dict(scheduler="cluster")))
        except ImportError:
            echo("scale: dask[distributed] is not installed; cluster run skipped (pip install 'colossus[dask]')")
        ref = None
        for label, kw in runs:
            cluster = None
            if kw.get("scheduler") == "cluster":
                t_up = time.perf_counter()
                cluster = local_cluster(2)
                rows["cluster_start_s"] = time.perf_counter() - t_up
                kw = dict(scheduler=cluster.scheduler_address)
            try:
                t0 = time.perf_counter()
                res = check_many(paths, **kw)
                rows[label] = time.perf_counter() - t0
            finally:
                if cluster is not None:
                    cluster.close()
            same = comparable(res.reports)
            ref = ref if ref is not None else same
            rows[label + " same"] = same == ref
        # per-asset overhead of the cluster path: one tiny task per asset round-trip
        if "LocalCluster(2)" in rows:
            rows["cluster_overhead_ms"] = _task_overhead(count) * 1e3
    j1 = rows["--jobs 1"]
    out = {"assets": count, "triangles": triangles, "clips": 3, "frames": frames, "cores": cores, "generate_s": t_gen,
           "jobs1_s": j1, "jobs2_s": rows["--jobs 2"], "speedup_jobs2": j1 / rows["--jobs 2"],
           "same_reports": all(v for k, v in rows.items() if k.endswith(" same"))}
    if "LocalCluster(2)" in rows:
        c = rows["LocalCluster(2)"]
        out.update(cluster_s=c, speedup_cluster=j1 / c, cluster_start_s=rows["cluster_start_s"],
                   cluster_vs_jobs2_per_asset_ms=(c - rows["--jobs 2"]) / count * 1e3,
                   cluster_task_roundtrip_ms=rows["cluster_overhead_ms"])
    return out


def _noop(i):
    return i


def _task_overhead(n):
    """Seconds per task of submitting ``n`` no-op tasks through the engine to a 2-worker
    LocalCluster (the cluster path's fixed cost per asset, compute excluded)."""
    from pipeline.engine import DaskBackend, Engine, Task, local_cluster

    cluster = local_cluster(2)
    try:
        b = DaskBackend(cluster.scheduler_address)
        b.submit(_noop, 0).result()
        t0 = time.perf_counter()
        Engine(b).run([Task(_noop, (i,), lambda v: [], print, print) for i in range(n)])
        return (time.perf_counter() - t0) / n
    finally:
        cluster.close()


def format_scale_bench(r) -> str:
    lines = [f"scale: validate {r['assets']} generated assets (~{r['triangles']} triangles, {r['clips']} clips x "
             f"{r['frames']} frames each) on {r['cores']} cores",
             f"  --jobs 1                     {r['jobs1_s']:8.2f} s   {r['jobs1_s'] / r['assets'] * 1e3:7.1f} ms/asset",
             f"  --jobs 2                     {r['jobs2_s']:8.2f} s   x{r['speedup_jobs2']:.2f} vs --jobs 1"]
    if "cluster_s" in r:
        lines += [f"  LocalCluster (2 workers)     {r['cluster_s']:8.2f} s   x{r['speedup_cluster']:.2f} vs --jobs 1 "
                  f"(+ {r['cluster_start_s']:.1f} s to start the cluster, not counted)",
                  f"  cluster path overhead        {r['cluster_vs_jobs2_per_asset_ms']:+8.1f} ms/asset vs --jobs 2; "
                  f"{r['cluster_task_roundtrip_ms']:.1f} ms per no-op task round trip"]
    lines.append(f"  reports identical across runs: {'yes' if r['same_reports'] else 'NO'}")
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    print(format_bench(run_bench()))
