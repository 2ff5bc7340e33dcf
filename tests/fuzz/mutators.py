"""Mutators: structure-aware ones per format, byte-level ones for every file.

Every mutator is ``fn(data: bytes, rng: numpy.random.Generator) -> (bytes, str)``: the mutated
file and a one-line description of what was done (the case's recipe names the mutator, the seed
file and the random seed, so :func:`mutate` replays it exactly).  A mutator that does not apply
to a given file (no JSON chunk, no array property...) raises :class:`NotApplicable`;
:func:`mutate` then falls back to a byte-level one.

Structure-aware mutators keep the container valid (chunk lengths, node offsets, zip entry
sizes) so the hostile value reaches the parser's deeper layers instead of being rejected at the
door:

=========== ==================================================================================
format      mutators
=========== ==================================================================================
glb         JSON chunk (:func:`gltf_json`), BIN chunk values behind an accessor (NaN, huge,
            out-of-range indices, zero matrices), chunk table (duplicated, swapped, dropped,
            lying lengths)
gltf        JSON (accessors/bufferViews with out-of-range and huge counts, offsets, strides,
            types; skins, nodes, meshes, animations), and the data-URI buffers' values
fbx         binary node records (end offsets, property counts and lengths), array properties
            (lengths, encodings, compressed sizes, values: NaN, huge, negative indices),
            scalar properties, deleted and duplicated nodes; ASCII FBX as text
usda        numbers, tokens (types, interpolation, elementSize, joint paths, relationship
            targets), lines (deleted, duplicated, swapped), brackets, invalid UTF-8, NUL bytes
usdc        the crate's bootstrap (TOC offset, version), its TOC (section counts, starts,
            sizes) and the bytes of one named section or of the value data
usdz        the inner layer's bytes in place (zip sizes kept), crate mutators on an inner usdc
refs        what a file refers to (``gltf_refs``, ``glb_refs``, ``usda_refs``): glTF buffer and
            image URIs, USD sublayers, references, payloads, a variant's payload and value clips
            pointed at absolute paths, ``..`` escapes, ``file:`` URIs, FIFOs, devices,
            directories, symlinks out, a symlink loop, the file itself (:data:`REF_TARGETS`)
dae         XML: count/stride/offset attributes, array values, zeroed matrices, references,
            removed and duplicated elements, broken tags
text        numbers and lines (``.x``, ``.md5mesh``, ASCII FBX, and every other text format)
bytes       bit flips, truncation, random runs, extreme integers, duplicated chunks, deleted
            ranges, digit swaps
=========== ==================================================================================
"""

from __future__ import annotations

import base64
import json
import re
import struct
import zlib

import numpy as np


class NotApplicable(Exception):
    """This mutator has nothing to work on in this file."""


#: Integers that break parsers: zero, one, sign boundaries, sizes that overflow 32/64 bits.
EXTREME_INTS = (0, 1, -1, 2, 255, 65535, 2**31 - 1, 2**31, 2**32 - 1, 2**32, 2**53 + 1, 2**63 - 1, -(2**31))
#: Floats that break geometry: NaN, infinities, the float32 edge, denormals, zero.
EXTREME_FLOATS = (float("nan"), float("inf"), float("-inf"), 3.4e38, -3.4e38, 1e30, 1e-40, 0.0, -0.0)
#: ... and for float64 fields, beyond float32's range too.
EXTREME_DOUBLES = EXTREME_FLOATS + (1e308, -1e308, 5e-324)
#: Numeric tokens for text formats.
EXTREME_TEXT = ("nan", "inf", "-inf", "1e308", "-1e308", "1e999", "1e-320", "0", "-0", "-1", "2147483647",
                "2147483648", "4294967295", "4294967296", "-2147483649", "9223372036854775807",
                "18446744073709551616", "1" + "0" * 40, "3.5e38", "0x7fffffff", "1.", ".", "-", "1e", "00000001")


def _pick(rng, seq):
    return seq[int(rng.integers(len(seq)))]


# ====================================================================== byte-level
def bitflip(data, rng):
    if not data:
        raise NotApplicable
    b = bytearray(data)
    n = int(rng.integers(1, 9))
    where = rng.integers(0, len(b), n)
    for i in where:
        b[int(i)] ^= 1 << int(rng.integers(8))
    return bytes(b), f"flip {n} bits at {sorted(int(i) for i in where)[:8]}"


def truncate(data, rng):
    if len(data) < 2:
        raise NotApplicable
    cut = int(rng.integers(1, len(data))) if rng.random() < 0.7 else len(data) - int(rng.integers(1, min(64, len(data))))
    return data[:cut], f"truncate to {cut} of {len(data)} bytes"


def random_run(data, rng):
    if not data:
        raise NotApplicable
    n = int(rng.integers(1, 65))
    at = int(rng.integers(0, len(data)))
    run = bytes(rng.integers(0, 256, n, dtype=np.uint8)) if rng.random() < 0.7 else bytes([_pick(rng, (0, 0xFF))]) * n
    return data[:at] + run + data[at + n:], f"overwrite {n} bytes at {at}"


def extreme_int(data, rng):
    if len(data) < 8:
        raise NotApplicable
    width = _pick(rng, (2, 4, 4, 8))
    value = _pick(rng, EXTREME_INTS) % (1 << (8 * width))
    at = int(rng.integers(0, len(data) - width)) & ~(width - 1 if rng.random() < 0.7 else 0)
    return data[:at] + value.to_bytes(width, "little") + data[at + width:], f"write {width}-byte {value:#x} at {at}"


def duplicate_chunk(data, rng):
    if len(data) < 4:
        raise NotApplicable
    a = int(rng.integers(0, len(data)))
    n = int(rng.integers(1, min(4096, len(data) - a) + 1))
    at = int(rng.integers(0, len(data)))
    return data[:at] + data[a:a + n] + data[at:], f"copy {n} bytes from {a} to {at}"


def delete_range(data, rng):
    if len(data) < 4:
        raise NotApplicable
    a = int(rng.integers(0, len(data)))
    n = int(rng.integers(1, min(4096, len(data) - a) + 1))
    return data[:a] + data[a + n:], f"delete {n} bytes at {a}"


_DIGITS = re.compile(rb"[0-9]")


def digit_swap(data, rng):
    found = [m.start() for m in _DIGITS.finditer(data[:2_000_000])]
    if not found:
        raise NotApplicable
    b = bytearray(data)
    at = _pick(rng, found)
    how = int(rng.integers(3))
    if how == 0:
        b[at] = ord(str(int(rng.integers(10))))
        what = "change"
    elif how == 1 and at + 1 < len(b):
        b[at], b[at + 1] = b[at + 1], b[at]
        what = "swap"
    else:
        b[at:at] = b"9" * int(rng.integers(1, 20))
        what = "lengthen"
    return bytes(b), f"digit {what} at {at}"


BYTE_MUTATORS = {f.__name__: f for f in (bitflip, truncate, random_run, extreme_int, duplicate_chunk, delete_range,
                                         digit_swap)}


