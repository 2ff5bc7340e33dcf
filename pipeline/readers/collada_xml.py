"""Collada skins and clips read from the XML, to check (and mend) what assimp hands over.

assimp gives every triangle corner of a Collada mesh a vertex of its own, in document order, and
its bones' weights should be those of each corner's ``VERTEX`` index in the skin controller's
``<vertex_weights>``.  For ``<polygons>`` primitives (one ``<p>`` per polygon, as Blender 2.6's
"Better Collada" exporter writes them) assimp 5/6 gives each vertex the influences of the Collada
vertex *before* its own (``assimp/library_animation_clips.dae``: 104 of 104 vertices shifted by
one, up to 0.24 x model size of wrong motion).  :func:`read_skins` reads, per skinned geometry,
the corner -> Collada vertex map and the file's own influences, so the reader can compare and use
the file's where they differ.  :func:`read_clips` reads ``<library_animation_clips>``: assimp
names those clips ``combinedAnim_<i>`` and plays each over its animations' whole key range
instead of the clip's ``start``..``end``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from ..errors import InputError


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _ints(text) -> np.ndarray:
    return np.array((text or "").split(), dtype=np.int64)


def _floats(text) -> np.ndarray:
    return np.array((text or "").split(), dtype=np.float64)


def _parse(path):
    """The file's XML root.  assimp's own reading of a Collada file differs from the file where this
    reader corrects it (vertex order of skins, clip names), so a file this reader cannot parse is
    refused, never silently left to assimp: a DTD with entities (never expanded: external or
    billion-laughs entities are a hostile file's), or XML that does not parse.  An unreadable
    file is left to the caller (its open fails the same way)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError:
        return None
    if b"<!ENTITY" in head or (b"<!DOCTYPE" in head and b"[" in head.split(b"<!DOCTYPE", 1)[1].split(b">", 1)[0]):
        raise InputError(path, "its XML declares DTD entities; they are never expanded (hostile XML?), so it is not read")
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as e:
        raise InputError(path, f"its Collada XML does not parse ({e}); assimp's reading of it would not be "
                         "corrected, so it is not read") from None
    except (OSError, ValueError):
        return None


def read_skins(path) -> dict:
    """``{geometry id or name: {"corners": (c,) int, "joints": [node names or ids, one per skin
    joint, as candidates], "vertex": (e,), "joint": (e,), "weight": (e,)}}`` for every skin
    controller of the file (``{}`` when it cannot be opened).  Raises :class:`InputError` for
    XML it cannot parse (:func:`_parse`)."""
    root = _parse(path)
    if root is None:
        return {}
    try:
        return _skins(root)
    except (KeyError, ValueError, IndexError, TypeError):
        return {}


def read_clips(path) -> list:
    """``[(name, start, end)]`` seconds, of the file's ``<animation_clip>`` elements in document
    order (``[]`` when there are none or the file cannot be opened; :class:`InputError` for XML
    it cannot parse, :func:`_parse`)."""
    root = _parse(path)
    if root is None:
        return []
    out = []
    for el in root.iter():
        if _local(el.tag) == "animation_clip":
            try:
                start, end = float(el.get("start", 0.0)), float(el.get("end", "nan"))
            except ValueError:
                continue
            out.append((el.get("name") or el.get("id") or "", start, end))
    return out


def _skins(root) -> dict:
    by_id = {}
    nodes_by_sid = {}
    for el in root.iter():
        i = el.get("id")
        if i:
            by_id[i] = el
        if _local(el.tag) == "node" and el.get("sid"):
            nodes_by_sid.setdefault(el.get("sid"), el)
    out = {}
    for skin in root.iter():
        if _local(skin.tag) != "skin":
            continue
        geom = by_id.get((skin.get("source") or "").lstrip("#"))
        if geom is None:
            continue
        sources = {s.get("id"): s for s in skin if _local(s.tag) == "source"}
        vw = next((c for c in skin if _local(c.tag) == "vertex_weights"), None)
        joints_el = next((c for c in skin if _local(c.tag) == "joints"), None)
        if vw is None or joints_el is None:
            continue
        inputs = {c.get("semantic"): c for c in vw if _local(c.tag) == "input"}
        jsrc = sources[inputs["JOINT"].get("source").lstrip("#")]
        wsrc = sources[inputs["WEIGHT"].get("source").lstrip("#")]
        arr = next(c for c in jsrc if _local(c.tag) in ("Name_array", "IDREF_array"))
        names = (arr.text or "").split()
        idref = _local(arr.tag) == "IDREF_array"
        candidates = []
        for n in names:
            node = by_id.get(n) if idref else nodes_by_sid.get(n, by_id.get(n))
            c = [n]
            if node is not None:
                c += [x for x in (node.get("id"), node.get("name"), node.get("sid")) if x]
            candidates.append(c)
        weights = _floats(next(c for c in wsrc if _local(c.tag) == "float_array").text)
        stride = max(int(c.get("offset", 0)) for c in inputs.values()) + 1
        joff, woff = int(inputs["JOINT"].get("offset", 0)), int(inputs["WEIGHT"].get("offset", 0))
        vcount = _ints(next(c for c in vw if _local(c.tag) == "vcount").text)
        v = _ints(next(c for c in vw if _local(c.tag) == "v").text).reshape(-1, stride)
        vertex = np.repeat(np.arange(len(vcount)), vcount)
        joint = v[:, joff]
        weight = weights[v[:, woff]]
        keep = joint >= 0  # -1 binds to the bind shape itself (no joint)
        corners = _corners(geom)
        if corners is None:
            continue
        entry = {"corners": corners, "joints": candidates, "vertex": vertex[keep], "joint": joint[keep],
                 "weight": weight[keep], "vertices": int(len(vcount))}
        for key in (geom.get("id"), geom.get("name")):
            if key:
                out[key] = entry
    return out


def _corners(geom):
    """Collada vertex index of every corner of every polygon primitive of ``geom``'s mesh, in
    document order (points and lines have no surface and are skipped, as assimp's
    SortByPType does)."""
    mesh = next((c for c in geom if _local(c.tag) == "mesh"), None)
    if mesh is None:
        return None
    out = []
    for prim in mesh:
        kind = _local(prim.tag)
        if kind not in ("triangles", "polylist", "polygons", "trifans", "tristrips"):
            continue
        inputs = [c for c in prim if _local(c.tag) == "input"]
        vin = next((c for c in inputs if c.get("semantic") == "VERTEX"), None)
        if vin is None:
            return None
        stride = max(int(c.get("offset", 0)) for c in inputs) + 1
        off = int(vin.get("offset", 0))
        for p in (c for c in prim if _local(c.tag) == "p"):
            idx = _ints(p.text)
            out.append(idx.reshape(-1, stride)[:, off])
        for ph in (c for c in prim if _local(c.tag) == "ph"):
            p = next((c for c in ph if _local(c.tag) == "p"), None)
            if p is not None:
                out.append(_ints(p.text).reshape(-1, stride)[:, off])
    return np.concatenate(out) if out else np.zeros(0, np.int64)
