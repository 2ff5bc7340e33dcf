"""A small reader of the FBX document tree, binary (any version) and ASCII, for what assimp does
not hand over: the version, skin deformers' ``SkinningType`` / ``BlendWeights``, models'
``Properties70``, bind poses, constraints, animation curves' interpolation, connections.

Only what those checks need is decoded: array properties are read for the node names in
:data:`ARRAYS` and left as ``None`` elsewhere (normals, UVs, polygon indices are never decoded
here).  Nothing here raises on a malformed file: :func:`read_document` returns ``None``.
"""

from __future__ import annotations

import re
import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

_MAGIC = b"Kaydara FBX Binary  \x00"

#: Node names whose array properties are decoded (every other array is skipped).
ARRAYS = frozenset({"BlendWeights", "Indexes", "Vertices", "Matrix", "KeyTime", "KeyValueFloat", "KeyAttrFlags",
                    "KeyAttrDataFloat", "KeyAttrRefCount", "Transform", "TransformLink", "a"})
_ARRAY = {"f": "<f4", "d": "<f8", "l": "<i8", "i": "<i4", "b": "u1", "c": "u1"}
_SCALAR = {"Y": "<h", "C": "<?", "I": "<i", "F": "<f", "D": "<d", "L": "<q"}


@dataclass
class Node:
    """One FBX node: its name, property values, children."""

    name: str
    props: list
    children: list = field(default_factory=list)

    def child(self, name):
        return next((c for c in self.children if c.name == name), None)

    def all(self, name):
        return [c for c in self.children if c.name == name]

    def value(self, name, default=None):
        """The first property of child ``name`` (an array child's decoded array)."""
        c = self.child(name)
        if c is not None and c.name in ARRAYS and c.child("a") is not None:  # ASCII arrays: *N { a: ... }
            return c.child("a").array()
        if c is None or not c.props:
            return default
        return c.props[0]

    def array(self):
        """This node's properties as one float64 array (ASCII ``a:`` lists, binary arrays)."""
        if len(self.props) == 1 and isinstance(self.props[0], np.ndarray):
            return self.props[0]
        if self.child("a") is not None:
            return self.child("a").array()
        vals = [p for p in self.props if isinstance(p, (int, float)) and not isinstance(p, bool)]
        return np.array(vals, dtype=np.float64)


@dataclass
class Document:
    """A read FBX file: ``version`` (e.g. 7400), ``binary``, and the top-level nodes."""

    version: int
    binary: bool
    root: Node

    def top(self, name) -> Node | None:
        return self.root.child(name)

    def properties(self, node) -> dict:
        """``{name: value or [values]}`` of a node's ``Properties70`` (or FBX 6 ``Properties60``)."""
        out = {}
        for block in ("Properties70", "Properties60"):
            p = node.child(block) if node is not None else None
            if p is None:
                continue
            for q in p.children:
                if q.name not in ("P", "Property") or not q.props or not isinstance(q.props[0], str):
                    continue
                vals = q.props[4:] if q.name == "P" else q.props[3:]
                out[q.props[0]] = vals[0] if len(vals) == 1 else vals
        return out


def object_name(raw) -> str:
    """``"pCube1\\x00\\x01Model"`` (binary) / ``"Model::pCube1"`` (ASCII) -> ``"pCube1"``."""
    s = str(raw)
    if "\x00\x01" in s:
        return s.split("\x00\x01")[0]
    return s.split("::", 1)[1] if "::" in s else s


def read_document(path) -> Document | None:
    """The FBX file's node tree (see the module docstring); ``None`` when it is not FBX or cannot
    be walked."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError:
        return None
    try:
        if data.startswith(_MAGIC):
            return _binary(data)
        head = data[:4096].decode("utf-8", "replace")
        if "FBX" not in head and "Kaydara" not in head:
            return None
        return _ascii(data.decode("utf-8", "replace"))
    except (struct.error, IndexError, ValueError, UnicodeError, zlib.error, RecursionError, OverflowError):
        return None


def file_version(path) -> int | None:
    """The FBX version of a file (``7400``...) from its first bytes: the binary header, or an
    ASCII file's ``FBXVersion`` / ``; FBX 6.1.0 project file`` comment.  ``None`` when not found."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError:
        return None
    if head.startswith(_MAGIC) and len(head) >= 27:
        return struct.unpack_from("<I", head, 23)[0]
    text = head.decode("utf-8", "replace")
    m = re.search(r"FBXVersion\s*:\s*(\d+)", text)
    if m:
        return int(m.group(1))
    m = re.search(r";\s*FBX\s+(\d+)\.(\d+)\.(\d+)\s+project file", text)
    if m:
        return int(m.group(1)) * 1000 + int(m.group(2)) * 100 + int(m.group(3))
    return None


