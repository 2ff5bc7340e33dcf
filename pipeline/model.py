"""The one core data object of the import stage: a skinned mesh with its skeleton and clips.

Every reader returns a :class:`SkinnedMesh`; every stage takes one and returns a new one
(:func:`dataclasses.replace`), never mutating its input.

Conventions
-----------
* Matrices are ``float64`` 4x4 in the **column-vector** convention: ``p' = M @ p``, translation
  in the last column.  (USD's ``Gf.Matrix4d`` is the transpose; conversion happens only in the
  USD reader and writer.)
* Bulk geometry is ``float32``; transforms are ``float64``.
* "Skeleton space" is the space of the skeleton: joint skel transforms map joint space to it.
  Skinned point of vertex ``v`` at frame ``f``::

      sum_k w[v,k] * skel[f, j[v,k]] @ inv(bind[j[v,k]]) @ geom_bind @ p[v]

  with ``p[v]`` first displaced by the blend shapes at the frame's weights
  (:class:`BlendShape`, ``Clip.shape_weights``; UsdSkel applies shapes before skinning).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from colossus.runtime.kernels.skin import METHODS as SKINNING_METHODS
from colossus.runtime.schema import parents_first


def _check(cond: bool, what: str, expected, actual) -> None:
    if not cond:
        raise ValueError(f"{what}: expected {expected}, got {actual}")


@dataclass(frozen=True, eq=False)
class Clip:
    """One animation clip, sampled at the source's own frames.

    Attributes
    ----------
    name : str
        Clip name (unique within a mesh).
    times : (f,) float64
        Time codes of the frames, in frames at the mesh's ``time_codes_per_second``.
    local : (f, b, 4, 4) float64
        Per-frame joint-local transforms (relative to the parent joint; roots relative to
        skeleton space).
    """

    name: str
    times: np.ndarray
    local: np.ndarray
    #: (f, S) float64 blend-shape weights per frame, in the mesh's shape order
    #: (:attr:`SkinnedMesh.blend_shapes`); ``(f, 0)`` when the mesh has none (the default)
    shape_weights: np.ndarray = None

    def __post_init__(self):
        t = np.ascontiguousarray(self.times, dtype=np.float64)
        m = np.ascontiguousarray(self.local, dtype=np.float64)
        w = np.zeros((len(t), 0)) if self.shape_weights is None else self.shape_weights
        w = np.ascontiguousarray(w, dtype=np.float64)
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "local", m)
        object.__setattr__(self, "shape_weights", w)
        _check(t.ndim == 1, f"clip {self.name!r} times shape", "(f,)", t.shape)
        _check(m.ndim == 4 and m.shape[0] == len(t) and m.shape[2:] == (4, 4),
               f"clip {self.name!r} local shape", f"({len(t)}, b, 4, 4)", m.shape)
        _check(w.ndim == 2 and w.shape[0] == len(t), f"clip {self.name!r} shape_weights shape", f"({len(t)}, S)",
               w.shape)

    @property
    def frame_count(self) -> int:
        return len(self.times)


@dataclass(frozen=True, eq=False)
class BlendShape:
    """One blend shape (morph target) as UsdSkel defines it (``UsdSkel.BlendShape``).

    Attributes
    ----------
    name : str
        The shape's name (unique within a mesh; ``skel:blendShapes`` / the clip weights' name).
    indices : (m,) int32
        The mesh points it moves (distinct; UsdSkel's ``pointIndices``).
    offsets : (m, 3) float32
        Mesh-space offsets of those points at weight 1.
    inbetweens : tuple of (float, (m, 3) float32)
        In-between shapes: ``(weight, offsets)`` at weights other than 0 and 1 (UsdSkel's
        ``inbetweens:*``), sorted by weight.  At weight ``w`` the shape moves its points by the
        piecewise-linear interpolation of the knots (0, 0), the in-betweens and (1, ``offsets``),
        extrapolated by the end segments (:class:`runtime.kernels.skin.Shapes`).
    """

    name: str
    indices: np.ndarray
    offsets: np.ndarray
    inbetweens: tuple = ()

    def __post_init__(self):
        i = np.ascontiguousarray(self.indices, dtype=np.int32).reshape(-1)
        o = np.ascontiguousarray(self.offsets, dtype=np.float32)
        object.__setattr__(self, "indices", i)
        object.__setattr__(self, "offsets", o)
        _check(o.shape == (len(i), 3), f"blend shape {self.name!r} offsets shape", (len(i), 3), o.shape)
        ib = tuple(sorted(((float(w), np.ascontiguousarray(x, dtype=np.float32)) for w, x in self.inbetweens),
                          key=lambda t: t[0]))
        object.__setattr__(self, "inbetweens", ib)
        for w, x in ib:
            _check(x.shape == (len(i), 3), f"blend shape {self.name!r} in-between {w} offsets shape", (len(i), 3),
                   x.shape)
        ws = [w for w, _ in ib]
        _check(len(set(ws + [0.0, 1.0])) == len(ws) + 2, f"blend shape {self.name!r} in-between weights",
               "distinct and neither 0 nor 1", ws)

    def knots(self):
        """``(weights (k,) float64 increasing, offsets (k, m, 3) float64)``: the rest (0), the
        in-betweens and the primary shape (1), sorted by weight."""
        pts = [(0.0, np.zeros((len(self.indices), 3))), (1.0, self.offsets.astype(np.float64))]
        pts += [(w, x.astype(np.float64)) for w, x in self.inbetweens]
        pts.sort(key=lambda t: t[0])
        return np.array([w for w, _ in pts]), np.stack([x for _, x in pts])

    def replace(self, **changes) -> "BlendShape":
        return replace(self, **changes)


def shape_table(shapes, point_count: int) -> np.ndarray:
    """(n, 3 K) float32: every vertex's offsets in every knot of every shape (0 where a shape does
    not move it): two vertices with equal rows move alike under every weight."""
    cols = []
    for s in shapes:
        for x in [s.offsets] + [o for _, o in s.inbetweens]:
            c = np.zeros((point_count, 3), dtype=np.float32)
            c[s.indices] = x
            cols.append(c)
    return np.concatenate(cols, axis=1) if cols else np.zeros((point_count, 0), dtype=np.float32)


def remap_shapes(shapes, old_to_new, new_count: int) -> tuple:
    """The shapes on a re-indexed mesh: old vertex ``v`` is new vertex ``old_to_new[v]`` (-1:
    dropped).  Where several old vertices become one, the first one's offsets are kept (callers
    merge only vertices whose offsets agree: :func:`shape_table`)."""
    out = []
    o2n = np.asarray(old_to_new, dtype=np.int64)
    for s in shapes:
        new = o2n[s.indices]
        live = new >= 0
        new_live = new[live]
        _, first = np.unique(new_live, return_index=True)
        first = np.sort(first)
        sel = np.flatnonzero(live)[first]
        out.append(BlendShape(s.name, o2n[s.indices[sel]], s.offsets[sel],
                              tuple((w, o[sel]) for w, o in s.inbetweens)))
    return tuple(out)


def transform_shapes(shapes, linear) -> tuple:
    """The shapes' offsets through the 3x3 ``linear`` map (points went through an affine map
    with this linear part: offsets, being differences, take the linear part only)."""
    A = np.asarray(linear, dtype=np.float64)
    mv = lambda o: (o.astype(np.float64) @ A.T).astype(np.float32)
    return tuple(BlendShape(s.name, s.indices, mv(s.offsets), tuple((w, mv(o)) for w, o in s.inbetweens))
                 for s in shapes)


def kernel_shapes(shapes, point_count: int):
    """The skinning pre-pass's layout (:class:`runtime.kernels.skin.Shapes`) of ``shapes``."""
    from colossus.runtime.kernels.skin import Shapes

    k = [s.knots() for s in shapes]
    return Shapes([s.name for s in shapes], [s.indices for s in shapes], [w for w, _ in k], [o for _, o in k],
                  point_count)


