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

    def __post_init__(self):
        t = np.ascontiguousarray(self.times, dtype=np.float64)
        m = np.ascontiguousarray(self.local, dtype=np.float64)
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "local", m)
        _check(t.ndim == 1, f"clip {self.name!r} times shape", "(f,)", t.shape)
        _check(m.ndim == 4 and m.shape[0] == len(t) and m.shape[2:] == (4, 4),
               f"clip {self.name!r} local shape", f"({len(t)}, b, 4, 4)", m.shape)

    @property
    def frame_count(self) -> int:
        return len(self.times)


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
        for c in self.clips:
            _check(c.local.shape[1] == b, f"clip {c.name!r} joint count", b, c.local.shape[1])
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


def skin_points(mesh: SkinnedMesh, skel: np.ndarray) -> np.ndarray:
    """The mesh skinned by its own method (linear blend: a plain numpy reference; dual quaternion:
    the one kernel's UsdSkel DQS, :func:`runtime.kernels.skin.fold_dq`).

    Parameters
    ----------
    mesh : SkinnedMesh
    skel : (b, 4, 4) or (f, b, 4, 4) float64 skeleton-space joint transforms.

    Returns
    -------
    (n, 3) or (f, n, 3) float64 skinned points in skeleton space.
    """
    skel = np.asarray(skel, dtype=np.float64)
    single = skel.ndim == 3
    if single:
        skel = skel[None]
    inv_bind = np.linalg.inv(mesh.bind_transforms)
    if mesh.skinning_method != "classicLinear":
        from colossus.runtime.kernels import skin as SK
        out = SK.skin_frames(mesh.positions, mesh.joint_indices, mesh.joint_weights,
                             SK.fold_method(mesh.skinning_method, skel @ inv_bind, mesh.geom_bind), dtype=np.float64)
        return out[0] if single else out
    p = np.c_[mesh.positions.astype(np.float64), np.ones(mesh.vertex_count)] @ mesh.geom_bind.T
    out = np.zeros((len(skel), mesh.vertex_count, 3))
    for f in range(len(skel)):
        m = skel[f] @ inv_bind  # (b, 4, 4)
        for k in range(mesh.joint_indices.shape[1]):
            w = mesh.joint_weights[:, k].astype(np.float64)
            mk = m[mesh.joint_indices[:, k]]  # (n, 4, 4)
            out[f] += w[:, None] * np.einsum("nij,nj->ni", mk[:, :3, :], p)
    return out[0] if single else out
