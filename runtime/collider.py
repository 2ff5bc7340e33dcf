"""The runtime collider: posing (UsdSkel-exact skinning at any time) and queries.

>>> col = load_collider("boss.usda")
>>> pose = col.pose("walk", 12.5)          # any time code, interpolated between samples
>>> hits = pose.raycast(origins, directions)
>>> cs = pose.sphere_contacts(center, radius)
>>> carried = cs.anchors().at(col.pose("walk", 13.0))   # momentum inheritance (thesis 5.5.3)

Shapes follow the contract: points (V, 3) float32 stage space, spheres (P, 4) float64.
Queries work in float64 on the float32 posed points.  Matrices are column-vector float64
(``p' = M @ p``; :mod:`runtime.schema` is the one conversion from USD's row-vector layout).

>>> pose = col.pose_from_joints(local)     # any pose: (J, 4, 4) joint-local, skeleton order
>>> pose.refit                             # (P,) bool: spheres grown because the stored one did not hold
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import kernels as K
from .asset import ClipData, ColliderData, read_collider
from .kernels import bounds as B
from .kernels import pose as PK
from .kernels import skin as SK
from .errors import ColliderError

#: Above this many rays the parallel ray kernel is used.
PARALLEL_RAYS = 256
#: Above this many vertices a pose's full skin runs on every core.  With the per-vertex kernel
#: inlined (runtime.kernels.skin._lbs) one skinning pass is memory-bound: on this project's 2
#: cores the one-thread pass is the faster one from 20,000 vertices (0.12 vs 0.15 ms) to 200,000
#: (1.2 vs 1.8 ms), so the threaded kernel is kept for meshes far larger than any seen here (and
#: compiles only for them).
PARALLEL_SKIN = 1_000_000
#: :meth:`Collider.pose_from_joints` grows a sphere that does not provably hold to the bound's
#: radius when that is at most this many times the stored radius, else to the farthest skinned
#: vertex of the part (exact, O(part vertices)).
REFIT_FROM_BOUND = 1.25


# -- results -----------------------------------------------------------------------------------


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


# -- backends ----------------------------------------------------------------------------------


class PartsBackend:
    """Part spheres first, then exact tests on the triangles of the parts they pass."""

    name = "parts"

    def raycast(self, pose, origins, directions, max_distance):
        d = pose._data
        dist, tri, part, bary = _ray_buffers(len(origins))
        if len(origins) > PARALLEL_RAYS:
            pose._skin_all()
            pose._all_chunks()
            kern = K._raycast_parallel
        else:
            kern = K._raycast
        kern(origins, directions, max_distance, pose._points, d.triangles, pose.cull, d.faces,
             d.chunk_offsets, d.part_chunks, pose.chunk_spheres, pose._ready, pose._version,
             pose._lazy(), dist, tri, part, bary)
        return pose._ray_hits(origins, directions, dist, tri, part, bary)

    def sphere_contacts(self, pose, center, radius):
        d = pose._data
        s = pose._scratch()
        pose._stamp += 1
        n = K._sphere_contacts(center, radius, pose._points, d.triangles, pose.cull, d.faces,
                               d.chunk_offsets, d.part_chunks, pose.chunk_spheres, pose._ready,
                               pose._version, pose._lazy(), d.faces_shared, s["mark"], pose._stamp,
                               *_contact_buffers(s))
        return _contacts(s, n)


class BruteForceBackend:
    """Every triangle, no culling: the reference the culled backend must always agree with
    (kernels of their own: game code never compiles them)."""

    name = "brute"

    def raycast(self, pose, origins, directions, max_distance):
        d = pose._data
        dist, tri, part, bary = _ray_buffers(len(origins))
        pose._skin_all()
        K._raycast_all(origins, directions, max_distance, pose._points, d.triangles, dist, tri, part, bary)
        part = np.where(tri >= 0, d.face_part[np.maximum(tri, 0)], -1)
        return pose._ray_hits(origins, directions, dist, tri, part, bary)

    def sphere_contacts(self, pose, center, radius):
        s = pose._scratch()
        pose._skin_all()
        return _contacts(s, K._sphere_contacts_all(center, radius, pose._points, pose._data.triangles,
                                                   *_contact_buffers(s)))


def _ray_buffers(R):
    """(distance (R,), triangle (R,), part (R,), barycentric (R, 3)) for a ray kernel to fill."""
    return np.empty(R), np.empty(R, dtype=np.int64), np.empty(R, dtype=np.int64), np.empty((R, 3))


def _contact_buffers(s):
    return s["tri"], s["point"], s["normal"], s["depth"], s["bary"]


def _contacts(s, n):
    """The first ``n`` contacts a kernel wrote into the pose's scratch ``s``, copied out."""
    return SphereContacts(s["tri"][:n].copy(), s["point"][:n].copy(), s["normal"][:n].copy(),
                          s["depth"][:n].copy(), s["bary"][:n].copy())


