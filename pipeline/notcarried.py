"""What a reader met in the source and does not carry exactly into the collider ("fail closed").

A reader lists each such thing in ``mesh.source["not_carried"]`` as one record::

    {"what": "fbx_skinning_type",          # short stable id of the class
     "where": ["skinCluster1"],            # node / mesh / clip / extension names
     "detail": "SkinningType Blend ...",   # one line
     "bound_relative": 0.12 or None}       # the largest vertex error it can cause / model size,
                                           # where it can be bounded; None where it cannot

Every record becomes one warning line of the import summary, is listed in ``colossus import
--json`` (``"not_carried"``), is stored in the asset's provenance (``customData["colossus"]
["notCarried"]``, a dictionary keyed ``"000"``, ``"001"``... since USD dictionaries hold no list
of dictionaries) so ``colossus inspect`` lists it, and ``colossus import --strict`` refuses the
import when there is any.

The ``what`` ids (README, "Not carried"):

========================  ======================================================================
``morph_targets``         FBX blend shapes on the assimp road (glTF morph targets, USD
                          ``skel:blendShapes`` and FBX blend channels on the ufbx road are carried
                          as UsdSkel blend shapes, by a simplified proxy too)
``fbx_evaluation``        (ufbx road) joint keys that do not reproduce ufbx's native evaluation
``fbx_skinning_type``     FBX Skin ``SkinningType`` DualQuaternion, or Blend with non-zero
                          per-vertex ``BlendWeights`` (we skin linearly)
``fbx_inherit_type``      FBX ``InheritType`` 0 (RrSs) under a non-uniformly scaled parent
``fbx_transform_skin``    a skinned mesh node whose world transform differs from its bind pose
``fbx_geometric_transform``  GeometricTranslation / Rotation / Scaling on a skinned mesh node
``fbx_instanced_skin``    one skinned geometry instanced by several models
``fbx_skin_deformers``    (ufbx road) a mesh with more than one skin deformer
``fbx_constraints``       FBX constraint objects (their effect is only in baked keys, if any)
``fbx_curve_interpolation``  cubic / constant FBX curve segments spanning grid frames (assimp
                          interpolates every curve linearly between its keys)
``gltf_extension``        a glTF extension used that changes geometry or deformation, not read
``ogre_vertex_animation``  an Ogre mesh's pose / morph (vertex) animation (assimp makes no clip)
``ogre_animation_link``   an Ogre skeleton's links to another skeleton's animations (not read)
``skin_influences``      (the ``bind`` stage) influences beyond ``--max-influences`` or negligible
                          ones dropped that move a vertex more than 1e-4 x the posed size
``usd_skinning_method``   meshes that mix ``primvars:skel:skinningMethod`` values: the collision
                          mesh carries one (the method of most points; a USD source whose
                          meshes agree has its method carried, linear or dual-quaternion)
========================  ======================================================================
"""

from __future__ import annotations

#: Key of the list in a reader's ``mesh.source`` and in the import's JSON summary.
SOURCE_KEY = "not_carried"
#: Key of the dictionary inside the asset's provenance (``customData["colossus"]``).
PROVENANCE_KEY = "notCarried"


def item(what: str, where, detail: str, bound_relative: float | None = None) -> dict:
    """One record (see the module docstring); ``where`` is a name or a list of names."""
    if isinstance(where, str):
        where = [where]
    b = None if bound_relative is None else float(bound_relative)
    return {"what": str(what), "where": [str(w) for w in where], "detail": " ".join(str(detail).split()),
            "bound_relative": b}


def warning_line(it: dict) -> str:
    """The one warning line of a record."""
    where = ", ".join(it.get("where") or [])
    b = it.get("bound_relative")
    bound = (f"; moves vertices up to {b:.2g} x the model size" if b is not None
             else "; its error cannot be bounded here")
    return f"not carried: {it['what']} ({where or '-'}): {it['detail']}{bound}"


def strict_refusal(items: list) -> str:
    """The one-line reason ``--strict`` refuses an import with ``items``."""
    first = items[0]
    where = ", ".join(first.get("where") or [])
    more = f" (and {len(items) - 1} more)" if len(items) > 1 else ""
    return (f"--strict: {len(items)} thing(s) in the source are not carried exactly{more}; first: "
            f"{first['what']} ({where or '-'}): {first['detail']}")


def to_provenance(items: list) -> dict:
    """``{"000": {"what", "where", "detail", "boundRelative"}, ...}`` for the asset's customData
    (``where`` joined with ", "; no bound: ``""``)."""
    out = {}
    for i, it in enumerate(items):
        b = it.get("bound_relative")
        out[f"{i:03d}"] = {"what": it["what"], "where": ", ".join(it.get("where") or []),
                           "detail": it["detail"], "boundRelative": "" if b is None else float(b)}
    return out


def from_provenance(d) -> list:
    """The records stored by :func:`to_provenance`, in order (``bound_relative`` None where absent)."""
    if not isinstance(d, dict):
        return []
    out = []
    for k in sorted(d):
        v = d[k]
        if not isinstance(v, dict):
            continue
        b = v.get("boundRelative")
        where = [w for w in str(v.get("where", "")).split(", ") if w]
        out.append({"what": str(v.get("what", "")), "where": where, "detail": str(v.get("detail", "")),
                    "bound_relative": float(b) if isinstance(b, (int, float)) and not isinstance(b, bool) else None})
    return out
