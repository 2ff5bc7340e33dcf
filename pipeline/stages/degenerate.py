"""``degenerate``: drop the triangles the validator's COL204 (zero-area) would reject.

A triangle is dropped when its bind-pose area is at most ``(DEGENERATE_MARGIN x ZERO_AREA_RELATIVE
x model size)^2``: the very test of COL204 (:func:`runtime.schema.zero_area_faces`, shared, with
the same model size: the diagonal of the bind-pose bounding box of every point, as stored in
float32), stricter by :data:`~pipeline.tolerances.DEGENERATE_MARGIN` in length, so a mesh this
stage leaves can never trip the rule.  That covers repeated vertex indices (area exactly 0),
collinear corners, and corners closer than the weld tolerance that ``weld`` keeps apart (their
skin weights differ, or they share the triangle).

It runs right after ``weld`` (welding is what collapses a triangle onto a line or a point, and the
winding of ``orient`` is undefined on a triangle without a normal), and again on a simplified
proxy (``simplify`` moves vertices).  ``orient``, ``bind``, ``parts`` and ``quantize`` move no
point.  Like ``weld``, it keeps the points: a vertex only a dropped triangle used stays, unused
(``vertices_unreferenced`` in the report; COL205 is a warning), so every vertex keeps its index.
"""

from __future__ import annotations

import numpy as np

from colossus.runtime import schema

from ..errors import InputError
from ..model import SkinnedMesh
from ..tolerances import DEGENERATE_MARGIN
from . import StageReport
from .weld import _drop_faces


def zero_area(mesh: SkinnedMesh) -> tuple[np.ndarray, float, float]:
    """``(mask (m,) bool of the triangles to drop, model size, area threshold)``, measured as the
    validator measures the written asset: the points rounded to float32, mapped by ``geom_bind``."""
    p = np.asarray(mesh.positions, dtype=np.float32).astype(np.float64)
    g = np.asarray(mesh.geom_bind, dtype=np.float64)
    size = schema.bind_model_size(p @ g[:3, :3].T + g[:3, 3])
    relative = DEGENERATE_MARGIN * schema.ZERO_AREA_RELATIVE
    return schema.zero_area_faces(p, mesh.triangles, g, size, relative), size, (relative * size) ** 2


def degenerate(mesh: SkinnedMesh) -> tuple[SkinnedMesh, StageReport]:
    """Drop the zero-area triangles (see the module's docstring).

    Returns
    -------
    (SkinnedMesh, StageReport)
        Report counts: ``faces_in``, ``dropped`` (zero-area triangles dropped), ``repeated_index``
        (of them, those naming one vertex twice), ``faces_out``, ``vertices_unreferenced`` (points
        no triangle uses any more, kept), ``area_threshold`` (stage units squared), ``model_size``.
    """
    bad, size, threshold = zero_area(mesh)
    t = np.asarray(mesh.triangles)
    if len(t) and bad.all():
        raise InputError(mesh.source.get("path") or mesh.source.get("file"),
                         f"every one of the {len(t)} triangles has zero area (at most {threshold:.3g} in "
                         f"the bind pose, model size {size:.6g}): no collision surface")
    out = mesh
    if bad.any():
        keep = ~bad
        changes = {"triangles": np.ascontiguousarray(t[keep], dtype=np.int32)}
        if mesh.parts is not None:
            changes["parts"] = _drop_faces(mesh.parts, keep)
        out = mesh.replace(**changes)
    dropped = t[bad]
    repeated = (dropped[:, 0] == dropped[:, 1]) | (dropped[:, 1] == dropped[:, 2]) | (dropped[:, 0] == dropped[:, 2])
    used = np.zeros(mesh.vertex_count, bool)
    used[np.asarray(out.triangles).ravel()] = True
    report = StageReport("degenerate", counts={
        "faces_in": int(len(t)), "dropped": int(bad.sum()), "repeated_index": int(repeated.sum()),
        "faces_out": int(len(t) - bad.sum()), "vertices_unreferenced": int((~used).sum()),
        "area_threshold": float(threshold), "model_size": float(size)})
    return out, report