# ---------------------------------------------------------------------------------- binary
def _binary(data: bytes) -> Document:
    version = struct.unpack_from("<I", data, 23)[0]
    head = struct.Struct("<QQQB" if version >= 7500 else "<IIIB")

    def props(pos, count, decode):
        out = []
        for _ in range(count):
            t = chr(data[pos])
            pos += 1
            if t in _SCALAR:
                fmt = _SCALAR[t]
                out.append(struct.unpack_from(fmt, data, pos)[0])
                pos += struct.calcsize(fmt)
            elif t in "SR":
                n = struct.unpack_from("<I", data, pos)[0]
                raw = data[pos + 4:pos + 4 + n]
                out.append(raw.decode("utf-8", "replace") if t == "S" else raw)
                pos += 4 + n
            elif t in _ARRAY:
                n, enc, clen = struct.unpack_from("<III", data, pos)
                if decode:
                    raw = data[pos + 12:pos + 12 + clen]
                    if enc == 1:
                        raw = zlib.decompress(raw)
                    out.append(np.frombuffer(raw, dtype=_ARRAY[t], count=n).astype(np.float64))
                else:
                    out.append(None)
                pos += 12 + clen
            else:
                raise ValueError(f"unknown FBX property type {t!r}")
        return out

    def nodes(pos, end, depth=0):
        if depth > 64:
            raise ValueError("FBX nodes nested too deep")
        out = []
        while pos + head.size <= end:
            end_off, nprops, plen, nlen = head.unpack_from(data, pos)
            if end_off == 0:
                break
            if end_off <= pos or end_off > len(data):
                raise ValueError("bad node record")
            name = data[pos + head.size:pos + head.size + nlen].decode("ascii", "replace")
            pat = pos + head.size + nlen
            out.append(Node(name, props(pat, nprops, name in ARRAYS), nodes(pat + plen, end_off, depth + 1)))
            pos = end_off
        return out

    return Document(version, True, Node("", [], nodes(27, len(data))))


# ---------------------------------------------------------------------------------- ASCII
_TOKEN = re.compile(r'\s*(?:;[^\n]*|"((?:[^"\\]|\\.)*)"|([A-Za-z_][\w|]*)\s*:|(\{)|(\})|(,)|(\*\d+)|([^\s,{}";]+))')


def _ascii(text: str) -> Document:
    toks = []
    pos, n = 0, len(text)
    last_key = None
    while pos < n:
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            if text[pos:].strip() == "":
                break
            raise ValueError(f"unreadable ASCII FBX at character {pos}")
        pos = m.end()
        s, key, lb, rb, comma, star, word = m.groups()
        if s is not None:
            toks.append(("v", s))
        elif key is not None:
            toks.append(("k", key))
            last_key = key
        elif lb:
            toks.append(("{", None))
        elif rb:
            toks.append(("}", None))
        elif comma:
            toks.append((",", None))
        elif star:
            toks.append(("*", int(star[1:])))
            if last_key not in ARRAYS:  # an array nobody reads (vertices, normals): skip its text
                lb_at = text.find("{", pos)
                rb_at = text.find("}", lb_at)
                if lb_at < 0 or rb_at < 0:
                    raise ValueError("unterminated ASCII FBX array")
                pos = rb_at + 1
        elif word is not None:
            toks.append(("v", _number(word)))
    i = 0

    def parse_nodes(depth):
        nonlocal i
        if depth > 64:
            raise ValueError("FBX nodes nested too deep")
        out = []
        while i < len(toks):
            kind, val = toks[i]
            if kind == "}":
                i += 1
                return out
            if kind != "k":
                i += 1  # stray value: skip
                continue
            i += 1
            node = Node(val, [])
            expect_value = True
            while i < len(toks) and toks[i][0] in ("v", ",", "*"):
                k, v = toks[i]
                if k == ",":
                    expect_value = True
                elif expect_value:
                    if k == "v":
                        node.props.append(v)
                    expect_value = False
                else:
                    break  # a value after a value without a comma: the next node's (never a key)
                i += 1
            if i < len(toks) and toks[i][0] == "{":
                i += 1
                node.children = parse_nodes(depth + 1)
            if node.name == "a":  # an array's values
                node.props = [np.array([p for p in node.props if isinstance(p, (int, float))], dtype=np.float64)]
            out.append(node)
        return out

    root = Node("", [], parse_nodes(0))
    version = 0
    ext = root.child("FBXHeaderExtension")
    if ext is not None and isinstance(ext.value("FBXVersion"), (int, float)):
        version = int(ext.value("FBXVersion"))
    else:
        m = re.search(r";\s*FBX\s+(\d+)\.(\d+)\.(\d+)\s+project file", text[:4096])
        if m:
            version = int(m.group(1)) * 1000 + int(m.group(2)) * 100 + int(m.group(3))
    return Document(version, False, root)


def _number(word: str):
    try:
        return int(word)
    except ValueError:
        pass
    try:
        return float(word)
    except ValueError:
        return word  # a bare word (ASCII booleans T / Y / N, enum names)
