"""Reader for glTF 2.0 (``.gltf`` with embedded or external buffers, ``.glb``), from the specification.

Read directly rather than through assimp because what a collider needs from glTF is exactly what
assimp does not hand over: each animation sampler's interpolation (LINEAR, STEP, CUBICSPLINE)
and its raw key times in seconds, the morph targets, several skins, and the node each mesh hangs
from.  The file becomes a :class:`~pipeline.readers.scene.Scene`; :func:`~pipeline.readers.scene.build.build`
does the rest (joints, rigid meshes, the frame grid).

Followed from the glTF 2.0 specification (https://registry.khronos.org/glTF/specs/2.0/glTF-2.0.html):

* accessors: ``byteOffset``/``byteStride``, ``normalized`` integer types, ``sparse`` substitution;
* nodes: ``matrix`` (column-major) or ``translation``/``rotation`` (x, y, z, w)/``scale``;
* skins: ``joints`` and ``inverseBindMatrices`` (identity when absent); a skinned mesh ignores its
  node's transform (section "Skins"), so its mesh-to-world transform at bind time is identity;
  ``JOINTS_n``/``WEIGHTS_n`` sets, all of them;
* primitives: TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN (points and lines carry no surface);
* animations: ``translation``/``rotation``/``scale`` channels (``weights`` channels drive morph
  targets, which the collider does not carry), times in seconds.

Y-up metres by specification.  Files this reader refuses say why in one line: not version 2.0,
a required extension (mesh compression), a pre-release draft (``jointNames``), bad accessors.
"""

from __future__ import annotations

import base64
import json
import os
import struct

import numpy as np

from ..errors import InputError, one_line
from ..xforms import compose_trs
from .. import notcarried
from .common import AllocationBudget, check_finite, check_input_file
from .scene import Animation, Channel, Scene, SceneMesh, Skin
from .scene.build import build

_COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_PATHS = {"translation": "t", "rotation": "r", "scale": "s"}
#: Extensions a file may require that this reader reads right (materials and textures do not
#: touch the collider; quantized attributes are plain normalized / integer accessors).
_SUPPORTED_REQUIRED = {"KHR_materials_unlit", "KHR_texture_transform", "KHR_materials_pbrSpecularGlossiness",
                       "KHR_texture_basisu", "EXT_texture_webp", "KHR_materials_emissive_strength",
                       "KHR_mesh_quantization", "EXT_texture_avif", "MSFT_texture_dds",
                       "KHR_animation_pointer"}  # node TRS read; what else can move the body is named
#: Extensions used (not required) that leave the collider exactly as read: materials, textures,
#: lights, metadata, and compressions whose uncompressed fallback the file also holds (a file
#: that needs them requires them, and is refused).
_HARMLESS_USED = {"KHR_mesh_quantization", "EXT_meshopt_compression", "KHR_draco_mesh_compression",
                  "KHR_lights_punctual", "FB_ngon_encoding", "KHR_xmp", "KHR_xmp_json_ld",
                  "MSFT_packing_normalRoughnessMetallic", "MSFT_packing_occlusionRoughnessMetallic",
                  "VRMC_materials_mtoon", "VRMC_materials_hdr_emissiveMultiplier", "CESIUM_primitive_outline"}
_HARMLESS_PREFIXES = ("KHR_materials_", "KHR_texture_", "EXT_texture_", "MSFT_texture_", "ADOBE_materials_",
                      "EXT_lights_")
#: What the extensions we name do to a collider that does not read them.
_EXTENSION_EFFECT = {
    "KHR_animation_pointer": "animation channels that point at morph weights or other node properties "
                             "than translation / rotation / scale are not read",
    "EXT_mesh_gpu_instancing": "mesh instances placed by per-instance transforms are not read",
    "VRMC_springBone": "spring-bone secondary motion (simulated at run time) is not carried",
    "VRMC_node_constraint": "node constraints (aim / roll / rotation) are not carried",
    "VRMC_vrm": "VRM look-at bones and expressions (driven at run time) are not carried",
    "VRM": "VRM 0.x secondary animation (spring bones) and blend shape groups are not carried",
    "KHR_node_visibility": "animated node visibility is not carried",
}


