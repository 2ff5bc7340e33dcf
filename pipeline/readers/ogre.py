"""Ogre meshes (binary ``.mesh`` and XML ``.mesh.xml``), read through assimp, with what assimp
does not check or does not carry as Ogre plays it.

* **The skeleton file.** An Ogre mesh names its skeleton (``M_MESH_SKELETON_LINK`` / the XML
  ``<skeletonlink name>``), and assimp opens that name relative to the mesh's folder.  The name
  is checked first by the rule every reference follows (:mod:`runtime.references`: a regular
  file inside the mesh's folder, unless ``--allow-outside-references``).  assimp reads a skeleton
  it cannot find as *no skeleton* (a static mesh, silently): that is refused here, naming the file
  it looked for.  For an XML mesh assimp tries ``<name>.xml`` and then ``<name>`` (binary); for a
  binary mesh only ``<name>``.
* **Keyframe translation.** Ogre adds a key's translation to the bone's binding position in the
  parent's space (``NodeAnimationTrack::applyToNode``: ``Node::translate`` is ``TS_PARENT``);
  assimp composes ``binding * key`` as matrices, which turns the translation by the bone's binding
  rotation and scale.  :func:`mend_translations` puts it back: ``p + R_b^-1 (p' - p)`` for
  assimp's ``p'`` (exact where the binding scale is uniform, as Ogre exporters write it).
* **Animation length.** Ogre plays an animation from 0 to its ``length``; a track whose last key
  comes before the length is interpolated from that key towards its first key, placed at
  ``length + first key time`` (``AnimationTrack::getKeyFramesAtTime`` wraps).  assimp keeps only
  the keys: :func:`wrap_to_length` adds that key, and the clip spans ``0 .. length``.
* Units: Ogre has none; Y-up metres as for the other assimp formats, unless the user says.
* **Not carried** (:func:`not_carried`, named, never dropped silently): a mesh's pose / morph
  (vertex) animation (``M_POSES`` / ``M_ANIMATIONS``, XML ``<poses>`` / ``<animations>``), which
  assimp does not turn into clips, and a skeleton's animation links (``SKELETON_ANIMATION_LINK``,
  XML ``<animationlinks>``: animations borrowed from another skeleton file, which assimp skips).
"""

from __future__ import annotations

import os
import struct
import xml.etree.ElementTree as ET

import numpy as np

from ..errors import InputError

EXTENSIONS = (".mesh", ".mesh.xml")

#: the binary serializers' chunk ids this module reads
_M_HEADER, _M_MESH, _M_SKELETON_LINK = 0x1000, 0x3000, 0x6000
_M_POSES, _M_ANIMATIONS = 0xC000, 0xD000
_SKELETON_ANIMATION_LINK = 0x5000
#: the chunk ids ``M_MESH`` may hold (geometry, submeshes, skeleton link, bone assignments, LOD,
#: bounds, submesh names, edge lists, poses, animations, extremes)
_MESH_CHUNKS = {0x4000, 0x5000, 0x6000, 0x7000, 0x8000, 0x9000, 0xA000, 0xB000, 0xC000, 0xD000, 0xE000}


def is_ogre(path) -> bool:
    return os.path.basename(os.fspath(path)).lower().endswith(EXTENSIONS)


def skeleton_links(path) -> list:
    """The skeleton names the mesh file gives (normally one; none for a static mesh)."""
    p = os.fspath(path)
    if p.lower().endswith(".xml"):
        return _xml_links(p)
    return _binary_links(p)


def _xml_links(path) -> list:
    out = []
    try:
        for _, el in ET.iterparse(path, events=("start",)):
            if el.tag == "skeletonlink" and el.get("name") is not None:
                out.append(el.get("name"))
    except ET.ParseError as e:
        raise InputError(path, f"not a readable Ogre XML mesh: {e}") from None
    return out


