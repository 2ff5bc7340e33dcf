"""Readers, one module per source family, registered in one table keyed by file extension.

``READERS[".glb"]`` is the function that reads a ``.glb``; compound suffixes (``.mesh.xml``)
are matched first.  Every reader returns a :class:`~pipeline.model.SkinnedMesh` in the source's
own axes and units (``up_axis``, ``meters_per_unit``); the ``bake`` stage converts.
"""

from __future__ import annotations

import os

from ..errors import InputError
from .assimp_reader import read_assimp
from .gltf_reader import read_gltf
from .ufbx_reader import available as _ufbx_available, read_ufbx
from .usd_reader import read_usd

#: Extensions assimp 5.x/6.x imports (https://assimp-docs.readthedocs.io, "Importer formats").
ASSIMP_EXTENSIONS = (
    ".glb", ".gltf", ".fbx", ".dae", ".zae", ".x", ".3ds", ".obj", ".ply", ".stl", ".blend",
    ".bvh", ".md5mesh", ".md5anim", ".smd", ".vta", ".ms3d", ".b3d", ".x3d", ".3mf", ".lwo",
    ".lws", ".ase", ".ask", ".ac", ".ac3d", ".acc", ".cob", ".scn", ".mdl", ".md2", ".md3",
    ".mdc", ".nff", ".off", ".ogex", ".irr", ".irrmesh", ".q3o", ".q3s", ".raw", ".ter",
    ".hmp", ".ndo", ".pmx", ".xgl", ".zgl", ".csm", ".iqm", ".sib", ".m3d", ".mesh.xml", ".mesh",
    ".amf", ".3d", ".uc", ".dxf", ".ifc", ".stp", ".lxo",
)
USD_EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")

#: extension -> reader function ``(path, meshes=None, fps=None) -> SkinnedMesh``
READERS = {ext: read_assimp for ext in ASSIMP_EXTENSIONS}
READERS.update({ext: read_usd for ext in USD_EXTENSIONS})
READERS.update({".glb": read_gltf, ".gltf": read_gltf})  # read from the spec: samplers, morph targets, skins


def read_fbx(path, meshes=None, fps=None):
    """FBX as the authoring tools evaluate it (inherit types, pivots, geometric transforms, Maya's
    transform_skin: :mod:`.ufbx_reader`) when the ufbx binding is installed (the ``pipeline``
    extra); through assimp otherwise, or when the environment sets ``COLOSSUS_FBX_READER=assimp``
    (to compare the two roads; the assimp path names what it does not carry)."""
    if os.environ.get("COLOSSUS_FBX_READER", "ufbx") != "assimp" and _ufbx_available():
        return read_ufbx(path, meshes=meshes, fps=fps)
    return read_assimp(path, meshes=meshes, fps=fps)


READERS[".fbx"] = read_fbx


def reader_for(path):
    """The reader registered for ``path``'s extension (longest matching suffix wins)."""
    name = os.path.basename(os.fspath(path)).lower()
    for ext in sorted(READERS, key=len, reverse=True):
        if name.endswith(ext):
            return READERS[ext]
    if name.endswith((".skeleton", ".skeleton.xml")):
        raise InputError(path, "an Ogre skeleton holds no mesh: import the .mesh (or .mesh.xml) that links it; "
                               "its skeleton is read from beside it")
    raise InputError(path, f"unsupported file type {os.path.splitext(name)[1] or '(no extension)'!r}; "
                     f"supported: {' '.join(USD_EXTENSIONS)} through usd-core, and {len(ASSIMP_EXTENSIONS)} "
                     f"through assimp ({' '.join(ASSIMP_EXTENSIONS[:4])} ... {ASSIMP_EXTENSIONS[-1]})")


def read(path, meshes=None, fps=None):
    """Read any supported file into a :class:`~pipeline.model.SkinnedMesh`."""
    return reader_for(path)(path, meshes=meshes, fps=fps)
