"""Every tolerance of the import stage in one place (after trimesh's ``constants.ToleranceMesh``).

Lengths are relative to the model size, the diagonal of the rest-pose bounding box in output
units, unless a name says otherwise.  Use :func:`model_scale` to turn them into absolute values.
"""

from __future__ import annotations

import numpy as np

#: Vertices closer than this (times the model size) are the same position for welding.
WELD_RELATIVE = 1e-6
#: ``degenerate`` drops a triangle whose bind-pose area is at most (this x ZERO_AREA_RELATIVE x
#: model size)^2 (``runtime.schema.zero_area_faces``, the very test of the validator's COL204 with
#: its ``ZERO_AREA_RELATIVE``): stricter by this factor in length (4 in area), so the rounding
#: that differs between the importer's numbers and the asset's (the roots' scale moved onto the
#: Skeleton, a simplified proxy's model size) can never leave a triangle the rule flags.
DEGENERATE_MARGIN = 2.0
#: Two influence weights are "the same" for welding when they differ by less than this (absolute).
WELD_WEIGHT = 1e-4
#: Influence weights below this (absolute, after normalisation) are negligible and dropped by ``bind``.
NEGLIGIBLE_WEIGHT = 1e-4
#: Default weight threshold for ``--parts any``: a bone owns a triangle if it has at least this
#: weight on one of its vertices.
PARTS_ANY_THRESHOLD = 0.1
#: Sphere padding: absolute pad is this times the model size ...
SPHERE_PAD_RELATIVE = 1e-5
#: ... plus this fraction of the sphere radius.
SPHERE_PAD_RADIUS = 1e-6
#: Weights must sum to 1 within this after ``bind``.
WEIGHT_SUM = 1e-5
#: A source key this close to a frame (in frames) is on the frame grid.
GRID_KEY_FRAMES = 1e-3
#: A source vertex whose weights sum this far from 1 (absolute) is counted as renormalised.
SOURCE_WEIGHT_SUM = 1e-3
#: A clip resampled off its keys must stay this close to the source (times the model size).
RESAMPLING_RELATIVE = 1e-3
#: Cap on what one input may make the importer allocate: bytes per byte of input file ...
ALLOC_FACTOR = 400
#: ... plus this many bytes, so that tiny files still import.
ALLOC_FLOOR = 256 * 1024 * 1024
#: Largest coordinate (absolute, source units) a vertex or a transform entry may have: float32
#: skinning of points near float32's limit (3.4e38) overflows to inf and NaN.  Real scenes are
#: below 1e8 even in millimetres.
LARGEST_COORDINATE = 1e12
#: A linear map whose columns are this much shorter than its longest one, or this far from
#: independent (``|det| / product of column lengths``), is degenerate: inverting it (every stage
#: maps points into joint space) gives garbage or fails.  Real rigs are nowhere near.
DEGENERATE_RATIO = 1e-6


def model_scale(points: np.ndarray) -> float:
    """Size of a model: the diagonal of the axis-aligned bounding box of ``points`` ``(n, 3)``.

    Returns 1.0 for an empty or degenerate point set so relative tolerances stay positive.
    """
    if len(points) == 0:
        return 1.0
    lo = np.min(points, axis=0).astype(np.float64)
    hi = np.max(points, axis=0).astype(np.float64)
    d = float(np.linalg.norm(hi - lo))
    return d if np.isfinite(d) and d > 0 else 1.0


#: ``simplify``: height of the step (in mean edge lengths around each vertex) between
#: neighbouring parts in the embedding the decimator chooses its collapses on.  A collapse across
#: a part boundary must leave the step, which costs about its height squared in the quadric
#: error, so such collapses wait until the mesh around is coarse enough (Unreal's "enforce bone
#: boundaries" as a penalty, not a wall; dropped when it keeps the proxy above its target).
SIMPLIFY_BONE_BOUNDARY = 0.5
#: ``simplify``: split a deviation piece (a source triangle or part of one) while its upper bound
#: is more than this fraction above the largest distance sampled (the bound then over-states the
#: largest distance found by at most this much, plus the resolution below).
DEVIATION_REFINE = 0.3
#: ``simplify``: added to the deviation bound (times the model size) for the float32 rounding of
#: stored positions and weights.
DEVIATION_PAD = 1e-6
#: ``simplify``: the deviation is resolved to this (times the model size): a piece whose bound is
#: within this of the threshold above is not split further.
DEVIATION_RESOLUTION = 1e-4
#: ``simplify``: a deviation piece is split at most this many times (its cover radius halves each
#: time); a piece at this depth keeps its bound, which stays an upper bound.
DEVIATION_MAX_DEPTH = 6
