"""The fast-math policies of every numba kernel in the project (after stumpy's ``config.py``):
every ``@njit`` takes its ``fastmath`` from one of these (``tests/test_layers.py`` checks it).

``FASTMATH_PROOF``: kernels whose results decide a proof (skinning for the frame proof and the
continuous certificate, the bounds).  The one skinning kernel serves the game too, and the
runtime pose's joint composition (``runtime.kernels.pose._compose``, which writes the transforms
it reads) runs under the same policy.  Contraction, reassociation, reciprocal approximation and
signed-zero freedom change results by a few ulps (far below the proof's relative tolerance of
1e-5 of a radius), but ``nnan``/``ninf`` are never allowed: with them LLVM may assume a NaN or
an infinity never occurs, so a NaN skinned point could compare as "inside".  Proof kernels keep
the IEEE semantics of NaN and inf, and test ``not (d <= limit)`` so a NaN reads as far.

``FASTMATH_OFF``: no fast-math flag at all (numba's default: strict IEEE arithmetic).  Every
other kernel runs so: the queries (rays, sphere contacts, surface points:
:mod:`runtime.kernels.query` and :mod:`runtime.kernels.triangle`), UsdSkel's interpolation (the
rest of :mod:`runtime.kernels.pose`, which follows GfSlerp and the half-precision scale lerp
operation by operation), the continuous certificate's factor terms
(:func:`runtime.kernels.interval.factor_terms`: infinities are meaningful there), the character
controller's kernels (:mod:`runtime.kernels.contact`) and the import's geometry kernels
(``pipeline/geometry/_distance_kernels.py``, ``pipeline/geometry/_collapse_kernels.py``).

A kernel's policy is part of its numbers: moving a kernel to another one may change its results
in the last bits.
"""

FASTMATH_PROOF = {"contract", "reassoc", "arcp", "nsz"}
FASTMATH_OFF = False