@dataclass(frozen=True, eq=False)
class Parts:
    """Per-bone collision parts (CSR layout: parts may overlap).

    Attributes
    ----------
    joints : (P,) int32
        Joint index of each part.
    face_offsets : (P + 1,) int32
        Faces of part ``p`` are ``faces[face_offsets[p]:face_offsets[p + 1]]``.
    faces : (sum,) int32
        Triangle indices.
    centers : (P, 3) float32
        Sphere centre of each part in its joint's space (zeros until ``spheres`` runs).
    radii : (P,) float32
        Sphere radius of each part (zeros until ``spheres`` runs).
    """

    joints: np.ndarray
    face_offsets: np.ndarray
    faces: np.ndarray
    centers: np.ndarray = None
    radii: np.ndarray = None

    def __post_init__(self):
        j = np.ascontiguousarray(self.joints, dtype=np.int32)
        P = len(j)
        object.__setattr__(self, "joints", j)
        object.__setattr__(self, "face_offsets", np.ascontiguousarray(self.face_offsets, dtype=np.int32))
        object.__setattr__(self, "faces", np.ascontiguousarray(self.faces, dtype=np.int32))
        c = np.zeros((P, 3)) if self.centers is None else self.centers
        r = np.zeros(P) if self.radii is None else self.radii
        object.__setattr__(self, "centers", np.ascontiguousarray(c, dtype=np.float32))
        object.__setattr__(self, "radii", np.ascontiguousarray(r, dtype=np.float32))
        _check(self.face_offsets.shape == (P + 1,), "parts face_offsets shape", (P + 1,), self.face_offsets.shape)
        _check(P == 0 or (self.face_offsets[0] == 0 and self.face_offsets[-1] == len(self.faces)
               and np.all(np.diff(self.face_offsets) >= 0)),
               "parts face_offsets", f"non-decreasing from 0 to {len(self.faces)}", self.face_offsets)
        _check(self.centers.shape == (P, 3), "parts centers shape", (P, 3), self.centers.shape)
        _check(self.radii.shape == (P,), "parts radii shape", (P,), self.radii.shape)

    def __len__(self) -> int:
        return len(self.joints)

    def part_faces(self, p: int) -> np.ndarray:
        """Triangle indices of part ``p``."""
        return self.faces[self.face_offsets[p]:self.face_offsets[p + 1]]


