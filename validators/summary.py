"""A readable summary of one collider asset (``colossus inspect``).

``summarize(asset) -> dict`` gathers what a person wants to know first (stage metadata, counts,
the joint tree, clips, parts, provenance) from a :class:`validators.asset.LoadedAsset`;
``format_summary(dict) -> str`` lays it out as text.  A malformed piece of the asset shows as
``None`` / missing rather than raising: the rules of ``colossus validate`` say what is wrong.

``open_asset(path)`` is the one way the picture and summary commands read an asset: it raises
:class:`AssetError` with a one-line reason when the file is missing or usd-core cannot read it.
"""

from __future__ import annotations

import os

import numpy as np
from pxr import UsdGeom

from colossus.runtime import schema
from colossus.runtime.errors import ColossusError, one_line

from .asset import LoadedAsset, open_stage


class AssetError(ColossusError):
    """The asset cannot be read (missing file, not USD, usd-core error).  ``str()`` is one line."""


def open_asset(path) -> LoadedAsset:
    """Read ``path`` into a :class:`~validators.asset.LoadedAsset`.

    Raises
    ------
    AssetError
        The file does not exist, is not readable, or usd-core cannot open it.
    """
    path = os.fspath(path)
    if not os.path.isfile(path) or not os.access(path, os.R_OK):
        raise AssetError(f"{path}: no such readable file")
    try:
        return LoadedAsset(open_stage(path), path)
    except Exception as e:  # usd-core raises Tf.ErrorException and friends
        raise AssetError(f"{path}: usd-core cannot read it: {one_line(e)}") from None


def _plain(v):
    """usd-core / numpy values -> JSON-able Python values."""
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (str, bool, int, float)) or v is None:
        return v
    try:
        return v.item()
    except AttributeError:
        return str(v)


