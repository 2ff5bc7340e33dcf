"""The import stage's benchmarks (``colossus bench --only import|scaling``; the command is
:mod:`validators.cli_bench`): printed as ratios against baselines run in the same process.

Absolute times are this machine's; the ratios are what to compare across machines.
"""

from __future__ import annotations

import math
import os
import tempfile
import time

import numpy as np


def _best(fn, repeat=3):
    best = math.inf
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _warm_min_sphere():
    """Compile the minimal sphere's kernel (the small warm-up import runs its plain-Python form:
    ``pipeline.geometry.minsphere.KERNEL_MIN``)."""
    from colossus.pipeline.geometry.minsphere import largest_min_sphere, min_sphere

    pts = np.random.default_rng(0).normal(size=(2, 20, 3))
    min_sphere(pts[0], compiled=True)
    largest_min_sphere(pts, pts[0].mean(0), compiled=True)


def bench_import(triangles=200_000, bones=60, clips=2, frames=120, echo=print):
    """Import a synthetic skinned tube (a real .glb); ratio of the whole import to assimp's load alone."""
    import assimp_py

    from colossus.pipeline.isolation import read_isolated
    from colossus.pipeline.readers import read
    from colossus.pipeline.readers.assimp_reader import assimp_flags
    from colossus.pipeline.run import import_asset
    from colossus.bench.synth import write_glb

    with tempfile.TemporaryDirectory() as tmp:
        # warm the numba kernels (compiled once per machine, cached on disk)
        small = os.path.join(tmp, "warm.glb")
        write_glb(small, 2_000, 8, 1, 10)
        import_asset(small, os.path.join(tmp, "warm.usda"))
        _warm_min_sphere()
        src = os.path.join(tmp, "bench.glb")
        nv, nf = write_glb(src, triangles, bones, clips, frames)
        t_assimp, _ = _best(lambda: assimp_py.import_file(src, assimp_flags()), 3)
        t_read, _ = _best(lambda: read(src), 3)
        t_contained, _ = _best(lambda: read_isolated(src), 3)
        t_import, res = _best(lambda: import_asset(src, os.path.join(tmp, "bench.usda")), 1)
    echo(f"import (synthetic tube; the real characters follow): {nf} triangles, {nv} vertices, {bones} bones, {clips} clips x {frames} frames")
    echo(f"  assimp load alone            {t_assimp:8.3f} s")
    echo(f"  reader in this process       {t_read:8.3f} s")
    echo(f"  reader contained (forked)    {t_contained:8.3f} s   = +{t_contained - t_read:.3f} s per file to survive "
         "a native crash (goal: < 0.2 s)")
    echo(f"  whole import (all stages)    {t_import:8.3f} s   = {t_import / t_assimp:6.1f} x assimp's load   (goal: < 10 s)")
    for rep in res.reports:
        echo(f"    {rep.stage:<8} {rep.seconds:8.3f} s")
    return {"triangles": nf, "assimp_s": t_assimp, "import_s": t_import, "ratio": t_import / t_assimp,
            "read_s": t_read, "read_contained_s": t_contained,
            "stages": {r.stage: r.seconds for r in res.reports}}