def extension_items(j: dict) -> list:
    """The :mod:`pipeline.notcarried` records of the extensions a glTF file uses that may change
    its geometry or deformation and that this reader does not read (one record per extension;
    ``KHR_animation_pointer`` only when a channel points at node transforms or morph weights)."""
    used = [e for e in (j.get("extensionsUsed") or []) if isinstance(e, str)]
    if "KHR_animation_pointer" not in used and any(  # pointer channels in a file that does not list it
            isinstance(ch, dict) and isinstance(ch.get("target"), dict) and ch["target"].get("path") == "pointer"
            for a in j.get("animations") or [] if isinstance(a, dict) for ch in a.get("channels") or []):
        used.append("KHR_animation_pointer")
    out = []
    for e in used:
        if e != "KHR_animation_pointer" and (e in _HARMLESS_USED or e in _SUPPORTED_REQUIRED
                                             or e.startswith(_HARMLESS_PREFIXES)):
            continue
        if e == "KHR_animation_pointer":
            ptrs = []
            for a in j.get("animations") or []:
                for ch in (a.get("channels") or []) if isinstance(a, dict) else []:
                    tgt = ch.get("target") or {} if isinstance(ch, dict) else {}
                    ptr = ((tgt.get("extensions") or {}).get(e) or {}).get("pointer") if isinstance(tgt, dict) else None
                    if isinstance(ptr, str) and pointer_target(ptr)[0] == "moves":
                        ptrs.append(ptr)
            if not ptrs:
                continue
            detail = (f"{_EXTENSION_EFFECT[e]}: {len(ptrs)} channel(s), e.g. {', '.join(ptrs[:3])}; the collider "
                      "does not move with them")
        else:
            detail = _EXTENSION_EFFECT.get(e, "extension not read by the collider's glTF reader; it may change "
                                              "the geometry or the deformation")
        out.append(notcarried.item("gltf_extension", [e], detail, None))
    return out


def pointer_target(ptr: str):
    """What a ``KHR_animation_pointer`` JSON pointer (RFC 6901) animates, for the collider:

    * ``("node", i, path)`` for ``/nodes/{i}/translation|rotation|scale``: read as a plain channel
      on node ``i`` (``i`` still to be range-checked), with its sampler's interpolation;
    * ``("moves", None, None)`` for what can move the body and is not carried: a node's morph
      ``weights`` (morph weights are read from plain channels only), ``/meshes/{i}/weights``, any other node
      property (``matrix``, a node extension such as ``KHR_node_visibility``);
    * ``("harmless", None, None)`` for the rest (materials, cameras, lights, textures, ...).

    https://github.com/KhronosGroup/glTF/tree/main/extensions/2.0/Khronos/KHR_animation_pointer
    """
    parts = [p.replace("~1", "/").replace("~0", "~") for p in ptr.split("/")[1:]] if ptr.startswith("/") else []
    if len(parts) >= 2 and parts[0] == "nodes":
        if len(parts) == 3 and parts[2] in _PATHS and parts[1].isdigit():
            return "node", int(parts[1]), _PATHS[parts[2]]
        return "moves", None, None
    if len(parts) == 3 and parts[0] == "meshes" and parts[2] == "weights":
        return "moves", None, None
    return "harmless", None, None