class TrimeshBackend:
    """trimesh on the posed mesh (embree when available), rebuilt per query: a baseline."""

    name = "trimesh"

    def _mesh(self, pose):
        import trimesh

        return trimesh.Trimesh(pose.points.astype(np.float64), pose._data.triangles, process=False)

    def raycast(self, pose, origins, directions, max_distance):
        m = self._mesh(pose)
        loc, ray, tri = m.ray.intersects_location(origins, directions, multiple_hits=True)
        R = len(origins)
        dist = np.full(R, np.inf)
        best = np.full(R, -1, dtype=np.int64)
        if len(ray):
            dd = np.einsum("ij,ij->i", loc - origins[ray], directions[ray])
            ok = (dd >= 0) & (dd <= max_distance)
            for r, t, f in zip(ray[ok], dd[ok], tri[ok]):
                if t < dist[r]:
                    dist[r], best[r] = t, f
        bary = np.zeros((R, 3))
        h = best >= 0
        if h.any():
            import trimesh

            pts = origins[h] + dist[h, None] * directions[h]
            bary[h] = trimesh.triangles.points_to_barycentric(m.triangles[best[h]], pts)
        part = np.where(h, pose._data.face_part[np.maximum(best, 0)], -1)
        return pose._ray_hits(origins, directions, dist, best, part, bary)

    def sphere_contacts(self, pose, center, radius):
        import trimesh

        m = self._mesh(pose)
        q = np.repeat(center[None], len(m.faces), 0)
        cp = trimesh.triangles.closest_point(m.triangles, q)
        dist = np.linalg.norm(cp - center, axis=1)
        idx = np.nonzero(dist <= radius)[0]
        nrm = center - cp[idx]
        ln = np.linalg.norm(nrm, axis=1, keepdims=True)
        nrm = np.divide(nrm, ln, out=np.zeros_like(nrm), where=ln > 0)
        bary = trimesh.triangles.points_to_barycentric(m.triangles[idx], cp[idx]) if len(idx) else np.zeros((0, 3))
        return SphereContacts(idx.astype(np.int64), cp[idx], nrm, radius - dist[idx], bary)


BACKENDS = {b.name: b for b in (PartsBackend(), BruteForceBackend(), TrimeshBackend())}


def get_backend(backend):
    if backend is None or hasattr(backend, "raycast"):
        return backend
    try:
        return BACKENDS[backend]
    except KeyError:
        raise ValueError(f"unknown backend {backend!r}; one of {sorted(BACKENDS)}") from None


# -- pose --------------------------------------------------------------------------------------


def _point(a):
    """``a`` as a contiguous (3,) float64 array, or None when it is not 3 finite numbers (a
    per-query check: the scalar tests cost a fifth of ``np.isfinite(a).all()``)."""
    c = np.ascontiguousarray(np.asarray(a, dtype=np.float64).reshape(-1))
    if c.shape != (3,) or not (math.isfinite(c[0]) and math.isfinite(c[1]) and math.isfinite(c[2])):
        return None
    return c


def _vec3s(a, name):
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 1 and a.shape[0] == 3:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must be (R, 3), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} must be finite")
    return np.ascontiguousarray(a)


