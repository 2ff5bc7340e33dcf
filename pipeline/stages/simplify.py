"""``simplify``: a collision proxy of a target size that carries the skin, with a bound on how far
it strays from the full skinned mesh on every frame of every clip.

Off by default; ``colossus import --target-faces N`` and/or ``--max-deviation D`` (stage units,
or ``D%`` of the model size) turn it on.  It runs **after** ``bind`` and before ``parts``: the
full mesh it measures against is then the collider colossus would write without it (unweighted
vertices resolved, at most ``--max-influences`` normalised influences, joints parents-first), and
the proxy's parts, spheres and the every-frame proof are made exactly as for any mesh.

1. Decimation (:mod:`colossus.pipeline.geometry.decimate`): fast-simplification's collapse
   history, chosen on an embedding of the rest mesh that makes part boundaries steps, replayed on
   the real rest positions by :func:`colossus.pipeline.geometry.collapse.apply_collapses` so that
   every closed shell stays closed with its Euler characteristic.
2. Skin (:mod:`colossus.pipeline.geometry.transfer`): closest-point transfer on the full rest mesh,
   at most ``--max-influences`` per vertex; the blend shapes' offsets (in-betweens included) by the
   same transfer, at the same nearest points.
3. Deviation (:mod:`colossus.pipeline.geometry.deviation`): an upper bound of the two-sided
   distance between the skinned surfaces (blend shapes applied at each frame's weights) on the
   bind pose and every frame of every clip.

``--max-deviation`` keeps the longest prefix of the history whose bound stays within the limit
(a bisection over the prefix length; each prefix is only *decided*: subdivided down to the limit,
rejected at the first distance measured above it), then measures the one kept in full.
"""

from __future__ import annotations

import time

import numpy as np

from ..geometry.decimate import Candidate, Decimator, shells
from ..geometry.deviation import deviation, dominant_joint, mesh_poses, rest_skel
from ..model import SkinnedMesh
from ..options import parse_max_deviation, resolve_max_deviation
from ..tolerances import model_scale
from . import StageReport
from .orient import orient

#: --max-deviation: the prefix search stops when the prefixes bracketing the limit differ by less
#: than this fraction of the collapses.
PREFIX_TOLERANCE = 0.02
#: With --max-deviation and no --target-faces, the history goes down to this fraction of the
#: faces (at least MIN_FACES), and the prefix search picks the longest prefix within the limit.
FLOOR_FRACTION = 0.005
MIN_FACES = 64


