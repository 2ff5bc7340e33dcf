"""Read the few FBX ``GlobalSettings`` that assimp does not apply: unit scale and up axis.

assimp's FBX importer leaves the header's ``UnitScaleFactor`` (centimetres per file unit) and
``UpAxis`` to the caller.  This is a small reader of the FBX node tree (binary 7.x and ASCII)
that looks only at ``GlobalSettings/Properties70``.
"""

from __future__ import annotations

import re
import struct
from zlib import error as zlib_error

_MAGIC = b"Kaydara FBX Binary  \x00"


def read_global_settings(path) -> dict:
    """Return ``{"UnitScaleFactor": float, "UpAxis": int, "UpAxisSign": int, ...}`` (what is present).

    Never raises on malformed input: an unreadable header yields ``{}``.
    """
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError:
        return {}
    try:
        if data.startswith(_MAGIC):
            return _binary(data)
        return _ascii(data.decode("utf-8", "replace"))
    except (struct.error, IndexError, ValueError, UnicodeError):
        return {}


def read_morph_geometry(path) -> dict:
    """``{name: number of blend-shape channels}`` for every FBX mesh with shape keys, keyed by
    both its Model and its Geometry name (assimp names meshes after either).  Binary FBX only;
    never raises (``{}`` when unreadable)."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
        if not data.startswith(_MAGIC):
            return {}
        return _morphs(data)
    except (OSError, struct.error, IndexError, ValueError, UnicodeError, zlib_error):
        return {}


#: FBX time units per second (FbxTime).
KTIME_PER_SECOND = 46186158000


def _object_properties(path, kind: str, wanted) -> dict:
    """``{object name: {property: value}}`` for every ``Objects/<kind>`` node of a binary FBX,
    with the ``Properties70`` entries named in ``wanted`` (their value, the fifth field); ``{}``
    for a file that is not binary FBX or cannot be walked."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
        if not data.startswith(_MAGIC):
            return {}
        nodes, props, sentinel = _walker(data)
        out = {}
        for top, _, _, children_at, end in nodes(27, len(data)):
            if top != "Objects":
                continue
            for cname, p_at, p_n, c_children, c_end in nodes(children_at, end - sentinel + 1):
                if cname != kind or p_n < 2:
                    continue
                name = str(props(p_at, 2)[1]).split("\x00")[0].split("::")[-1]
                found = out.setdefault(name, {})
                for pname, _, _, pc, pe in nodes(c_children, c_end - sentinel + 1):
                    if pname != "Properties70":
                        continue
                    for q, q_at, q_n, _, _ in nodes(pc, pe - sentinel + 1):
                        if q == "P" and q_n >= 5:
                            v = props(q_at, q_n)
                            if v[0] in wanted:
                                found[v[0]] = v[4]
        return out
    except (OSError, struct.error, IndexError, ValueError, UnicodeError, zlib_error):
        return {}


def read_anim_stacks(path) -> dict:
    """``{stack name: (start, stop)}`` in seconds of global scene time, from each
    ``AnimationStack``'s ``LocalStart``/``LocalStop`` (binary FBX only; ``{}`` when unreadable).

    assimp shifts every stack's keys so that the stack starts at time 0; this gives the shift
    back (stacks placed one after another on the global timeline keep their own times)."""
    out = {}
    try:
        for name, p in _object_properties(path, "AnimationStack",
                                          ("LocalStart", "LocalStop", "ReferenceStart", "ReferenceStop")).items():
            span = {k: float(v) / KTIME_PER_SECOND for k, v in p.items()}
            start = span.get("LocalStart", span.get("ReferenceStart"))
            stop = span.get("LocalStop", span.get("ReferenceStop"))
            if start is not None and stop is not None and stop >= start:
                out[name] = (start, stop)
    except (TypeError, ValueError, OverflowError):
        return {}
    return out


def read_inherit_types(path) -> dict:
    """``{model name: InheritType}`` for every FBX ``Model`` whose ``InheritType`` is authored
    (0 RrSs... FbxTransform::EInheritType: 0 eInheritRrSs, 1 eInheritRSrs, 2 eInheritRrs; Maya's
    joints with segment scale compensation are 2).  Binary FBX only; ``{}`` when unreadable."""
    try:
        return {name: int(p["InheritType"]) for name, p in _object_properties(path, "Model", ("InheritType",)).items()
                if "InheritType" in p}
    except (TypeError, ValueError, OverflowError):
        return {}