def _binary_links(path) -> list:
    """Every ``M_MESH_SKELETON_LINK`` chunk's name.  The chunks of ``M_MESH`` are walked by their
    lengths; in a file whose lengths do not add up (assimp reads the chunks in order and ignores
    most lengths) the bytes are scanned for the chunk id instead, so no link a reader could follow
    is missed."""
    with open(path, "rb") as fh:
        data = fh.read()
    if len(data) < 2 or struct.unpack_from("<H", data)[0] != _M_HEADER:
        raise InputError(path, "not an Ogre binary mesh (no serializer header chunk)")
    walked = _mesh_subchunks(data)
    if walked is not None:
        out = []
        for cid, body, end in walked:
            if cid == _M_SKELETON_LINK:
                nl = data.find(b"\n", body, end)
                out.append(data[body:nl if nl >= 0 else end].decode("utf-8", "replace"))
        return list(dict.fromkeys(out))
    links = []
    i = 0
    tag = struct.pack("<H", _M_SKELETON_LINK)
    while True:
        j = data.find(tag, i)
        if j < 0 or j + 6 > len(data):
            break
        end = data.find(b"\n", j + 6, j + 6 + 4096)  # a bounded look: never quadratic
        if end > j + 6:
            raw = data[j + 6:end]
            length = struct.unpack_from("<I", data, j + 2)[0]
            printable = all(32 <= c < 127 for c in raw)
            if printable and (length == end + 1 - j or raw.lower().endswith((b".skeleton", b".skeleton.xml"))):
                links.append(raw.decode("ascii"))
        i = j + 1
    return list(dict.fromkeys(links))


def check_skeleton(path) -> str | None:
    """The skeleton file assimp will read for this mesh, checked (None for a mesh without a
    link); raises :class:`InputError` when it would leave the folder, is not a regular file, or
    is missing (assimp would silently read the mesh without its skeleton)."""
    from colossus.runtime.references import OutsideReference, resolve

    p = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(p))
    links = skeleton_links(p)
    found = None
    for link in links:
        names = [link + ".xml", link] if p.lower().endswith(".xml") and link.lower().endswith(".skeleton") else [link]
        present = [n for n in names if os.path.lexists(os.path.join(folder, n))]
        for n in present:
            try:
                full = resolve(p, n, "skeleton")
            except OutsideReference as e:
                raise InputError(p, str(e)) from None
            found = found or full
        if not present:
            raise InputError(p, f"its skeleton {' or '.join(repr(n) for n in names)} is not in its folder "
                             "(an Ogre mesh's skeleton is the file its skeleton link names, beside it)")
    return found


def wrap_to_length(channels, length: float) -> list:
    """The channels as Ogre plays them over ``0 .. length``: a channel whose last key comes
    before ``length`` gets its first key's value again at ``length + first key time`` (Ogre
    interpolates the gap towards the first key, wrapping; see the module docstring)."""
    from .scene import Channel

    out = []
    eps = 1e-6 * max(1.0, abs(length))
    for ch in channels:
        t = np.asarray(ch.times, dtype=np.float64)
        if len(t) > 1 and t[-1] < length - eps:
            v = np.asarray(ch.values)
            ch = Channel(ch.node, ch.path, np.r_[t, length + t[0]], np.concatenate([v, v[:1]]), ch.interpolation,
                         ch.static)
        out.append(ch)
    return out


def mend_translations(local, channels_by_anim) -> None:
    """Ogre's keyframe translation (added in the parent's space) from assimp's (turned by the
    bone's binding rotation); see the module docstring.  ``local`` is the nodes' binding local
    transforms ``(n, 4, 4)`` (assimp's node of an Ogre bone holds its binding pose);
    ``channels_by_anim`` holds the :class:`~.scene.Channel` lists, whose translation channels
    are rewritten in place."""
    for chans in channels_by_anim:
        for ch in chans:
            if ch.path != "t":
                continue
            bind = local[ch.node]
            m = bind[:3, :3]
            p = bind[:3, 3]
            ch.values[:] = p + (ch.values - p) @ np.linalg.inv(m).T


