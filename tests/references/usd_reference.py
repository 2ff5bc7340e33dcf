"""Plain usd-core references for a collider asset: posed points, joint transforms and the part
spheres' distances, computed the way any UsdSkel consumer reads the file.

Nothing here imports project code: the asset is read with ``pxr`` (``UsdSkel.SkinningQuery``
and ``UsdSkel.SkeletonQuery``) and the contract's attribute names, so the runtime and the
validators can be judged against it.  Edits needed to choose a clip (the skeleton's
``skel:animationSource``) go to each reference's own session layer, never to the file's layer,
which other readers of the same file share.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pxr import Usd, UsdGeom, UsdSkel, Vt


class UsdSkelReference:
    """Plain usd-core skinning of the asset's collider mesh, in stage space.

    ``use_clip(name)`` binds that SkelAnimation (``None``: no animation, the rest pose); then
    ``points(t)`` (V, 3) float64 stage-space skinned points, ``skel_transforms(t)`` (J, 4, 4) and
    ``joint_world(t)`` (J, 4, 4) joint-to-stage transforms, ``local_to_world(t)`` (4, 4) the
    Skeleton prim's; all column-vector, the project's convention (``p' = M @ p``; USD hands
    numpy the row-vector transpose)."""

    def __init__(self, path):
        self.stage = Usd.Stage.Open(str(path))
        self.stage.SetEditTarget(self.stage.GetSessionLayer())
        prims = list(self.stage.Traverse())
        dp = self.stage.GetDefaultPrim()
        self.root = UsdSkel.Root(dp if dp.IsA(UsdSkel.Root) else next(p for p in prims if p.IsA(UsdSkel.Root)))
        self.skel = next(UsdSkel.Skeleton(p) for p in prims if p.IsA(UsdSkel.Skeleton))
        self.mesh = next(p for p in prims if p.IsA(UsdGeom.Mesh))
        self.rest = Vt.Vec3fArray(self.mesh.GetAttribute("points").Get())
        # clips: the SkelAnimation prims (the contract puts them under the SkelRoot; Blender's
        # USD export under the Skeleton), in file order
        self._anims = {p.GetName(): p for p in prims if p.IsA(UsdSkel.Animation)}
        self.clips = list(self._anims)
        self._populate()

    def use_clip(self, clip):
        rel = UsdSkel.BindingAPI(self.skel.GetPrim()).GetAnimationSourceRel()
        rel.SetTargets([] if clip is None else [self._anims[clip].GetPath()])
        return self._populate()

    def _populate(self):
        self.cache = UsdSkel.Cache()
        self.cache.Populate(self.root, Usd.TraverseInstanceProxies())
        self.sq = self.cache.GetSkelQuery(self.skel)
        self.skq = self.cache.GetSkinningQuery(self.mesh)
        return self

    def times(self, clip):
        """(f,) the clip's time samples (its frames)."""
        anim = self._anims[clip]
        return np.array(sorted(set().union(*(a.GetTimeSamples() for a in anim.GetAttributes()))), dtype=np.float64)

    def local_to_world(self, t):
        return np.asarray(UsdGeom.Imageable(self.skel.GetPrim()).ComputeLocalToWorldTransform(t)).T

    def points(self, t):
        pts = Vt.Vec3fArray(self.rest)
        assert self.skq.ComputeSkinnedPoints(self.sq.ComputeSkinningTransforms(t), pts, t)
        m = self.local_to_world(t)
        return np.asarray(pts, dtype=np.float64) @ m[:3, :3].T + m[:3, 3]

    def skel_transforms(self, t):
        return np.asarray(self.sq.ComputeJointSkelTransforms(t)).transpose(0, 2, 1)

    def joint_world(self, t):
        return self.local_to_world(t) @ self.skel_transforms(t)

    def model_size(self):
        """Diagonal of the bind-pose bounding box in stage space (geomBind and the skeleton's
        transform applied), the validators' and the contract's "model size"."""
        m = self.local_to_world(Usd.TimeCode.Default()) @ np.asarray(self.skq.GetGeomBindTransform()).T
        p = np.asarray(self.rest, dtype=np.float64) @ m[:3, :3].T + m[:3, 3]
        return float(np.linalg.norm(p.max(0) - p.min(0)))