def _walker(data: bytes):
    version = struct.unpack_from("<I", data, 23)[0]
    wide = version >= 7500
    head = struct.Struct("<QQQB" if wide else "<IIIB")
    sentinel = head.size + 1  # a null record ends a node list

    def nodes(pos, end):
        while pos + head.size <= end:
            end_off, nprops, plen, nlen = head.unpack_from(data, pos)
            if end_off == 0:
                return
            if end_off <= pos or end_off > len(data):
                raise ValueError("bad node record")
            name = data[pos + head.size: pos + head.size + nlen].decode("ascii", "replace")
            props_at = pos + head.size + nlen
            yield name, props_at, nprops, props_at + plen, end_off
            pos = end_off

    def props(pos, count):
        out = []
        for _ in range(count):
            t = chr(data[pos]); pos += 1
            if t in "SR":
                n = struct.unpack_from("<I", data, pos)[0]; pos += 4
                v = data[pos:pos + n]; pos += n
                out.append(v.decode("utf-8", "replace") if t == "S" else v)
            elif t in "YCILFD":
                fmt = {"Y": "<h", "C": "<?", "I": "<i", "L": "<q", "F": "<f", "D": "<d"}[t]
                out.append(struct.unpack_from(fmt, data, pos)[0]); pos += struct.calcsize(fmt)
            else:  # arrays: skip
                _, enc, clen = struct.unpack_from("<III", data, pos); pos += 12 + clen
                out.append(None)
        return out

    return nodes, props, sentinel


def _morphs(data: bytes) -> dict:
    nodes, props, sentinel = _walker(data)
    kind, name = {}, {}
    links = []
    for top, _, _, children_at, end in nodes(27, len(data)):
        if top == "Objects":
            for cname, p_at, p_n, _, _ in nodes(children_at, end - sentinel + 1):
                if cname in ("Geometry", "Deformer", "Model") and p_n >= 3:
                    vals = props(p_at, 3)
                    if isinstance(vals[0], int) and isinstance(vals[1], str):
                        kind[vals[0]] = (cname, vals[2])
                        name[vals[0]] = vals[1].split("\x00")[0].split("::")[-1]
        elif top == "Connections":
            for cname, p_at, p_n, _, _ in nodes(children_at, end - sentinel + 1):
                if cname == "C" and p_n >= 3:
                    vals = props(p_at, 3)
                    if vals[0] == "OO":
                        links.append((vals[1], vals[2]))
    channels = {}
    parent_of = {}
    for child, parent in links:
        parent_of.setdefault(child, []).append(parent)
        if kind.get(child) == ("Deformer", "BlendShapeChannel"):
            channels[parent] = channels.get(parent, 0) + 1
    out = {}
    for bs, count in channels.items():
        for geo in parent_of.get(bs, []):
            if kind.get(geo, ("",))[0] != "Geometry":
                continue
            out[name[geo]] = max(out.get(name[geo], 0), count)
            for model in parent_of.get(geo, []):
                if kind.get(model, ("",))[0] == "Model":
                    out[name[model]] = max(out.get(name[model], 0), count)
    return out


def _binary(data: bytes) -> dict:
    nodes, props, sentinel = _walker(data)
    for name, pat, nprops, children_at, end in nodes(27, len(data)):
        if name != "GlobalSettings":
            continue
        for cname, _, _, c_children, c_end in nodes(children_at, end - sentinel + 1):
            if cname != "Properties70":
                continue
            result = {}
            for pname, p_at, p_n, _, _ in nodes(c_children, c_end - sentinel + 1):
                if pname == "P" and p_n >= 5:
                    vals = props(p_at, p_n)
                    if isinstance(vals[0], str):
                        result[vals[0]] = vals[4]
            return result
    return {}


_P = re.compile(r'P:\s*"(\w+)"\s*,\s*"[^"]*"\s*,\s*"[^"]*"\s*,\s*"[^"]*"\s*,\s*([-+0-9.eE]+)')


def _ascii(text: str) -> dict:
    start = text.find("GlobalSettings:")
    if start < 0:
        return {}
    out = {}
    for m in _P.finditer(text, start, min(len(text), start + 20000)):
        v = float(m.group(2))
        out[m.group(1)] = int(v) if v.is_integer() and m.group(1).endswith(("Axis", "Sign")) else v
    return out
