"""ufbx's own skinning of an FBX file: the independent reference for what the FBX reader carries.

``skinned_points(path, seconds)`` loads the file with ufbx, evaluates the first animation stack
at each time with ``evaluate_skinning=True`` (linear, dual-quaternion and Maya's blended
skinning, blend shapes, as ufbx evaluates them against Maya's and 3ds Max's own output) and
returns every skinned mesh's points in world space: our reader's code is not involved.  It runs
in a forked worker (the registry binding 0.0.5 frees element wrappers it still hands out; the
worker is terminated, never garbage-collected), and takes one reference per element it reads
for the same reason.
"""

from __future__ import annotations

import ctypes

import numpy as np


def _keep(x):
    import ufbx
    if isinstance(x, ufbx.Element):
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(x))
    return x


def _skinned(path, seconds):
    import gc

    import ufbx
    gc.disable()
    scene = ufbx.load_file(str(path), load_external_files=False)
    stacks = [_keep(s) for s in scene.anim_stacks]
    anim = stacks[0].anim if stacks else scene.anim
    out = []
    for t in seconds:
        ev = scene.evaluate(anim, float(t), evaluate_skinning=True)
        frame = []
        for node in (_keep(n) for n in ev.nodes):
            mesh = node.mesh
            if mesh is None or not len(mesh.skin_deformers):
                continue
            pos = np.array([tuple(v) for v in mesh.skinned_position.values], dtype=np.float64).reshape(-1, 3)
            if mesh.skinned_is_local:
                m = np.asarray(node.geometry_to_world, dtype=np.float64).reshape(4, 3)
                pos = pos @ m[:3].T + m[3]
            frame.append(pos)
        out.append(np.concatenate(frame) if frame else np.zeros((0, 3)))
    return out


def skinned_points(path, seconds) -> list:
    """``[(n, 3) float64]``: ufbx's skinned world points of every skinned mesh at each time
    (seconds, first stack), in the file's own axes and units.  (A forked worker of the standard
    library: the references import nothing of the project.)"""
    import multiprocessing
    import warnings

    with warnings.catch_warnings():  # the worker only runs ufbx: no thread of the parent is needed
        warnings.simplefilter("ignore", DeprecationWarning)
        with multiprocessing.get_context("fork").Pool(1) as pool:
            return pool.apply(_skinned, (str(path), list(seconds)))
