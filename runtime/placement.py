"""A collider placed in a game's world: the world transform the queries accept (``world=``).

A game puts the boss somewhere: ``world`` (4, 4) is the collider's stage -> world transform in the
runtime's **column-vector** convention (``p_world = world @ p_stage``, translation in the last
column; USD's ``Gf.Matrix4d`` is its transpose).  Supported: a **similarity**, i.e. a proper
rotation times a uniform positive scale, plus a translation (what a game's scene node places a
character with).  Refused with ``ValueError``: a shear, a non-uniform scale, a mirror (negative
determinant: the mesh would turn inside out, its outward normals inward), a projective last row,
anything not finite.  "Uniform" and "rotation" are judged within :data:`ORTHOGONAL_TOLERANCE`
(single-precision matrices from an engine pass).

The query runs in stage space on the inputs carried there by the inverse transform (a ray's origin
and direction, a sphere's centre and radius / scale, a ray's ``max_distance`` / scale), and its
results are carried back: points by ``world``, normals by its rotation, distances and depths
times the scale; triangle, part and barycentric coordinates are the same in both spaces.  So a
world-space query answers exactly as the stage-space query on inputs transformed by hand.
"""

from __future__ import annotations

import numpy as np

from .results import RayHits, SphereContacts

#: ``world``'s 3x3 part divided by its scale must be a rotation within this (max abs entry of
#: ``R^T R - I``).
ORTHOGONAL_TOLERANCE = 1e-5


class Placement:
    """A validated world transform (see the module docstring).

    Attributes
    ----------
    matrix : (4, 4) float64 column-vector stage -> world
    inverse : (4, 4) float64 world -> stage
    scale : float, the uniform scale (``det(matrix[:3, :3]) ** (1/3)``)
    rotation : (3, 3) float64, ``matrix[:3, :3] / scale``
    """

    __slots__ = ("matrix", "inverse", "scale", "rotation")

    def __init__(self, world):
        m = np.array(world, dtype=np.float64)
        if m.shape != (4, 4):
            raise ValueError(f"world must be a (4, 4) matrix, got shape {m.shape}")
        if not np.isfinite(m).all():
            raise ValueError("world must be finite")
        if not np.array_equal(m[3], [0.0, 0.0, 0.0, 1.0]):
            hint = (" (it looks row-vector, USD's layout: pass its transpose)"
                    if np.array_equal(m[:, 3], [0.0, 0.0, 0.0, 1.0]) else "")
            raise ValueError(f"world must be an affine column-vector matrix (last row 0 0 0 1){hint}")
        lin = m[:3, :3]
        det = float(np.linalg.det(lin))
        if not det > 0:
            raise ValueError(f"world must keep orientation and not collapse (det {det:.6g} <= 0: a mirror "
                             "turns the collider inside out)")
        s = det ** (1.0 / 3.0)
        r = lin / s
        off = float(np.abs(r.T @ r - np.eye(3)).max())
        if not off <= ORTHOGONAL_TOLERANCE:
            raise ValueError(f"world must be a rotation, a uniform scale and a translation (its 3x3 part / scale "
                             f"is {off:.3g} off a rotation: shear or non-uniform scale is not supported)")
        self.matrix = m
        self.scale = s
        self.rotation = r
        self.inverse = np.linalg.inv(m)

    @classmethod
    def of(cls, world) -> "Placement":
        """``world`` as a :class:`Placement` (one already made is returned as is: a game that
        places the collider once per frame validates it once)."""
        return world if isinstance(world, cls) else cls(world)

    # -- stage <- world
    def to_stage(self, points) -> np.ndarray:
        """(n, 3) world points -> stage space."""
        p = np.asarray(points, dtype=np.float64)
        return p @ self.inverse[:3, :3].T + self.inverse[:3, 3]

    def vectors_to_stage(self, vectors) -> np.ndarray:
        """(n, 3) world directions -> stage space (not normalised)."""
        return np.asarray(vectors, dtype=np.float64) @ self.inverse[:3, :3].T

    # -- world <- stage
    def to_world(self, points) -> np.ndarray:
        """(n, 3) stage points -> world space."""
        p = np.asarray(points, dtype=np.float64)
        return p @ self.matrix[:3, :3].T + self.matrix[:3, 3]

    def normals_to_world(self, normals) -> np.ndarray:
        """(n, 3) unit stage normals -> unit world normals (the inverse transpose, renormalised: the
        rotation's for a similarity; a miss's NaN stays NaN)."""
        n = np.asarray(normals, dtype=np.float64) @ self.inverse[:3, :3]
        with np.errstate(invalid="ignore", divide="ignore"):
            return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def spheres(self, spheres) -> np.ndarray:
        """(P, 4) stage spheres (centre xyz, radius; ``pose.spheres``) -> world spheres."""
        s = np.asarray(spheres, dtype=np.float64)
        out = np.empty(s.shape)
        out[:, :3] = self.to_world(s[:, :3])
        out[:, 3] = s[:, 3] * self.scale
        return out

    def ray_hits(self, h: RayHits) -> RayHits:
        """Stage-space hits of rays carried from the world -> the same hits in world space."""
        return RayHits(h.distance * self.scale, self.to_world(h.point), self.normals_to_world(h.normal),
                       h.triangle, h.barycentric, h.part)

    def sphere_contacts(self, cs: SphereContacts) -> SphereContacts:
        """Stage-space contacts of a sphere carried from the world -> world space."""
        return SphereContacts(cs.triangle, self.to_world(cs.point), self.normals_to_world(cs.normal),
                              cs.depth * self.scale, cs.barycentric)
