"""The records the runtime's queries return: :class:`RayHits` (:meth:`Pose.raycast
<runtime.collider.Pose.raycast>`), :class:`SphereContacts` (:meth:`Pose.sphere_contacts
<runtime.collider.Pose.sphere_contacts>`) and :class:`SurfacePoints`, points glued to the skin
that any pose places (:meth:`Pose.track <runtime.collider.Pose.track>`).

Shapes follow the contract: float64 stage space, triangle indices int64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class RayHits:
    """Nearest hit per ray. A miss has distance ``inf``, triangle and part ``-1``, point and
    normal NaN, barycentric 0.

    distance (R,) float64 (stage units along the normalised direction), point (R, 3),
    normal (R, 3) unit geometric normal of the triangle (outward = counter-clockwise),
    triangle (R,) int64, barycentric (R, 3) weights of the triangle's 3 vertices,
    part (R,) int64 the first part (in part order) holding the triangle."""

    distance: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    triangle: np.ndarray
    barycentric: np.ndarray
    part: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        """(R,) bool: which rays hit."""
        return self.triangle >= 0

    def __len__(self):
        return len(self.distance)


@dataclass
class SphereContacts:
    """Every triangle a sphere touches (closest point within the radius), each once, in the
    order found (parts, then chunks; ``np.argsort(cs.triangle)`` to sort).

    triangle (C,) int64, point (C, 3) closest point on the triangle, normal (C, 3) unit vector
    from the point towards the sphere centre (the face normal if the centre is on the face),
    depth (C,) radius - distance, barycentric (C, 3) of the point on its triangle."""

    triangle: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    barycentric: np.ndarray

    def __len__(self):
        return len(self.triangle)

    def anchors(self) -> "SurfacePoints":
        """The contact points as surface points that move with the skin."""
        return SurfacePoints(self.triangle, self.barycentric)

    def resolve_vector(self) -> np.ndarray:
        """(3,) the thesis' discrete resolution: the average of ``normal * depth`` over the
        contacts (zeros when there are none)."""
        if len(self) == 0:
            return np.zeros(3)
        return (self.normal * self.depth[:, None]).mean(0)


@dataclass
class SurfacePoints:
    """Points glued to the skin by barycentric coordinates on triangles (thesis 5.5.3).

    triangles (C,) int, barycentric (C, 3)."""

    triangles: np.ndarray
    barycentric: np.ndarray

    def __post_init__(self):
        self.triangles = np.ascontiguousarray(np.asarray(self.triangles, dtype=np.int64).ravel())
        b = np.asarray(self.barycentric, dtype=np.float64)
        if b.ndim == 2 and b.shape[1] == 2:  # (u, v) of vertices 1 and 2
            b = np.column_stack([1.0 - b.sum(1), b])
        if b.shape != (len(self.triangles), 3):
            raise ValueError(f"barycentric must be ({len(self.triangles)}, 3) or "
                             f"({len(self.triangles)}, 2), got {b.shape}")
        self.barycentric = np.ascontiguousarray(b)

    def __len__(self):
        return len(self.triangles)

    def at(self, pose: "Pose") -> np.ndarray:
        """(C, 3) stage-space positions on ``pose``."""
        return pose.track(self.triangles, self.barycentric)

    def velocity(self, pose_a: "Pose", pose_b: "Pose") -> np.ndarray:
        """(C, 3) average velocity between two poses, stage units per second."""
        dt = pose_b.seconds - pose_a.seconds
        if dt == 0:
            raise ValueError("the two poses are at the same time")
        return (self.at(pose_b) - self.at(pose_a)) / dt

    def velocity_at(self, collider: "Collider", clip: str | None, time: float, step: float = 0.05):
        """(C, 3) velocity at ``time`` by central difference over ``step`` time codes."""
        a = collider.pose(clip, time - step)
        b = collider.pose(clip, time + step)
        return self.velocity(a, b)