@dataclass
class Parts:
    """The contract's part attributes, read with plain pxr.

    joints (P,) joint index in the skeleton, centers (P, 3) float64 joint space, radii (P,),
    offsets (P + 1,), faces (sum,), triangles (F, 3), vertices: list of P arrays (the distinct
    vertices of each part's faces), first_part (F,) the lowest part holding each face (-1: none),
    face_count (F,) how many parts hold each face."""

    joints: np.ndarray
    centers: np.ndarray
    radii: np.ndarray
    offsets: np.ndarray
    faces: np.ndarray
    triangles: np.ndarray
    vertices: list
    first_part: np.ndarray
    face_count: np.ndarray


def read_parts(stage_or_path) -> Parts:
    stage = stage_or_path if isinstance(stage_or_path, Usd.Stage) else Usd.Stage.Open(str(stage_or_path))
    skel = next(UsdSkel.Skeleton(p) for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton))
    mesh = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    names = [str(j) for j in skel.GetJointsAttr().Get()]
    joints = np.array([names.index(j) for j in mesh.GetAttribute("colossus:parts:joints").Get()])
    offsets = np.array(mesh.GetAttribute("colossus:parts:faceOffsets").Get(), dtype=np.int64)
    faces = np.array(mesh.GetAttribute("colossus:parts:faces").Get(), dtype=np.int64)
    tris = np.array(mesh.GetAttribute("faceVertexIndices").Get(), dtype=np.int64).reshape(-1, 3)
    first = np.full(len(tris), -1)
    for p in range(len(joints) - 1, -1, -1):  # lowest part last, so it wins
        first[faces[offsets[p]:offsets[p + 1]]] = p
    return Parts(joints=joints,
                 centers=np.array(mesh.GetAttribute("colossus:parts:centers").Get(), dtype=np.float64),
                 radii=np.array(mesh.GetAttribute("colossus:parts:radii").Get(), dtype=np.float64),
                 offsets=offsets, faces=faces, triangles=tris,
                 vertices=[np.unique(tris[faces[offsets[p]:offsets[p + 1]]]) for p in range(len(joints))],
                 first_part=first, face_count=np.bincount(faces, minlength=len(tris)))


@dataclass
class ClipDistances:
    """Per frame of one clip and per part: the farthest part vertex from the part's moving centre.

    times (f,), distance (f, P) stage units, vertex (f, P) its index, scale (f, P) the largest
    axis scale of the part joint's joint-to-stage transform (the contract's radius multiplier),
    world_radius (f, P) = radius x scale, centers (f, P, 3) the moving centres, points (f, V, 3)
    the skinned points (stage space)."""

    times: np.ndarray
    distance: np.ndarray
    vertex: np.ndarray
    scale: np.ndarray
    world_radius: np.ndarray
    centers: np.ndarray
    points: np.ndarray

    @property
    def excess(self):
        """(f, P) distance - world radius: > 0 where a vertex is outside its sphere."""
        return self.distance - self.world_radius


def part_distances(path, radii=None):
    """``({clip: ClipDistances}, parts, model_size)`` for every clip of the asset at ``path``,
    skinned by usd-core at every frame; ``radii`` (P,) replaces the stored radii if given."""
    ref = UsdSkelReference(path)
    parts = read_parts(ref.stage)
    radii = parts.radii if radii is None else np.asarray(radii, dtype=np.float64)
    out = {}
    for clip in ref.clips:
        ref.use_clip(clip)
        times = ref.times(clip)
        P = len(parts.joints)
        D, V, S = np.zeros((len(times), P)), np.zeros((len(times), P), dtype=np.int64), np.zeros((len(times), P))
        C = np.zeros((len(times), P, 3))
        X = np.zeros((len(times), len(ref.rest), 3))
        for f, t in enumerate(times):
            X[f] = pts = ref.points(t)
            jw = ref.joint_world(t)
            for p, j in enumerate(parts.joints):
                C[f, p] = c = (jw[j] @ np.append(parts.centers[p], 1.0))[:3]
                d = np.linalg.norm(pts[parts.vertices[p]] - c, axis=1)
                D[f, p] = d.max()
                V[f, p] = parts.vertices[p][d.argmax()]
                S[f, p] = np.linalg.norm(jw[j][:3, :3], axis=0).max()  # largest axis scale (columns)
        out[clip] = ClipDistances(times, D, V, S, S * radii, C, X)
    return out, parts, ref.model_size()


def tightest(distances) -> np.ndarray:
    """(P,) the smallest joint-space radius that holds on every frame of every clip."""
    return np.max([(c.distance / c.scale).max(0) for c in distances.values()], axis=0)