def summarize(asset: LoadedAsset) -> dict:
    """Everything ``colossus inspect`` prints, as plain data.

    Returns
    -------
    dict with keys ``path``, ``stage`` (``upAxis``, ``metersPerUnit``, ``timeCodesPerSecond``,
    ``defaultPrim``), ``prims`` (root, skeleton, mesh paths), ``counts`` (vertices, triangles,
    faces, joints, parts, clips, frames, influences: elementSize / nonzero / max_per_vertex /
    mean_per_vertex), ``joints`` (``[{"name", "path", "parent", "depth"}]``, parents first as
    stored), ``clips`` (``[{"name", "frames", "start", "end", "seconds", "source"}]``, ``source`` how
    the clip was sampled from its source: ``sourceKeys``, ``interpolation``, ``sampling``,
    ``keysOnGrid``, ``errorBound``), ``meshes`` (``[{"name", "kind", "vertices", "joint"}]``: the
    source meshes in the collider, skinned or rigid), ``parts``
    (``[{"index", "joint", "faces", "radius"}]``) and ``provenance`` (the mesh's
    ``customData["colossus"]``, or ``{}``) and ``proxy`` (a simplified proxy's ``sourceFaces``,
    ``maxDeviation``, ``measuredDeviation``, ``worstClip``, ``worstFrame``, ``worstBone``,
    ``worstDirection``; None for a full mesh) and ``not_carried`` (what the importer met in the
    source and did not carry exactly: ``[{"what", "where", "detail", "bound_relative"}]``, from
    the provenance's ``notCarried``; empty when nothing) and ``skinning_method`` (the mesh's
    ``primvars:skel:skinningMethod``, ``classicLinear`` when not authored) and ``usd_tools``
    (what other USD tools are given: ``clip_variants`` the ``clip`` variant names, ``selection``,
    ``guide_spheres`` their count).
    """
    stage = asset.stage
    tcps = float(stage.GetTimeCodesPerSecond())
    dp = stage.GetDefaultPrim()
    out = {
        "path": asset.path,
        "stage": {
            "upAxis": str(UsdGeom.GetStageUpAxis(stage)),
            "metersPerUnit": float(UsdGeom.GetStageMetersPerUnit(stage)),
            "timeCodesPerSecond": tcps,
            "defaultPrim": str(dp.GetPath()) if dp else None,
        },
        "prims": {
            "root": str(asset.root.GetPath()) if asset.root is not None else None,
            "skeleton": str(asset.skeleton.GetPath()) if asset.skeleton is not None else None,
            "mesh": str(asset.mesh.GetPath()) if asset.mesh is not None else None,
        },
    }
    infl = None
    if asset.jw is not None:
        nz = (asset.jw != 0).sum(axis=1)
        infl = {"elementSize": int(asset.k), "nonzero": int(nz.sum()),
                "max_per_vertex": int(nz.max()) if len(nz) else 0,
                "mean_per_vertex": round(float(nz.mean()), 3) if len(nz) else 0.0}
    P = len(asset.part_joints) if asset.part_joints is not None else None
    out["counts"] = {
        "vertices": asset.n if asset.points is not None else None,
        "triangles": len(asset.tris) if asset.tris is not None else None,
        "faces": len(asset.face_counts) if asset.face_counts is not None else None,
        "joints": len(asset.joints) if asset.joints is not None else None,
        "parts": P,
        "clips": len(asset.clips),
        "frames": int(sum(len(c.times) for c in asset.clips)),
        "influences": infl,
    }
    joints = []
    if asset.joints is not None:
        parents = asset.parents if asset.parents is not None else np.full(len(asset.joints), -1)
        depth = {}
        for i, j in enumerate(asset.joints):
            p = int(parents[i]) if i < len(parents) else -1
            depth[i] = depth.get(p, -1) + 1 if p >= 0 else 0
            joints.append({"name": j.rsplit("/", 1)[-1], "path": j, "parent": p, "depth": depth[i]})
    out["joints"] = joints
    out["clips"] = [{
        "name": c.name,
        "frames": len(c.times),
        "start": float(c.times[0]) if len(c.times) else None,
        "end": float(c.times[-1]) if len(c.times) else None,
        "seconds": round(float(c.times[-1] - c.times[0]) / tcps, 4) if len(c.times) and tcps > 0 else None,
        "source": _plain(dict(c.prim.GetCustomDataByKey(schema.CLIP_SOURCE_KEY) or {})),
    } for c in asset.clips]
    parts = []
    if P is not None and asset.part_offsets is not None and asset.part_radii is not None:
        faces = np.diff(asset.part_offsets)
        for p in range(P):
            parts.append({"index": p, "joint": asset.part_joints[p],
                          "faces": int(faces[p]) if p < len(faces) else None,
                          "radius": float(asset.part_radii[p]) if p < len(asset.part_radii) else None})
    out["parts"] = parts
    prov = {}
    if asset.mesh is not None:
        prov = _plain(dict(asset.mesh.GetCustomData().get(schema.PROVENANCE_KEY, {}) or {}))
    out["provenance"] = prov
    out["model_size"] = float(asset.model_size) if asset.points is not None else None
    out["skinning_method"] = schema.skinning_method(asset.mesh) if asset.mesh is not None else None
    out["usd_tools"] = _usd_tools(asset)
    out["proxy"] = None
    if asset.mesh is not None and isinstance(asset.mesh.GetCustomDataByKey(schema.PROXY_KEY), dict):
        g = asset.mesh.GetCustomDataByKey
        out["proxy"] = {"sourceFaces": _plain(g(schema.PROXY_SOURCE_FACES)),
                        "maxDeviation": _plain(g(schema.PROXY_MAX_DEVIATION)),
                        "measuredDeviation": _plain(g(schema.PROXY_MEASURED_DEVIATION)),
                        "worstClip": _plain(g(schema.PROXY_WORST_CLIP)), "worstFrame": _plain(g(schema.PROXY_WORST_FRAME)),
                        "worstBone": _plain(g(schema.PROXY_WORST_BONE)),
                        "worstDirection": _plain(g(schema.PROXY_WORST_DIRECTION))}
    out["meshes"] = [{"name": k, **(v if isinstance(v, dict) else {})} for k, v in (prov.get("meshes") or {}).items()]
    from colossus.pipeline import notcarried
    out["not_carried"] = notcarried.from_provenance(prov.get(notcarried.PROVENANCE_KEY))
    return out


def _usd_tools(asset) -> dict:
    """What other USD tools are given: the SkelRoot's ``clip`` variant names (sorted, as USD
    lists them) and selection, and the guide spheres (``UsdGeom.Sphere`` prims under the SkelRoot)."""
    from pxr import Usd

    if asset.root is None:
        return {"clip_variants": [], "selection": None, "guide_spheres": 0}
    vsets = asset.root.GetVariantSets()
    has = vsets.HasVariantSet(schema.CLIP_VARIANT_SET)
    vset = vsets.GetVariantSet(schema.CLIP_VARIANT_SET) if has else None
    spheres = [p for p in Usd.PrimRange(asset.root) if p.IsA(UsdGeom.Sphere)]
    return {"clip_variants": list(vset.GetVariantNames()) if has else [],
            "selection": (vset.GetVariantSelection() or None) if has else None,
            "guide_spheres": len(spheres)}


def _fmt(v, spec="g"):
    return "-" if v is None else format(v, spec)


