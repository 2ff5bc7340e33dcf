"""Read the few FBX ``GlobalSettings`` that assimp does not apply: unit scale and up axis.

assimp's FBX importer leaves the header's ``UnitScaleFactor`` (centimetres per file unit) and
``UpAxis`` to the caller.  This is a small reader of the FBX node tree (binary 7.x and ASCII)
that looks only at ``GlobalSettings/Properties70``.
"""

from __future__ import annotations

import re
import struct

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


def _binary(data: bytes) -> dict:
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
