"""UsdSkel's own skinning of a USD source, as an independent motion reference.

Everything is computed by usd-core: ``UsdSkel.Cache`` resolves the bindings,
``SkelQuery.ComputeSkinningTransforms`` gives the skinning transforms at a time code,
``SkinningQuery.ComputeSkinnedPoints`` skins point-based prims (linear blend skinning, the
``skel:geomBindTransform`` applied), and ``SkinningQuery.ComputeSkinnedTransform`` gives the
transform of a rigidly bound prim (constant ``jointIndices``/``jointWeights`` interpolation).
UsdSkel's skinned results are in skeleton space; the skeleton prim's local-to-world transform
takes them to world space, which is what ``UsdSkel.BakeSkinning`` writes (into each prim's own
space).  A test checks this module against Pixar's baked result of ``openusd_lbs.usda``.

World space here is the stage's own (its ``upAxis``, ``metersPerUnit``); times are the stage's
time codes (seconds = time code / ``timeCodesPerSecond``).  Matrices are float64 column-vector
(``p' = M @ p``); pxr's row-vector matrices are transposed on the way in.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np
from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt


def _m44(m) -> np.ndarray:
    """Gf.Matrix4d (row-vector) -> (4, 4) float64 column-vector."""
    return np.array(m, dtype=np.float64).reshape(4, 4).T


def _apply(m, p):
    return p @ m[:3, :3].T + m[:3, 3]


@dataclass(frozen=True)
class Target:
    """One prim the reference evaluates.

    Attributes
    ----------
    path : str
        Prim path.
    type_name : str
        ``Mesh``, ``BasisCurves``, ``Sphere``, ...
    kind : str
        ``"skinned"`` (per-vertex influences), ``"rigid"`` (constant influences: moves as one
        body with its joints) or ``"static"`` (an unbound Mesh; shown for completeness).
    skeleton : str or None
        Skeleton prim path of a bound prim.
    vertex_count : int
        Points of a point-based prim; 0 for an implicit gprim (``Sphere``, ``Cube``...).
    used : (vertex_count,) bool
        Points referenced by a Mesh's faces (all for other point-based prims).
    """

    path: str
    type_name: str
    kind: str
    skeleton: str | None
    vertex_count: int
    used: np.ndarray = field(repr=False)

    @property
    def is_mesh(self) -> bool:
        return self.type_name == "Mesh"


class UsdSkelReference:
    """Posed world-space points of every skinned/rigid prim of a USD file, by UsdSkel.

    Parameters
    ----------
    path : str or PathLike
        Any USD file (``.usda``, ``.usdc``, ``.usdz``).

    Attributes
    ----------
    targets : list of Target
    up_axis : str
    meters_per_unit, time_codes_per_second : float
    animations : list of str
        SkelAnimation prim paths bound as some skeleton's ``skel:animationSource``, in the
        order the skeletons are found.
    unbound_animations : list of str
        SkelAnimation prims no skeleton binds (UsdSkel never plays them).
    """

    def __init__(self, path):
        self.path = os.fspath(path)
        self.stage = Usd.Stage.Open(self.path, Usd.Stage.LoadAll)
        if self.stage is None:
            raise ValueError(f"{self.path}: not a USD stage")
        st = self.stage
        self.up_axis = str(UsdGeom.GetStageUpAxis(st))
        self.meters_per_unit = float(UsdGeom.GetStageMetersPerUnit(st))
        self.time_codes_per_second = float(st.GetTimeCodesPerSecond())
        self._cache = UsdSkel.Cache()
        pred = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
        self._entries = []  # (Target, skel_query or None, skinning_query or None, prim)
        self._skels = {}
        bound_prims = set()
        for prim in st.Traverse(pred):
            if not prim.IsA(UsdSkel.Root):
                continue
            root = UsdSkel.Root(prim)
            self._cache.Populate(root, pred)
            for binding in self._cache.ComputeSkelBindings(root, pred):
                skel = binding.GetSkeleton()
                sq = self._cache.GetSkelQuery(skel)
                spath = str(skel.GetPrim().GetPath())
                self._skels[spath] = sq
                for q in binding.GetSkinningTargets():
                    p = q.GetPrim()
                    if not q.HasJointInfluences():
                        continue
                    bound_prims.add(p.GetPath())
                    self._entries.append((self._target(p, "rigid" if q.IsRigidlyDeformed() else "skinned", spath), sq, q, p))
        for prim in st.Traverse(pred):
            if prim.IsA(UsdGeom.Mesh) and prim.GetPath() not in bound_prims:
                self._entries.append((self._target(prim, "static", None), None, None, prim))
        self.targets = [e[0] for e in self._entries]
        self.animations = []
        for sq in self._skels.values():
            aq = sq.GetAnimQuery()
            if aq and str(aq.GetPrim().GetPath()) not in self.animations:
                self.animations.append(str(aq.GetPrim().GetPath()))
        self.unbound_animations = [str(p.GetPath()) for p in st.Traverse(pred)
                                   if p.IsA(UsdSkel.Animation) and str(p.GetPath()) not in self.animations]

    @staticmethod
    def _target(prim, kind, skel):
        n, used = 0, np.zeros(0, dtype=bool)
        if prim.IsA(UsdGeom.PointBased):
            pts = UsdGeom.PointBased(prim).GetPointsAttr().Get(Usd.TimeCode.EarliestTime())
            n = len(pts) if pts is not None else 0
            used = np.ones(n, dtype=bool)
            if prim.IsA(UsdGeom.Mesh):
                idx = UsdGeom.Mesh(prim).GetFaceVertexIndicesAttr().Get()
                used[:] = False
                if idx is not None and len(idx):
                    i = np.asarray(idx, dtype=np.int64)
                    used[i[(i >= 0) & (i < n)]] = True
        return Target(str(prim.GetPath()), str(prim.GetTypeName()), kind, skel, n, used)

    # ------------------------------------------------------------------------------- times
    def key_times(self) -> np.ndarray:
        """Sorted union of the time samples of every bound animation's joint transforms, and of
        the skeletons' (and their ancestors') transforms (time codes, float64)."""
        times = set()
        for sq in self._skels.values():
            aq = sq.GetAnimQuery()
            if aq:
                times.update(aq.GetJointTransformTimeSamples())
            prim = sq.GetPrim()
            while prim and not prim.IsPseudoRoot():
                if prim.IsA(UsdGeom.Xformable):
                    times.update(UsdGeom.Xformable(prim).GetTimeSamples())
                prim = prim.GetParent()
        return np.array(sorted(times), dtype=np.float64)

    # ------------------------------------------------------------------------------- posing
    def _points(self, prim, time):
        pts = UsdGeom.PointBased(prim).GetPointsAttr().Get(time)
        return Vt.Vec3fArray(pts) if pts is not None else Vt.Vec3fArray()

    def pose(self, time, at_bind: bool = False) -> list:
        """World-space points of every target at time code ``time``.

        Parameters
        ----------
        time : float
            Stage time code.
        at_bind : bool
            Pose with identity skinning transforms (every joint at its ``bindTransforms``), i.e.
            the bind pose UsdSkel skins from.

        Returns
        -------
        list of (vertex_count, 3) float64 (an implicit gprim gives ``(0, 3)``), one per target.
        """
        tc = Usd.TimeCode(time)
        xf = UsdGeom.XformCache(tc)
        out, skin_xf = [], {}
        for target, sq, q, prim in self._entries:
            if target.kind == "static":
                out.append(_apply(_m44(xf.GetLocalToWorldTransform(prim)), np.asarray(self._points(prim, tc), dtype=np.float64).reshape(-1, 3)))
                continue
            key = target.skeleton
            if key not in skin_xf:
                if at_bind:
                    nj = len(sq.GetJointOrder())
                    skin_xf[key] = Vt.Matrix4dArray([Gf.Matrix4d(1.0)] * nj)
                else:
                    skin_xf[key] = sq.ComputeSkinningTransforms(tc)
            skel_w = _m44(xf.GetLocalToWorldTransform(sq.GetPrim()))
            if target.kind == "rigid":
                m = q.ComputeSkinnedTransform(skin_xf[key], tc)
                if m is None:
                    raise ValueError(f"{self.path}: UsdSkel cannot skin {target.path} at {time}")
                gm = skel_w @ _m44(m)  # gprim space -> skel space -> world
                pts = np.asarray(self._points(prim, tc), dtype=np.float64).reshape(-1, 3) if target.vertex_count else np.zeros((0, 3))
                out.append(_apply(gm, pts))
            else:
                pts = self._points(prim, tc)
                if not at_bind:
                    apply_blend_shapes(sq, q, pts, tc)
                if not q.ComputeSkinnedPoints(skin_xf[key], pts, tc):
                    raise ValueError(f"{self.path}: UsdSkel cannot skin {target.path} at {time}")
                out.append(_apply(skel_w, np.asarray(pts, dtype=np.float64).reshape(-1, 3)))
        return out

    def rigid_transforms(self, time) -> dict:
        """``{path: (4, 4) float64}`` world transform of every rigidly bound prim at ``time``
        (UsdSkel's skinned transform, then the skeleton's local-to-world)."""
        tc = Usd.TimeCode(time)
        xf = UsdGeom.XformCache(tc)
        out = {}
        for target, sq, q, prim in self._entries:
            if target.kind != "rigid":
                continue
            m = q.ComputeSkinnedTransform(sq.ComputeSkinningTransforms(tc), tc)
            out[target.path] = _m44(xf.GetLocalToWorldTransform(sq.GetPrim())) @ _m44(m)
        return out


def apply_blend_shapes(sq, q, pts, tc):
    """UsdSkel's blend shapes on ``pts`` (a Vt.Vec3fArray, in place) at time code ``tc``: the
    skeleton's animation's ``blendShapeWeights`` mapped to the prim's ``skel:blendShapes``
    (``SkinningQuery.GetBlendShapeMapper``), then ``BlendShapeQuery``'s sub-shape weights and
    ``ComputeDeformedPoints`` (what ``UsdSkel.BakeSkinning`` does before skinning).  No-op when the
    prim binds no shapes or the skeleton has no animation."""
    if not q.HasBlendShapes():
        return pts
    aq = sq.GetAnimQuery()
    if not aq:
        return pts
    w = aq.ComputeBlendShapeWeights(tc)
    mapper = q.GetBlendShapeMapper()
    if mapper:
        w = mapper.Remap(w)
    bq = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(q.GetPrim()))
    sw, bi, si = bq.ComputeSubShapeWeights(w)
    bq.ComputeDeformedPoints(sw, bi, si, bq.ComputeBlendShapePointIndices(), bq.ComputeSubShapePointOffsets(), pts)
    return pts


def load(path) -> UsdSkelReference:
    return UsdSkelReference(path)


def baked_pose(path, time) -> dict:
    """World-space points and transforms of a stage as it stands (e.g. a ``BakeSkinning`` result).

    Returns
    -------
    dict
        ``{prim path: (n, 3) float64 points}`` for point-based prims and
        ``{prim path: (4, 4) float64 local-to-world}`` for implicit gprims, at time code ``time``.
    """
    stage = Usd.Stage.Open(os.fspath(path))
    tc = Usd.TimeCode(time)
    xf = UsdGeom.XformCache(tc)
    out = {}
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Gprim):
            continue
        w = _m44(xf.GetLocalToWorldTransform(prim))
        if prim.IsA(UsdGeom.PointBased):
            pts = UsdGeom.PointBased(prim).GetPointsAttr().Get(tc)
            out[str(prim.GetPath())] = _apply(w, np.asarray(pts, dtype=np.float64).reshape(-1, 3))
        else:
            out[str(prim.GetPath())] = w
    return out
