"""The project's numba kernels, one module per concern (private ``_``-prefixed kernels behind
validating public wrappers; each checked against a slow numpy reference in ``tests/references/naive.py``
or ``tests/references/naive_queries.py``):

* :mod:`~runtime.kernels.skin`: the one linear-blend-skinning kernel (runtime, frame proof,
  continuous certificate, import spheres stage);
* :mod:`~runtime.kernels.pose`: UsdSkel's interpolation and joint composition;
* :mod:`~runtime.kernels.bounds`: sound bounds on a part's skinned vertices at a pose (tests K
  and D, the culling spheres);
* :mod:`~runtime.kernels.interval`: sound bounds between two samples (deviation from the chord:
  the continuous certificate);
* :mod:`~runtime.kernels.subdivide`: the continuous certificate's levels B and C batched (one
  kernel per subdivision level over every open node);
* :mod:`~runtime.kernels.farthest`: the sampled proof's exact tier by chunks of vertices (chunk
  bounds, then exact skinning of the chunks that can hold the farthest vertex);
* :mod:`~runtime.kernels.query`: rays, sphere contacts, surface points;
* :mod:`~runtime.kernels.triangle`: the ray-triangle and closest-point-on-triangle primitives
  (public: the query kernels and the import's surface distance share them);
* :mod:`~runtime.kernels.contact`: the character controller's (contact summary, carrying a point
  with a moving surface);
* :mod:`~runtime.kernels.swept`: the continuous contact query of :mod:`runtime.sweep` (a sphere
  against triangles moving along their chords, conservative advancement);
* :mod:`~runtime.kernels.config`: the fast-math policies.

This package's face is the modules' public functions (below); the private kernels are reached
through their modules (``kernels.query._raycast``) by the runtime's own wrappers only.

Numba compiles each kernel on first use (``cache=True``: once per machine), so importing this
package compiles nothing.
"""

from .bounds import BoundData, bound_data, pareto_set, pose_bounds
from .interval import chain_bounds, chord_tasks, factor_terms
from .pose import compose, locals_at, trs_at, trs_matrices
from .skin import check_skin_inputs, fold, part_farthest, skin_frames
from .triangle import closest_on_triangle, ray_triangle

__all__ = ["BoundData", "bound_data", "pareto_set", "pose_bounds", "chain_bounds", "chord_tasks", "factor_terms",
           "compose", "locals_at", "trs_at", "trs_matrices", "check_skin_inputs", "fold", "part_farthest",
           "skin_frames", "closest_on_triangle", "ray_triangle"]
