"""The fast-math policies of every numba kernel in the project (after stumpy's ``config.py``).

``FASTMATH_PROOF``: kernels whose results decide a proof (skinning for the frame proof and the
continuous certificate, the bounds).  Contraction, reassociation, reciprocal approximation and
signed-zero freedom change results by a few ulps (far below the proof's relative tolerance of
1e-5 of a radius), but ``nnan``/``ninf`` are never allowed: with them LLVM may assume a NaN or
an infinity never occurs, so a NaN skinned point could compare as "inside".  Proof kernels keep
the IEEE semantics of NaN and inf, and test ``not (d <= limit)`` so a NaN reads as far.

``FASTMATH_GAME``: kernels that only serve queries a game makes (rays, contacts); their inputs are
checked finite by the wrappers, so every flag is allowed.
"""

FASTMATH_PROOF = {"contract", "reassoc", "arcp", "nsz"}
FASTMATH_GAME = True