def morph_item(j: dict, g, chosen: list, size: float):
    """The ``morph_targets`` record of the chosen meshes whose morph targets are live (a weight
    that is not zero, by default or in an animation), with a bound: the sum over targets of the
    largest weight times the target's largest POSITION offset (mesh space), / ``size``; None when
    no chosen mesh's targets can move a vertex."""
    meshes = j.get("meshes") or []
    nodes = j.get("nodes") or []
    live, total = [], 0.0
    for mi, m in enumerate(meshes):
        name = str(m.get("name") or f"mesh_{mi}")
        if name not in chosen:
            continue
        prims = m.get("primitives") or []
        nt = max((len(p.get("targets") or []) for p in prims), default=0)
        if not nt:
            continue
        wmax = np.zeros(nt)
        wmax = np.maximum(wmax, np.abs(np.resize(np.asarray(m.get("weights") or [0.0], float), nt)))
        users = [i for i, n in enumerate(nodes) if isinstance(n, dict) and n.get("mesh") == mi]
        for i in users:
            if nodes[i].get("weights"):
                wmax = np.maximum(wmax, np.abs(np.resize(np.asarray(nodes[i]["weights"], float), nt)))
        for a in j.get("animations") or []:
            smp = a.get("samplers") or []
            for ch in a.get("channels") or []:
                tgt = ch.get("target") or {}
                if tgt.get("path") != "weights" or tgt.get("node") not in users:
                    continue
                try:
                    out = np.abs(g.accessor(smp[ch["sampler"]]["output"], "morph weights").astype(float)).reshape(-1)
                except (KeyError, IndexError, TypeError, ValueError):
                    continue
                if len(out) >= nt:
                    wmax = np.maximum(wmax, out[: len(out) // nt * nt].reshape(-1, nt).max(axis=0))
        if not wmax.any():
            continue
        reach = np.zeros(nt)
        for pi, p in enumerate(prims):
            for ti, t in enumerate(p.get("targets") or []):
                if "POSITION" in t:
                    d = g.accessor(t["POSITION"], f"mesh {name!r} primitive {pi} target {ti}").astype(float)
                    if len(d):
                        reach[ti] = max(reach[ti], float(np.linalg.norm(d, axis=1).max()))
        live.append(f"{name} ({nt})")
        total += float(np.sum(wmax * reach))
    if not live:
        return None
    return notcarried.item(
        "morph_targets", [x.rsplit(" (", 1)[0] for x in live],
        "morph targets / shape keys are not carried into the collider (it follows the skeleton only): "
        + ", ".join(live) + " (bound: largest weights times largest offsets, mesh space)", total / size)


class _File:
    """The JSON and the buffers of one glTF file, with checked accessor decoding."""

    def __init__(self, path):
        self.path = path
        with open(path, "rb") as fh:
            data = fh.read()
        bin_chunk = None
        if data[:4] == b"glTF":
            if len(data) < 20:
                raise InputError(path, "GLB header is truncated")
            version, length = struct.unpack_from("<II", data, 4)
            if version != 2:
                raise InputError(path, f"GLB container version {version} is not supported (2 only)")
            pos, chunks = 12, []
            while pos + 8 <= min(length, len(data)):
                clen, ctype = struct.unpack_from("<II", data, pos)
                chunks.append((ctype, data[pos + 8:pos + 8 + clen]))
                pos += 8 + clen + (-clen % 4)
            js = [c for t, c in chunks if t == 0x4E4F534A]
            if not js:
                raise InputError(path, "GLB has no JSON chunk")
            text = js[0]
            bins = [c for t, c in chunks if t == 0x004E4942]
            bin_chunk = bins[0] if bins else None
        else:
            text = data
        try:
            self.j = json.loads(text.decode("utf-8-sig") if isinstance(text, bytes) else text)
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(path, f"not a readable glTF file: JSON does not parse ({exc})") from None
        if not isinstance(self.j, dict):
            raise InputError(path, "not a readable glTF file: the JSON is not an object")
        version = str((self.j.get("asset") or {}).get("version", ""))
        if not version.startswith("2."):
            raise InputError(path, f"glTF version {version or '(none)'} is not supported (2.0 only)")
        need = set(self.j.get("extensionsRequired") or []) - _SUPPORTED_REQUIRED
        if need:
            raise InputError(path, f"requires glTF extension(s) this reader does not support: {', '.join(sorted(need))}")
        self.buffers = []
        for i, b in enumerate(self.j.get("buffers") or []):
            uri = b.get("uri")
            if uri is None:
                if bin_chunk is None:
                    raise InputError(path, f"buffer {i} has no uri and the file has no binary chunk")
                raw = bin_chunk
            elif uri.startswith("data:"):
                try:
                    raw = base64.b64decode(uri.split(",", 1)[1])
                except (IndexError, ValueError):
                    raise InputError(path, f"buffer {i}: data URI is not valid base64") from None
            else:  # a file beside it: checked before it is opened (runtime.references)
                from colossus.runtime.references import OutsideReference, open_regular, resolve
                try:
                    raw = open_regular(resolve(path, uri, f"buffer {i}"))
                except OutsideReference as e:
                    raise InputError(path, str(e)) from None
                except OSError:
                    raise InputError(path, f"buffer {i}: external file {uri!r} cannot be read") from None
            if len(raw) < int(b.get("byteLength", 0)):
                raise InputError(path, f"buffer {i} holds {len(raw)} bytes, byteLength says {b.get('byteLength')}")
            self.buffers.append(raw)

    def list(self, key):
        v = self.j.get(key) or []
        if not isinstance(v, list):
            raise InputError(self.path, f"'{key}' is not a list")
        return v

    def item(self, key, i, what):
        arr = self.list(key)
        if not isinstance(i, int) or isinstance(i, bool) or not 0 <= i < len(arr):
            raise InputError(self.path, f"{what}: {key} index {i!r} out of range ({len(arr)} {key})")
        if not isinstance(arr[i], dict):
            raise InputError(self.path, f"{what}: {key} {i} is not a JSON object")
        return arr[i]

    def _view(self, bv_index, dtype, width, count, offset, what):
        bv = self.item("bufferViews", bv_index, what)
        b = bv.get("buffer", 0)
        buf = self.buffers[b] if isinstance(b, int) and 0 <= b < len(self.buffers) else None
        if buf is None:
            raise InputError(self.path, f"{what}: buffer view {bv_index} names a missing buffer")
        item = np.dtype(dtype).itemsize * width
        stride = bv.get("byteStride") or item
        start = bv.get("byteOffset", 0) + offset
        end = start + (stride * (count - 1) + item if count else 0)
        if end > bv.get("byteOffset", 0) + bv.get("byteLength", 0) or end > len(buf):
            raise InputError(self.path, f"{what}: accessor reads past the end of its buffer view")
        if count == 0:
            return np.zeros((0, width), dtype)
        raw = np.frombuffer(buf, dtype=np.uint8, count=end - start, offset=start)
        if stride == item:
            return raw.view(dtype).reshape(count, width).copy()
        rows = np.lib.stride_tricks.as_strided(raw, shape=(count, item), strides=(stride, 1))
        return np.ascontiguousarray(rows).view(dtype).reshape(count, width)

    def accessor(self, i, what) -> np.ndarray:
        """Accessor ``i`` as ``(count, width)`` float64 (normalized integers mapped to [0, 1] /
        [-1, 1]) or the integer type for unnormalized integers."""
        a = self.item("accessors", i, what)
        try:
            dtype = _COMPONENT[a["componentType"]]
            width = _WIDTH[a["type"]]
            count = int(a["count"])
        except KeyError as exc:
            raise InputError(self.path, f"{what}: accessor {i} has a bad or missing {exc}") from None
        if count < 0:
            raise InputError(self.path, f"{what}: accessor {i} has a negative count ({count})")
        if "bufferView" in a:
            out = self._view(a["bufferView"], dtype, width, count, a.get("byteOffset", 0), what)
        else:
            out = np.zeros((count, width), dtype)
        sp = a.get("sparse")
        if sp:
            n = int(sp["count"])
            idx = self._view(sp["indices"]["bufferView"], _COMPONENT[sp["indices"]["componentType"]], 1, n,
                             sp["indices"].get("byteOffset", 0), what)[:, 0].astype(np.int64)
            val = self._view(sp["values"]["bufferView"], dtype, width, n, sp["values"].get("byteOffset", 0), what)
            if len(idx) and (idx.max() >= count or idx.min() < 0):
                raise InputError(self.path, f"{what}: sparse accessor {i} index out of range")
            out = out.copy()
            out[idx] = val
        if a.get("normalized") and dtype != np.float32:
            info = np.iinfo(dtype)
            f = out.astype(np.float64) / info.max
            return np.maximum(f, -1.0) if info.min < 0 else f
        with np.errstate(invalid="ignore"):  # signalling NaNs of a corrupt file: check_scene reports them
            return out.astype(np.float64) if dtype == np.float32 else out


def _node_matrix(n) -> np.ndarray:
    if "matrix" in n:
        m = np.array(n["matrix"], dtype=np.float64)
        if m.shape != (16,):
            raise ValueError("matrix must have 16 numbers")
        return m.reshape(4, 4).T  # column-major in the file
    t = np.array(n.get("translation", [0, 0, 0]), dtype=np.float64)
    r = np.array(n.get("rotation", [0, 0, 0, 1]), dtype=np.float64)
    s = np.array(n.get("scale", [1, 1, 1]), dtype=np.float64)
    if t.shape != (3,) or r.shape != (4,) or s.shape != (3,):
        raise ValueError("translation/rotation/scale have the wrong length")
    with np.errstate(over="ignore", invalid="ignore"):
        nr = np.linalg.norm(r)
    if not np.isfinite(nr):  # a huge but finite quaternion: scaled first, its norm would overflow
        big = float(np.abs(r).max())
        r, nr = (r / big, np.linalg.norm(r / big)) if np.isfinite(big) and big > 0 else (r, 0.0)
    return compose_trs(t, r / nr if nr > 0 else np.array([0, 0, 0, 1.0]), s)


def _triangles(mode, idx, path, what):
    idx = idx.reshape(-1).astype(np.int64)
    if mode == 4:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    if mode == 5:  # strip: alternate winding so every triangle keeps the strip's orientation
        if len(idx) < 3:
            return np.zeros((0, 3), np.int64)
        i = np.arange(len(idx) - 2)
        a, b, c = idx[i], idx[i + 1], idx[i + 2]
        odd = i % 2 == 1
        return np.stack([np.where(odd, b, a), np.where(odd, a, b), c], axis=1)
    if mode == 6:
        if len(idx) < 3:
            return np.zeros((0, 3), np.int64)
        i = np.arange(1, len(idx) - 1)
        return np.stack([np.full(len(i), idx[0]), idx[i], idx[i + 1]], axis=1)
    return None  # points / lines: no surface


def _sampler(path, samplers, ch, ai, what):
    """``(sampler, interpolation)`` of animation ``ai``'s channel ``ch``, checked (one line each)."""
    si = ch.get("sampler")
    if not isinstance(si, int) or not 0 <= si < len(samplers):
        raise InputError(path, f"{what}: sampler {si!r} out of range")
    smp = samplers[si]
    interp = smp.get("interpolation", "LINEAR")
    if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
        raise InputError(path, f"animation {ai}: unknown interpolation {interp!r}")
    return smp, interp


def read_scene(path, budget: AllocationBudget) -> Scene:
    """Read a glTF 2.0 file into a :class:`Scene` (no joint or mesh choice made yet)."""
    return _read_scene(path, budget)[0]


def _read_scene(path, budget: AllocationBudget):
    """``(scene, file)``: :func:`read_scene` and the :class:`_File` it read."""
    g = _File(path)
    nodes = g.list("nodes")
    k = len(nodes)
    for i, s in enumerate(g.list("skins")):
        if "joints" not in s:
            extra = " (it has 'jointNames': a pre-release glTF 2.0 draft)" if "jointNames" in s else ""
            raise InputError(path, f"skin {i} has no 'joints'{extra}")
    # parents, then a parents-first order
    parent = np.full(k, -1, dtype=np.int64)
    for i, n in enumerate(nodes):
        for c in n.get("children", []) or []:
            if not isinstance(c, int) or not 0 <= c < k or c == i:
                raise InputError(path, f"node {i}: child {c!r} out of range")
            if parent[c] >= 0:
                raise InputError(path, f"node {c} has two parents ({parent[c]} and {i})")
            parent[c] = i
    order = []
    stack = [i for i in range(k) if parent[i] < 0][::-1]
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend(reversed([c for c in nodes[i].get("children", []) or []]))
    if len(order) != k:
        raise InputError(path, "the node hierarchy has a cycle")
    new = np.empty(k, dtype=np.int64)
    new[order] = np.arange(k)
    parents = np.array([-1 if parent[i] < 0 else new[parent[i]] for i in order], dtype=np.int64)
    names = []
    seen = {}
    for i in order:
        nm = str(nodes[i].get("name") or f"node_{i}")
        names.append(nm)
        seen[nm] = seen.get(nm, 0) + 1
    try:
        local = np.array([_node_matrix(nodes[i]) for i in order]) if k else np.zeros((0, 4, 4))
    except (ValueError, TypeError) as exc:
        raise InputError(path, f"a node has a bad transform: {exc}") from None
    check_finite(path, "node transforms", local.reshape(k, 16))
    world = np.empty_like(local)
    for q, p in enumerate(parents):
        world[q] = local[q] if p < 0 else world[p] @ local[q]

    # ---- skins and meshes -----------------------------------------------------------------
    skins = []
    for i, s in enumerate(g.list("skins")):
        joints = s["joints"]
        if not isinstance(joints, list) or any(not isinstance(j, int) or not 0 <= j < k for j in joints):
            raise InputError(path, f"skin {i}: a joint index is out of range for {k} nodes")
        if "inverseBindMatrices" in s:
            ibm = g.accessor(s["inverseBindMatrices"], f"skin {i} inverseBindMatrices").astype(np.float64)
            if ibm.shape != (len(joints), 16):
                raise InputError(path, f"skin {i}: {len(ibm)} inverse bind matrices for {len(joints)} joints")
            ibm = ibm.reshape(-1, 4, 4).transpose(0, 2, 1)
            check_finite(path, f"skin {i} inverse bind matrices", ibm.reshape(len(joints), 16))
        else:
            ibm = np.tile(np.eye(4), (len(joints), 1, 1))
        skins.append((np.array([new[j] for j in joints], dtype=np.int64), ibm))
    meshes = []
    node_meshes = {}  # glTF node -> indices into meshes of its primitives (their morph targets)
    gl_meshes = g.list("meshes")
    for ni in order:
        n = nodes[ni]
        if "mesh" not in n:
            continue
        mi = n["mesh"]
        gm = g.item("meshes", mi, f"node {ni}")
        mname = str(gm.get("name") or f"mesh_{mi}")
        skin = None
        if "skin" in n:
            if not isinstance(n["skin"], int) or not 0 <= n["skin"] < len(skins):
                raise InputError(path, f"node {ni}: skin {n['skin']!r} out of range")
            skin = skins[n["skin"]]
        for pi, prim in enumerate(gm.get("primitives") or []):
            what = f"mesh {mname!r} primitive {pi}"
            attrs = prim.get("attributes") or {}
            if "POSITION" not in attrs:
                continue
            pos = g.accessor(attrs["POSITION"], what + " POSITION").astype(np.float64)
            nv = len(pos)
            budget.claim(nv * 200, f"{what} ({nv} vertices)")
            if pos.shape[1] != 3:
                raise InputError(path, f"{what}: POSITION is not VEC3")
            check_finite(path, f"{what} positions", pos)
            idx = (g.accessor(prim["indices"], what + " indices") if "indices" in prim
                   else np.arange(nv, dtype=np.int64))
            if np.issubdtype(np.asarray(idx).dtype, np.floating):
                raise InputError(path, f"{what}: indices are not integers")
            tri = _triangles(prim.get("mode", 4), np.asarray(idx), path, what)
            if tri is None:
                continue
            budget.claim(len(tri) * 40, f"{what} faces")
            if len(tri) and (tri.max() >= nv or tri.min() < 0):
                raise InputError(path, f"{what}: index {int(tri.max())} out of range for {nv} vertices")
            sk = None
            if skin is not None:
                sets = sorted(int(a.split("_")[1]) for a in attrs if a.startswith("JOINTS_") and a.split("_")[1].isdigit())
                vv, jj, ww = [], [], []
                for s_ in sets:
                    if f"WEIGHTS_{s_}" not in attrs:
                        continue
                    j = g.accessor(attrs[f"JOINTS_{s_}"], f"{what} JOINTS_{s_}")
                    w = g.accessor(attrs[f"WEIGHTS_{s_}"], f"{what} WEIGHTS_{s_}").astype(np.float64)
                    if j.shape != (nv, 4) or w.shape != (nv, 4):
                        raise InputError(path, f"{what}: JOINTS_{s_}/WEIGHTS_{s_} are not {nv} x VEC4")
                    check_finite(path, f"{what} weights", w)
                    if w.min() < 0:
                        raise InputError(path, f"{what}: negative skin weights")
                    j = j.astype(np.int64)
                    live = w > 0
                    if np.any(j[live] >= len(skin[0])) or np.any(j[live] < 0):
                        raise InputError(path, f"{what}: joint index out of range for its skin's {len(skin[0])} joints")
                    vv.append(np.broadcast_to(np.arange(nv)[:, None], (nv, 4))[live])
                    jj.append(j[live])
                    ww.append(w[live])
                if vv:
                    sk = Skin(skin[0], skin[1], [names[x] for x in skin[0]], np.concatenate(vv),
                              np.concatenate(jj), np.concatenate(ww))
            node_meshes.setdefault(ni, []).append(len(meshes))
            meshes.append(SceneMesh(
                name=mname, node=int(new[ni]), positions=pos, triangles=tri,
                to_world=np.eye(4) if sk is not None else world[new[ni]], skin=sk,
                morph_targets=len(prim.get("targets") or []),
                shapes=_morph_shapes(g, gm, prim, nv, what, path)))

    # ---- animations -----------------------------------------------------------------------
    anims = []
    for ai, a in enumerate(g.list("animations")):
        samplers = a.get("samplers") or []
        chans = []
        weights = _weight_channels(g, a, ai, samplers, nodes, node_meshes, meshes, path)
        for ci, ch in enumerate(a.get("channels") or []):
            tgt = ch.get("target") or {}
            if tgt.get("path") == "pointer":  # KHR_animation_pointer: node TRS pointers are plain channels
                ptr = ((tgt.get("extensions") or {}).get("KHR_animation_pointer") or {}).get("pointer")
                if not isinstance(ptr, str):
                    raise InputError(path, f"animation {ai} channel {ci}: a pointer channel without a "
                                           "KHR_animation_pointer pointer")
                kind, node, p = pointer_target(ptr)
                if kind != "node":
                    continue  # named in the summary when it can move the body (extension_items)
                if not 0 <= node < k:
                    raise InputError(path, f"animation {ai} channel {ci}: pointer {ptr!r} names node {node}, "
                                           f"out of range")
            else:
                p = _PATHS.get(tgt.get("path"))
                if p is None or "node" not in tgt:
                    continue  # morph weights / extension paths: not part of the skeleton's motion
                node = tgt["node"]
            if not isinstance(node, int) or not 0 <= node < k:
                raise InputError(path, f"animation {ai} channel {ci}: node {node!r} out of range")
            what = f"animation {ai} channel {ci}"
            smp, interp = _sampler(path, samplers, ch, ai, what)
            t = g.accessor(smp["input"], what + " input").astype(np.float64).reshape(-1)
            v = g.accessor(smp["output"], what + " output").astype(np.float64)
            width = 4 if p == "r" else 3
            if v.shape[1] != width:
                raise InputError(path, f"{what}: output has {v.shape[1]} components, expected {width}")
            check_finite(path, f"{what} key times", t[:, None])
            check_finite(path, f"{what} key values", v)
            if len(t) > 1 and np.any(np.diff(t) <= 0):
                raise InputError(path, f"{what}: key times are not strictly increasing")
            if interp == "CUBICSPLINE":
                if len(v) != 3 * len(t):
                    raise InputError(path, f"{what}: CUBICSPLINE output has {len(v)} values for {len(t)} keys (expected 3 per key)")
                v = v.reshape(len(t), 3, width)
            elif len(v) != len(t):
                raise InputError(path, f"{what}: {len(t)} key times but {len(v)} values")
            if p == "r":
                vals = v[:, 1] if interp == "CUBICSPLINE" else v
                with np.errstate(over="ignore", invalid="ignore"):  # a huge quaternion: refused just below
                    nrm = np.linalg.norm(vals, axis=-1)
                if np.any(nrm < 1e-12):
                    raise InputError(path, f"{what}: a zero rotation quaternion")
                if interp != "CUBICSPLINE":
                    v = v / nrm[:, None]
            if len(t):
                chans.append(Channel(int(new[node]), p, t, v, interp))
        anims.append(Animation(str(a.get("name") or ""), chans, weights=weights))
    return Scene(names=names, parents=parents, local=local, meshes=meshes, animations=anims,
                 sampling_note="glTF samplers read from the file"), g


def _morph_shapes(g, gm, prim, nv, what, path) -> list:
    """A primitive's morph targets as :class:`model.BlendShape` (glTF 2.0 section 3.7.2.2: the
    morphed position is ``POSITION + sum_i w_i POSITION_i``, linear in the weights: no
    in-betweens), each on the vertices it moves; named by the mesh's ``extras.targetNames`` where
    given.  Targets without POSITION move nothing (normals and tangents are not collision)."""
    from ..model import BlendShape

    targets = prim.get("targets") or []
    names = (gm.get("extras") or {}).get("targetNames") if isinstance(gm.get("extras"), dict) else None
    out = []
    for ti, t in enumerate(targets):
        name = str(names[ti]) if isinstance(names, list) and ti < len(names) else f"target_{ti}"
        if not isinstance(t, dict) or "POSITION" not in t:
            off = np.zeros((0, 3))
            idx = np.zeros(0, np.int64)
        else:
            d = g.accessor(t["POSITION"], f"{what} morph target {ti} POSITION").astype(np.float64)
            if d.shape != (nv, 3):
                raise InputError(path, f"{what}: morph target {ti} POSITION is {d.shape}, expected ({nv}, 3)")
            check_finite(path, f"{what} morph target {ti} positions", d)
            idx = np.flatnonzero(np.any(d != 0, axis=1))
            off = d[idx]
        out.append(BlendShape(name, idx, off))
    return out


def _default_weights(gm, node, count) -> np.ndarray:
    """A mesh instance's morph weights when no animation drives them: the node's ``weights``,
    else the mesh's, else 0 (glTF 2.0 section 3.7.2.2)."""
    w = node.get("weights") if node.get("weights") is not None else gm.get("weights")
    out = np.zeros(count)
    if w:
        w = np.asarray(w, dtype=np.float64).reshape(-1)[:count]
        out[:len(w)] = w
    return out


def _weight_channels(g, a, ai, samplers, nodes, node_meshes, meshes, path) -> list:
    """Animation ``a``'s morph-weight channels (``target.path == "weights"``) as weight
    :class:`Channel` per scene mesh (each primitive of the node's mesh), with their sampler's
    interpolation (LINEAR, STEP, CUBICSPLINE: the glTF spec's Hermite, in-tangent / value /
    out-tangent per key); a mesh instance the animation does not drive keeps its default weights
    (a static channel)."""
    out, driven = [], set()
    for ci, ch in enumerate(a.get("channels") or []):
        tgt = ch.get("target") or {}
        if tgt.get("path") != "weights" or not isinstance(tgt.get("node"), int):
            continue
        ni = tgt["node"]
        if ni not in node_meshes:
            continue
        what = f"animation {ai} channel {ci}"
        smp, interp = _sampler(path, samplers, ch, ai, what)
        t = g.accessor(smp["input"], what + " input").astype(np.float64).reshape(-1)
        v = g.accessor(smp["output"], what + " output").astype(np.float64).reshape(-1)
        count = len(meshes[node_meshes[ni][0]].shapes)
        if count == 0 or len(t) == 0:
            continue
        per = 3 if interp == "CUBICSPLINE" else 1
        if len(v) != per * len(t) * count:
            raise InputError(path, f"{what}: {len(v)} morph weights for {len(t)} keys x {count} targets"
                             + (" x 3 (CUBICSPLINE)" if per == 3 else ""))
        check_finite(path, f"{what} key times", t[:, None])
        check_finite(path, f"{what} morph weights", v[:, None])
        if len(t) > 1 and np.any(np.diff(t) <= 0):
            raise InputError(path, f"{what}: key times are not strictly increasing")
        v = v.reshape(len(t), 3, count) if per == 3 else v.reshape(len(t), count)
        driven.add(ni)
        out += [Channel(m, "w", t, v, interp) for m in node_meshes[ni]]
    for ni, ms in node_meshes.items():
        if ni in driven or not meshes[ms[0]].shapes:
            continue
        gm = g.item("meshes", nodes[ni]["mesh"], f"node {ni}")
        w = _default_weights(gm, nodes[ni], len(meshes[ms[0]].shapes))
        if np.any(w != 0):
            out += [Channel(m, "w", np.zeros(1), w[None], static=True) for m in ms]
    return out


def read_gltf(path, meshes=None, fps=None):
    """Read a glTF 2.0 file into a :class:`~pipeline.model.SkinnedMesh` (see the module docstring).

    Parameters
    ----------
    path : str or PathLike
    meshes : list of str, optional
        glTF mesh names to take; default every skinned mesh and every mesh parented to a joint.
    fps : float, optional
        Frame grid rate; default the file's own (the rate every key falls on), else 30.
    """
    path = os.fspath(path)
    size = check_input_file(path)
    budget = AllocationBudget(path, size)
    ext = os.path.splitext(path)[1].lower()
    try:
        scene, g = _read_scene(path, budget)
    except (TypeError, KeyError, AttributeError, IndexError, ValueError, OverflowError) as exc:
        # the JSON's values are of the wrong type or shape where the specification fixes them
        # (a number where an object belongs, a missing required property): a malformed file
        raise InputError(path, f"malformed glTF ({type(exc).__name__}: {one_line(exc, 120)})") from None
    mesh = build(scene, path, meshes=meshes, fps=fps, budget=budget,
                 source={"file": os.path.basename(path), "format": ext.lstrip("."), "reader": "gltf",
                         "frame": "glTF: Y-up metres by specification"})
    items = extension_items(g.j)
    if mesh.source.get("morph_meshes"):
        from .bounds import posed_size
        try:
            m_item = morph_item(g.j, g, list(mesh.source["morph_meshes"]), posed_size(mesh))
        except (TypeError, KeyError, AttributeError, IndexError, ValueError) as exc:
            raise InputError(path, f"malformed glTF morph targets ({type(exc).__name__}: {one_line(exc, 120)})") from None
        if m_item is not None:
            items.insert(0, m_item)
        else:
            mesh.source["notes"] = mesh.source.get("notes", []) + [
                "morph targets of " + ", ".join(f"{k} ({v})" for k, v in mesh.source["morph_meshes"].items())
                + " have weight 0 by default and in every clip: nothing of them to carry"]
        mesh.source["morph_meshes"] = {}  # judged here: live targets only
    mesh.source["not_carried"] = items
    return mesh.replace(up_axis="Y", meters_per_unit=1.0)
