"""An asset as any UsdSkel consumer shows it, against the runtime (imported by tests; never a test module).

:func:`bake_every_variant` selects each variant of the SkelRoot's ``clip`` variant set in turn (as
usdview's or Blender's user would), bakes a flattened copy with ``UsdSkel.BakeSkinning`` and reads
back, at every frame of the clip, the collision mesh's world points and each guide sphere's world
centre and radius (its baked local-to-world applied to the sphere's origin, the radius scaled by
the largest axis scale: the contract's radius scale), next to the runtime's ``pose.points`` and
``pose.spheres`` for that clip.
"""

from __future__ import annotations

import os

import numpy as np


def bake_every_variant(path, frames_per_clip: int | None = None) -> dict:
    """Bake each clip variant of the asset at ``path`` and compare with the runtime.

    Returns
    -------
    dict
        ``variants`` (list of variant names), ``default`` (the selection as authored), ``clips``
        (the runtime's clip names), ``size`` (the runtime's model size), ``spheres`` / ``mesh``:
        the largest difference (stage units) over every compared frame of every variant between
        the baked guide spheres (centre and radius) / mesh points and the runtime's, ``guides``:
        the number of guide spheres, ``baked``: ``{variant: (T, V, 3) baked mesh points at the
        compared frames}``, ``times``: ``{variant: compared time codes}``.
    """
    from pxr import Gf, Usd, UsdGeom, UsdSkel

    from colossus import load_collider

    path = os.fspath(path)
    col = load_collider(path)
    stage = Usd.Stage.Open(path)
    vset = stage.GetDefaultPrim().GetVariantSets().GetVariantSet("clip")
    out = {"variants": list(vset.GetVariantNames()), "default": vset.GetVariantSelection(), "clips": col.clips,
           "size": col.size(), "spheres": 0.0, "mesh": 0.0, "guides": 0, "baked": {}, "times": {}}
    for name in out["variants"]:
        vset.SetVariantSelection(name)
        copy = Usd.Stage.Open(stage.Flatten())
        times = col.frame_times(name)
        if frames_per_clip is not None and len(times) > frames_per_clip:
            times = times[np.linspace(0, len(times) - 1, frames_per_clip).round().astype(int)]
        assert UsdSkel.BakeSkinning(copy.Traverse(), Gf.Interval(float(times.min()), float(times.max())))
        guides = [p for p in copy.Traverse() if p.IsA(UsdGeom.Sphere)]
        out["guides"] = len(guides)
        mesh = copy.GetPrimAtPath(col.data.mesh_path)
        baked = []
        for t in times:
            tc = Usd.TimeCode(float(t))
            xf = UsdGeom.XformCache(tc)
            pose = col.pose(name, float(t))
            for g in guides:
                p = g.GetCustomDataByKey("colossus:part")
                w = np.array(xf.GetLocalToWorldTransform(g), dtype=np.float64).reshape(4, 4)  # row-vector
                r = float(UsdGeom.Sphere(g).GetRadiusAttr().Get(tc)) * np.linalg.norm(w[:3, :3], axis=1).max()
                err = max(np.abs(w[3, :3] - pose.spheres[p, :3]).max(), abs(r - pose.spheres[p, 3]))
                out["spheres"] = max(out["spheres"], float(err))
            w = np.array(xf.GetLocalToWorldTransform(mesh), dtype=np.float64).reshape(4, 4)
            pts = np.asarray(UsdGeom.Mesh(mesh).GetPointsAttr().Get(tc), dtype=np.float64) @ w[:3, :3] + w[3, :3]
            out["mesh"] = max(out["mesh"], float(np.abs(pts - pose.points).max()))
            baked.append(pts)
        out["baked"][name] = np.array(baked)
        out["times"][name] = times
    vset.SetVariantSelection(out["default"])
    return out
