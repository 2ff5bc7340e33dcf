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
* Units: Ogre has none; Y-up metres as for the other assimp formats, unless the user says.
"""

from __future__ import annotations

import os
import struct
import xml.etree.ElementTree as ET

import numpy as np

from ..errors import InputError

EXTENSIONS = (".mesh", ".mesh.xml")

#: the binary mesh serializer's chunk ids this module reads
_M_HEADER, _M_MESH, _M_SKELETON_LINK = 0x1000, 0x3000, 0x6000


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
    lengths; a file whose lengths do not add up is scanned for the chunk id instead (assimp reads
    the chunks in order and ignores most lengths), so no link a reader could follow is missed."""
    with open(path, "rb") as fh:
        data = fh.read()
    if len(data) < 2 or struct.unpack_from("<H", data)[0] != _M_HEADER:
        raise InputError(path, "not an Ogre binary mesh (no serializer header chunk)")
    links = []
    i = 0
    while i + 6 <= len(data):
        j = data.find(struct.pack("<H", _M_SKELETON_LINK), i)
        if j < 0 or j + 6 > len(data):
            break
        end = data.find(b"\n", j + 6)
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
