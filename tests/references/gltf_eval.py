"""A small glTF 2.0 evaluator written from the specification, as an independent motion reference.

Specification: https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html (section numbers below
refer to it).  Only numpy, scipy and the standard library are used; nothing of the project.

What it covers
--------------
* Containers: ``.gltf`` (buffers as ``data:`` URIs or external files next to it) and ``.glb``
  (a JSON chunk and an optional BIN chunk, 4.4).
* Accessors (3.6.2): ``bufferView``/``byteOffset``/``byteStride``, every ``componentType``,
  ``normalized`` integers (3.11: ``c / 255``, ``max(c / 127, -1)``, ...), matrix column padding,
  accessors without a buffer view (zeros) and sparse accessors (3.6.2.3).
* Nodes (3.5.2): TRS or ``matrix``, the default scene's hierarchy.
* Skins (3.7.3): ``joints``, ``inverseBindMatrices`` (identity when absent); ``skeleton`` is not
  used for the math, as the specification says.  A skinned vertex is
  ``sum_k w_k * jointWorld_k(t) @ IBM_k @ p`` over every ``JOINTS_n``/``WEIGHTS_n`` set; the
  mesh node's own transform is ignored (3.7.3.3).  An unskinned primitive moves rigidly with its
  node's world transform, hence with any joint it is parented to.
* Animations (3.11): channels on ``translation``/``rotation``/``scale`` (also when a
  ``KHR_animation_pointer`` channel names them as ``/nodes/{i}/translation`` ...); samplers ``LINEAR``
  (lerp, and slerp for rotations along the shorter arc, as Appendix "Interpolation" and every
  implementation do), ``STEP`` and ``CUBICSPLINE`` (Hermite with in/out tangents scaled by the
  key interval, rotations normalised after).  Times are seconds; outside a sampler's key range
  its first/last value holds.  Morph targets (3.7.2.2) are applied before skinning: POSITION
  plus the weighted target displacements, the weights from the animation's ``weights`` channel
  of the node (its sampler, CUBICSPLINE included) or else the node's / mesh's default weights
  (:meth:`GltfDocument.morphed_positions`); the bind pose is POSITION as written.

Weights convention
------------------
The specification says the weights of a vertex should sum to 1; real files do not (three.js
RobotExpressive up to 1.755, CesiumMan down to 0.185).  Every skinning call takes
``normalise``: ``True`` (the default, what an importer that normalises must reproduce) divides
each vertex's weights by their sum; ``False`` evaluates them as written.  Vertices whose
weights sum to 0 are left at the origin as written and counted in
:attr:`Primitive.zero_weight_vertices`.

Quaternions are scalar-last ``(x, y, z, w)`` as in glTF and scipy.  Matrices are float64,
column-vector convention (``p' = M @ p``).
"""

from __future__ import annotations

import base64
import json
import os
import struct
import urllib.parse
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

#: componentType -> numpy dtype (3.6.2.2)
COMPONENT_TYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16,
                   5125: np.uint32, 5126: np.float32}
#: accessor type -> (rows, columns)
ACCESSOR_TYPES = {"SCALAR": (1, 1), "VEC2": (2, 1), "VEC3": (3, 1), "VEC4": (4, 1),
                  "MAT2": (2, 2), "MAT3": (3, 3), "MAT4": (4, 4)}
#: primitive modes that draw triangles (TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN)
TRIANGLE_MODES = (4, 5, 6)
#: extensions that change how geometry or animation is decoded; a file requiring one is refused
#: (KHR_mesh_quantization needs nothing more than the integer accessors decoded here)
UNSUPPORTED_REQUIRED = ("KHR_draco_mesh_compression", "EXT_meshopt_compression")


class GltfError(ValueError):
    """The file is not a glTF 2.0 asset this evaluator can read (message names the problem)."""


@dataclass(frozen=True)
class Primitive:
    """One drawn mesh primitive (a mesh on a node of the default scene).

    Attributes
    ----------
    key : str
        ``"<node name>/<mesh name>/<primitive index>"`` (unique within the file).
    node, mesh, index : int
        Node index, mesh index and primitive index within the mesh.
    node_name, mesh_name : str
    skin : int or None
        Skin index when the primitive is skinned (its node has a skin and it has ``JOINTS_0``).
    vertex_count : int
    mode : int
        glTF primitive mode (4 = triangles).
    used : (vertex_count,) bool
        Vertices referenced by the primitive's indices (all when it has none).
    weight_sum_range : (float, float)
        Min and max of the as-written weight sums (``(1, 1)`` for a rigid primitive).
    zero_weight_vertices : int
    morph_targets : int
    """

    key: str
    node: int
    node_name: str
    mesh: int
    mesh_name: str
    index: int
    skin: int | None
    vertex_count: int
    mode: int
    used: np.ndarray = field(repr=False)
    weight_sum_range: tuple = (1.0, 1.0)
    zero_weight_vertices: int = 0
    morph_targets: int = 0

    @property
    def skinned(self) -> bool:
        return self.skin is not None