def bench_scaling(sizes=(50_000, 200_000, 800_000), echo=print):
    """Weld and orient at three sizes; time / (n log n) should stay flat (or fall)."""
    from colossus.pipeline.model import SkinnedMesh
    from colossus.pipeline.stages.orient import orient
    from colossus.pipeline.stages.weld import weld
    from colossus.bench.synth import chain_weights, tube

    rows = []
    echo("weld and orient scaling (per-corner split tube, as FBX delivers it):")
    echo(f"  {'triangles':>10} {'weld s':>8} {'orient s':>9} {'weld/(n log n)':>15} {'orient/(n log n)':>17}")
    base = None
    for n in sizes:
        pos, faces = tube(n)
        j, w = chain_weights(pos[:, 1].astype(np.float64), 8, 10.0)
        corner = faces.reshape(-1)
        rng = np.random.default_rng(0)
        flip = rng.random(len(faces)) < 0.3
        tri = np.arange(len(corner)).reshape(-1, 3)
        tri[flip] = tri[flip][:, ::-1]
        m = SkinnedMesh(positions=pos[corner], triangles=tri, joint_indices=j[corner], joint_weights=w[corner],
                        joint_names=[f"j{i}" for i in range(8)], parents=np.arange(8) - 1,
                        bind_transforms=np.tile(np.eye(4), (8, 1, 1)), rest_transforms=np.tile(np.eye(4), (8, 1, 1)))
        tw, (wm, _) = _best(lambda: weld(m), 2)
        to, _ = _best(lambda: orient(wm), 2)
        nlogn = len(faces) * math.log(len(faces))
        if base is None:
            base = (tw / nlogn, to / nlogn)
        rows.append({"triangles": len(faces), "weld_s": tw, "orient_s": to})
        echo(f"  {len(faces):>10} {tw:8.3f} {to:9.3f} {tw / nlogn / base[0]:15.2f} {to / nlogn / base[1]:17.2f}")
    echo("  (columns 4-5: time per n log n relative to the smallest size; <= ~1 means no worse than n log n)")
    return rows


def bench_simplify(triangles=200_000, target=5_000, bones=60, clips=2, frames=120, echo=print):
    """The 200,000-triangle tube reduced to ``target`` faces: the simplify stage (decimation and the
    deviation over every frame) beside the rest of the import, and a game frame (pose + 1 sphere
    + 16 rays, :func:`runtime.bench.game_frame`) on the proxy vs on the full mesh."""
    from colossus.runtime import load_collider
    from colossus.bench.runtime import _median_time, game_frame

    from colossus.pipeline.run import ImportSettings, import_asset
    from colossus.bench.synth import write_glb

    with tempfile.TemporaryDirectory() as tmp:
        small = os.path.join(tmp, "warm.glb")
        write_glb(small, 2_000, 8, 1, 10)
        import_asset(small, os.path.join(tmp, "warm.usda"), ImportSettings(target_faces=500))
        src = os.path.join(tmp, "bench.glb")
        nv, nf = write_glb(src, triangles, bones, clips, frames)
        full = import_asset(src, os.path.join(tmp, "full.usda"))
        prox = import_asset(src, os.path.join(tmp, "proxy.usda"), ImportSettings(target_faces=target))
        cf, cp = load_collider(os.path.join(tmp, "full.usda")), load_collider(os.path.join(tmp, "proxy.usda"))
        clip = cf.clips[0]
        tf = _median_time(game_frame(cf, clip), 50)
        tp = _median_time(game_frame(cp, clip), 50)
    rep = {r.stage: r for r in prox.reports}
    c = rep["simplify"].counts
    rest = sum(r.seconds for r in prox.reports if r.stage != "simplify")
    echo(f"simplify: {nf} triangles -> {c['faces_out']} ({bones} bones, {clips} clips x {frames} frames)")
    echo(f"  decimation (collapses, repair, skin transfer) {c['decimate_seconds']:8.3f} s")
    echo(f"  deviation over all {1 + clips * frames} poses          {c['deviation_seconds']:8.3f} s   "
         f"(bound {c['deviation']:.4g} = {100 * c['deviation_relative']:.3g}% of size)")
    echo(f"  rest of the import                            {rest:8.3f} s   (full import {full.seconds:.3f} s)")
    echo(f"  game frame: full {tf * 1e3:.3f} ms, proxy {tp * 1e3:.3f} ms = {tf / tp:.1f}x faster on the proxy")
    return {"faces_out": c["faces_out"], "decimate_s": c["decimate_seconds"], "deviation_s": c["deviation_seconds"],
            "rest_s": rest, "full_import_s": full.seconds, "frame_full_s": tf, "frame_proxy_s": tp}
