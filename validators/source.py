"""The asset against the export it was made from (``colossus validate ASSET --source FILE``).

The source is read and baked by the importer's own reader with the settings recorded in the
asset's provenance (:func:`pipeline.run.read_baked`); each asset vertex is matched with the source
vertices at its bind position (several where a seam was welded: the one whose motion agrees best
is used), and both are skinned on every frame of every clip the asset holds, the asset by its
own UsdSkel data (``UsdSkel.AnimQuery``, as any consumer plays it), the source by linear-blend
skinning of what the reader found.  A CI gate for stale colliders: a source whose motion, clips
or geometry changed since the import no longer matches.

A simplified proxy (``--target-faces`` / ``--max-deviation`` in its provenance) is compared with
the source imported again with those settings up to the ``simplify`` stage: the same proxy when
the source is unchanged (the decimation is deterministic), other vertices when it changed.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from colossus.runtime import schema

from . import tolerances as tol


@dataclass
class SourceCheck:
    """What :func:`compare_source` found.

    Attributes
    ----------
    path : str                 the source file
    error : str or None        why the source could not be read (nothing else is filled then)
    sha256 : str               the source file's sha256
    recorded_sha256 : str      the provenance's ``sourceSha256`` ('' when absent)
    size : float               model size (stage units) the tolerances are relative to
    clip_motion : dict         clip -> (max error in stage units, frame index, time code, asset vertex)
    clip_size : dict           clip -> model size (stage units) of the asset as the clip's first frame
                               poses it (the bind pose can be at another scale: a centimetre mesh
                               bound by x100 joints)
    clip_storage : dict        clip -> the storage error bound the clip states (relative to that
                               size; 0 when none): what UsdSkel's half3 scales move at the frames
    clip_problems : list       (clip, message) for clips missing on either side or on other frames
    unmatched_asset : (u,) int asset vertices with no source vertex at their bind position
    unmatched_source : int     source vertices with no asset vertex at their bind position
    """

    path: str
    error: str | None = None
    sha256: str = ""
    recorded_sha256: str = ""
    size: float = 1.0
    clip_motion: dict = field(default_factory=dict)
    clip_size: dict = field(default_factory=dict)
    clip_storage: dict = field(default_factory=dict)
    clip_problems: list = field(default_factory=list)
    unmatched_asset: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    unmatched_source: int = 0


def provenance(asset) -> dict:
    if asset.mesh is None:
        return {}
    return dict(asset.mesh.GetCustomData().get(schema.PROVENANCE_KEY, {}) or {})


def compare_source(asset, source_path, chunk_frames: int = 64) -> SourceCheck:
    """Compare ``asset`` (a :class:`~validators.asset.LoadedAsset` whose skin and clips are usable)
    with the export ``source_path``.  Never raises for a bad source: ``error`` says why."""
    from colossus.pipeline.errors import ColossusError
    from colossus.pipeline.model import skel_transforms, skin_points
    from colossus.pipeline.run import build_collider, read_baked, settings_from_provenance, sha256_of
    from scipy.spatial import cKDTree

    from .frameproof import skin_frames, skin_layout

    src = os.fspath(source_path)
    prov = provenance(asset)
    out = SourceCheck(src, recorded_sha256=str(prov.get("sourceSha256", "")), size=asset.model_size)
    try:
        out.sha256 = sha256_of(src)
        settings = settings_from_provenance(dict(prov.get("settings") or {}))
        if settings.proxy:
            # a simplified proxy's vertices are not the source's: simplify the source again with
            # the asset's settings (deterministic) and compare with that proxy
            m = build_collider(src, settings, stop_after="simplify")[0]
        else:
            m = as_limited(read_baked(src, settings), settings.max_influences)
    except (ColossusError, OSError, ValueError) as exc:
        out.error = str(exc)
        return out

    # ---- vertices: match at the bind pose ------------------------------------------------------
    a_pts = asset.bind_points
    # the asset's points are pointScale x the source's where the importer folded a skeleton's
    # scale into them (pipeline.stages.quantize.fold_point_scale: the same skinned points)
    ps = prov.get("pointScale", 1.0)
    ps = float(ps) if isinstance(ps, (int, float)) and not isinstance(ps, bool) and np.isfinite(ps) and ps > 0 else 1.0
    s_pts = m.positions.astype(np.float64) * ps
    near = tol.SOURCE_MATCH_RELATIVE * out.size
    tree = cKDTree(s_pts)
    k = min(8, len(s_pts))
    dist, cand = tree.query(a_pts, k=k)
    dist, cand = dist.reshape(len(a_pts), k), cand.reshape(len(a_pts), k)
    ok = dist <= near
    out.unmatched_asset = np.flatnonzero(~ok.any(axis=1))
    d_back, _ = cKDTree(a_pts).query(s_pts)
    out.unmatched_source = int(np.count_nonzero(d_back > near))
    cand = np.where(ok, cand, cand[:, :1])

    # ---- motion on every frame of every clip ---------------------------------------------------
    src_clips = {c.name: c for c in m.clips}
    asset_names = set()
    tcps = float(asset.stage.GetTimeCodesPerSecond())
    inv_bind = asset.inv_bind
    for clip in asset.clips:
        name = clip.prim.GetCustomDataByKey(schema.CLIP_NAME_KEY) or clip.name
        asset_names.add(name)
        sc = src_clips.get(name) or next((c for c in m.clips if _ident(c.name) == clip.name), None)
        if sc is None:
            out.clip_problems.append((clip.name, f"clip {clip.name!r} is not in the source (source clips: "
                                                 f"{', '.join(c.name for c in m.clips) or 'none'})"))
            continue
        asset_names.add(sc.name)
        st = sc.times * (tcps / float(m.time_codes_per_second))
        if len(st) != len(clip.times) or np.max(np.abs(st - clip.times)) > 1e-6:
            out.clip_problems.append((clip.name, f"clip {clip.name!r}: the source has {len(st)} frames at "
                                                 f"{st[0]:g}..{st[-1]:g}, the asset {len(clip.times)} at "
                                                 f"{clip.times[0]:g}..{clip.times[-1]:g}"))
            continue
        worst = (0.0, 0, float(clip.times[0]), -1)
        per_cand = np.zeros((len(a_pts), k))  # per asset vertex and candidate: max error over frames
        chunk = max(1, min(chunk_frames, 2_000_000 // max(1, len(a_pts) * k)))
        for f0 in range(0, len(clip.times), chunk):
            times = clip.times[f0:f0 + chunk]
            skel = asset.skel_transforms(asset.anim_local(clip, times))
            xf = skin_layout(skel, inv_bind, asset.geom_bind, asset.skel_world, asset.skinning_method)
            pa = skin_frames(asset.points, asset.jidx, asset.jw, xf).astype(np.float64)
            if f0 == 0:
                fin = pa[0][np.all(np.isfinite(pa[0]), axis=1)]
                posed = float(np.linalg.norm(fin.max(0) - fin.min(0))) if len(fin) else 0.0
                out.clip_size[clip.name] = posed if np.isfinite(posed) and posed > 0 else out.size
                stated = (clip.prim.GetCustomDataByKey(schema.CLIP_SOURCE_KEY) or {}).get("storageErrorBoundRelative")
                out.clip_storage[clip.name] = float(stated) if stated is not None and np.isfinite(stated) else 0.0
            ps = skin_points(m, skel_transforms(sc.local[f0:f0 + chunk], m.parents))
            err = np.linalg.norm(pa[:, :, None, :] - ps[:, cand, :], axis=-1)  # (f, n, k)
            per_cand = np.maximum(per_cand, err.max(axis=0))
        choice = np.argmin(np.where(ok, per_cand, np.inf), axis=1)
        best_c = per_cand[np.arange(len(a_pts)), choice]
        best_c[out.unmatched_asset] = 0.0
        if len(best_c):
            v = int(np.argmax(best_c))
            # locate the frame of the worst vertex (one more pass over its candidate only)
            skel = asset.skel_transforms(asset.anim_local(clip, clip.times))
            xf = skin_layout(skel, inv_bind, asset.geom_bind, asset.skel_world, asset.skinning_method)
            pa = skin_frames(asset.points[v:v + 1], asset.jidx[v:v + 1], asset.jw[v:v + 1], xf)[:, 0]
            ps = skin_points(m, skel_transforms(sc.local, m.parents))[:, cand[v, choice[v]]]
            e = np.linalg.norm(pa - ps, axis=1)
            f = int(np.argmax(e))
            worst = (float(best_c[v]), f, float(clip.times[f]), v)
        out.clip_motion[clip.name] = worst
    for c in m.clips:
        if c.name not in asset_names and _ident(c.name) not in {cl.name for cl in asset.clips}:
            out.clip_problems.append((c.name, f"the source's clip {c.name!r} is not in the asset"))
    return out


def as_limited(m, max_influences: int):
    """The source's skin weights limited as the import's ``bind`` stage limits them (the strongest
    ``max_influences``, negligible ones dropped, renormalised; :func:`pipeline.stages.bind.limit_influences`):
    a deliberate, stated change (the asset's ``skin_influences`` not-carried record gives its
    bound), so the comparison judges the rest exactly.  Unweighted vertices stay as read."""
    from colossus.pipeline.stages.bind import limit_influences

    jw = np.where(m.joint_weights > 0, m.joint_weights.astype(np.float64), 0.0)
    total = jw.sum(axis=1)
    live = total > 0
    if not live.any():
        return m
    kk = max(int(max_influences), 1)
    oj, ow, _, _, _ = limit_influences(m.joint_indices[live], jw[live] / total[live, None], kk)
    k = max(kk, m.joint_indices.shape[1])
    ji = np.zeros((m.vertex_count, k), np.int32)
    w = np.zeros((m.vertex_count, k), np.float32)
    ji[:, :m.joint_indices.shape[1]], w[:, :m.joint_weights.shape[1]] = m.joint_indices, m.joint_weights
    ji[live], w[live] = 0, 0.0
    ji[live, :kk], w[live, :kk] = oj, ow.astype(np.float32)
    return m.replace(joint_indices=ji, joint_weights=w)


def _ident(name: str) -> str:
    from pxr import Tf
    return Tf.MakeValidIdentifier(str(name) or "_")