@dataclass(frozen=True, eq=False)
class SkinnedMesh:
    """A triangle mesh skinned to a skeleton, with every animation clip of the source.

    Attributes
    ----------
    positions : (n, 3) float32
        Vertex positions in mesh space (``geom_bind`` maps them to skeleton space).
    triangles : (m, 3) int32
        Vertex indices of each triangle, counter-clockwise seen from outside once oriented.
    joint_indices : (n, k) int32
        Influencing joints of each vertex (padding entries have weight 0).
    joint_weights : (n, k) float32
        Influence weights, matching ``joint_indices``.
    joint_names : tuple of str, length b
    parents : (b,) int32
        Parent joint index, -1 for roots.
    bind_transforms : (b, 4, 4) float64
        Joint-to-skeleton-space transform at bind time (UsdSkel ``bindTransforms``).
    rest_transforms : (b, 4, 4) float64
        Joint-local rest transforms (UsdSkel ``restTransforms``).
    geom_bind : (4, 4) float64
        Mesh space to skeleton space at bind time (UsdSkel ``geomBindTransform``).
    clips : tuple of Clip
    up_axis : {"Y", "Z"}
        Up axis of skeleton space.
    meters_per_unit : float
        Length of one skeleton-space unit in metres.
    time_codes_per_second : float
        Frame rate of the clip time codes.
    source : dict
        Provenance: file name, format, reader notes.
    parts : Parts or None
        Collision parts, once the ``parts`` stage has run.
    stored_clips : tuple of runtime.schema.Clip
        Once the ``quantize`` stage has run: each clip exactly as the asset stores it (TRS,
        rounded to the stored types, the roots without ``root_scale``), what the spheres are
        proven on and what ``write`` writes; empty before.
    root_scale : float
        The roots' common scale ``k`` (``quantize``), which the writer puts on the Skeleton prim.
    skinning_method : {"classicLinear", "dualQuaternion"}
        How the skin deforms (UsdSkel's ``primvars:skel:skinningMethod``): linear blend (the
        default) or dual-quaternion skinning exactly as UsdSkel does it
        (:mod:`runtime.kernels.skin`).  Only the USD reader sets ``dualQuaternion`` (glTF has no
        DQS; assimp files stay linear).
    blend_shapes : tuple of BlendShape
        The mesh's blend shapes (morph targets), applied to ``positions`` before skinning; each
        clip's ``shape_weights`` has one column per shape, in this order.
    """

    positions: np.ndarray
    triangles: np.ndarray
    joint_indices: np.ndarray
    joint_weights: np.ndarray
    joint_names: tuple
    parents: np.ndarray
    bind_transforms: np.ndarray
    rest_transforms: np.ndarray
    geom_bind: np.ndarray = field(default_factory=lambda: np.eye(4))
    clips: tuple = ()
    up_axis: str = "Y"
    meters_per_unit: float = 1.0
    time_codes_per_second: float = 24.0
    source: dict = field(default_factory=dict)
    parts: Parts | None = None
    stored_clips: tuple = ()
    root_scale: float = 1.0
    skinning_method: str = "classicLinear"
    blend_shapes: tuple = ()

    def __post_init__(self):
        conv = {
            "positions": np.float32, "triangles": np.int32, "joint_indices": np.int32,
            "joint_weights": np.float32, "parents": np.int32, "bind_transforms": np.float64,
            "rest_transforms": np.float64, "geom_bind": np.float64,
        }
        for name, dt in conv.items():
            object.__setattr__(self, name, np.ascontiguousarray(getattr(self, name), dtype=dt))
        object.__setattr__(self, "joint_names", tuple(str(n) for n in self.joint_names))
        object.__setattr__(self, "clips", tuple(self.clips))
        n, b = len(self.positions), len(self.joint_names)
        _check(self.positions.ndim == 2 and self.positions.shape[1] == 3, "positions shape", "(n, 3)", self.positions.shape)
        _check(self.triangles.ndim == 2 and self.triangles.shape[1] == 3, "triangles shape", "(m, 3)", self.triangles.shape)
        _check(self.joint_indices.ndim == 2 and self.joint_indices.shape[0] == n, "joint_indices shape", f"({n}, k)", self.joint_indices.shape)
        _check(self.joint_weights.shape == self.joint_indices.shape, "joint_weights shape", self.joint_indices.shape, self.joint_weights.shape)
        _check(self.parents.shape == (b,), "parents shape", (b,), self.parents.shape)
        _check(self.bind_transforms.shape == (b, 4, 4), "bind_transforms shape", (b, 4, 4), self.bind_transforms.shape)
        _check(self.rest_transforms.shape == (b, 4, 4), "rest_transforms shape", (b, 4, 4), self.rest_transforms.shape)
        _check(self.geom_bind.shape == (4, 4), "geom_bind shape", (4, 4), self.geom_bind.shape)
        _check(self.up_axis in ("Y", "Z"), "up_axis", "'Y' or 'Z'", self.up_axis)
        _check(self.skinning_method in SKINNING_METHODS, "skinning_method", " or ".join(SKINNING_METHODS),
               self.skinning_method)
        object.__setattr__(self, "blend_shapes", tuple(self.blend_shapes))
        S = len(self.blend_shapes)
        names = [s.name for s in self.blend_shapes]
        _check(len(set(names)) == S, "blend shape names", "unique", names)
        for s in self.blend_shapes:
            _check(not s.indices.size or (s.indices.min() >= 0 and s.indices.max() < n and
                                          len(np.unique(s.indices)) == len(s.indices)),
                   f"blend shape {s.name!r} indices", f"distinct, in [0, {n})", s.indices)
        clips = []
        for c in self.clips:
            _check(c.local.shape[1] == b, f"clip {c.name!r} joint count", b, c.local.shape[1])
            if c.shape_weights.shape[1] == 0 and S:  # a clip that animates no shape holds them at 0
                c = replace(c, shape_weights=np.zeros((c.frame_count, S)))
            _check(c.shape_weights.shape[1] == S, f"clip {c.name!r} shape weight count", S, c.shape_weights.shape[1])
            clips.append(c)
        object.__setattr__(self, "clips", tuple(clips))
        object.__setattr__(self, "stored_clips", tuple(self.stored_clips))
        _check(not self.stored_clips or [c.name for c in self.stored_clips] == [c.name for c in self.clips],
               "stored_clips", "none, or one per clip in order", [c.name for c in self.stored_clips])

    # -- convenience -------------------------------------------------------------------
    @property
    def vertex_count(self) -> int:
        return len(self.positions)

    @property
    def face_count(self) -> int:
        return len(self.triangles)

    @property
    def joint_count(self) -> int:
        return len(self.joint_names)

    def replace(self, **changes) -> "SkinnedMesh":
        """A copy with ``changes`` applied (the input is never mutated)."""
        return replace(self, **changes)

    def clip(self, name: str) -> Clip:
        for c in self.clips:
            if c.name == name:
                return c
        raise KeyError(name)