def simplify(mesh: SkinnedMesh, target_faces: int | None = None, max_deviation=None,
             max_influences: int = 4) -> tuple[SkinnedMesh, StageReport]:
    """Decimate ``mesh`` into a collision proxy, carry its skin, and bound its deviation.

    Parameters
    ----------
    mesh : SkinnedMesh
        Bound (after ``bind``), without parts.
    target_faces : int, optional
        Face count to reach (at most; fewer when ``max_deviation`` stops it first).
    max_deviation : float, str or (float, bool), optional
        Limit of the deviation bound: stage units, or ``"D%"`` of the model size
        (:func:`colossus.pipeline.options.parse_max_deviation`).
    max_influences : int
        Influences kept per proxy vertex.

    Returns
    -------
    (SkinnedMesh, StageReport)
        Report counts: ``faces_in``, ``faces_out``, ``vertices_in``, ``vertices_out``,
        ``target_faces``, ``max_deviation_limit``, ``deviation`` (the bound, stage units),
        ``deviation_relative`` (over the model size), ``sampled_deviation`` (the largest distance
        measured), ``worst`` (``{"clip",
        "frame", "time", "bone", "direction", "measured", "samples"}``: where it was
        measured), ``worst_by_direction`` (the same per direction, with its sample count),
        ``closed_shells_in``, ``closed_shells_out``,
        ``shells_in``, ``shells_out``, ``euler_changed`` (closed shells whose Euler characteristic
        changed: 0), ``collapses``, ``collapses_refused``, ``decimations`` (library runs),
        ``bone_crossing_collapses`` (accepted collapses joining vertices of different dominant
        bones), ``bone_boundary_step`` (the step used, in edge lengths: 0 when it was dropped), ``crossing_faces_in``/``crossing_faces_out`` (faces whose corners have different
        dominant bones), ``deviation_samples``, ``decimate_seconds``, ``deviation_seconds``;
        details: ``clips`` (per clip: ``{"clip", "frames", "deviation"`` (the bound over its
        frames)``, "measured"`` (the largest distance measured)``, "frame", "time"`` (where)``}``),
        ``bind_pose_deviation`` and ``bind_pose_measured``.  ``worst`` is where the largest
        distance was measured (the bound is nearly flat near its top: where it peaks says little).
    """
    if target_faces is None and max_deviation is None:
        raise ValueError("simplify: expected target_faces or max_deviation, got neither")
    if target_faces is not None and int(target_faces) < 4:
        raise ValueError(f"simplify target_faces: expected >= 4, got {target_faces}")
    spec = parse_max_deviation(max_deviation)
    t_start = time.perf_counter()
    n, m = mesh.vertex_count, mesh.face_count
    size = model_scale(rest_skel(mesh))
    limit = resolve_max_deviation(spec, size)
    poses = mesh_poses(mesh)
    report = StageReport("simplify")
    dec = Decimator(mesh, max_influences)
    t_dev = 0.0

    goal = int(target_faces) if target_faces is not None else max(MIN_FACES, int(FLOOR_FRACTION * m))
    cand = Candidate(mesh, 0, 0, 0, 0)
    if goal < m:
        dec.history(goal)
        if len(dec.col):
            cand = dec.build(goal)

    if limit is not None and cand.mesh is not mesh:
        # the longest history prefix whose bound is within the limit (bisection; each prefix is
        # only decided, the one kept is then measured in full)
        td = time.perf_counter()

        def within(c):
            d = deviation(mesh, c.mesh, poses, limit=limit, decide=True)
            return not d.exceeded and d.bound <= limit

        if not within(cand):
            lo, hi = 0, cand.limit  # history prefixes: lo within the limit (the full mesh), hi not
            best = None
            while hi - lo > max(1, PREFIX_TOLERANCE * cand.limit):
                mid = (lo + hi) // 2
                c = dec.build(goal, mid)
                if within(c):
                    lo, best = mid, c
                else:
                    hi = mid
            cand = best if best is not None else Candidate(mesh, 0, 0, 0, 0)
        if cand.mesh is not mesh:
            cand.deviation = deviation(mesh, cand.mesh, poses, limit=limit)
        t_dev += time.perf_counter() - td
    if cand.mesh is not mesh and cand.deviation is None:
        td = time.perf_counter()
        cand.deviation = deviation(mesh, cand.mesh, poses)
        t_dev += time.perf_counter() - td

    proxy, dev = cand.mesh, cand.deviation
    _, orep = orient(proxy)
    oc = orep.counts
    shell_out, count_out, closed_out, euler_out = shells(proxy.triangles, proxy.vertex_count)
    crossing = lambda mm: int(np.count_nonzero(  # noqa: E731
        np.ptp(mm.joint_indices[np.arange(mm.vertex_count), np.argmax(mm.joint_weights, 1)][mm.triangles], 1)))
    def where(i, joint, direction, measured, samples):
        return {"clip": poses.clip[i] or "bind pose", "frame": int(poses.frame[i]) if poses.clip[i] else -1,
                "time": float(poses.time[i]) if poses.clip[i] else "", "bone": mesh.joint_names[joint],
                "direction": direction, "measured": float(measured), "samples": int(samples)}

    by_direction = {}
    if dev is None:
        worst = {"clip": "", "frame": -1, "time": "", "bone": "", "direction": "", "measured": 0.0, "samples": 0}
        bound = 0.0
    else:
        worst = where(dev.worst_pose, dev.worst_joint, dev.direction, dev.sampled, dev.samples)
        for name, side in dev.directions.items():
            src = mesh if name == "full->proxy" else proxy
            by_direction[name] = where(side.sampled_pose, dominant_joint(src, side.sampled_vertex), name,
                                       side.sampled, side.samples)
        bound = float(dev.bound)
    report.counts = {
        "faces_in": int(m), "faces_out": int(proxy.face_count), "vertices_in": int(n),
        "vertices_out": int(proxy.vertex_count), "target_faces": int(target_faces) if target_faces else None,
        "max_deviation_limit": float(limit) if limit is not None else None,
        "deviation": bound, "deviation_relative": bound / size,
        "sampled_deviation": float(dev.sampled) if dev else 0.0, "worst": worst, "worst_by_direction": by_direction,
        "shells_in": int(dec.count), "closed_shells_in": int(dec.closed.sum()),
        "shells_out": int(count_out), "closed_shells_out": int(closed_out.sum()),
        "euler_changed": int(abs(np.sort(dec.euler[dec.closed]).sum() - np.sort(euler_out[closed_out]).sum()) > 0
                             or int(closed_out.sum()) != int(dec.closed.sum())),
        "faces_flipped_out": int(oc["faces_flipped"]), "nonmanifold_edges_out": int(oc["nonmanifold_edges"]),
        "collapses": cand.collapses, "collapses_refused": cand.refused, "decimations": dec.runs,
        "bone_crossing_collapses": cand.crossing, "bone_boundary_step": float(dec.step),
        "crossing_faces_in": crossing(mesh), "crossing_faces_out": crossing(proxy),
        "deviation_samples": int(dev.samples) if dev else 0,
        "decimate_seconds": round(time.perf_counter() - t_start - t_dev, 4), "deviation_seconds": round(t_dev, 4),
    }
    if dev is not None:
        clips = []
        for c in mesh.clips:
            idx = np.flatnonzero(np.array([x == c.name for x in poses.clip]))
            k = idx[int(np.argmax(dev.pose_sampled[idx]))]
            clips.append({"clip": c.name, "frames": int(len(idx)), "frame": int(poses.frame[k]),
                          "time": float(poses.time[k]), "deviation": float(dev.pose_bound[idx].max()),
                          "measured": float(dev.pose_sampled[k])})
        report.details = {"clips": clips, "bind_pose_deviation": float(dev.pose_bound[0]),
                          "bind_pose_measured": float(dev.pose_sampled[0])}
    if target_faces is not None and proxy.face_count > target_faces and limit is None:
        report.warnings.append(f"simplify reached {proxy.face_count} faces, above --target-faces {target_faces} "
                               "(the remaining collapses would change a shell's topology or open border)")
    if limit is not None and proxy is mesh and m > goal:
        report.warnings.append(f"no decimation keeps the deviation within {limit:.6g}; the full mesh is kept")
    if int(closed_out.sum()) < int(dec.closed.sum()):
        report.warnings.append(f"{int(dec.closed.sum()) - int(closed_out.sum())} closed shells did not stay closed")
    return proxy, report

