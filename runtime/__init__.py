"""colossus runtime: pose a collider asset at any time and query it (rays, sphere contacts,
surface points that move with the skin). See :func:`load_collider`."""

from .backends import BACKENDS, BruteForceBackend, PartsBackend, TrimeshBackend
from .collider import Collider, Pose, load_collider
from .errors import ColliderError
from .placement import Placement
from .results import RayHits, SphereContacts, SurfacePoints

__all__ = ["load_collider", "ColliderError", "Collider", "Pose", "Placement", "RayHits", "SphereContacts",
           "SurfacePoints", "PartsBackend", "BruteForceBackend", "TrimeshBackend", "BACKENDS"]