def skel_transforms(local: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """Compose joint-local transforms into skeleton-space transforms.

    Parameters
    ----------
    local : (..., b, 4, 4) float64
    parents : (b,) int, each parent index lower than its child (parents-first) or -1.
        Joints in any order are accepted; they are visited parents-first.

    Returns
    -------
    (..., b, 4, 4) float64
    """
    local = np.asarray(local, dtype=np.float64)
    out = np.empty_like(local)
    for j in parents_first(parents):
        p = parents[j]
        out[..., j, :, :] = local[..., j, :, :] if p < 0 else out[..., p, :, :] @ local[..., j, :, :]
    return out


def skin_points(mesh: SkinnedMesh, skel: np.ndarray, shape_weights=None) -> np.ndarray:
    """The mesh skinned by its own method (linear blend: a plain numpy reference; dual quaternion:
    the one kernel's UsdSkel DQS, :func:`runtime.kernels.skin.fold_dq`), its blend shapes applied
    first at ``shape_weights`` (UsdSkel's order: shapes, then skinning).

    Parameters
    ----------
    mesh : SkinnedMesh
    skel : (b, 4, 4) or (f, b, 4, 4) float64 skeleton-space joint transforms.
    shape_weights : (S,) or (f, S) float64, optional  (default: every shape at 0)

    Returns
    -------
    (n, 3) or (f, n, 3) float64 skinned points in skeleton space.
    """
    skel = np.asarray(skel, dtype=np.float64)
    single = skel.ndim == 3
    if single:
        skel = skel[None]
    inv_bind = np.linalg.inv(mesh.bind_transforms)
    points = mesh.positions
    if shape_weights is not None and len(mesh.blend_shapes):
        from colossus.runtime.kernels import skin as SK
        S = len(mesh.blend_shapes)
        W = np.broadcast_to(np.asarray(shape_weights, dtype=np.float64).reshape(-1, S), (len(skel), S))
        points = SK.shape_points(mesh.positions, kernel_shapes(mesh.blend_shapes, mesh.vertex_count), W)
    if mesh.skinning_method != "classicLinear":
        from colossus.runtime.kernels import skin as SK
        out = SK.skin_frames(points, mesh.joint_indices, mesh.joint_weights,
                             SK.fold_method(mesh.skinning_method, skel @ inv_bind, mesh.geom_bind), dtype=np.float64)
        return out[0] if single else out
    pts = np.broadcast_to(points, (len(skel), mesh.vertex_count, 3))
    out = np.zeros((len(skel), mesh.vertex_count, 3))
    for f in range(len(skel)):
        p = np.c_[pts[f].astype(np.float64), np.ones(mesh.vertex_count)] @ mesh.geom_bind.T
        m = skel[f] @ inv_bind  # (b, 4, 4)
        for k in range(mesh.joint_indices.shape[1]):
            w = mesh.joint_weights[:, k].astype(np.float64)
            mk = m[mesh.joint_indices[:, k]]  # (n, 4, 4)
            out[f] += w[:, None] * np.einsum("nij,nj->ni", mk[:, :3, :], p)
    return out[0] if single else out