@dataclass(frozen=True)
class Animation:
    """One glTF animation.

    Attributes
    ----------
    index : int
    name : str
        The animation's name, or ``animation_<index>`` when it has none (the contract's rule).
    key_times : (k,) float64
        Sorted union of the inputs of the samplers its TRS channels use (seconds).
    interpolations : tuple of str
        Interpolations its samplers use, sorted.
    morph_channels : int
        ``weights`` channels (morph target animation, applied by :meth:`GltfDocument.poses`).
    """

    index: int
    name: str
    key_times: np.ndarray = field(repr=False)
    interpolations: tuple
    morph_channels: int
    channels: tuple = field(repr=False, default=())  # (node, path, input (k,), output (k, c) or (k, 3, c), interpolation)
    #: ``weights`` channels: (node, input (k,), output (k, T) or (k, 3, T), interpolation)
    weight_channels: tuple = field(repr=False, default=())


def _read_container(path):
    """(json dict, BIN chunk bytes or None) of a .gltf or .glb file."""
    with open(path, "rb") as fh:
        data = fh.read()
    if data[:4] == b"glTF":
        magic, version, length = struct.unpack_from("<4sII", data, 0)
        if version != 2:
            raise GltfError(f"{path}: GLB container version {version}, expected 2")
        pos, doc, bin_chunk = 12, None, None
        while pos + 8 <= min(length, len(data)):
            clen, ctype = struct.unpack_from("<II", data, pos)
            chunk = data[pos + 8: pos + 8 + clen]
            if ctype == 0x4E4F534A:  # "JSON"
                doc = json.loads(chunk.decode("utf-8"))
            elif ctype == 0x004E4942 and bin_chunk is None:  # "BIN\0"
                bin_chunk = chunk
            pos += 8 + clen
        if doc is None:
            raise GltfError(f"{path}: GLB has no JSON chunk")
        return doc, bin_chunk
    return json.loads(data.decode("utf-8-sig")), None


def _trs(t, q, s):
    """(..., 3), (..., 4) xyzw, (..., 3) -> (..., 4, 4) = T @ R @ S."""
    t, q, s = (np.asarray(a, dtype=np.float64) for a in (t, q, s))
    shape = np.broadcast_shapes(t.shape[:-1], q.shape[:-1], s.shape[:-1])
    r = Rotation.from_quat(np.broadcast_to(q, shape + (4,)).reshape(-1, 4)).as_matrix().reshape(shape + (3, 3))
    out = np.zeros(shape + (4, 4))
    out[..., :3, :3] = r * np.broadcast_to(s, shape + (3,))[..., None, :]
    out[..., :3, 3] = np.broadcast_to(t, shape + (3,))
    out[..., 3, 3] = 1.0
    return out


