"""Blender's own view of collider assets (run by ``tests/references/test_blender.py`` with the
``bpy`` venv that ``make samples`` builds: CPython 3.11, never imported by the test suite itself).

Usage: ``python blender_points.py JOBS.json``.  Each job ``{"usd", "mesh", "times", "out"}``: a new
empty scene, ``bpy.ops.wm.usd_import`` of ``usd`` (Blender's USD importer, its defaults: armature
and modifiers, blend shapes as shape keys, unit and up-axis conversion), then at every time code
in ``times`` the evaluated mesh object named ``mesh`` (the armature modifier and shape keys
applied by Blender's depsgraph) in Blender's world space: saved as ``out`` (``.npy``, (T, n, 3)
float64), with the object's name list and the scene's frame rate in ``out + ".json"``.
"""

import json
import sys

import bpy
import numpy as np


def run(job):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=job["usd"])
    scene = bpy.context.scene
    meshes = [o for o in scene.objects if o.type == "MESH"]
    obj = next((o for o in meshes if o.name == job["mesh"]), meshes[0] if len(meshes) == 1 else None)
    info = {"objects": sorted(o.name for o in scene.objects), "fps": scene.render.fps / scene.render.fps_base,
            "mesh": obj.name if obj else None,
            "modifiers": [m.type for m in obj.modifiers] if obj else [],
            "shape_keys": len(obj.data.shape_keys.key_blocks) if obj and obj.data.shape_keys else 0}
    out = []
    for t in job["times"]:
        f = int(np.floor(t))
        scene.frame_set(f, subframe=float(t - f))
        dg = bpy.context.evaluated_depsgraph_get()
        ev = obj.evaluated_get(dg)
        m = ev.to_mesh()
        co = np.empty(len(m.vertices) * 3)
        m.vertices.foreach_get("co", co)
        w = np.array(ev.matrix_world, dtype=np.float64)
        out.append(co.reshape(-1, 3) @ w[:3, :3].T + w[:3, 3])
        ev.to_mesh_clear()
    np.save(job["out"], np.array(out))
    with open(job["out"] + ".json", "w") as fh:
        json.dump(info, fh)


if __name__ == "__main__":
    with open(sys.argv[1]) as fh:
        for job in json.load(fh)["jobs"]:
            run(job)
