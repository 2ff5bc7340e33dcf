"""The project's numba kernels, one module per concern (private ``_``-prefixed kernels behind
validating public wrappers; each checked against a slow numpy reference in ``tests/references/naive.py``
or ``tests/references/naive_queries.py``):

* :mod:`~runtime.kernels.skin`: the one linear-blend-skinning kernel (runtime, frame proof,
  continuous certificate, import spheres stage);
* :mod:`~runtime.kernels.pose`: UsdSkel's interpolation and joint composition;
* :mod:`~runtime.kernels.bounds`: sound bounds on a part's skinned vertices (tests K and D,
  deviation from the chord between samples);
* :mod:`~runtime.kernels.query`: rays, sphere contacts, surface points;
* :mod:`~runtime.kernels.triangle`: the ray-triangle and closest-point-on-triangle primitives
  (public: the query kernels and the import's surface distance share them);
* :mod:`~runtime.kernels.config`: the fast-math policies.

Numba compiles each kernel on first use (``cache=True``: once per machine), so importing this
package compiles nothing.
"""

from .query import (_all_chunk_spheres, _face_normals, _hit_fill,  # noqa: F401
                    _raycast, _raycast_all, _raycast_parallel, _ready_faces, _sphere_contacts,
                    _sphere_contacts_all, _surface_frame, _surface_points)
