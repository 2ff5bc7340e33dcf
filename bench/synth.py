"""Write a skinned, animated tube as a real glTF 2.0 binary (``.glb``) for benchmarks.

The tube is a closed capped cylinder along +Y skinned smoothly to a chain of ``bones`` joints,
with ``clips`` animations of ``frames`` frames at 24 fps bending the chain.  Written with plain
numpy and json (no exporter needed) so ``make bench`` works without Blender.
"""

from __future__ import annotations

import json
import struct

import numpy as np


def tube(triangles: int, length: float = 10.0, radius: float = 0.6):
    """A closed capped tube with about ``triangles`` triangles.

    Returns
    -------
    positions : (n, 3) float32
    faces : (m, 3) uint32, counter-clockwise seen from outside
    """
    seg = max(8, int(round(np.sqrt(triangles / 5.0))))
    rings = max(2, int(round((triangles - 2 * seg) / (2 * seg))) + 1)
    y = np.linspace(0.0, length, rings)
    a = np.linspace(0.0, 2 * np.pi, seg, endpoint=False)
    ring = np.stack([radius * np.cos(a), np.zeros(seg), -radius * np.sin(a)], 1)
    pos = (ring[None] + y[:, None, None] * np.array([0, 1, 0])).reshape(-1, 3)
    pos = np.vstack([pos, [[0, 0, 0], [0, length, 0]]]).astype(np.float32)
    r, s = np.meshgrid(np.arange(rings - 1), np.arange(seg), indexing="ij")
    v00 = r * seg + s
    v01 = r * seg + (s + 1) % seg
    v10 = (r + 1) * seg + s
    v11 = (r + 1) * seg + (s + 1) % seg
    quads = np.concatenate([np.stack([v00, v01, v11], -1).reshape(-1, 3), np.stack([v00, v11, v10], -1).reshape(-1, 3)])
    bottom, top = rings * seg, rings * seg + 1
    s = np.arange(seg)
    cap0 = np.stack([np.full(seg, bottom), (s + 1) % seg, s], 1)
    cap1 = np.stack([np.full(seg, top), (rings - 1) * seg + s, (rings - 1) * seg + (s + 1) % seg], 1)
    faces = np.concatenate([quads, cap0, cap1]).astype(np.uint32)
    return pos, faces


def chain_weights(y: np.ndarray, bones: int, length: float, influences: int = 4):
    """Smooth weights of points at heights ``y`` over a chain of ``bones`` equal bones.

    Returns joints (n, influences) uint16 and weights (n, influences) float32 (summing to 1).
    """
    seg = length / bones
    centre = (np.arange(bones) + 0.5) * seg
    d = np.abs(y[:, None] - centre[None]) / seg
    w = np.clip(1.5 - d, 0.0, None) ** 2
    order = np.argsort(-w, axis=1)[:, :influences]
    wk = np.take_along_axis(w, order, 1)
    wk /= wk.sum(1, keepdims=True)
    return order.astype(np.uint16), wk.astype(np.float32)


def write_glb(path, triangles: int = 200_000, bones: int = 60, clips: int = 2, frames: int = 120, fps: float = 24.0):
    """Write the benchmark tube to ``path``; returns ``(vertex_count, triangle_count)``."""
    length = 10.0
    pos, faces = tube(triangles, length)
    joints, weights = chain_weights(pos[:, 1].astype(np.float64), bones, length)
    seg = length / bones
    ibm = np.tile(np.eye(4, dtype=np.float32), (bones, 1, 1))
    ibm[:, 1, 3] = -np.arange(bones) * seg  # joint j sits at y = j * seg (chain in world)
    blobs, views, accessors = [], [], []

    def add(arr, comp, ctype, target=None, minmax=False):
        arr = np.ascontiguousarray(arr)
        off = sum(len(b) for b in blobs)
        data = arr.tobytes()
        data += b"\0" * (-len(data) % 4)
        blobs.append(data)
        view = {"buffer": 0, "byteOffset": off, "byteLength": arr.nbytes}
        if target:
            view["target"] = target
        views.append(view)
        acc = {"bufferView": len(views) - 1, "componentType": ctype, "count": int(arr.shape[0]), "type": comp}
        if minmax:
            flat = arr.reshape(arr.shape[0], -1)
            acc["min"] = flat.min(0).tolist()
            acc["max"] = flat.max(0).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    a_pos = add(pos, "VEC3", 5126, 34962, minmax=True)
    a_idx = add(faces.reshape(-1), "SCALAR", 5125, 34963)
    a_j = add(joints, "VEC4", 5123, 34962)
    a_w = add(weights, "VEC4", 5126, 34962)
    a_ibm = add(np.swapaxes(ibm, 1, 2).reshape(bones, 16), "MAT4", 5126)
    # nodes: 0 = mesh, 1..bones = joints (chain), bones+1 = armature root
    nodes = [{"name": "Tube", "mesh": 0, "skin": 0}]
    for j in range(bones):
        n = {"name": f"bone_{j:02d}", "translation": [0.0, 0.0 if j == 0 else seg, 0.0]}
        if j + 1 < bones:
            n["children"] = [j + 2]
        nodes.append(n)
    nodes.append({"name": "Armature", "children": [0, 1]})
    t = (np.arange(frames) / fps).astype(np.float32)
    animations = []
    for c in range(clips):
        a_t = add(t, "SCALAR", 5126, minmax=True)
        channels, samplers = [], []
        for j in range(bones):
            ang = 0.25 * np.sin(2 * np.pi * (t / t[-1]) * (c + 1) + j * 0.3) / max(1, bones / 10)
            axis = np.array([0, 0, 1.0]) if c % 2 == 0 else np.array([1.0, 0, 0])
            q = np.zeros((frames, 4), dtype=np.float32)  # x y z w
            q[:, :3] = axis * np.sin(ang / 2)[:, None]
            q[:, 3] = np.cos(ang / 2)
            samplers.append({"input": a_t, "output": add(q, "VEC4", 5126), "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": j + 1, "path": "rotation"}})
        animations.append({"name": f"clip_{c}", "channels": channels, "samplers": samplers})
    binary = b"".join(blobs)
    doc = {
        "asset": {"version": "2.0", "generator": "colossus pipeline.synth.glb"},
        "scene": 0, "scenes": [{"nodes": [bones + 1]}], "nodes": nodes,
        "meshes": [{"name": "Tube", "primitives": [{"attributes": {"POSITION": a_pos, "JOINTS_0": a_j, "WEIGHTS_0": a_w},
                                                    "indices": a_idx, "mode": 4}]}],
        "skins": [{"joints": list(range(1, bones + 1)), "inverseBindMatrices": a_ibm, "skeleton": 1}],
        "animations": animations, "accessors": accessors, "bufferViews": views,
        "buffers": [{"byteLength": len(binary)}],
    }
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    total = 12 + 8 + len(js) + 8 + len(binary)
    with open(path, "wb") as fh:
        fh.write(struct.pack("<III", 0x46546C67, 2, total))
        fh.write(struct.pack("<II", len(js), 0x4E4F534A) + js)
        fh.write(struct.pack("<II", len(binary), 0x004E4942) + binary)
    return len(pos), len(faces)