def format_summary(s: dict) -> str:
    """The text ``colossus inspect`` prints for a :func:`summarize` dict."""
    st, c = s["stage"], s["counts"]
    lines = [s["path"],
             f"  stage     upAxis {st['upAxis']}, metersPerUnit {st['metersPerUnit']:g}, "
             f"timeCodesPerSecond {st['timeCodesPerSecond']:g}, defaultPrim {st['defaultPrim'] or '-'}",
             f"  prims     root {s['prims']['root'] or '-'}, skeleton {s['prims']['skeleton'] or '-'}, "
             f"mesh {s['prims']['mesh'] or '-'}"]
    infl = c["influences"]
    itext = ("-" if infl is None else
             f"{infl['nonzero']} (elementSize {infl['elementSize']}, max {infl['max_per_vertex']}, "
             f"mean {infl['mean_per_vertex']:g} per vertex)")
    lines.append(f"  counts    {_fmt(c['vertices'])} vertices, {_fmt(c['triangles'])} triangles, "
                 f"{_fmt(c['joints'])} joints, {_fmt(c['parts'])} parts, {c['clips']} clips "
                 f"({c['frames']} frames), influences {itext}")
    u = s.get("usd_tools")
    if u is not None:
        lines.append(f"  usd tools variant set {schema.CLIP_VARIANT_SET!r}: {len(u['clip_variants'])} clips "
                     f"(selected {u['selection'] or '-'}), {u['guide_spheres']} guide part spheres")
    if s.get("skinning_method"):
        lines.append(f"  skinning  {s['skinning_method']}"
                     + ("" if s["skinning_method"] in schema.SKINNING_METHODS else " (not a method the runtime poses)"))
    if s["provenance"]:
        p = s["provenance"]
        lines.append("")
        lines.append("provenance")
        for key in ("source", "sourceSha256", "importer", "reader", "sourceFrame"):  # meshes: own section
            if key in p:
                lines.append(f"  {key:<13} {p[key]}")
        settings = p.get("settings") or {}
        if settings:
            lines.append("  settings      " + ", ".join(f"{k}={v!s}" for k, v in sorted(settings.items())
                                                      if v not in ("", None)))
    px = s.get("proxy")
    if px:
        lines.append("")
        lines.append("proxy (simplified collision mesh)")
        lines.append(f"  faces         {_fmt(c['triangles'])} (source {px['sourceFaces']})")
        dev = px["maxDeviation"]
        rel = f" ({100 * dev / s['model_size']:.3g}% of size)" if isinstance(dev, float) and s.get("model_size") else ""
        where = ("the bind pose" if px["worstFrame"] in (-1, None) else f"clip {px['worstClip']} frame {px['worstFrame']}")
        meas = px.get("measuredDeviation")
        meas = f"{_fmt(meas, '.4g')} measured" if isinstance(meas, (int, float)) else "largest measured"
        lines.append(f"  deviation     <= {_fmt(dev, '.4g') if isinstance(dev, (int, float)) else '-'}{rel}; {meas} at "
                     f"{where}, bone {px['worstBone'] or '-'} ({px['worstDirection'] or '-'})")
    if s.get("not_carried"):
        from colossus.pipeline import notcarried
        lines.append("")
        lines.append(f"not carried from the source ({len(s['not_carried'])})")
        for it in s["not_carried"]:
            lines.append("  " + notcarried.warning_line(it).removeprefix("not carried: "))
    if s.get("meshes"):
        lines.append("")
        lines.append(f"source meshes ({len(s['meshes'])})")
        for m in s["meshes"]:
            bound = f"  bound to {m['joint']}" if m.get("joint") else ""
            lines.append(f"  {str(m['name']):<28} {str(m.get('kind', '-')):<8} {_fmt(m.get('vertices'), 'd'):>8} vertices{bound}")
    if s["joints"]:
        lines.append("")
        lines.append(f"joints ({len(s['joints'])})")
        for i, j in enumerate(s["joints"]):
            lines.append(f"  {i:>3} {'  ' * j['depth']}{j['name']}")
    lines.append("")
    lines.append(f"clips ({len(s['clips'])})")
    if not s["clips"]:
        lines.append("  (none)")
    for cl in s["clips"]:
        src = cl.get("source") or {}
        how = ""
        if src:
            how = f"  {src.get('sourceKeys', '-')} source keys, {src.get('sampling', '')}"
            if "errorBoundRelative" in src:
                how += f", off-grid error <= {src['errorBoundRelative']:.2g} x size"
        lines.append(f"  {cl['name']:<20} {cl['frames']:>5} frames  {_fmt(cl['seconds'], '.3f'):>8} s  "
                     f"time codes {_fmt(cl['start'])}..{_fmt(cl['end'])}{how}")
    lines.append("")
    lines.append(f"parts ({len(s['parts'])})")
    if s["parts"]:
        lines.append(f"  {'part':>4} {'joint':<24} {'faces':>6} {'radius':>10}")
    for p in s["parts"]:
        name = p["joint"].rsplit("/", 1)[-1]
        lines.append(f"  {p['index']:>4} {name:<24} {_fmt(p['faces'], 'd'):>6} {_fmt(p['radius'], '.4g'):>10}")
    return "\n".join(lines) + "\n"