class Pose:
    """The collider at one pose: skinned points, part spheres, queries.

    Made by :meth:`Collider.pose` (a clip at a time) or :meth:`Collider.pose_from_joints` (any
    joint-local pose).  Posing is lazy: :meth:`set` computes the joints; the part spheres and
    provable culling spheres (tests K and D of :mod:`runtime.kernels.bounds`, no vertex
    skinned) are computed when first read (by a query, or :attr:`spheres` / :attr:`cull`), so a
    program that only reads points never compiles the bounds kernel; a query skins only the
    parts it reaches, and reading :attr:`points` skins the rest (same numbers either way).

    Attributes
    ----------
    points : (V, 3) float32, stage space (preallocated, updated in place)
    spheres : (P, 4) float64, part sphere centres + radii: the stored spheres moved with their
        joints; for :meth:`Collider.pose_from_joints`, grown where they do not provably hold
    refit : (P,) bool, the parts whose sphere was grown for this pose (always False for a clip
        pose: the validator certifies those spheres for every time of every clip)
    cull : (P, 4) float64, the spheres used for culling: same centres, radius provably reaching
        every posed vertex of the part, so culling never changes an answer
    skel_transforms : (J, 4, 4) float64, joint skeleton-space transforms (column-vector)
    skinning_transforms : (J, 4, 4), ``skel @ inv_bind @ geom_bind``
    joint_world : (J, 4, 4), joint -> stage space (``local_to_world @ skel``)
    local_to_world : (4, 4), the skeleton prim's local-to-world transform
    clip, time, seconds
    """

    def __init__(self, collider: "Collider"):
        d = collider.data
        self.collider = collider
        self._data = d
        V, J, P = len(d.rest_points), len(d.joints), len(d.part_joint)
        self._points = np.empty((V, 3), dtype=np.float32)
        self._points1 = self._points.reshape(1, V, 3)  # the skinning kernel's (F, V, 3) view
        self._full = -1  # version at which every vertex was skinned
        self._spheres = np.empty((P, 4))
        self._cull = np.empty((P, 4))
        self._bounded = -1  # version at which spheres and cull were computed
        self.refit = np.zeros(P, dtype=bool)
        self.skel_transforms = np.empty((J, 4, 4))
        self.skinning_transforms = np.empty((J, 4, 4))
        self._skin_world = np.empty((1, J, 12))  # local_to_world @ skinning_transforms (kernels.skin.fold)
        self.joint_world = np.empty((J, 4, 4))
        self._world1 = self.joint_world.reshape(1, J, 4, 4)
        self.local_to_world = np.eye(4)
        self.chunk_spheres = np.empty((len(d.chunk_offsets) - 1, 4))
        self._ready = np.zeros(P, dtype=np.int64)  # part p's chunk spheres are valid if == _version
        self._version = 0
        self._local = np.empty((J, 4, 4))
        self._local1 = self._local.reshape(1, J, 4, 4)  # the interpolation kernel's (T, J, 4, 4) view
        self._time1 = np.zeros(1)
        self._trs = {}  # per clip: the interpolation kernel's (1, A, 10) scratch
        self._sph = np.empty((1, P, 4))
        self._kb = np.empty((1, P))
        self._db = np.empty((1, P))
        self._buffers = None
        self._stamp = 0
        self.clip = None
        self.time = 0.0

    @property
    def seconds(self) -> float:
        return self.time / self._data.time_codes_per_second

    def set(self, clip: str | None, time: float) -> "Pose":
        """Re-pose in place (no allocation) at ``clip`` and time code ``time``."""
        d = self._data
        c = self.collider._clip(clip)
        time = float(time)
        if not np.isfinite(time):
            raise ValueError(f"time must be finite, got {time}")
        self._set_world(time)
        self._time1[0] = time
        trs = self._trs.get(c.name)
        if trs is None:
            trs = self._trs[c.name] = np.empty((1, len(c.anim_to_skel), 10))
        PK._locals_at(self._time1, c.tt, c.vt, c.tr, c.vr, c.ts, c.vs, c.anim_to_skel, d.rest_local, self._local1, trs)
        self._posed()
        self.refit[:] = False
        self.clip = c.name if clip is not None else None
        self.time = time
        return self

    def set_joints(self, local, time: float = 0.0) -> "Pose":
        """Re-pose in place at joint-local transforms ``local`` (J, 4, 4) column-vector, skeleton
        joint order (validated by :meth:`Collider.pose_from_joints`); grow the spheres that do
        not provably hold (see :attr:`refit`)."""
        self._set_world(float(time))
        self._local[:] = local
        self._posed()
        self._refit()
        self.clip = None
        self.time = float(time)
        return self

    def _set_world(self, time):
        d = self._data
        if d.static_local_to_world is not None:
            self.local_to_world = d.static_local_to_world
        else:
            from pxr import UsdGeom

            from . import schema

            prim = d.stage.GetPrimAtPath(d.skeleton_path)
            self.local_to_world = schema.matrices_from_usd(UsdGeom.Imageable(prim).ComputeLocalToWorldTransform(time))

    @property
    def spheres(self) -> np.ndarray:
        """(P, 4) float64 part sphere centres + radii at this pose (computed on first read)."""
        self._bounds()
        return self._spheres

    @property
    def cull(self) -> np.ndarray:
        """(P, 4) float64 culling spheres at this pose (computed on first read)."""
        self._bounds()
        return self._cull

    def _posed(self):
        d = self._data
        PK._compose(self._local, d.parents, d.topo_order, d.inv_bind, d.geom_bind, self.local_to_world,
                    self.skel_transforms, self.skinning_transforms, self.joint_world, self._skin_world)
        self._version += 1
        if not self.collider.lazy:
            self._bounds()

    def _bounds(self):
        if self._bounded == self._version:
            return
        self._bounded = self._version
        d = self._data
        B._pose_bounds_serial(self._world1, *d.bounds.args(), self._sph, self._kb, self._db)
        B._cull_spheres(self._sph, self._kb, self._db, self._spheres, self._cull)
        if not self.collider.lazy:
            self._skin_all()
            d_, _ = SK.part_farthest(d.rest_points, d.joint_indices, d.joint_weights, self._skin_world,
                                     d.vert_offsets, d.verts, self.spheres[None, :, :3])
            far = d_[0] * (1.0 + 1e-6) + 1e-9
            self.cull[:, 3] = np.maximum(self.spheres[:, 3], far)

    def _refit(self):
        """Parts whose stored sphere the bounds cannot prove: the bound's sphere when it is at
        most :data:`REFIT_FROM_BOUND` times larger, else the farthest skinned vertex."""
        s = self.spheres  # computes the bounds
        bound = np.minimum(self._kb[0], self._db[0])
        grow = ~(bound <= s[:, 3])
        self.refit[:] = grow
        if not grow.any():
            return
        loose = grow & ~(bound <= REFIT_FROM_BOUND * s[:, 3])
        s[grow, 3] = bound[grow]
        if loose.any():
            d = self._data
            far, _ = SK.part_farthest(d.rest_points, d.joint_indices, d.joint_weights, self._skin_world,
                                      d.vert_offsets, d.verts, s[None, :, :3], todo=loose[None])
            stored = self._sph[0, :, 3]
            held = loose & (far[0] <= stored)  # the bounds were too loose: the stored sphere does hold
            s[loose, 3] = far[0, loose] * (1.0 + 1e-9)
            s[held, 3] = stored[held]
            self.refit[held] = False

    # -- queries

    def raycast(self, origins, directions, max_distance=np.inf, backend=None) -> RayHits:
        """Nearest hit of each ray ``origins + t * directions``, ``0 <= t <= max_distance``.

        origins, directions : (R, 3) (a single (3,) ray is accepted); directions need not be
        unit (they are normalised; distances are stage units). Both sides of a triangle hit."""
        o = _vec3s(origins, "origins")
        dirs = _vec3s(directions, "directions")
        if o.shape != dirs.shape:
            raise ValueError(f"origins {o.shape} and directions {dirs.shape} differ in shape")
        n = np.linalg.norm(dirs, axis=1)
        if (n == 0).any():
            raise ValueError("a direction is zero")
        dirs = dirs / n[:, None]
        md = float(max_distance)
        if not md >= 0:
            raise ValueError(f"max_distance must be >= 0, got {max_distance}")
        return (get_backend(backend) or self.collider.backend).raycast(self, o, dirs, md)

    def sphere_contacts(self, center, radius, backend=None) -> SphereContacts:
        """Every triangle whose closest point lies within ``radius`` of ``center`` (3,)."""
        c = _point(center)
        if c is None:
            raise ValueError(f"center must be 3 finite numbers, got {center!r}")
        r = float(radius)
        if not (r >= 0 and math.isfinite(r)):
            raise ValueError(f"radius must be finite and >= 0, got {radius!r}")
        return (get_backend(backend) or self.collider.backend).sphere_contacts(self, c, r)

    def track(self, triangles, barycentric) -> np.ndarray:
        """(C, 3) stage positions of surface points (triangle index + barycentric (C, 3|2)).
        Skins only the parts holding those triangles (lazy, as the queries)."""
        sp = SurfacePoints(triangles, barycentric)
        self._ready_faces(sp.triangles)
        out = np.empty((len(sp), 3))
        K._surface_points(self._points, self._data.triangles, sp.triangles, sp.barycentric, out)
        return out

    def surface_frame(self, surface: "SurfacePoints", out=None) -> np.ndarray:
        """(6,) float64: the centroid of ``surface``'s points and the unit mean of their
        triangles' unit normals (counter-clockwise = outward; zeros when they cancel or there are
        none) - ``track(...).mean(0)`` and the normalised ``face_normals(...).sum(0)`` in one
        pass, skinning only the parts holding the triangles.  A contact patch's frame: how the
        patch moves and turns from one pose to the next (:mod:`runtime.controller` carries its
        player with it).  ``out``: an optional (6,) float64 array to write into."""
        if not isinstance(surface, SurfacePoints):
            raise TypeError(f"surface must be SurfacePoints, got {type(surface).__name__}")
        if out is None:
            out = np.empty(6)
        elif not (isinstance(out, np.ndarray) and out.shape == (6,) and out.dtype == np.float64
                  and out.flags.c_contiguous and out.flags.writeable):
            raise ValueError("out must be a writable contiguous (6,) float64 array")
        if self._full != self._version:
            self._ready_faces(surface.triangles)
        if not K._surface_frame(self._points, self._data.triangles, surface.triangles, surface.barycentric, out):
            raise ValueError(f"triangle index out of range 0..{len(self._data.triangles) - 1}")
        return out

    def face_normals(self, triangles=None) -> np.ndarray:
        """(n, 3) unit geometric normals (counter-clockwise = outward) of ``triangles`` (all)."""
        if triangles is None:
            return self._normals(self.points, None)
        tri = np.ascontiguousarray(np.asarray(triangles, dtype=np.int64).ravel())
        self._ready_faces(tri)
        return self._normals(self._points, tri)

    def _normals(self, points, triangles):
        tri = np.arange(len(self._data.triangles)) if triangles is None else triangles
        out = np.empty((len(tri), 3))
        K._face_normals(points, self._data.triangles, tri, out)
        return out

    def _ready_faces(self, tri):
        """Skin the corners of triangles ``tri`` (int64, contiguous) at this pose, if not yet;
        ValueError on an index out of range."""
        d = self._data
        if not K._ready_faces(tri, d.face_part, self._ready, self._version, self._lazy(), self._points,
                              d.part_chunks, self.chunk_spheres):
            raise ValueError(f"triangle index out of range 0..{len(d.triangles) - 1}")

    @property
    def points(self) -> np.ndarray:
        """(V, 3) float32 skinned points, stage space."""
        self._skin_all()
        return self._points

    # -- helpers

    def _skin_all(self):
        if self._full != self._version:
            d = self._data
            kern = SK._skin_frames if len(d.rest_points) > PARALLEL_SKIN else SK._skin_frames_serial
            kern(d.rest_points, d.joint_indices, d.joint_weights, self._skin_world, self._points1)
            self._full = self._version

    def _lazy(self):
        d = self._data
        return (self._full, d.rest_points, d.joint_indices, d.joint_weights,
                self._skin_world, d.vert_offsets, d.verts, d.chunk_vert_offsets, d.chunk_verts)

    def _all_chunks(self):
        d = self._data
        K._all_chunk_spheres(self._points, d.chunk_vert_offsets, d.chunk_verts, d.part_chunks,
                             self.chunk_spheres, self._ready, self._version)

    def _scratch(self):
        if self._buffers is None:
            F = len(self._data.triangles)
            self._buffers = dict(mark=np.zeros(F, dtype=np.int64), tri=np.empty(F, dtype=np.int64),
                                 point=np.empty((F, 3)), normal=np.empty((F, 3)),
                                 depth=np.empty(F), bary=np.empty((F, 3)))
        return self._buffers

    def _ray_hits(self, origins, directions, dist, tri, part, bary):
        point = np.empty(origins.shape)
        normal = np.empty(origins.shape)
        K._hit_fill(origins, directions, dist, tri, self._points, self._data.triangles, point, normal)
        return RayHits(dist, point, normal, tri, bary, part)