# ------------------------------------------------------------------------------ not carried
def _chunks(data: bytes, start: int, end: int):
    """``[(id, body start, chunk end)]`` of the chunks laid end to end in ``data[start:end]``;
    None when their lengths do not tile it (a file whose chunks cannot be walked)."""
    out = []
    i = start
    while i < end:
        if i + 6 > end:
            return None
        cid, length = struct.unpack_from("<HI", data, i)
        if length < 6 or i + length > end:
            return None
        out.append((cid, i + 6, i + length))
        i += length
    return out


def _mesh_subchunks(data: bytes):
    """``[(id, body start, end)]`` of the chunks directly inside ``M_MESH``; None when the
    chunks cannot be walked."""
    head = data.find(b"\n", 2, 2 + 256)
    if head < 0:
        return None
    top = _chunks(data, head + 1, len(data))
    if top is None:
        return None
    if not top or any(cid != _M_MESH for cid, _, _ in top):
        return None
    out = []
    for cid, body, end in top:
        inner = _chunks(data, body + 1, end)  # after the bool "skeletally animated"
        if inner is None or any(c not in _MESH_CHUNKS for c, _, _ in inner):
            return None
        out += inner
    return out


def _binary_mesh_parts(data: bytes):
    """The chunk ids directly inside ``M_MESH``; None when the chunks cannot be walked."""
    inner = _mesh_subchunks(data)
    return None if inner is None else {c for c, _, _ in inner}


def _binary_skeleton_parts(data: bytes):
    head = data.find(b"\n", 2, 2 + 256)
    top = _chunks(data, head + 1, len(data)) if head >= 0 else None
    if top is None or any(c not in (0x1010, 0x2000, 0x3000, 0x4000, _SKELETON_ANIMATION_LINK) for c, _, _ in top):
        return None
    return {c for c, _, _ in top}


def not_carried(path, skeleton) -> list:
    """The :mod:`pipeline.notcarried` records of an Ogre mesh (and its skeleton file, when it has
    one) for what assimp does not carry; see the module docstring."""
    from .. import notcarried

    p = os.fspath(path)
    name = os.path.basename(p)
    out = []
    vertex_anim = skel_links = None
    try:
        if p.lower().endswith(".xml"):
            tags = {el.tag for _, el in ET.iterparse(p, events=("start",))}
            vertex_anim = bool({"pose", "animation"} & tags)
        else:
            with open(p, "rb") as fh:
                parts = _binary_mesh_parts(fh.read())
            vertex_anim = None if parts is None else bool({_M_POSES, _M_ANIMATIONS} & parts)
        if skeleton:
            if skeleton.lower().endswith(".xml"):
                skel_links = "animationlink" in {el.tag for _, el in ET.iterparse(skeleton, events=("start",))}
            else:
                with open(skeleton, "rb") as fh:
                    parts = _binary_skeleton_parts(fh.read())
                skel_links = None if parts is None else _SKELETON_ANIMATION_LINK in parts
        else:
            skel_links = False
    except (OSError, ET.ParseError):
        pass  # assimp has read the files: what could not be checked is said below
    if vertex_anim or vertex_anim is None:
        out.append(notcarried.item(
            "ogre_vertex_animation", [name],
            "pose / morph (vertex) animation of the mesh is not read (assimp makes no clip of it)" if vertex_anim else
            "its chunks could not be walked to check for pose / morph (vertex) animation, which is not read"))
    if skel_links or skel_links is None:
        out.append(notcarried.item(
            "ogre_animation_link", [os.path.basename(skeleton or "")],
            "the skeleton links animations from another skeleton file, which are not read" if skel_links else
            "its skeleton's chunks could not be walked to check for animation links, which are not read"))
    return out