# ====================================================================== text helpers
_NUMBER = re.compile(rb"(?<![A-Za-z_0-9.])-?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def text_number(data, rng):
    """Replace 1-3 numeric tokens with extreme ones (or garbage that looks numeric)."""
    found = [(m.start(), m.end()) for m in _NUMBER.finditer(data[:4_000_000])]
    if not found:
        raise NotApplicable
    picks = sorted({_pick(rng, found) for _ in range(int(rng.integers(1, 4)))}, reverse=True)
    out, said = data, []
    for a, b in picks:
        tok = _pick(rng, EXTREME_TEXT).encode()
        out = out[:a] + tok + out[b:]
        said.append(f"{data[a:b][:12].decode('ascii', 'replace')}->{tok.decode()}")
    return out, "numbers " + ", ".join(said)


def _lines(data):
    lines = data.split(b"\n")
    if len(lines) < 3:
        raise NotApplicable
    return lines


def text_lines(data, rng):
    """Delete, duplicate or swap lines (or a block of lines)."""
    lines = _lines(data)
    i = int(rng.integers(len(lines)))
    n = int(rng.integers(1, 4)) if rng.random() < 0.8 else int(rng.integers(1, max(2, len(lines) // 4)))
    how = _pick(rng, ("delete", "duplicate", "swap"))
    if how == "delete":
        lines[i:i + n] = []
    elif how == "duplicate":
        lines[i:i] = lines[i:i + n]
    else:
        j = int(rng.integers(len(lines)))
        lines[i], lines[j] = lines[j], lines[i]
        n = f"{i}<->{j}"
    return b"\n".join(lines), f"{how} lines {i} (+{n})"


def text_brackets(data, rng):
    """Delete or insert one bracket, brace, parenthesis or quote."""
    found = [m.start() for m in re.finditer(rb'[\[\](){}<>"]', data[:4_000_000])]
    if not found:
        raise NotApplicable
    at = _pick(rng, found)
    if rng.random() < 0.5:
        return data[:at] + data[at + 1:], f"delete {chr(data[at])!r} at {at}"
    ch = _pick(rng, (b"[", b"]", b"(", b")", b"{", b"}", b'"', b"<"))
    return data[:at] + ch + data[at:], f"insert {ch.decode()!r} at {at}"


def text_encoding(data, rng):
    """Insert bytes that are not UTF-8 (or a NUL) somewhere in the text."""
    junk = _pick(rng, (b"\xff", b"\xc3\x28", b"\xe2\x82", b"\x00", b"\xed\xa0\x80", b"\xf8\x88\x80\x80\x80"))
    at = int(rng.integers(0, len(data) + 1))
    return data[:at] + junk + data[at:], f"insert {junk!r} at {at}"


TEXT_MUTATORS = {"text_number": text_number, "text_lines": text_lines, "text_brackets": text_brackets,
                 "text_encoding": text_encoding, "digit_swap": digit_swap}


# ====================================================================== glTF / GLB
_JSON, _BIN = 0x4E4F534A, 0x004E4942
_COMPONENT = {5120: ("b", 1), 5121: ("B", 1), 5122: ("h", 2), 5123: ("H", 2), 5125: ("I", 4), 5126: ("f", 4)}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def glb_split(data):
    """(json dict, [(type, bytes), ...] every chunk) of a GLB, or NotApplicable."""
    if len(data) < 20 or data[:4] != b"glTF":
        raise NotApplicable
    chunks, pos = [], 12
    while pos + 8 <= len(data):
        n, t = struct.unpack_from("<II", data, pos)
        chunks.append((t, data[pos + 8:pos + 8 + n]))
        pos += 8 + n
    if not chunks or chunks[0][0] != _JSON:
        raise NotApplicable
    try:
        doc = json.loads(chunks[0][1])
    except ValueError:
        raise NotApplicable from None
    return doc, chunks


def glb_join(chunks, version=2):
    body = b""
    for t, c in chunks:
        pad = (-len(c)) % 4
        c = c + (b" " if t == _JSON else b"\x00") * pad
        body += struct.pack("<II", len(c), t) + c
    return b"glTF" + struct.pack("<II", version, 12 + len(body)) + body


def _json_bytes(doc):
    return json.dumps(doc, separators=(",", ":"), allow_nan=True).encode()


def _index_or_junk(rng, n):
    return _pick(rng, (n, n + 1, -1, 2**31 - 1, 2**32, None, "0", 1.5, [0]))


def gltf_json(doc, rng):
    """Mutate a glTF document in place (accessors, bufferViews, skins, nodes, meshes,
    animations, or any numeric leaf); returns what was done."""
    acc, views = doc.get("accessors", []), doc.get("bufferViews", [])
    choices = []
    if acc:
        choices += ["acc_count"] * 3 + ["acc_offset", "acc_type", "acc_component", "acc_view", "acc_sparse", "acc_minmax"]
    if views:
        choices += ["view_length", "view_offset", "view_stride", "view_buffer"]
    if doc.get("buffers"):
        choices.append("buffer_length")
    if doc.get("skins"):
        choices += ["skin_joints", "skin_ibm"]
    if doc.get("nodes"):
        choices += ["node_children", "node_trs", "node_refs"]
    if doc.get("meshes"):
        choices += ["mesh_prim"]
    if doc.get("animations"):
        choices += ["anim_sampler", "anim_channel"]
    choices += ["leaf", "leaf", "delete", "confuse"]
    what = _pick(rng, choices)

    def one(seq):
        i = int(rng.integers(len(seq)))
        return i, seq[i]

    if what == "acc_count":
        i, a = one(acc)
        c = a.get("count", 0)
        a["count"] = _pick(rng, (0, 1, c + 1, c * 2, c - 1, 2**31 - 1, 2**32 - 1, 2**53, -1, 2**64))
        return f"accessors[{i}].count {c} -> {a['count']}"
    if what == "acc_offset":
        i, a = one(acc)
        a["byteOffset"] = _pick(rng, (1, 3, 2**31 - 1, 2**32, -4, 2**62))
        return f"accessors[{i}].byteOffset -> {a['byteOffset']}"
    if what == "acc_type":
        i, a = one(acc)
        a["type"] = _pick(rng, ("SCALAR", "VEC2", "VEC3", "VEC4", "MAT2", "MAT3", "MAT4", "BOGUS", 7))
        return f"accessors[{i}].type -> {a['type']}"
    if what == "acc_component":
        i, a = one(acc)
        a["componentType"] = _pick(rng, (5120, 5121, 5122, 5123, 5125, 5126, 5124, 0, -1, 2**32))
        if rng.random() < 0.3:
            a["normalized"] = True
        return f"accessors[{i}].componentType -> {a['componentType']}"
    if what == "acc_view":
        i, a = one(acc)
        if rng.random() < 0.3:
            a.pop("bufferView", None)
            return f"accessors[{i}].bufferView removed (zeros)"
        a["bufferView"] = _index_or_junk(rng, len(views))
        return f"accessors[{i}].bufferView -> {a['bufferView']}"
    if what == "acc_sparse":
        i, a = one(acc)
        a["sparse"] = {"count": _pick(rng, (1, 2**31 - 1, a.get("count", 1) + 5)),
                       "indices": {"bufferView": int(rng.integers(max(1, len(views)))), "componentType": 5125},
                       "values": {"bufferView": int(rng.integers(max(1, len(views))))}}
        return f"accessors[{i}].sparse count {a['sparse']['count']}"
    if what == "acc_minmax":
        i, a = one(acc)
        a["min"] = [_pick(rng, EXTREME_FLOATS)] * _NCOMP.get(a.get("type"), 1)
        a["max"] = [_pick(rng, EXTREME_FLOATS)] * _NCOMP.get(a.get("type"), 1)
        return f"accessors[{i}] min/max -> {a['min'][0]}/{a['max'][0]}"
    if what == "view_length":
        i, v = one(views)
        n = v.get("byteLength", 0)
        v["byteLength"] = _pick(rng, (0, 1, n - 1, n + 4, 2**31 - 1, 2**32, -1))
        return f"bufferViews[{i}].byteLength {n} -> {v['byteLength']}"
    if what == "view_offset":
        i, v = one(views)
        v["byteOffset"] = _pick(rng, (1, 2, v.get("byteOffset", 0) + 4, 2**31 - 1, 2**32 + 4, -8))
        return f"bufferViews[{i}].byteOffset -> {v['byteOffset']}"
    if what == "view_stride":
        i, v = one(views)
        v["byteStride"] = _pick(rng, (0, 1, 3, 4, 252, 256, 2**31 - 1, -4))
        return f"bufferViews[{i}].byteStride -> {v['byteStride']}"
    if what == "view_buffer":
        i, v = one(views)
        v["buffer"] = _index_or_junk(rng, len(doc.get("buffers", [])))
        return f"bufferViews[{i}].buffer -> {v['buffer']}"
    if what == "buffer_length":
        i, b = one(doc["buffers"])
        b["byteLength"] = _pick(rng, (0, 1, b.get("byteLength", 0) * 2, 2**31 - 1, 2**40, -1))
        return f"buffers[{i}].byteLength -> {b['byteLength']}"
    if what == "skin_joints":
        i, s = one(doc["skins"])
        j = list(s.get("joints", []))
        how = int(rng.integers(4))
        if how == 0 and j:
            j[int(rng.integers(len(j)))] = _index_or_junk(rng, len(doc.get("nodes", [])))
        elif how == 1 and j:
            j.append(j[0])
        elif how == 2:
            j = []
        else:
            j = j[: max(0, len(j) - 1)]
        s["joints"] = j
        return f"skins[{i}].joints -> {j[:6]}"
    if what == "skin_ibm":
        i, s = one(doc["skins"])
        if rng.random() < 0.3:
            s.pop("inverseBindMatrices", None)
            return f"skins[{i}].inverseBindMatrices removed"
        s["inverseBindMatrices"] = _index_or_junk(rng, len(acc)) if rng.random() < 0.5 else int(rng.integers(max(1, len(acc))))
        return f"skins[{i}].inverseBindMatrices -> {s['inverseBindMatrices']}"
    if what == "node_children":
        nodes = doc["nodes"]
        i, n = one(nodes)
        how = int(rng.integers(3))
        if how == 0:
            n["children"] = list(n.get("children", [])) + [i]  # a node its own child: a cycle
        elif how == 1:
            n["children"] = list(n.get("children", [])) + [_index_or_junk(rng, len(nodes))]
        else:
            j = int(rng.integers(len(nodes)))
            nodes[j].setdefault("children", []).append(i)
            n.setdefault("children", []).append(j)
        return f"nodes[{i}].children -> {n.get('children')}"
    if what == "node_trs":
        i, n = one(doc["nodes"])
        key = _pick(rng, ("matrix", "rotation", "scale", "translation"))
        size = {"matrix": 16, "rotation": 4, "scale": 3, "translation": 3}[key]
        val = _pick(rng, EXTREME_FLOATS)
        n[key] = [val] * size if rng.random() < 0.6 else [val] * (size - 1)
        if key == "matrix":
            for k in ("rotation", "scale", "translation"):
                n.pop(k, None)
        return f"nodes[{i}].{key} -> [{val}] * {len(n[key])}"
    if what == "node_refs":
        i, n = one(doc["nodes"])
        key = _pick(rng, ("mesh", "skin", "camera"))
        n[key] = _index_or_junk(rng, len(doc.get({"mesh": "meshes", "skin": "skins", "camera": "cameras"}[key], [])))
        return f"nodes[{i}].{key} -> {n[key]}"
    if what == "mesh_prim":
        i, m = one(doc["meshes"])
        p = _pick(rng, m.get("primitives") or [{}])
        how = int(rng.integers(4))
        if how == 0:
            p["mode"] = _pick(rng, (0, 1, 2, 3, 5, 6, 7, 99))
            return f"meshes[{i}] primitive mode -> {p['mode']}"
        if how == 1:
            p["indices"] = int(rng.integers(max(1, len(acc))))
            return f"meshes[{i}] primitive indices -> accessor {p['indices']}"
        attrs = p.setdefault("attributes", {})
        if how == 2 and attrs:
            k = _pick(rng, sorted(attrs))
            del attrs[k]
            return f"meshes[{i}] primitive attribute {k} removed"
        k = _pick(rng, ("POSITION", "JOINTS_0", "WEIGHTS_0", "NORMAL", "JOINTS_1"))
        attrs[k] = int(rng.integers(max(1, len(acc))))
        return f"meshes[{i}] primitive {k} -> accessor {attrs[k]}"
    if what == "anim_sampler":
        a = _pick(rng, doc["animations"])
        s = _pick(rng, a.get("samplers") or [{}])
        key = _pick(rng, ("input", "output", "interpolation"))
        s[key] = (_pick(rng, ("STEP", "CUBICSPLINE", "BOGUS", "")) if key == "interpolation"
                  else int(rng.integers(max(1, len(acc)))))
        return f"animation sampler {key} -> {s[key]}"
    if what == "anim_channel":
        a = _pick(rng, doc["animations"])
        c = _pick(rng, a.get("channels") or [{}])
        t = c.setdefault("target", {})
        how = int(rng.integers(3))
        if how == 0:
            t["node"] = _index_or_junk(rng, len(doc.get("nodes", [])))
        elif how == 1:
            t["path"] = _pick(rng, ("weights", "bogus", "rotation", "scale"))
        else:
            c["sampler"] = _index_or_junk(rng, len(a.get("samplers", [])))
        return f"animation channel -> {c}"
    leaves = []

    def walk(node, path):
        if isinstance(node, dict):
            for k, v in node.items():
                walk(v, path + [k])
        elif isinstance(node, list):
            for k, v in enumerate(node):
                walk(v, path + [k])
        leaves.append((path, node))

    walk(doc, [])
    if what == "leaf":
        nums = [(p, v) for p, v in leaves if isinstance(v, (int, float)) and not isinstance(v, bool) and p]
        if not nums:
            raise NotApplicable
        path, v = _pick(rng, nums)
        new = _pick(rng, EXTREME_INTS) if isinstance(v, int) else _pick(rng, EXTREME_FLOATS)
    else:
        inner = [(p, v) for p, v in leaves if p]
        path, v = _pick(rng, inner)
        new = None if what == "delete" else _pick(rng, ("x", [], {}, None, True, -1, [[0]]))
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    if what == "delete":
        if isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent.pop(path[-1])
        return f"delete {'/'.join(map(str, path))}"
    parent[path[-1]] = new
    return f"{'/'.join(map(str, path))}: {str(v)[:20]} -> {new}"


def _accessor_span(doc, i, buffer_len):
    """(buffer index, start, element stride, element size, count, component fmt, ncomp) of accessor i."""
    a = doc["accessors"][i]
    v = doc["bufferViews"][a["bufferView"]]
    fmt, size = _COMPONENT[a["componentType"]]
    n = _NCOMP[a["type"]]
    start = v.get("byteOffset", 0) + a.get("byteOffset", 0)
    stride = v.get("byteStride") or size * n
    count = min(a["count"], max(0, (buffer_len - start) // max(stride, 1)))
    return v.get("buffer", 0), start, stride, size * n, count, fmt, n


def gltf_values(doc, buffers, rng):
    """Overwrite values behind one accessor in ``buffers`` (list of bytearray), in place."""
    acc = [i for i, a in enumerate(doc.get("accessors", [])) if "bufferView" in a]
    if not acc:
        raise NotApplicable
    i = _pick(rng, acc)
    try:
        b, start, stride, _, count, fmt, n = _accessor_span(doc, i, len(buffers[doc["bufferViews"][doc["accessors"][i]["bufferView"]].get("buffer", 0)]))
    except (KeyError, IndexError, TypeError):
        raise NotApplicable from None
    if count == 0:
        raise NotApplicable
    buf = buffers[b]
    k = int(rng.integers(1, min(count, 8) + 1)) if rng.random() < 0.8 else count
    rows = rng.choice(count, size=k, replace=False)
    mt = doc["accessors"][i]["type"]
    if fmt == "f":
        val = _pick(rng, EXTREME_FLOATS)
        what = f"{val}"
    else:
        bits = 8 * struct.calcsize(fmt)
        val = _pick(rng, (2 ** (bits - 1) - 1, 2**bits - 1 if fmt.isupper() else -1, 255, 1000))
        val = val if fmt.isupper() or val < 2 ** (bits - 1) else -1
        what = f"{val}"
    whole = rng.random() < 0.5  # every component of the element (a zero or NaN matrix) or one
    for r in rows:
        base = start + int(r) * stride
        comps = range(n) if whole else [int(rng.integers(n))]
        for c in comps:
            struct.pack_into("<" + fmt, buf, base + c * struct.calcsize(fmt), val)
    return f"accessor {i} ({mt}) {k} element(s) {'all' if whole else 'one'} component(s) = {what}"


def _data_uri(uri):
    if not isinstance(uri, str) or not uri.startswith("data:") or "base64," not in uri:
        return None
    head, _, b64 = uri.partition("base64,")
    try:
        return head + "base64,", bytearray(base64.b64decode(b64))
    except ValueError:  # binascii.Error: an earlier mutation broke it
        return None


def glb_json(data, rng):
    doc, chunks = glb_split(data)
    what = gltf_json(doc, rng)
    chunks[0] = (_JSON, _json_bytes(doc))
    return glb_join(chunks), "GLB JSON chunk: " + what


def glb_bin(data, rng):
    doc, chunks = glb_split(data)
    bins = [k for k, (t, _) in enumerate(chunks) if t == _BIN]
    if not bins:
        raise NotApplicable
    buf = bytearray(chunks[bins[0]][1])
    what = gltf_values(doc, [buf], rng)
    chunks[bins[0]] = (_BIN, bytes(buf))
    return glb_join(chunks), "GLB BIN chunk: " + what


def glb_chunks(data, rng):
    doc, chunks = glb_split(data)
    how = int(rng.integers(6))
    if how == 0:
        chunks.insert(int(rng.integers(len(chunks) + 1)), chunks[0])
        return glb_join(chunks), "GLB: JSON chunk duplicated"
    if how == 1 and len(chunks) > 1:
        chunks[0], chunks[1] = chunks[1], chunks[0]
        return glb_join(chunks), "GLB: first two chunks swapped"
    if how == 2 and len(chunks) > 1:
        return glb_join(chunks[:1]), "GLB: BIN chunk dropped"
    out = bytearray(glb_join(chunks))
    if how == 3:
        v = _pick(rng, (0, 1, 2**31 - 1, 2**32 - 1, len(out) + 4))
        struct.pack_into("<I", out, 8, v)
        return bytes(out), f"GLB: total length -> {v}"
    if how == 4:
        v = _pick(rng, (0, 3, 2**31 - 1, 2**32 - 8, len(chunks[0][1]) + 8))
        struct.pack_into("<I", out, 12, v)
        return bytes(out), f"GLB: JSON chunk length -> {v}"
    v = _pick(rng, (0, 1, 3, 2**32 - 1))
    struct.pack_into("<I", out, 4, v)
    return bytes(out), f"GLB: version -> {v}"


def gltf_json_mut(data, rng):
    try:
        doc = json.loads(data)
    except ValueError:
        raise NotApplicable from None
    if not isinstance(doc, dict):
        raise NotApplicable
    what = gltf_json(doc, rng)
    return json.dumps(doc, indent=1, allow_nan=True).encode(), "glTF JSON: " + what


def gltf_buffers(data, rng):
    try:
        doc = json.loads(data)
    except ValueError:
        raise NotApplicable from None
    uris = [_data_uri(b.get("uri")) for b in doc.get("buffers", [])]
    if not uris or any(u is None for u in uris):
        raise NotApplicable
    bufs = [u[1] for u in uris]
    what = gltf_values(doc, bufs, rng)
    for b, (head, buf) in zip(doc["buffers"], uris):
        b["uri"] = head + base64.b64encode(bytes(buf)).decode()
    return json.dumps(doc, indent=1, allow_nan=True).encode(), "glTF data-URI buffer: " + what


# ====================================================================== FBX (binary)
_FBX_MAGIC = b"Kaydara FBX Binary  \x00"
_SCALAR = {"Y": 2, "C": 1, "I": 4, "F": 4, "D": 8, "L": 8}
_ARRAY = {"f": ("f", 4), "d": ("d", 8), "l": ("q", 8), "i": ("i", 4), "b": ("B", 1)}


class _Node:
    __slots__ = ("name", "props", "children", "sentinel")

    def __init__(self, name, props, children, sentinel):
        self.name, self.props, self.children, self.sentinel = name, props, children, sentinel


def fbx_parse(data):
    """(version, [top-level _Node], footer bytes); props are (type, raw bytes incl. type code)."""
    if not data.startswith(_FBX_MAGIC) or len(data) < 27:
        raise NotApplicable
    version = struct.unpack_from("<I", data, 23)[0]
    head = struct.Struct("<QQQB" if version >= 7500 else "<IIIB")

    def parse_list(pos, end):
        nodes = []
        while pos + head.size <= end:
            end_off, nprops, plen, nlen = head.unpack_from(data, pos)
            if end_off == 0:
                return nodes, pos + head.size
            if end_off <= pos or end_off > len(data):
                raise NotApplicable
            name = data[pos + head.size: pos + head.size + nlen]
            p = pos + head.size + nlen
            props = []
            for _ in range(nprops):
                t = chr(data[p])
                if t in _SCALAR:
                    n = 1 + _SCALAR[t]
                elif t in "SR":
                    n = 5 + struct.unpack_from("<I", data, p + 1)[0]
                elif t in _ARRAY:
                    n = 13 + struct.unpack_from("<III", data, p + 1)[2]
                else:
                    raise NotApplicable
                props.append((t, data[p:p + n]))
                p += n
            children, q = parse_list(p, end_off) if p < end_off else ([], p)
            nodes.append(_Node(name, props, children, q == end_off and p < end_off))
            pos = end_off
        return nodes, pos

    try:
        top, after = parse_list(27, len(data))
    except (struct.error, IndexError):
        raise NotApplicable from None
    return version, top, data[after:]


def fbx_write(version, top, footer):
    head = struct.Struct("<QQQB" if version >= 7500 else "<IIIB")
    null = b"\x00" * head.size
    out = bytearray(_FBX_MAGIC + b"\x1a\x00" + struct.pack("<I", version))

    def write(node):
        start = len(out)
        out.extend(b"\x00" * head.size)
        out.extend(node.name)
        props = b"".join(raw for _, raw in node.props)
        out.extend(props)
        for c in node.children:
            write(c)
        if node.children or node.sentinel:
            out.extend(null)
        head.pack_into(out, start, len(out), len(node.props), len(props), len(node.name))

    for n in top:
        write(n)
    out.extend(null)
    out.extend(footer)
    return bytes(out)


def _fbx_all(top):
    out, stack = [], [(n, None, i) for i, n in enumerate(top)]
    while stack:
        n, parent, i = stack.pop()
        out.append((n, parent, i))
        stack.extend((c, n, k) for k, c in enumerate(n.children))
    return out


def _array_values(t, raw):
    fmt, size = _ARRAY[t]
    length, enc, clen = struct.unpack_from("<III", raw, 1)
    body = raw[13:13 + clen]
    body = zlib.decompress(body) if enc == 1 else body
    return np.frombuffer(body, dtype="<" + fmt).copy()


def _array_raw(t, values, compress):
    fmt, _ = _ARRAY[t]
    body = np.asarray(values, dtype="<" + fmt).tobytes()
    enc = 0
    if compress:
        body, enc = zlib.compress(body), 1
    return t.encode() + struct.pack("<III", len(values), enc, len(body)) + body


def _pick_fbx_array(data, rng):
    """Parse an FBX and pick one array property: ``(version, top, footer, node, k, type, raw)``."""
    version, top, footer = fbx_parse(data)
    arrays = [(n, k) for n, _, _ in _fbx_all(top) for k, (t, _) in enumerate(n.props) if t in _ARRAY]
    if not arrays:
        raise NotApplicable
    node, k = _pick(rng, arrays)
    t, raw = node.props[k]
    return version, top, footer, node, k, t, raw


def fbx_array(data, rng):
    """Change one array property's values (NaN, huge, negative or out-of-range indices) or its
    length (elements dropped or added), re-encoded so the file stays well formed."""
    version, top, footer, node, k, t, raw = _pick_fbx_array(data, rng)
    try:
        vals = _array_values(t, raw)
    except (zlib.error, ValueError):
        raise NotApplicable from None
    compressed = struct.unpack_from("<III", raw, 1)[1] == 1
    how = int(rng.integers(4))
    if how == 0 and len(vals):
        vals = vals[: int(rng.integers(len(vals)))]
        what = f"cut to {len(vals)}"
    elif how == 1:
        extra = vals[: int(rng.integers(1, max(2, len(vals) + 1)))] if len(vals) else np.zeros(3, vals.dtype)
        vals = np.concatenate([vals, extra])
        what = f"lengthened to {len(vals)}"
    elif len(vals):
        m = int(rng.integers(1, min(len(vals), 8) + 1)) if rng.random() < 0.8 else len(vals)
        at = rng.choice(len(vals), size=m, replace=False)
        if t in "fd":
            v = _pick(rng, EXTREME_FLOATS if t == "f" else EXTREME_DOUBLES)
        elif t == "b":
            v = _pick(rng, (0, 1, 255))
        else:
            v = _pick(rng, (-1, -2**31, 2**31 - 1, 10**6, int(vals.max()) + 1 if len(vals) else 1))
            if t == "i":
                v = int(np.int32(np.int64(v)))
        vals[at] = v
        what = f"{m} value(s) = {v}"
    else:
        raise NotApplicable
    node.props[k] = (t, _array_raw(t, vals, compressed))
    return fbx_write(version, top, footer), f"FBX {node.name.decode('ascii', 'replace')} array {t}[{k}] {what}"


def fbx_array_header(data, rng):
    """Lie in one array property's header: length, encoding or compressed size."""
    version, top, footer, node, k, t, raw = _pick_fbx_array(data, rng)
    raw = bytearray(raw)
    length, enc, clen = struct.unpack_from("<III", raw, 1)
    field = int(rng.integers(3))
    v = _pick(rng, (0, 1, length + 1, length * 2, 2**31 - 1, 2**32 - 1, 2**28)) if field == 0 else \
        _pick(rng, (0, 1, 2, 7)) if field == 1 else _pick(rng, (0, clen - 1, clen + 1, 2**32 - 1))
    struct.pack_into("<I", raw, 1 + 4 * field, v % 2**32)
    node.props[k] = (t, bytes(raw))
    out = fbx_write(version, top, footer)
    return out, f"FBX {node.name.decode('ascii', 'replace')} array {t}[{k}] {('length', 'encoding', 'compressedLength')[field]} -> {v}"


def fbx_scalar(data, rng):
    """Set one scalar property (I, L, D, F) to an extreme value."""
    version, top, footer = fbx_parse(data)
    scal = [(n, k) for n, _, _ in _fbx_all(top) for k, (t, _) in enumerate(n.props) if t in "ILDF"]
    if not scal:
        raise NotApplicable
    node, k = _pick(rng, scal)
    t, _ = node.props[k]
    if t in "DF":
        v = _pick(rng, EXTREME_FLOATS if t == "F" else EXTREME_DOUBLES)
        raw = t.encode() + struct.pack("<" + t.lower(), v)
    else:
        v = _pick(rng, EXTREME_INTS)
        fmt = "<i" if t == "I" else "<q"
        v = int(np.array(v).astype(np.int64).astype(np.int32 if t == "I" else np.int64)) if abs(v) >= 2**31 or t == "I" else v
        raw = t.encode() + struct.pack(fmt, v)
    node.props[k] = (t, raw)
    return fbx_write(version, top, footer), f"FBX {node.name.decode('ascii', 'replace')} scalar {t}[{k}] -> {v}"


def fbx_nodes(data, rng):
    """Delete, duplicate or re-parent a node record."""
    version, top, footer = fbx_parse(data)
    nodes = _fbx_all(top)
    node, parent, i = _pick(rng, nodes)
    siblings = top if parent is None else parent.children
    how = int(rng.integers(3))
    if how == 0:
        siblings.remove(node)
        what = "deleted"
    elif how == 1:
        siblings.insert(i, node)
        what = "duplicated"
    else:
        other, _, _ = _pick(rng, nodes)
        if other is node:
            raise NotApplicable
        siblings.remove(node)
        other.children.append(node)
        what = f"moved under {other.name.decode('ascii', 'replace')}"
    return fbx_write(version, top, footer), f"FBX node {node.name.decode('ascii', 'replace')} {what}"


def fbx_record(data, rng):
    """Lie in one node record's header: end offset, property count or property-list length."""
    version, top, footer = fbx_parse(data)
    head = struct.Struct("<QQQB" if version >= 7500 else "<IIIB")
    raw = bytearray(data)
    offsets = []
    pos = 27

    def scan(pos, end):
        while pos + head.size <= end:
            end_off, nprops, plen, nlen = head.unpack_from(raw, pos)
            if end_off == 0:
                return
            offsets.append(pos)
            p = pos + head.size + nlen + plen
            if p < end_off:
                scan(p, end_off)
            pos = end_off

    scan(pos, len(raw))
    if not offsets:
        raise NotApplicable
    at = _pick(rng, offsets)
    end_off, nprops, plen, nlen = head.unpack_from(raw, at)
    field = int(rng.integers(4))
    big = 2**64 - 1 if version >= 7500 else 2**32 - 1
    v = _pick(rng, (0, 1, at, end_off - 1, end_off + 1, big, len(raw) + 100)) if field == 0 else \
        _pick(rng, (0, nprops + 1, 2**31, big)) if field == 1 else \
        _pick(rng, (0, plen - 1, plen + 1, big)) if field == 2 else _pick(rng, (0, 255, nlen + 1))
    vals = [end_off, nprops, plen, nlen]
    vals[field] = v % (256 if field == 3 else big + 1)
    head.pack_into(raw, at, *vals)
    return bytes(raw), f"FBX record at {at} {('endOffset', 'numProperties', 'propertyListLen', 'nameLen')[field]} -> {v}"


# ====================================================================== USDA
_USDA_TYPES = (b"float3[]", b"point3f[]", b"int[]", b"token[]", b"matrix4d[]", b"float[]", b"quatf[]", b"half3[]",
               b"uniform token[]", b"double", b"string", b"rel", b"bool", b"int64[]")


#: USDA token edits (``how`` 1..5 of the USDA mutator): the regex whose group 1 is replaced, the
#: replacements (or a function of the old text giving them), and the label of the recipe.
_USDA_EDITS = (
    (rb"elementSize = (\d+)", (b"0", b"-1", b"3", b"1", b"100000", b"2147483647", b"99999999999"), "elementSize"),
    (rb'interpolation = "(\w+)"', (b"constant", b"uniform", b"faceVarying", b"bogus", b""), "interpolation"),
    (rb'"([\w/]+)"', lambda old: (b"", b"nope", old + b"/" + old, b"/" + old, old.split(b"/")[0], b"a" * 300,
                                  old + b" "), "string"),
    (rb"<([^<>\s]+)>", lambda old: (b"/nowhere", b"/", b".", old + b"/x", b"../.."), "target"),
    (rb"\bdef (\w+)", (b"Xform", b"Mesh", b"Skeleton", b"SkelRoot", b"SkelAnimation", b"Scope", b"Bogus"),
     "prim type"),
)


def usda_tokens(data, rng):
    """Change one meaningful token: a type name, elementSize, interpolation, a quoted joint
    path or name, a relationship target, a prim type, the header."""
    how = int(rng.integers(7))
    if how == 0:
        found = [m for m in re.finditer(rb"\b(float3|point3f|normal3f|int|token|matrix4d|float|quatf|half3|double3|float2|texCoord2f)(\[\])?(?= [\w:]+ ?[=.(\n])", data)]
        if not found:
            raise NotApplicable
        m = _pick(rng, found)
        new = _pick(rng, _USDA_TYPES)
        return data[:m.start()] + new + data[m.end():], f"USDA type {m.group(0).decode()} -> {new.decode()}"
    if 1 <= how <= 5:
        pattern, choices, label = _USDA_EDITS[how - 1]
        found = list(re.finditer(pattern, data))
        if not found:
            raise NotApplicable
        m = _pick(rng, found)
        old = m.group(1)
        new = _pick(rng, choices(old) if callable(choices) else choices)
        return data[:m.start(1)] + new + data[m.end(1):], f"USDA {label} {old[:30].decode()} -> {new[:30].decode()}"
    new = _pick(rng, (b"#usda 9.0", b"#usda", b"#usdb 1.0", b"", b"#usda 1.0\x00"))
    nl = data.find(b"\n")
    return new + data[nl if nl >= 0 else len(data):], f"USDA header -> {new!r}"


def usda_arrays(data, rng):
    """Shorten or lengthen one array literal ``[a, b, ...]`` (counts no longer agree)."""
    found = [m for m in re.finditer(rb"\[([^\[\]\n]{3,})\]", data[:8_000_000])]
    if not found:
        raise NotApplicable
    m = _pick(rng, found)
    items = m.group(1).split(b", ")
    how = int(rng.integers(3))
    if how == 0:
        items = items[: int(rng.integers(len(items)))]
    elif how == 1:
        items = items + items[: int(rng.integers(1, len(items) + 1))]
    else:
        items = []
    return data[:m.start(1)] + b", ".join(items) + data[m.end(1):], f"USDA array at {m.start()} -> {len(items)} items"


# ====================================================================== USDC (crate)
def _crate(data):
    if len(data) < 88 or data[:8] != b"PXR-USDC":
        raise NotApplicable
    toc = struct.unpack_from("<q", data, 16)[0]
    if not 0 < toc <= len(data) - 8:
        raise NotApplicable
    n = struct.unpack_from("<Q", data, toc)[0]
    if n > 64 or toc + 8 + 32 * n > len(data):
        raise NotApplicable
    secs = []
    for k in range(n):
        at = toc + 8 + 32 * k
        name = data[at:at + 16].rstrip(b"\x00").decode("ascii", "replace")
        start, size = struct.unpack_from("<qq", data, at + 16)
        secs.append((name, at, start, size))
    return toc, secs


def usdc_bootstrap(data, rng):
    toc, secs = _crate(data)
    b = bytearray(data)
    if rng.random() < 0.6:
        v = _pick(rng, (0, 8, 87, toc - 1, toc + 1, toc + 8, len(data), 2**62, -1))
        struct.pack_into("<q", b, 16, v)
        return bytes(b), f"USDC TOC offset {toc} -> {v}"
    k = int(rng.integers(8, 11))
    v = _pick(rng, (0, 1, 9, 255))
    b[k] = v
    return bytes(b), f"USDC version byte {k} -> {v}"


def usdc_toc(data, rng):
    toc, secs = _crate(data)
    b = bytearray(data)
    if rng.random() < 0.2:
        v = _pick(rng, (0, len(secs) + 1, 2**31, 2**63 - 1))
        struct.pack_into("<Q", b, toc, v)
        return bytes(b), f"USDC section count -> {v}"
    name, at, start, size = _pick(rng, secs)
    if rng.random() < 0.5:
        v = _pick(rng, (0, 88, start + 1, start - 1, toc, len(data), 2**62, -1))
        struct.pack_into("<q", b, at + 16, v)
        return bytes(b), f"USDC section {name} start {start} -> {v}"
    v = _pick(rng, (0, 1, size - 1, size + 1, size * 2, 2**62, -1))
    struct.pack_into("<q", b, at + 24, v)
    return bytes(b), f"USDC section {name} size {size} -> {v}"


def usdc_section(data, rng):
    """Bit flips, a random run or an extreme integer inside one named section (TOKENS, STRINGS,
    FIELDS, FIELDSETS, PATHS, SPECS) or in the value data before them."""
    toc, secs = _crate(data)
    first = min((s[2] for s in secs if s[2] > 0), default=toc)
    regions = [(n, st, sz) for n, _, st, sz in secs if sz > 0 and 0 < st and st + sz <= len(data)]
    if first > 88:
        regions.append(("values", 88, first - 88))
    if not regions:
        raise NotApplicable
    name, st, sz = _pick(rng, regions)
    inner, what = _pick(rng, (bitflip, random_run, extreme_int, bitflip))(data[st:st + sz], rng)
    inner = (inner + data[st + len(inner):st + sz])[:sz]  # keep the section's size
    return data[:st] + inner + data[st + sz:], f"USDC section {name}: {what}"


# ====================================================================== USDZ
def _usdz_inner(data):
    """(start, end, name) of the first zip entry's stored bytes."""
    if data[:4] != b"PK\x03\x04" or len(data) < 30:
        raise NotApplicable
    method, = struct.unpack_from("<H", data, 8)
    csize, = struct.unpack_from("<I", data, 18)
    nlen, xlen = struct.unpack_from("<HH", data, 26)
    start = 30 + nlen + xlen
    if method != 0 or start + csize > len(data):
        raise NotApplicable
    return start, start + csize, data[30:30 + nlen].decode("ascii", "replace")


def usdz_inner(data, rng):
    """Mutate the first layer inside the package in place (its size kept, so the zip directory
    stays right): crate mutators on a usdc, in-place byte mutators otherwise."""
    a, b, name = _usdz_inner(data)
    inner = data[a:b]
    pool = (usdc_toc, usdc_section, usdc_bootstrap) if inner[:8] == b"PXR-USDC" else (bitflip, random_run, extreme_int)
    new, what = _pick(rng, pool)(inner, rng)
    new = (new + inner[len(new):])[: len(inner)]
    return data[:a] + new + data[b:], f"USDZ {name}: {what}"


# ====================================================================== Collada (XML)
def dae_attrs(data, rng):
    found = list(re.finditer(rb'\b(count|stride|offset|set|sid|vcount)="(-?\d+)"', data))
    if not found:
        raise NotApplicable
    m = _pick(rng, found)
    new = _pick(rng, (b"0", b"-1", b"1", b"2147483647", b"4294967296", b"99999999999999999999", b"x", b""))
    return data[:m.start(2)] + new + data[m.end(2):], f"DAE {m.group(1).decode()}={m.group(2).decode()} -> {new.decode()}"


def dae_arrays(data, rng):
    """One array's values (NaN, huge, negative indices), or its list cut short."""
    found = list(re.finditer(rb"<(float_array|int_array|p|v|vcount|matrix|bind_shape_matrix|Name_array)\b[^>]*>([^<]*)</", data))
    found = [m for m in found if m.group(2).strip()]
    if not found:
        raise NotApplicable
    m = _pick(rng, found)
    items = m.group(2).split()
    tag = m.group(1).decode()
    how = int(rng.integers(3))
    if how == 0:
        items = items[: int(rng.integers(len(items)))]
        what = f"cut to {len(items)} items"
    elif how == 1 and tag in ("matrix", "bind_shape_matrix", "float_array"):
        items = ["0"] * len(items) if rng.random() < 0.5 else items
        k = int(rng.integers(len(items)))
        items[k] = _pick(rng, ("nan", "inf", "1e39", "-1e308", "0"))
        what = "zeroed/extreme"
    else:
        for _ in range(int(rng.integers(1, 5))):
            items[int(rng.integers(len(items)))] = _pick(rng, ("-1", "2147483647", "99999", "nan", "1e40", "x"))
        what = "values replaced"
    body = " ".join(i if isinstance(i, str) else i.decode("ascii", "replace") for i in items).encode()
    return data[:m.start(2)] + body + data[m.end(2):], f"DAE <{tag}> {what}"


def dae_elements(data, rng):
    """Remove or duplicate one element; point a reference (``#id``) nowhere; break a tag."""
    how = int(rng.integers(4))
    if how in (0, 1):
        found = list(re.finditer(rb"<(input|source|joints|vertex_weights|skin|controller|node|instance_controller|channel|sampler|accessor|param|skeleton|triangles|polylist|vertices)\b[^>]*?(/>|>.*?</\1>)", data, re.S))
        if not found:
            raise NotApplicable
        m = _pick(rng, found)
        if how == 0:
            return data[:m.start()] + data[m.end():], f"DAE <{m.group(1).decode()}> at {m.start()} removed"
        return data[:m.end()] + m.group(0) + data[m.end():], f"DAE <{m.group(1).decode()}> at {m.start()} duplicated"
    if how == 2:
        found = list(re.finditer(rb'(?:source|url|target|symbol)="#?([^"]+)"', data))
        if not found:
            raise NotApplicable
        m = _pick(rng, found)
        new = _pick(rng, (b"nowhere", b"", m.group(1) + m.group(1)))
        return data[:m.start(1)] + new + data[m.end(1):], f"DAE reference {m.group(1)[:30].decode()} -> {new[:30].decode()}"
    found = [m.start() for m in re.finditer(rb"</\w+>", data)]
    if not found:
        raise NotApplicable
    at = _pick(rng, found)
    end = data.index(b">", at) + 1
    return data[:at] + data[end:], f"DAE closing tag at {at} removed"


# ====================================================================== references (issue 26 item 7)
#: Placeholders a reference mutation writes; :func:`tests.fuzz.oracle.materialise` replaces them
#: when the case is written: ``__OUT__`` the absolute path of a folder *outside* the case's folder
#: (holding ``canary.bin``, ``canary.usda``, the FIFOs ``fifo`` and ``fifo.usda``), ``__SELF__``
#: the case file's own name.  The case's folder holds ``sub/`` (a directory), the FIFOs ``fifo``
#: and ``fifo.usda``, ``link.bin`` / ``link.usda`` (symlinks to the canaries outside) and ``loop``
#: (a symlink to itself).  Any of them opened is a bad outcome (the oracle watches both folders).
OUT, SELF = "__OUT__", "__SELF__"

#: Where a mutated reference points, by kind of target: {suffix} is ``.bin`` or ``.usda``.
REF_TARGETS = (
    OUT + "/canary{sfx}",            # an absolute path outside
    "../outside/canary{sfx}",        # a ../ escape
    "file://" + OUT + "/canary{sfx}",  # a file:// URI
    "file:canary{sfx}",
    OUT + "/fifo{fifo}",             # a FIFO outside
    "fifo{fifo}",                    # a FIFO inside
    "./fifo{fifo}",
    "/dev/zero",
    "/dev/urandom",
    "/proc/self/mem",
    "sub",                           # a directory
    "sub/",
    ".",
    "link{sfx}",                     # a symlink out
    "loop",                          # a symlink loop
    "sub/../../outside/canary{sfx}",
    SELF,                            # the file itself
    "./" + SELF,
    "missing{sfx}",
    "//" + OUT + "/canary{sfx}",
    "%2e%2e/outside/canary{sfx}",
)


def _ref_target(rng, usd):
    t = _pick(rng, REF_TARGETS)
    return t.format(sfx=".usda" if usd else ".bin", fifo=".usda" if usd else "")


def _gltf_refs(doc, rng):
    """Point a buffer's or an image's ``uri`` (a new image when there is none) at a target."""
    if not isinstance(doc, dict):
        raise NotApplicable
    target = _ref_target(rng, usd=False)
    bufs = doc.get("buffers") if isinstance(doc.get("buffers"), list) else []
    if bufs and isinstance(bufs[0], dict) and rng.random() < 0.75:
        i = int(rng.integers(len(bufs)))
        if not isinstance(bufs[i], dict):
            raise NotApplicable
        bufs[i]["uri"] = target
        return f"buffer {i} uri -> {target!r}"
    imgs = doc.setdefault("images", []) if isinstance(doc.get("images", []), list) else None
    if imgs is None:
        raise NotApplicable
    imgs.append({"uri": target})
    return f"image {len(imgs) - 1} uri -> {target!r}"


def gltf_refs(data, rng):
    try:
        doc = json.loads(data)
    except ValueError:
        raise NotApplicable from None
    what = _gltf_refs(doc, rng)
    return json.dumps(doc, indent=1, allow_nan=True).encode(), "glTF reference: " + what


def glb_refs(data, rng):
    doc, chunks = glb_split(data)
    what = _gltf_refs(doc, rng)
    chunks[0] = (_JSON, _json_bytes(doc))
    return glb_join(chunks), "GLB reference: " + what


_USD_ARCS = ("subLayers", "references", "payload", "clips", "inherits_ref", "variant_payload", "clip_manifest")
_DEF = re.compile(rb'^([ \t]*)(?:def|over) +(?:\w+ +)?"[^"\n]*"[ \t]*(\(?)', re.M)


def usda_refs(data, rng):
    """Add a composition arc (sublayer, reference, payload, value clip, a variant's payload) whose
    asset path points at a target (see :data:`REF_TARGETS`)."""
    if not data.startswith(b"#usda"):
        raise NotApplicable
    target = _ref_target(rng, usd=True).encode()
    arc = _pick(rng, _USD_ARCS)
    if arc == "subLayers":
        nl = data.find(b"\n")
        head = data[nl + 1:].lstrip()
        if head.startswith(b"("):
            at = data.index(b"(", nl) + 1
            data = data[:at] + b"\n    subLayers = [@" + target + b"@]\n" + data[at:]
        else:
            data = data[:nl + 1] + b"(\n    subLayers = [@" + target + b"@]\n)\n" + data[nl + 1:]
        return data, f"USD subLayers -> {target.decode()!r}"
    defs = list(_DEF.finditer(data))
    if not defs:
        raise NotApplicable
    m = defs[int(rng.integers(len(defs)))]
    meta = {
        "references": b"prepend references = @" + target + b"@",
        "inherits_ref": b"references = @" + target + b"@</root>",
        "payload": b"prepend payload = @" + target + b"@",
        "clips": (b'clips = {\n dictionary default = {\n asset[] assetPaths = [@' + target + b'@]\n'
                  b' string primPath = "/root"\n double2[] active = [(0, 0)]\n double2[] times = [(0, 0)]\n }\n }'),
        "clip_manifest": (b'clips = {\n dictionary default = {\n asset manifestAssetPath = @' + target + b'@\n'
                          b' asset[] assetPaths = [@' + target + b'@]\n double2[] active = [(0, 0)]\n }\n }'),
        "variant_payload": b'variantSets = "v"\n variants = {\n string v = "a"\n }',
    }[arc]
    if m.group(2):  # the prim already has metadata: add to it
        at = m.end()
        data = data[:at] + b"\n    " + meta + b"\n" + data[at:]
    else:
        at = m.end()
        data = data[:at] + b" (\n    " + meta + b"\n)" + data[at:]
    if arc == "variant_payload":  # the variant itself, in the prim's body
        brace = data.find(b"{", at)
        if brace < 0:
            raise NotApplicable
        body = (b'\n    variantSet "v" = {\n        "a" (\n            prepend payload = @' + target +
                b'@\n        ) {\n        }\n    }\n')
        data = data[:brace + 1] + body + data[brace + 1:]
    return data, f"USD {arc} -> {target.decode()!r}"


# ====================================================================== the table
#: extension -> structure-aware mutators for it (byte and text ones apply on top)
FORMAT_MUTATORS = {
    ".glb": {"glb_json": glb_json, "glb_bin": glb_bin, "glb_chunks": glb_chunks, "glb_refs": glb_refs},
    ".gltf": {"gltf_json": gltf_json_mut, "gltf_buffers": gltf_buffers, "gltf_refs": gltf_refs},
    ".fbx": {"fbx_array": fbx_array, "fbx_array_header": fbx_array_header, "fbx_scalar": fbx_scalar,
             "fbx_nodes": fbx_nodes, "fbx_record": fbx_record},
    ".usda": {"usda_tokens": usda_tokens, "usda_arrays": usda_arrays, "usda_refs": usda_refs, "text_number": text_number,
              "text_lines": text_lines, "text_brackets": text_brackets, "text_encoding": text_encoding},
    ".usdc": {"usdc_bootstrap": usdc_bootstrap, "usdc_toc": usdc_toc, "usdc_section": usdc_section},
    ".usdz": {"usdz_inner": usdz_inner},
    ".dae": {"dae_attrs": dae_attrs, "dae_arrays": dae_arrays, "dae_elements": dae_elements,
             "text_encoding": text_encoding},
}
TEXT_FORMATS = (".usda", ".dae", ".gltf", ".x", ".md5mesh", ".md5anim", ".obj", ".fbx")

ALL = {**BYTE_MUTATORS, **TEXT_MUTATORS}
for _table in FORMAT_MUTATORS.values():
    ALL.update(_table)


def mutators_for(ext: str, data: bytes) -> dict:
    """name -> mutator for a file of extension ``ext`` (structure-aware first)."""
    table = dict(FORMAT_MUTATORS.get(ext, {}))
    if ext in TEXT_FORMATS and not data.startswith(_FBX_MAGIC):
        table.update({k: v for k, v in TEXT_MUTATORS.items() if k != "text_encoding" or ext != ".gltf"})
    return table


#: Share of the cases of a format with a reference mutator (``*_refs``) that get one first.
REFS_SHARE = 0.15


def mutate(data: bytes, ext: str, rng, structured: float = 0.7, stack: float = 0.2, refs: float = REFS_SHARE):
    """Mutate ``data`` (a file of extension ``ext``); returns ``(bytes, [(mutator, what), ...])``.

    With probability ``refs`` (when the format has a reference mutator) that one first; then a
    structure-aware mutator with probability ``structured`` (when the format has any), else a
    byte-level one; with probability ``stack`` a second mutation on top.  Deterministic for a
    given ``rng`` state.
    """
    steps = []
    ref = next((n for n in sorted(FORMAT_MUTATORS.get(ext, {})) if n.endswith("_refs")), None)
    if ref and rng.random() < refs:
        try:
            data, what = FORMAT_MUTATORS[ext][ref](data, rng)
            steps.append((ref, what))
        except NotApplicable:
            pass
    for _ in range(2 if rng.random() < stack else 1):
        fmt = mutators_for(ext, data)
        pool = fmt if fmt and rng.random() < structured else BYTE_MUTATORS
        names = sorted(pool)
        for _try in range(4):
            name = _pick(rng, names)
            try:
                data, what = pool[name](data, rng)
                steps.append((name, what))
                break
            except NotApplicable:
                pool, names = BYTE_MUTATORS, sorted(BYTE_MUTATORS)
    return data, steps
