"""What the assimp road reads from an FBX file besides assimp's scene: the ``GlobalSettings`` assimp
does not apply (unit scale, up axis, frame rate), each animation stack's span on the scene's
timeline, models' ``InheritType`` and which meshes have blend shapes.

Everything here is read from one parse of the file's node tree, :func:`.fbx_doc.read_document`
(binary of any version and ASCII), so there is one FBX walker in the project.  Every function
takes that :class:`~.fbx_doc.Document` (``None`` when the file could not be walked) and never
raises on malformed values: what cannot be read is left out.
"""

from __future__ import annotations

from .fbx_doc import Document, object_name

#: FBX time units per second (FbxTime).
KTIME_PER_SECOND = 46186158000


def read_global_settings(doc: Document | None) -> dict:
    """``{"UnitScaleFactor": float, "UpAxis": int, "UpAxisSign": int, "TimeMode": int, ...}``:
    the ``GlobalSettings`` properties present (numbers only)."""
    if doc is None:
        return {}
    out = {}
    for k, v in doc.properties(doc.top("GlobalSettings")).items():
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            out[k] = v
    return out


def _objects(doc: Document | None, kind: str):
    """``(id, name, subclass, node)`` of every ``Objects/<kind>`` node."""
    objs = doc.top("Objects") if doc is not None else None
    for n in (objs.all(kind) if objs is not None else []):
        if len(n.props) >= 3 and isinstance(n.props[0], int):
            yield n.props[0], object_name(n.props[1]), str(n.props[2]), n


def read_anim_stacks(doc: Document | None) -> dict:
    """``{stack name: (start, stop)}`` in seconds of global scene time, from each
    ``AnimationStack``'s ``LocalStart``/``LocalStop`` (else ``ReferenceStart``/``Stop``).

    assimp shifts every stack's keys so that the stack starts at time 0; this gives the shift
    back (stacks placed one after another on the global timeline keep their own times)."""
    out = {}
    for _, name, _, node in _objects(doc, "AnimationStack"):
        p = doc.properties(node)
        try:
            span = {k: float(p[k]) / KTIME_PER_SECOND for k in ("LocalStart", "LocalStop", "ReferenceStart",
                                                                 "ReferenceStop") if k in p}
        except (TypeError, ValueError, OverflowError):
            continue
        start = span.get("LocalStart", span.get("ReferenceStart"))
        stop = span.get("LocalStop", span.get("ReferenceStop"))
        if start is not None and stop is not None and stop >= start:
            out[name] = (start, stop)
    return out


def read_inherit_types(doc: Document | None) -> dict:
    """``{model name: InheritType}`` for every ``Model`` whose ``InheritType`` is authored
    (FbxTransform::EInheritType: 0 eInheritRrSs, 1 eInheritRSrs, 2 eInheritRrs; Maya's joints
    with segment scale compensation are 2)."""
    out = {}
    for _, name, _, node in _objects(doc, "Model"):
        v = doc.properties(node).get("InheritType")
        try:
            if v is not None:
                out[name] = int(v)
        except (TypeError, ValueError, OverflowError):
            continue
    return out


def read_morph_geometry(doc: Document | None) -> dict:
    """``{name: number of blend-shape channels}`` for every mesh with shape keys, keyed by both its
    Model and its Geometry name (assimp names meshes after either)."""
    if doc is None:
        return {}
    kind, name = {}, {}
    for cls in ("Geometry", "Deformer", "Model"):
        for oid, n, sub, _ in _objects(doc, cls):
            kind[oid] = (cls, sub)
            name[oid] = n
    parent_of, channels = {}, {}
    conns = doc.top("Connections")
    for c in (conns.all("C") if conns is not None else []):
        if len(c.props) >= 3 and c.props[0] == "OO":
            child, parent = c.props[1], c.props[2]
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
