"""colossus runtime: pose a collider asset at any time and query it (rays, sphere contacts,
surface points that move with the skin). See :func:`load_collider`."""

from .collider import (BACKENDS, BruteForceBackend, Collider, PartsBackend, Pose, RayHits,
                       SphereContacts, SurfacePoints, TrimeshBackend, load_collider)
from .errors import ColliderError

__all__ = ["load_collider", "ColliderError", "Collider", "Pose", "RayHits", "SphereContacts",
           "SurfacePoints", "PartsBackend", "BruteForceBackend", "TrimeshBackend", "BACKENDS"]