# -- collider ----------------------------------------------------------------------------------


class Collider:
    """A loaded collider asset (see :func:`load_collider`).

    Attributes
    ----------
    data : :class:`runtime.asset.ColliderData` (all arrays)
    clips : list of clip names, file order
    triangles : (F, 3) int64
    backend : query backend (``"parts"`` default, ``"brute"``, ``"trimesh"``), same methods
    """

    def __init__(self, data: ColliderData, backend="parts", lazy=True):
        self.data = data
        self.lazy = lazy
        self.backend = get_backend(backend)
        self._clips = {c.name: c for c in data.clips}
        A0 = np.zeros((1, 0, 3))
        self._rest = ClipData("", "", np.zeros(1), A0, np.zeros(1), np.zeros((1, 0, 4)),
                              np.zeros(1), A0, np.zeros(0, dtype=np.int64), np.zeros(0))

    @property
    def clips(self) -> list:
        return [c.name for c in self.data.clips]

    @property
    def triangles(self) -> np.ndarray:
        return self.data.triangles

    @property
    def rest_points(self) -> np.ndarray:
        return self.data.rest_points

    @property
    def parts(self) -> int:
        return len(self.data.part_joint)

    @property
    def up(self) -> np.ndarray:
        """(3,) the stage's up vector."""
        return np.array([0.0, 0.0, 1.0]) if self.data.up_axis == "Z" else np.array([0.0, 1.0, 0.0])

    @property
    def joints(self) -> list:
        """Skeleton joint paths, in skeleton order (the order of :meth:`pose_from_joints`)."""
        return list(self.data.joints)

    @property
    def rest_local(self) -> np.ndarray:
        """(J, 4, 4) column-vector joint-local rest transforms (a starting point for IK)."""
        return self.data.rest_local.copy()

    def pose_from_joints(self, local=None, *, translations=None, rotations=None, scales=None,
                         time: float = 0.0, out: Pose | None = None) -> Pose:
        """The collider at any pose (IK, ragdoll, procedural), with spheres that hold for it.

        Parameters
        ----------
        local : (J, 4, 4) float64, optional
            Joint-local transforms in skeleton joint order (:attr:`joints`), **column-vector**
            (``p_parent = local[j] @ p_joint``, translation in the last column), affine (last row
            ``0 0 0 1``).  Or give the TRS arrays instead:
        translations : (J, 3), rotations : (J, 4) ``(x, y, z, w)``, scales : (J, 3), optional
            ``local = T R S`` (UsdSkel's composition); translations default to the rest pose's,
            scales to 1; rotations are required and normalised.
        time : float
            Time code for an animated skeleton transform (only then does it matter).
        out : Pose, optional  reuse its buffers

        Returns
        -------
        Pose
            ``pose.spheres`` hold every skinned vertex of their part: the stored sphere where the
            bounds prove it (tests K and D, O(parts x influencing joints)), otherwise grown
            (``pose.refit[p]``) to the bound's radius or, when that is loose, to the part's
            farthest skinned vertex.  Queries are exact (culling never drops a triangle).
        """
        J = len(self.data.joints)
        if local is None:
            if rotations is None:
                raise ValueError("pose_from_joints: give local (J, 4, 4) or rotations (J, 4)")
            t = self.data.rest_local[:, :3, 3] if translations is None else translations
            sc = np.ones((J, 3)) if scales is None else scales
            arrs = [np.asarray(a, dtype=np.float64) for a in (t, rotations, sc)]
            for name, a, w in zip(("translations", "rotations", "scales"), arrs, (3, 4, 3)):
                if a.shape != (J, w):
                    raise ValueError(f"pose_from_joints: {name} must be ({J}, {w}), got {a.shape}")
                if not np.isfinite(a).all():
                    raise ValueError(f"pose_from_joints: {name} must be finite")
            if (np.linalg.norm(arrs[1], axis=1) == 0).any():
                raise ValueError("pose_from_joints: a rotation quaternion is zero")
            local = PK.trs_matrices(*arrs)
        else:
            if translations is not None or rotations is not None or scales is not None:
                raise ValueError("pose_from_joints: give local or translations/rotations/scales, not both")
            local = np.asarray(local, dtype=np.float64)
            if local.shape != (J, 4, 4):
                raise ValueError(f"pose_from_joints: local must be ({J}, 4, 4) (one per skeleton joint), "
                                 f"got {local.shape}")
            if not np.isfinite(local).all():
                raise ValueError("pose_from_joints: local transforms must be finite")
            if not np.allclose(local[:, 3], [0, 0, 0, 1], atol=1e-9):
                raise ValueError("pose_from_joints: local transforms must be affine column-vector matrices "
                                 "(last row 0 0 0 1); a row-vector (USD layout) matrix must be transposed")
        p = out if out is not None else Pose(self)
        if p.collider is not self:
            raise ValueError("out is a pose of another collider")
        return p.set_joints(local, time)

    def frame_times(self, clip: str) -> np.ndarray:
        """(n,) float64 time codes of the clip's samples (its frames)."""
        return self._clip(clip).times.copy()

    def _clip(self, clip):
        if clip is None:
            return self._rest
        try:
            return self._clips[clip]
        except KeyError:
            raise KeyError(f"no clip {clip!r}; clips are {self.clips}") from None

    def pose(self, clip: str | None, time: float = 0.0, out: Pose | None = None) -> Pose:
        """The collider at ``clip`` (None: the rest pose) and time code ``time`` (any value:
        interpolated as UsdSkel does, held outside the clip). ``out`` reuses a pose's buffers."""
        p = out if out is not None else Pose(self)
        if p.collider is not self:
            raise ValueError("out is a pose of another collider")
        return p.set(clip, time)

    def size(self) -> float:
        """Diagonal of the rest points' bounding box (the model size)."""
        p = self.data.rest_points
        return float(np.linalg.norm(p.max(0) - p.min(0)))


def load_collider(path, verify=None, backend="parts") -> Collider:
    """Read a collider asset.

    Parameters
    ----------
    path : str or PathLike
    verify : callable, optional
        ``verify(path)`` is called after reading and must raise :class:`ColliderError` (one
        line) when the asset is not fit for use; the validators' error-severity rules are
        ``validators.require_passing``.  The runtime never imports the validators itself
        (layers: runtime is the lowest), so game code that wants verification passes it here.
    backend : {"parts", "brute", "trimesh"} or a backend object

    Raises :class:`ColliderError` (one-line message) on a missing, unreadable or invalid asset."""
    if verify is not None and verify is not False and not callable(verify):
        raise TypeError("verify must be a callable such as validators.require_passing, or None")
    data = read_collider(path)
    if verify:
        verify(path)
    return Collider(data, backend=backend)
