"""Read a binary FBX into an editable tree that keeps every property's type code, and write it
back as binary (any version) or as ASCII FBX 7 -- to build small test files from real ones
(``samples/limb.fbx``): a skin made dual-quaternion, a model given a geometric transform, ...

Independent of the project's own FBX code (tests must not judge the reader with itself).
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

MAGIC = b"Kaydara FBX Binary  \x00\x1a\x00"
_SCALAR = {"Y": "<h", "C": "<?", "I": "<i", "F": "<f", "D": "<d", "L": "<q"}
_ARRAY = {"f": "<f4", "d": "<f8", "l": "<i8", "i": "<i4", "b": "u1"}


@dataclass
class N:
    """A node: name, ``props`` as ``[(type code, value)]`` (arrays: numpy), children."""

    name: str
    props: list = field(default_factory=list)
    children: list = field(default_factory=list)
    block: bool = False  #: written with a (possibly empty) children block, as some readers expect

    def child(self, name):
        return next((c for c in self.children if c.name == name), None)

    def all(self, name):
        return [c for c in self.children if c.name == name]


def read(path):
    """``(version, top-level nodes, footer bytes)`` of a binary FBX file."""
    data = open(path, "rb").read()
    assert data.startswith(MAGIC[:21])
    version = struct.unpack_from("<I", data, 23)[0]
    head = struct.Struct("<QQQB" if version >= 7500 else "<IIIB")

    def props(pos, count):
        out = []
        for _ in range(count):
            t = chr(data[pos])
            pos += 1
            if t in _SCALAR:
                out.append((t, struct.unpack_from(_SCALAR[t], data, pos)[0]))
                pos += struct.calcsize(_SCALAR[t])
            elif t in "SR":
                n = struct.unpack_from("<I", data, pos)[0]
                raw = data[pos + 4:pos + 4 + n]
                out.append((t, raw.decode("utf-8", "surrogateescape") if t == "S" else raw))
                pos += 4 + n
            else:
                n, enc, clen = struct.unpack_from("<III", data, pos)
                raw = data[pos + 12:pos + 12 + clen]
                if enc == 1:
                    raw = zlib.decompress(raw)
                out.append((t, np.frombuffer(raw, dtype=_ARRAY[t], count=n).copy()))
                pos += 12 + clen
        return out

    def nodes(pos, end):
        out = []
        while pos + head.size <= end:
            end_off, nprops, plen, nlen = head.unpack_from(data, pos)
            if end_off == 0:
                return out, pos + head.size
            name = data[pos + head.size:pos + head.size + nlen].decode("ascii")
            pat = pos + head.size + nlen
            kids, _ = nodes(pat + plen, end_off)
            out.append(N(name, props(pat, nprops), kids, block=end_off > pat + plen))
            pos = end_off
        return out, pos

    top, after = nodes(27, len(data))
    return version, top, data[after:]


def write_binary(path, version, top, footer=b""):
    head = struct.Struct("<QQQB" if version >= 7500 else "<IIIB")
    null = b"\x00" * head.size

    def enc_props(props):
        out = b""
        for t, v in props:
            out += t.encode()
            if t in _SCALAR:
                out += struct.pack(_SCALAR[t], v)
            elif t == "S":
                b = v.encode("utf-8", "surrogateescape")
                out += struct.pack("<I", len(b)) + b
            elif t == "R":
                out += struct.pack("<I", len(v)) + bytes(v)
            else:
                raw = np.ascontiguousarray(v, dtype=_ARRAY[t]).tobytes()
                if len(raw) > 128:  # as the FBX SDK and Blender write them
                    z = zlib.compress(raw)
                    out += struct.pack("<III", len(v), 1, len(z)) + z
                else:
                    out += struct.pack("<III", len(v), 0, len(raw)) + raw
        return out

    def enc(node, pos):
        p = enc_props(node.props)
        name = node.name.encode("ascii")
        body_at = pos + head.size + len(name) + len(p)
        kids = b""
        for c in node.children:
            kids += enc(c, body_at + len(kids))
        if node.children or not node.props or node.block:
            kids += null
        end = body_at + len(kids)
        return head.pack(end, len(node.props), len(p), len(name)) + name + p + kids

    out = bytearray(MAGIC + struct.pack("<I", version))
    for n in top:
        out += enc(n, len(out))
    out += null + footer
    with open(path, "wb") as fh:
        fh.write(bytes(out))


def _ascii_value(t, v):
    if t == "S":
        s = v.encode("utf-8", "surrogateescape").decode("utf-8", "replace")
        if "\x00\x01" in s:
            name, cls = s.split("\x00\x01", 1)
            s = f"{cls}::{name}"
        return '"' + s.replace('"', "&quot;") + '"'
    if t == "R":
        return '""'
    if t == "C":
        return "T" if v else "F"
    if t in "FD":
        return repr(float(v))
    return str(int(v))


def write_ascii(path, version, top):
    lines = [f"; FBX {version // 1000}.{version % 1000 // 100}.0 project file", ""]

    def emit(node, depth):
        ind = "\t" * depth
        arrays = [(t, v) for t, v in node.props if isinstance(v, np.ndarray)]
        if arrays:
            t, v = arrays[0]
            vals = ",".join(repr(float(x)) if t in "fd" else str(int(x)) for x in v)
            lines.append(f"{ind}{node.name}: *{len(v)} {{")
            lines.append(f"{ind}\ta: {vals}")
            lines.append(f"{ind}}}")
            return
        vals = ", ".join(_ascii_value(t, v) for t, v in node.props)
        if node.children or not node.props or node.block:
            lines.append(f"{ind}{node.name}: {vals} {{".replace(":  {", ":  {"))
            for c in node.children:
                emit(c, depth + 1)
            lines.append(f"{ind}}}")
        else:
            lines.append(f"{ind}{node.name}: {vals}")

    for n in top:
        emit(n, 0)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")


# ------------------------------------------------------------------------------ editing
def objects(top):
    return next(n for n in top if n.name == "Objects")


def connections(top):
    return next(n for n in top if n.name == "Connections")


def find(top, kind, sub=None, name=None):
    """Objects of node name ``kind`` (``Model``, ``Deformer``...), sub-class ``sub`` (``Skin``,
    ``LimbNode``...) and object name ``name``."""
    out = []
    for n in objects(top).children:
        if n.name != kind:
            continue
        if sub is not None and (len(n.props) < 3 or n.props[2][1] != sub):
            continue
        if name is not None and n.props[1][1].split("\x00\x01")[0] != name:
            continue
        out.append(n)
    return out


def oid(node):
    return node.props[0][1]


def set_p70(node, name, kind, values, flags="A"):
    """Set (or add) ``P: name`` in a node's Properties70 (``values``: numbers; doubles unless
    ``kind`` is an int type)."""
    p70 = node.child("Properties70")
    if p70 is None:
        p70 = N("Properties70")
        node.children.append(p70)
    code = "I" if kind in ("enum", "int", "bool") else "D"
    label = {"Vector3D": "Vector"}.get(kind, "")
    new = N("P", [("S", name), ("S", kind), ("S", label), ("S", flags)] + [(code, v) for v in values])
    for i, p in enumerate(p70.children):
        if p.props and p.props[0][1] == name:
            p70.children[i] = new
            return
    p70.children.append(new)


def set_child(node, name, props):
    c = node.child(name)
    if c is None:
        node.children.append(N(name, props))
    else:
        c.props = props


def connect(top, kind, a, b, prop=None):
    props = [("S", kind), ("L", a), ("L", b)] + ([("S", prop)] if prop else [])
    connections(top).children.append(N("C", props))


def parent_of(top, child_id):
    for c in connections(top).children:
        if c.props[0][1] == "OO" and c.props[1][1] == child_id:
            return c.props[2][1]
    return None
