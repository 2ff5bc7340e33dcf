"""Stage 1, ``bake``: the rest (bind) pose mesh in output space.

Applies the mesh-to-skeleton bind transform (``geom_bind``) to the points and converts the whole
rig from the source's axes and units to the output convention (Y-up metres by default).  The
conversion ``C`` (a rotation about X and a uniform scale) is put in front of skeleton space: bind
transforms and the root joints' local transforms become ``C @ M``, so every joint keeps the
source's own joint space (a Blender FBX, whose armature node carries x100 and whose bones are in
metres, ends up with unit-scale joints) and skinned points come out as ``C @ skinned``.
"""

from __future__ import annotations

import numpy as np

from ..model import Clip, SkinnedMesh
from ..xforms import apply_points, axis_conversion
from . import StageReport


def bake(mesh: SkinnedMesh, up_axis: str = "Y", meters_per_unit: float = 1.0):
    """Bake ``mesh`` into a ``up_axis``-up space of ``meters_per_unit`` metres per unit.

    Returns
    -------
    (SkinnedMesh, StageReport)
        The baked mesh has ``geom_bind`` = identity.
    """
    c = axis_conversion(mesh.up_axis, up_axis, mesh.meters_per_unit, meters_per_unit)
    roots = mesh.parents < 0

    def front(m):
        """``C @ m`` for the root joints of (..., b, 4, 4) local transforms."""
        out = np.array(m, dtype=np.float64, copy=True)
        out[..., roots, :, :] = c @ out[..., roots, :, :]
        return affine(out)

    def affine(m):
        """Exact (0, 0, 0, 1) last rows: inverting source matrices leaves ~1e-9 residue there."""
        m = np.array(m, dtype=np.float64, copy=True)
        m[..., 3, :] = (0.0, 0.0, 0.0, 1.0)
        return m

    positions = apply_points(c @ mesh.geom_bind, mesh.positions).astype(np.float32)
    clips = tuple(Clip(cl.name, cl.times, front(cl.local), cl.shape_weights) for cl in mesh.clips)
    from ..model import transform_shapes

    out = mesh.replace(
        blend_shapes=transform_shapes(mesh.blend_shapes, (c @ mesh.geom_bind)[:3, :3]),
        positions=positions, geom_bind=np.eye(4), bind_transforms=affine(c @ mesh.bind_transforms),
        rest_transforms=front(mesh.rest_transforms), clips=clips, up_axis=up_axis,
        meters_per_unit=float(meters_per_unit),
    )
    scale = float(mesh.meters_per_unit) / float(meters_per_unit)
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    report = StageReport("bake", counts={
        "vertices": mesh.vertex_count, "faces": mesh.face_count,
        "source_up_axis": mesh.up_axis, "source_meters_per_unit": mesh.meters_per_unit,
        "up_axis": up_axis, "meters_per_unit": float(meters_per_unit), "scale_applied": scale,
        "bbox_min": [round(float(x), 6) for x in lo], "bbox_max": [round(float(x), 6) for x in hi],
    })
    return out, report
