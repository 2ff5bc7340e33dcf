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

The records the queries return are in :mod:`runtime.results`; the backends that answer them
(parts, brute force, trimesh) in :mod:`runtime.backends`.
"""

from __future__ import annotations

import math

import numpy as np

from .asset import ColliderData, read_collider, read_collider_stage
from .schema import Clip
from .backends import get_backend
from .kernels import bounds as B
from .kernels import pose as PK
from .kernels import query as QK
from .kernels import skin as SK
from .errors import ColliderError
from .placement import Placement
from .results import RayHits, SphereContacts, SurfacePoints

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


#: Largest entry a posed joint's composed transform may have: beyond it products in float64 lose
#: every bit the sphere bounds rely on (and 1e154 squared overflows).
LARGEST_TRANSFORM = 1e12


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
        # local_to_world @ skinning_transforms (kernels.skin.fold); dual-quaternion meshes: the
        # wider layout of kernels.skin.fold_dq, which the one kernel's method switch reads
        self._dq = d.skinning_method == SK.DUAL_QUATERNION
        # blend shapes (kernels.skin.shape_points, the one kernel's pre-pass): the rest points
        # displaced at this pose's weights, what every skinning call below reads
        self._S = 0 if d.shapes is None else len(d.shapes)
        self.shape_weights = np.zeros(self._S)
        self._rest_points = d.rest_points if self._S == 0 else d.rest_points.copy()
        self._shaped = False  # a weight is not 0: tests K and D (rest points) do not bound it
        self._skin_world = np.empty((1, J, 1, SK.DQ_WIDTH)) if self._dq else np.empty((1, J, 12))
        self._lbs_world = np.empty((1, J, 12)) if self._dq else self._skin_world
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
        if self._S:
            self._set_shapes(c.shape_weights(self._time1, self._S)[0])
        self._posed()
        self.refit[:] = False
        self.clip = c.name if clip is not None else None
        self.time = time
        return self

    def set_joints(self, local, time: float = 0.0, shape_weights=None) -> "Pose":
        """Re-pose in place at joint-local transforms ``local`` (J, 4, 4) column-vector, skeleton
        joint order, and blend-shape weights ``shape_weights`` (S,) (none: all 0) (validated by
        :meth:`Collider.pose_from_joints`); grow the spheres that do not provably hold (see
        :attr:`refit`)."""
        self._set_world(float(time))
        self._local[:] = local
        if self._S:
            self._set_shapes(np.zeros(self._S) if shape_weights is None else shape_weights)
        self._posed()
        st = self.skinning_transforms
        if not (np.isfinite(st).all() and np.abs(st).max(initial=0.0) <= LARGEST_TRANSFORM):
            raise ValueError("pose_from_joints: the joints' composed transforms overflow (an entry is "
                             f"not finite or beyond {LARGEST_TRANSFORM:g}); no pose, no spheres for them")
        self._refit()
        self.clip = None
        self.time = float(time)
        return self

    def _set_shapes(self, w):
        """The rest points displaced by the blend shapes at weights ``w`` (S,)."""
        d = self._data
        self.shape_weights[:] = w
        self._shaped = bool(np.any(self.shape_weights != 0.0))
        if self._shaped:
            self._rest_points[:] = SK.shape_points(d.rest_points, d.shapes, self.shape_weights[None])[0]
        else:
            self._rest_points[:] = d.rest_points

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
                    self.skel_transforms, self.skinning_transforms, self.joint_world, self._lbs_world)
        if self._dq:  # UsdSkel's DQS skins in skeleton space: geomBind first, local-to-world last
            self._skin_world[:] = SK.fold_dq(self.skel_transforms @ d.inv_bind, d.geom_bind, self.local_to_world)
        self._version += 1
        if not self.collider.lazy:
            self._bounds()

    def _bounds(self):
        if self._bounded == self._version:
            return
        self._bounded = self._version
        d = self._data
        B._pose_bounds_serial(self._world1, *d.bounds.args(), self._sph, self._kb, self._db)
        if self._dq or self._shaped:  # tests K and D bound linear blends of the rest points only: a
            self._kb[:] = np.inf       # dual-quaternion part, or one under blend shapes, is skinned
            self._db[:] = np.inf
        B._cull_spheres(self._sph, self._kb, self._db, self._spheres, self._cull)
        if not self.collider.lazy or self._dq or self._shaped:
            self._skin_all()
            d_, _ = SK.part_farthest(self._rest_points, d.joint_indices, d.joint_weights, self._skin_world,
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
            far, _ = SK.part_farthest(self._rest_points, d.joint_indices, d.joint_weights, self._skin_world,
                                      d.vert_offsets, d.verts, s[None, :, :3], todo=loose[None])
            stored = self._sph[0, :, 3]
            held = loose & (far[0] <= stored)  # the bounds were too loose: the stored sphere does hold
            s[loose, 3] = far[0, loose] * (1.0 + 1e-9)
            s[held, 3] = stored[held]
            self.refit[held] = False

    # -- queries

    def raycast(self, origins, directions, max_distance=np.inf, backend=None, world=None) -> RayHits:
        """Nearest hit of each ray ``origins + t * directions``, ``0 <= t <= max_distance``.

        origins, directions : (R, 3) (a single (3,) ray is accepted); directions need not be
        unit (they are normalised; distances are stage units). Both sides of a triangle hit.
        world : (4, 4) or :class:`runtime.placement.Placement`, optional: the collider's stage ->
        world transform (column-vector; rotation, uniform scale, translation): rays,
        ``max_distance`` and every result in world space (:mod:`runtime.placement`)."""
        o = _vec3s(origins, "origins")
        dirs = _vec3s(directions, "directions")
        if o.shape != dirs.shape:
            raise ValueError(f"origins {o.shape} and directions {dirs.shape} differ in shape")
        if world is not None:
            place = Placement.of(world)
            hits = self.raycast(place.to_stage(o), place.vectors_to_stage(dirs),
                                float(max_distance) / place.scale, backend)
            return place.ray_hits(hits)
        # scaled by its largest component first: a finite but huge direction (1e200) would overflow
        # its norm to inf and become a zero direction, a silent miss
        big = np.abs(dirs).max(axis=1) if len(dirs) else np.zeros(0)
        if (big == 0).any():
            raise ValueError("a direction is zero")
        dirs = dirs / big[:, None]
        dirs = dirs / np.linalg.norm(dirs, axis=1)[:, None]
        md = float(max_distance)
        if not md >= 0:
            raise ValueError(f"max_distance must be >= 0, got {max_distance}")
        return (get_backend(backend) or self.collider.backend).raycast(self, o, dirs, md)

    def sphere_contacts(self, center, radius, backend=None, world=None) -> SphereContacts:
        """Every triangle whose closest point lies within ``radius`` of ``center`` (3,).
        ``world``: as :meth:`raycast` (centre, radius and the contacts in world space)."""
        c = _point(center)
        if c is None:
            raise ValueError(f"center must be 3 finite numbers, got {center!r}")
        r = float(radius)
        if not (r >= 0 and math.isfinite(r)):
            raise ValueError(f"radius must be finite and >= 0, got {radius!r}")
        if world is not None:
            place = Placement.of(world)
            return place.sphere_contacts(self.sphere_contacts(place.to_stage(c[None])[0], r / place.scale, backend))
        return (get_backend(backend) or self.collider.backend).sphere_contacts(self, c, r)

    def track(self, triangles, barycentric, world=None) -> np.ndarray:
        """(C, 3) stage positions of surface points (triangle index + barycentric (C, 3|2)).
        Skins only the parts holding those triangles (lazy, as the queries).  ``world``: as
        :meth:`raycast` (the positions in world space)."""
        sp = SurfacePoints(triangles, barycentric)
        place = None if world is None else Placement.of(world)  # refused before any work
        self._ready_faces(sp.triangles)
        out = np.empty((len(sp), 3))
        QK._surface_points(self._points, self._data.triangles, sp.triangles, sp.barycentric, out)
        return out if place is None else place.to_world(out)

    def surface_frame(self, surface: "SurfacePoints", out=None, world=None) -> np.ndarray:
        """(6,) float64: the centroid of ``surface``'s points and the unit mean of their
        triangles' unit normals (counter-clockwise = outward; zeros when they cancel or there are
        none) - ``track(...).mean(0)`` and the normalised ``face_normals(...).sum(0)`` in one
        pass, skinning only the parts holding the triangles.  A contact patch's frame: how the
        patch moves and turns from one pose to the next (:mod:`runtime.controller` carries its
        player with it).  ``out``: an optional (6,) float64 array to write into.  ``world``: as
        :meth:`raycast` (the centroid carried by it, the normal by its rotation; zeros stay zeros)."""
        if not isinstance(surface, SurfacePoints):
            raise TypeError(f"surface must be SurfacePoints, got {type(surface).__name__}")
        place = None if world is None else Placement.of(world)
        if out is None:
            out = np.empty(6)
        elif not (isinstance(out, np.ndarray) and out.shape == (6,) and out.dtype == np.float64
                  and out.flags.c_contiguous and out.flags.writeable):
            raise ValueError("out must be a writable contiguous (6,) float64 array")
        if self._full != self._version:
            self._ready_faces(surface.triangles)
        if not QK._surface_frame(self._points, self._data.triangles, surface.triangles, surface.barycentric, out):
            raise ValueError(f"triangle index out of range 0..{len(self._data.triangles) - 1}")
        if place is not None:
            out[:3] = place.to_world(out[None, :3])[0]
            out[3:] = out[3:] @ place.rotation.T  # a unit normal stays unit under a rotation
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
        QK._face_normals(points, self._data.triangles, tri, out)
        return out

    def _ready_faces(self, tri):
        """Skin the corners of triangles ``tri`` (int64, contiguous) at this pose, if not yet;
        ValueError on an index out of range."""
        d = self._data
        if not QK._ready_faces(tri, d.face_part, self._ready, self._version, self._lazy(), self._points,
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
            kern(self._rest_points, d.joint_indices, d.joint_weights, self._skin_world, self._points1)
            self._full = self._version

    def _lazy(self):
        d = self._data
        return (self._full, self._rest_points, d.joint_indices, d.joint_weights,
                self._skin_world, d.vert_offsets, d.verts, d.chunk_vert_offsets, d.chunk_verts)

    def _all_chunks(self):
        d = self._data
        QK._all_chunk_spheres(self._points, d.chunk_vert_offsets, d.chunk_verts, d.part_chunks,
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
        QK._hit_fill(origins, directions, dist, tri, self._points, self._data.triangles, point, normal)
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
        # a clip's source names (``Take 001`` for the prim ``Take_001``) reach it too, where no
        # other clip has that name or alias
        alias = {}
        for c in data.clips:
            for a in getattr(c, "source_names", ()):
                if a not in self._clips:
                    alias.setdefault(a, []).append(c)
        self._aliases = {a: cs[0] for a, cs in alias.items() if len(cs) == 1}
        A0 = np.zeros((1, 0, 3))
        self._rest = Clip("", "", np.zeros(1), A0, np.zeros(1), np.zeros((1, 0, 4)),
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
                         shape_weights=None, time: float = 0.0, out: Pose | None = None) -> Pose:
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
        shape_weights : (S,) float64 or dict, optional
            Blend-shape weights in the mesh's shape order (:attr:`shapes`), or ``{name: weight}``
            (shapes not named are 0); default: every shape at 0.  Applied before skinning, as
            UsdSkel does.
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
        sw = self._shape_weight_vector(shape_weights)
        p = out if out is not None else Pose(self)
        if p.collider is not self:
            raise ValueError("out is a pose of another collider")
        return p.set_joints(local, time, sw)

    @property
    def shapes(self) -> list:
        """The mesh's blend-shape names, in the order of :meth:`pose_from_joints`'s weights."""
        return [] if self.data.shapes is None else list(self.data.shapes.names)

    def _shape_weight_vector(self, shape_weights):
        names = self.shapes
        if shape_weights is None:
            return None
        if isinstance(shape_weights, dict):
            idx = {n: i for i, n in enumerate(names)}
            unknown = [k for k in shape_weights if k not in idx]
            if unknown:
                raise ValueError(f"pose_from_joints: {unknown[0]!r} is not a blend shape of this collider "
                                 f"({len(names)} shapes)")
            w = np.zeros(len(names))
            for k, v in shape_weights.items():
                w[idx[k]] = float(v)
        else:
            w = np.asarray(shape_weights, dtype=np.float64).reshape(-1)
            if w.shape != (len(names),):
                raise ValueError(f"pose_from_joints: shape_weights must be ({len(names)},), got {w.shape}")
        if not np.isfinite(w).all():
            raise ValueError("pose_from_joints: shape_weights must be finite")
        return w

    def frame_times(self, clip: str) -> np.ndarray:
        """(n,) float64 time codes of the clip's samples (its frames)."""
        return self._clip(clip).times.copy()

    def _clip(self, clip):
        if clip is None:
            return self._rest
        found = self._clips.get(clip) or self._aliases.get(clip)
        if found is None:
            raise KeyError(f"no clip {clip!r}; clips are {self.clips}")
        return found

    @property
    def fps(self) -> float:
        """Time codes per second of the asset (its clips' frame rate)."""
        return float(self.data.time_codes_per_second)

    def duration(self, clip: str) -> float:
        """Seconds from the clip's first frame to its last."""
        t = self._clip(clip).times
        return float(t[-1] - t[0]) / self.fps if len(t) else 0.0

    def time_code(self, clip: str, seconds: float, loop: bool = True) -> float:
        """The clip's time code ``seconds`` after its first frame; ``loop`` wraps it into the clip
        (a game's looping animation), else it is held at the ends."""
        t = self._clip(clip).times
        if not len(t):
            return 0.0
        s = float(seconds)
        if not np.isfinite(s):
            raise ValueError(f"seconds must be finite, got {seconds!r}")
        span = float(t[-1] - t[0])
        code = s * self.fps
        if loop and span > 0:
            code = code % span
        return float(t[0]) + min(max(code, 0.0), span)

    def pose_at_seconds(self, clip: str, seconds: float, loop: bool = True, out: Pose | None = None) -> Pose:
        """:meth:`pose` at ``seconds`` into the clip (:meth:`time_code`)."""
        return self.pose(clip, self.time_code(clip, seconds, loop), out=out)

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
        A verifier with ``accepts_stage = True`` (``require_passing`` has it) is handed the
        ``Usd.Stage`` just read instead of the path: the file is read once.
    backend : {"parts", "brute", "trimesh"} or a backend object

    Raises :class:`ColliderError` (one-line message) on a missing, unreadable or invalid asset."""
    if verify is not None and verify is not False and not callable(verify):
        raise TypeError("verify must be a callable such as validators.require_passing, or None")
    data, stage = read_collider_stage(path)
    if verify:
        verify(stage if getattr(verify, "accepts_stage", False) else path)
    return Collider(data, backend=backend)