class GltfDocument:
    """A parsed glTF 2.0 file that evaluates its drawn vertices at any animation time.

    Parameters
    ----------
    path : str or PathLike
        A ``.gltf`` or ``.glb`` file.

    Attributes
    ----------
    primitives : list of Primitive
        Every primitive drawn by the default scene, in node order.
    animations : list of Animation
    node_names : list of str
    parents : (n,) int64
        Parent node index, -1 for roots.
    """

    def __init__(self, path):
        self.path = os.fspath(path)
        self.doc, self._bin = _read_container(self.path)
        d = self.doc
        ver = str(d.get("asset", {}).get("version", ""))
        if not ver.startswith("2."):
            raise GltfError(f"{self.path}: asset.version {ver!r}, expected 2.x")
        bad = [e for e in d.get("extensionsRequired", []) if e in UNSUPPORTED_REQUIRED]
        if bad:
            raise GltfError(f"{self.path}: requires unsupported extension {bad[0]}")
        self._buffers = {}
        nodes = d.get("nodes", [])
        self.node_names = [n.get("name", f"node_{i}") for i, n in enumerate(nodes)]
        parents = np.full(len(nodes), -1, dtype=np.int64)
        for i, n in enumerate(nodes):
            for c in n.get("children", []):
                if parents[c] >= 0:
                    raise GltfError(f"{self.path}: node {c} has two parents")
                parents[c] = i
        self.parents = parents
        self._order = self._topological_order()
        self._static_t = np.zeros((len(nodes), 3))
        self._static_q = np.tile([0.0, 0.0, 0.0, 1.0], (len(nodes), 1))
        self._static_s = np.ones((len(nodes), 3))
        self._static_local = np.tile(np.eye(4), (len(nodes), 1, 1))
        self._is_matrix = np.zeros(len(nodes), dtype=bool)
        for i, n in enumerate(nodes):
            if "matrix" in n:
                # column-major 16 floats (3.5.3): reshape gives the transpose
                self._static_local[i] = np.array(n["matrix"], dtype=np.float64).reshape(4, 4).T
                self._is_matrix[i] = True
            else:
                self._static_t[i] = n.get("translation", [0, 0, 0])
                self._static_q[i] = n.get("rotation", [0, 0, 0, 1])
                self._static_s[i] = n.get("scale", [1, 1, 1])
        trs = ~self._is_matrix
        if trs.any():
            self._static_local[trs] = _trs(self._static_t[trs], self._static_q[trs], self._static_s[trs])
        self._scene_nodes = self._scene_node_set()
        self._ibm = {}
        self._skin_cache = {}
        self.primitives = self._collect_primitives()
        self.animations = [self._collect_animation(i, a) for i, a in enumerate(d.get("animations", []))]

    # ------------------------------------------------------------------ buffers and accessors
    def _buffer(self, i) -> bytes:
        if i not in self._buffers:
            b = self.doc["buffers"][i]
            uri = b.get("uri")
            if uri is None:
                if self._bin is None:
                    raise GltfError(f"{self.path}: buffer {i} has no uri and the file has no BIN chunk")
                data = self._bin
            elif uri.startswith("data:"):
                head, _, payload = uri.partition(",")
                data = base64.b64decode(payload) if head.endswith(";base64") else urllib.parse.unquote_to_bytes(payload)
            else:
                full = os.path.join(os.path.dirname(self.path), urllib.parse.unquote(uri))
                with open(full, "rb") as fh:
                    data = fh.read()
            if len(data) < b.get("byteLength", 0):
                raise GltfError(f"{self.path}: buffer {i} holds {len(data)} bytes, byteLength says {b['byteLength']}")
            self._buffers[i] = data
        return self._buffers[i]

    def _view_bytes(self, view_index):
        v = self.doc["bufferViews"][view_index]
        data = self._buffer(v["buffer"])
        start = v.get("byteOffset", 0)
        return data, start, v.get("byteLength", len(data) - start), v.get("byteStride")

    def _read_elements(self, view_index, byte_offset, count, dtype, rows, cols):
        """Raw (count, rows * cols) array of ``dtype`` from a buffer view, honouring stride and padding."""
        data, start, length, stride = self._view_bytes(view_index)
        isz = np.dtype(dtype).itemsize
        col_bytes = rows * isz
        col_stride = (col_bytes + 3) // 4 * 4 if cols > 1 else col_bytes  # matrix columns are 4-byte aligned
        elem = col_stride * cols
        stride = stride or elem
        base = start + byte_offset
        if count and base + (count - 1) * stride + elem > start + length:
            raise GltfError(f"{self.path}: accessor reads past the end of buffer view {view_index}")
        buf = np.frombuffer(data, dtype=np.uint8)
        out = np.empty((count, rows * cols), dtype=dtype)
        for c in range(cols):
            a = np.ndarray((count, rows), dtype=np.dtype(dtype).newbyteorder("<"), buffer=buf,
                           offset=base + c * col_stride, strides=(stride, isz)) if count else np.zeros((0, rows), dtype)
            out[:, c * rows:(c + 1) * rows] = a
        return out

    def accessor(self, index) -> np.ndarray:
        """Decoded accessor ``index``: ``(count, components)`` float64 (normalised integers mapped
        to [0, 1] / [-1, 1]) or integer for non-normalised integer types.  Matrices are
        ``(count, 16)`` column-major as stored."""
        a = self.doc["accessors"][index]
        dtype = COMPONENT_TYPES[a["componentType"]]
        rows, cols = ACCESSOR_TYPES[a["type"]]
        count = a["count"]
        if "bufferView" in a:
            raw = self._read_elements(a["bufferView"], a.get("byteOffset", 0), count, dtype, rows, cols)
        else:
            raw = np.zeros((count, rows * cols), dtype=dtype)
        if "sparse" in a:
            sp = a["sparse"]
            n = sp["count"]
            it = sp["indices"]
            idx = self._read_elements(it["bufferView"], it.get("byteOffset", 0), n,
                                      COMPONENT_TYPES[it["componentType"]], 1, 1)[:, 0].astype(np.int64)
            vt = sp["values"]
            vals = self._read_elements(vt["bufferView"], vt.get("byteOffset", 0), n, dtype, rows, cols)
            raw = raw.copy()
            raw[idx] = vals
        if dtype == np.float32:
            return raw.astype(np.float64)
        if a.get("normalized", False):
            x = raw.astype(np.float64)
            info = np.iinfo(dtype)
            # 3.11 "Animation Samplers" / 3.7.2.1: f = c / max for unsigned, max(c / max, -1) for signed
            return np.maximum(x / info.max, -1.0) if info.min < 0 else x / info.max
        return raw.astype(np.int64)

    # ------------------------------------------------------------------ hierarchy
    def _topological_order(self):
        order, seen = [], np.zeros(len(self.parents), dtype=bool)

        def visit(i):
            chain = []
            while i >= 0 and not seen[i]:
                chain.append(i)
                i = self.parents[i]
            for j in reversed(chain):
                seen[j] = True
                order.append(j)

        for i in range(len(self.parents)):
            visit(i)
        return np.array(order, dtype=np.int64)

    def _scene_node_set(self):
        d = self.doc
        scenes = d.get("scenes", [])
        if scenes:
            roots = scenes[d.get("scene", 0)].get("nodes", [])
        else:
            roots = [i for i in range(len(self.parents)) if self.parents[i] < 0]
        out, stack = set(), list(roots)
        while stack:
            i = stack.pop()
            if i in out:
                continue
            out.add(i)
            stack.extend(d["nodes"][i].get("children", []))
        return out

    def world(self, local) -> np.ndarray:
        """World transforms ``(..., n, 4, 4)`` from local transforms ``(..., n, 4, 4)``."""
        out = np.empty_like(local)
        for i in self._order:
            p = self.parents[i]
            out[..., i, :, :] = local[..., i, :, :] if p < 0 else out[..., p, :, :] @ local[..., i, :, :]
        return out

    def static_world(self) -> np.ndarray:
        """``(n, 4, 4)`` world transforms of the nodes as written (no animation)."""
        return self.world(self._static_local)

    # ------------------------------------------------------------------ meshes and skins
    def _collect_primitives(self):
        d = self.doc
        out = []
        for ni in sorted(self._scene_nodes):
            node = d["nodes"][ni]
            if "mesh" not in node:
                continue
            mi = node["mesh"]
            mesh = d["meshes"][mi]
            for pi, prim in enumerate(mesh["primitives"]):
                attrs = prim["attributes"]
                if "POSITION" not in attrs:
                    continue
                count = d["accessors"][attrs["POSITION"]]["count"]
                used = np.ones(count, dtype=bool)
                if "indices" in prim:
                    used[:] = False
                    idx = self.accessor(prim["indices"])[:, 0]
                    used[idx[idx < count]] = True
                skin = node.get("skin") if "JOINTS_0" in attrs and "WEIGHTS_0" in attrs else None
                wmin = wmax = 1.0
                zero = 0
                if skin is not None:
                    _, w = self._influences(mi, pi)
                    s = w.sum(axis=1)[used] if used.any() else np.ones(1)
                    wmin, wmax, zero = float(s.min()), float(s.max()), int(np.count_nonzero(s <= 0))
                out.append(Primitive(
                    key=f"{self.node_names[ni]}/{mesh.get('name', f'mesh_{mi}')}/{pi}", node=ni,
                    node_name=self.node_names[ni], mesh=mi, mesh_name=mesh.get("name", f"mesh_{mi}"), index=pi,
                    skin=skin, vertex_count=count, mode=prim.get("mode", 4), used=used,
                    weight_sum_range=(wmin, wmax), zero_weight_vertices=zero,
                    morph_targets=len(prim.get("targets", []))))
        return out

    def positions(self, prim: Primitive) -> np.ndarray:
        """``(vertex_count, 3)`` float64 POSITION of a primitive (mesh space)."""
        a = self.doc["meshes"][prim.mesh]["primitives"][prim.index]["attributes"]["POSITION"]
        return self.accessor(a)

    def triangles(self, prim: Primitive) -> np.ndarray:
        """``(m, 3)`` int64 triangles of a triangle-mode primitive (strips and fans unrolled)."""
        p = self.doc["meshes"][prim.mesh]["primitives"][prim.index]
        idx = self.accessor(p["indices"])[:, 0] if "indices" in p else np.arange(prim.vertex_count)
        if prim.mode == 4:
            return idx[: len(idx) // 3 * 3].reshape(-1, 3)
        if prim.mode == 5:
            t = [(idx[i], idx[i + 1], idx[i + 2]) if i % 2 == 0 else (idx[i + 1], idx[i], idx[i + 2])
                 for i in range(len(idx) - 2)]
            return np.array(t, dtype=np.int64).reshape(-1, 3)
        if prim.mode == 6:
            return np.array([(idx[0], idx[i], idx[i + 1]) for i in range(1, len(idx) - 1)], dtype=np.int64).reshape(-1, 3)
        return np.zeros((0, 3), dtype=np.int64)

    def _influences(self, mesh_index, prim_index):
        """(joints (V, 4s) int64, weights (V, 4s) float64) over every JOINTS_n/WEIGHTS_n set."""
        key = (mesh_index, prim_index)
        if key not in self._skin_cache:
            attrs = self.doc["meshes"][mesh_index]["primitives"][prim_index]["attributes"]
            js, ws, n = [], [], 0
            while f"JOINTS_{n}" in attrs and f"WEIGHTS_{n}" in attrs:
                js.append(self.accessor(attrs[f"JOINTS_{n}"]).astype(np.int64))
                ws.append(self.accessor(attrs[f"WEIGHTS_{n}"]).astype(np.float64))
                n += 1
            self._skin_cache[key] = (np.concatenate(js, axis=1), np.concatenate(ws, axis=1))
        return self._skin_cache[key]

    def influences(self, prim: Primitive):
        """``(joints, weights)``: ``(V, 4 * sets)`` int64 indices into the skin's ``joints`` and
        float64 weights as written."""
        return self._influences(prim.mesh, prim.index)

    def inverse_binds(self, skin) -> np.ndarray:
        """``(J, 4, 4)`` float64 inverse bind matrices of skin ``skin`` (identity when absent)."""
        if skin not in self._ibm:
            s = self.doc["skins"][skin]
            nj = len(s["joints"])
            if "inverseBindMatrices" in s:
                m = self.accessor(s["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
                if len(m) < nj:
                    raise GltfError(f"{self.path}: skin {skin} has {len(m)} inverse bind matrices for {nj} joints")
                m = m[:nj]
            else:
                m = np.tile(np.eye(4), (nj, 1, 1))
            self._ibm[skin] = m
        return self._ibm[skin]

    def skin_joints(self, skin) -> list:
        """Node indices of skin ``skin``'s joints."""
        return list(self.doc["skins"][skin]["joints"])

    def morph_offsets(self, prim: Primitive) -> np.ndarray:
        """``(targets, vertex_count, 3)`` float64 POSITION displacements of the primitive's morph
        targets (3.7.2.2; a target without POSITION moves nothing)."""
        tg = self.doc["meshes"][prim.mesh]["primitives"][prim.index].get("targets", [])
        out = np.zeros((len(tg), prim.vertex_count, 3))
        for i, t in enumerate(tg):
            if "POSITION" in t:
                out[i] = self.accessor(t["POSITION"])
        return out

    def morph_weights(self, prim: Primitive, animation, times) -> np.ndarray:
        """``(T, targets)`` morph weights of the primitive's node at ``times`` seconds: the
        animation's ``weights`` channel for the node (its sampler), else the default weights."""
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        w = np.broadcast_to(self.default_morph_weights(prim)[:prim.morph_targets], (len(times), prim.morph_targets))
        w = np.array(w)
        if animation is not None:
            anim = animation if isinstance(animation, Animation) else self.animations[animation]
            for node, inp, out, interp in anim.weight_channels:
                if node == prim.node:
                    w = self.sample(inp, out, interp, "weights", times)
        return w

    def morphed_positions(self, prim: Primitive, animation, times) -> np.ndarray:
        """``(T, vertex_count, 3)`` POSITION plus the weighted morph targets (3.7.2.2)."""
        p = self.positions(prim)
        if not prim.morph_targets:
            return np.broadcast_to(p, (len(np.atleast_1d(times)),) + p.shape)
        return p[None] + np.einsum("ti,ivc->tvc", self.morph_weights(prim, animation, times), self.morph_offsets(prim))

    def skin_points(self, prim: Primitive, joint_world: np.ndarray, normalise: bool = True,
                    points=None) -> np.ndarray:
        """Linear blend skinning of a skinned primitive (3.7.3.3).

        Parameters
        ----------
        joint_world : (J, 4, 4) float64
            World transform of each of the skin's joints (in ``skin.joints`` order).
        normalise : bool
            Divide each vertex's weights by their sum (see the module docstring).

        Returns
        -------
        (vertex_count, 3) float64 world positions ``sum_k w_k * joint_world[j_k] @ IBM[j_k] @ p``.
        """
        p = self.positions(prim) if points is None else points
        j, w = self.influences(prim)
        if normalise:
            s = w.sum(axis=1, keepdims=True)
            w = np.where(s > 0, w / np.where(s > 0, s, 1.0), w)
        jm = joint_world @ self.inverse_binds(prim.skin)
        if j.size and j.max() >= len(jm):
            raise GltfError(f"{self.path}: primitive {prim.key} uses joint {int(j.max())} of a {len(jm)}-joint skin")
        ph = np.concatenate([p, np.ones((len(p), 1))], axis=1)
        out = np.zeros((len(p), 3))
        for k in range(j.shape[1]):
            live = w[:, k] != 0
            if not live.any():
                continue
            m = jm[j[live, k]]  # (v, 4, 4)
            out[live] += w[live, k, None] * np.einsum("vij,vj->vi", m[:, :3, :], ph[live])
        return out

    # ------------------------------------------------------------------ animations
    def _collect_animation(self, index, a):
        chans, times, interps, morph = [], [], set(), 0
        wchans = []
        for ch in a.get("channels", []):
            tgt = ch.get("target", {})
            if tgt.get("path") == "pointer":  # KHR_animation_pointer: a JSON pointer names the property
                tgt = self._pointer_target(index, tgt)
                if tgt is None:
                    continue
            if "node" not in tgt:
                continue
            samp = a["samplers"][ch["sampler"]]
            interp = samp.get("interpolation", "LINEAR")
            if tgt["path"] == "weights":
                morph += 1
                inp = self.accessor(samp["input"])[:, 0].astype(np.float64)
                out = self.accessor(samp["output"]).astype(np.float64).reshape(-1)
                nt = len(self.doc["meshes"][self.doc["nodes"][tgt["node"]]["mesh"]]["primitives"][0].get("targets", []))
                if len(inp) and nt:
                    out = out.reshape(len(inp), 3, nt) if interp == "CUBICSPLINE" else out.reshape(len(inp), nt)
                    wchans.append((tgt["node"], inp, out, interp))
                continue
            if tgt["path"] not in ("translation", "rotation", "scale"):
                continue
            if self._is_matrix[tgt["node"]]:
                raise GltfError(f"{self.path}: animation {index} targets matrix node {tgt['node']} (3.11 forbids it)")
            inp = self.accessor(samp["input"])[:, 0].astype(np.float64)
            out = self.accessor(samp["output"]).astype(np.float64)
            ncomp = 4 if tgt["path"] == "rotation" else 3
            out = out.reshape(len(inp), 3, ncomp) if interp == "CUBICSPLINE" else out.reshape(len(inp), ncomp)
            if len(inp) == 0:
                continue
            if np.any(np.diff(inp) < 0):  # the spec says strictly increasing; equal times are tolerated
                raise GltfError(f"{self.path}: animation {index} sampler input decreases")
            chans.append((tgt["node"], tgt["path"], inp, out, interp))
            times.append(inp)
            interps.add(interp)
        name = a.get("name") or f"animation_{index}"
        kt = np.unique(np.concatenate(times)) if times else np.zeros(0)
        return Animation(index, name, kt, tuple(sorted(interps)), morph, tuple(chans), tuple(wchans))

    def _pointer_target(self, index, tgt):
        """A ``KHR_animation_pointer`` target as the plain target it stands for, when its JSON
        pointer (RFC 6901) is ``/nodes/{i}/translation|rotation|scale|weights``; None for any
        other pointer (materials, cameras, lights, ...: nothing this evaluator poses).

        KHR_animation_pointer: https://github.com/KhronosGroup/glTF/tree/main/extensions/2.0/Khronos/KHR_animation_pointer
        (the channel's ``target.path`` is ``"pointer"`` and ``target.node`` is absent; the sampler
        animates the property the pointer names exactly as a plain channel would)."""
        ptr = ((tgt.get("extensions") or {}).get("KHR_animation_pointer") or {}).get("pointer")
        if not isinstance(ptr, str):
            raise GltfError(f"{self.path}: animation {index}: a pointer channel without a pointer")
        parts = [p.replace("~1", "/").replace("~0", "~") for p in ptr.split("/")[1:]] if ptr.startswith("/") else []
        if len(parts) != 3 or parts[0] != "nodes" or parts[2] not in ("translation", "rotation", "scale", "weights"):
            return None
        if not parts[1].isdigit() or int(parts[1]) >= len(self.doc.get("nodes", [])):
            raise GltfError(f"{self.path}: animation {index}: pointer {ptr!r} names no node")
        return {"node": int(parts[1]), "path": parts[2]}

    @staticmethod
    def sample(inp, out, interp, path, times) -> np.ndarray:
        """Evaluate one sampler at ``times`` (T,) seconds -> ``(T, c)`` values (3.11, Appendix C).

        ``out`` is ``(k, c)`` for LINEAR/STEP and ``(k, 3, c)`` (in-tangent, value, out-tangent)
        for CUBICSPLINE.  Rotations come out as unit quaternions (x, y, z, w).
        """
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        values = out[:, 1] if interp == "CUBICSPLINE" else out
        k = len(inp)
        if k == 1:
            res = np.repeat(values[:1], len(times), axis=0)
        elif interp == "STEP":
            i = np.clip(np.searchsorted(inp, times, side="right") - 1, 0, k - 1)
            res = values[i]
        else:
            tc = np.clip(times, inp[0], inp[-1])
            i = np.clip(np.searchsorted(inp, tc, side="right") - 1, 0, k - 2)
            td = inp[i + 1] - inp[i]
            u = np.where(td > 0, (tc - inp[i]) / np.where(td > 0, td, 1.0), 1.0)  # a repeated time: the later key
            if interp == "LINEAR":
                if path == "rotation":
                    # slerp along the shorter arc: the relative rotation's rotvec has angle <= pi
                    r0 = Rotation.from_quat(values[i])
                    rel = (r0.inv() * Rotation.from_quat(values[i + 1])).as_rotvec()
                    return (r0 * Rotation.from_rotvec(rel * u[:, None])).as_quat()
                res = values[i] + (values[i + 1] - values[i]) * u[:, None]
            elif interp == "CUBICSPLINE":
                a_next, v0, b0, v1 = out[i + 1, 0], out[i, 1], out[i, 2], out[i + 1, 1]
                u2, u3 = u * u, u * u * u
                h00 = 2 * u3 - 3 * u2 + 1
                h10 = u3 - 2 * u2 + u
                h01 = -2 * u3 + 3 * u2
                h11 = u3 - u2
                res = (h00[:, None] * v0 + (td * h10)[:, None] * b0 + h01[:, None] * v1
                       + (td * h11)[:, None] * a_next)
            else:
                raise GltfError(f"unknown interpolation {interp!r}")
        if path == "rotation":
            res = res / np.linalg.norm(res, axis=1, keepdims=True)
        return res

    def local_transforms(self, animation, times) -> np.ndarray:
        """``(T, n, 4, 4)`` node local transforms at ``times`` seconds of animation ``animation``
        (an index or :class:`Animation`; ``None``: the nodes as written)."""
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        n = len(self.node_names)
        if animation is None:
            return np.broadcast_to(self._static_local, (len(times), n, 4, 4)).copy()
        anim = animation if isinstance(animation, Animation) else self.animations[animation]
        t = np.broadcast_to(self._static_t, (len(times), n, 3)).copy()
        q = np.broadcast_to(self._static_q, (len(times), n, 4)).copy()
        s = np.broadcast_to(self._static_s, (len(times), n, 3)).copy()
        touched = set()
        for node, path, inp, out, interp in anim.channels:
            v = self.sample(inp, out, interp, path, times)
            {"translation": t, "rotation": q, "scale": s}[path][:, node] = v
            touched.add(node)
        local = np.broadcast_to(self._static_local, (len(times), n, 4, 4)).copy()
        if touched:
            idx = np.array(sorted(touched))
            local[:, idx] = _trs(t[:, idx], q[:, idx], s[:, idx])
        return local

    def pose(self, animation, time, normalise: bool = True) -> list:
        """World positions of every drawn primitive at ``time`` seconds of ``animation``.

        Parameters
        ----------
        animation : int, Animation or None
            ``None`` poses the nodes as written (no animation).
        time : float
        normalise : bool
            See the module docstring.

        Returns
        -------
        list of (vertex_count, 3) float64, one per entry of :attr:`primitives`.
        """
        return self.poses(animation, [time], normalise)[0]

    def poses(self, animation, times, normalise: bool = True) -> list:
        """:meth:`pose` at each of ``times`` (T,) seconds (the samplers evaluated once for all).

        Returns
        -------
        list (T) of lists of (vertex_count, 3) float64.
        """
        worlds = self.world(self.local_transforms(animation, times))
        morphed = [self.morphed_positions(prim, animation, times) for prim in self.primitives]
        out = []
        for f, world in enumerate(worlds):
            frame = []
            for k, prim in enumerate(self.primitives):
                if prim.skinned:
                    frame.append(self.skin_points(prim, world[self.skin_joints(prim.skin)], normalise, morphed[k][f]))
                else:
                    m = world[prim.node]
                    frame.append(morphed[k][f] @ m[:3, :3].T + m[:3, 3])
            out.append(frame)
        return out

    def bind_world(self):
        """Node world transforms at the bind pose.

        Every skin joint sits at ``inv(IBM)`` (where the skins were bound); every other node
        follows its parent with its local transform as written.  A mesh parented to a joint
        therefore keeps its place relative to that joint, as it does in any animated pose.

        Returns
        -------
        world : (n, 4, 4) float64
        conflicts : int
            Joints whose inverse bind matrices disagree between skins (the first skin's wins).
        """
        at = {}
        conflicts = 0
        for s in range(len(self.doc.get("skins", []))):
            inv = np.linalg.inv(self.inverse_binds(s))
            for k, node in enumerate(self.skin_joints(s)):
                if node in at:
                    conflicts += int(not np.allclose(at[node], inv[k], rtol=1e-5, atol=1e-6 * max(1.0, np.abs(inv[k][:3, 3]).max())))
                else:
                    at[node] = inv[k]
        out = np.empty_like(self._static_local)
        for i in self._order:
            p = self.parents[i]
            if i in at:
                out[i] = at[i]
            else:
                out[i] = self._static_local[i] if p < 0 else out[p] @ self._static_local[i]
        return out, conflicts

    def joint_nodes(self) -> set:
        """Indices of the nodes that are a joint of some skin."""
        return {n for s in self.doc.get("skins", []) for n in s["joints"]}

    def default_morph_weights(self, prim: Primitive) -> np.ndarray:
        """``(targets,)`` float64 morph weights shown without animation (node ``weights``, else the
        mesh's, else zeros), applied where no animation drives them."""
        w = self.doc["nodes"][prim.node].get("weights", self.doc["meshes"][prim.mesh].get("weights"))
        return np.zeros(prim.morph_targets) if w is None else np.asarray(w, dtype=np.float64)

    def animated_nodes(self) -> set:
        """Indices of the nodes some animation moves (TRS channels)."""
        return {c[0] for a in self.animations for c in a.channels}

    def moves_with_skeleton(self, prim: Primitive) -> bool:
        """True for a skinned primitive, or one whose node or an ancestor is a joint or animated."""
        if prim.skinned:
            return True
        movers = self.joint_nodes() | self.animated_nodes()
        i = prim.node
        while i >= 0:
            if i in movers:
                return True
            i = self.parents[i]
        return False

    def bind_pose(self, normalise: bool = True) -> list:
        """Positions at the bind pose (see :meth:`bind_world`): a skinned vertex is its POSITION
        (when its weights sum to 1), a rigid one its node's bind world transform applied.

        Returns
        -------
        list of (vertex_count, 3) float64, one per entry of :attr:`primitives`.
        """
        world, _ = self.bind_world()
        out = []
        for prim in self.primitives:
            if prim.skinned:
                out.append(self.skin_points(prim, world[self.skin_joints(prim.skin)], normalise))
            else:
                m = world[prim.node]
                out.append(self.positions(prim) @ m[:3, :3].T + m[:3, 3])
        return out


def load(path) -> GltfDocument:
    """Parse a ``.gltf``/``.glb`` file (raises :class:`GltfError` when it cannot)."""
    return GltfDocument(path)
