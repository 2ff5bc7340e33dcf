"""Skin a colossus asset with plain usd-core and compare its motion with an independent reference.

The asset side uses only usd-core: ``UsdSkel.Cache``, the skeleton's
``ComputeSkinningTransforms`` and ``SkinningQuery.ComputeSkinnedPoints`` at a time code, then
the skeleton prim's local-to-world transform.  A clip other than the bound one is played by
re-binding the skeleton's ``skel:animationSource`` in the stage's session layer (in memory; the
file is never written).

The reference side is :mod:`.gltf_eval` (glTF/GLB), :mod:`.usd_eval` (USD) or
:mod:`.fbx_truth` (the ufbx FBX files with Maya truth).

Mapping (``shared/CONTRACT.md``)
--------------------------------
* Time: the asset's time code of source instant ``s`` seconds is ``s * timeCodesPerSecond``
  (the source's time zero kept).  For a USD source ``s = timeCode / source timeCodesPerSecond``.
* Clips: one SkelAnimation per source animation, named as the source's (FBX ``Armature|walk``
  -> ``walk``; unnamed glTF animations ``animation_0``, ...), made a valid USD identifier
  (``idle.001`` -> ``idle_001``, as ``Tf.MakeValidIdentifier`` does).  A clip missing by name is
  compared by position and reported as a name mismatch.
* Space: the reference is converted into the asset's ``upAxis`` and ``metersPerUnit``.
* Vertices: the asset is welded and may merge, drop or reorder vertices, so each reference
  vertex is matched to the asset vertex at the same rest (bind) position with a KD-tree (up to
  :data:`CANDIDATES` asset vertices within ``MATCH_TOL x`` the rest model size).  Where several
  asset vertices share that rest position (a seam between separately skinned parts), the one
  whose motion agrees best over the compared instants is taken, and the count is reported as
  ``ambiguous``.  A reference vertex with no asset vertex that close is MISSING.  The reference
  may offer more than one rest hypothesis (glTF: the bind pose of the skins, and the scene as
  written); per source mesh the one that matches more vertices is used.
* Error: ``max |asset - reference| / model size`` over matched vertices and instants; model size
  = the diagonal of the bounding box of the reference's moving meshes in their pose as written
  (glTF: the nodes as written; USD: the bind pose; FBX: the bind pose), in asset units.
  The issue calls it the bind-pose box; the pose as written is used for glTF because some files
  (lumberjack, quad_skin, RobotExpressive's hands) are bound at 100x their shown size.

Instants: every source key time and every midpoint between consecutive keys, subsampled evenly
to at most ``max_instants / 2`` of each per clip (the FBX truth: its frames only).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np
from pxr import Gf, Tf, Usd, UsdGeom, UsdSkel, Vt
from scipy.spatial import cKDTree

from . import fbx_truth, gltf_eval, usd_eval

#: the issue's motion tolerance, x model size
TOL = 1e-4
#: the issue's bound for clips whose keys are off any regular grid, x model size
OFF_GRID_TOL = 1e-3
#: a reference vertex with no asset vertex this close at rest (x rest model size) is missing
MATCH_TOL = 1e-4
#: a key is on the asset's grid when key * timeCodesPerSecond is this close to an integer (frames)
GRID_TOL = 1e-3
#: asset vertices considered per reference vertex
CANDIDATES = 4
#: default cap on compared instants per clip (half keys, half mid-keys)
MAX_INSTANTS = 40


class NoReference(Exception):
    """The source's format has no independent reference here."""


def axis_scale(src_up: str, src_mpu: float, dst_up: str, dst_mpu: float) -> np.ndarray:
    """(4, 4) float64 taking points of a ``src_up``-up space of ``src_mpu`` metres per unit to a
    ``dst_up``-up space of ``dst_mpu`` (right-handed; a rotation about X between Y-up and Z-up)."""
    r = np.eye(4)
    if (src_up, dst_up) == ("Z", "Y"):
        r[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]  # (x, y, z) -> (x, z, -y)
    elif (src_up, dst_up) == ("Y", "Z"):
        r[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # (x, y, z) -> (x, -z, y)
    elif src_up != dst_up:
        raise ValueError(f"unsupported up axes {src_up} -> {dst_up}")
    r[:3, :3] *= float(src_mpu) / float(dst_mpu)
    return r


def _apply(m, p):
    return np.asarray(p, dtype=np.float64) @ m[:3, :3].T + m[:3, 3]


def _diag(points) -> float:
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return 1.0
    d = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
    return d if d > 0 else 1.0


def _subsample(a, n):
    a = np.asarray(a, dtype=np.float64)
    if n <= 0:
        return a[:0]
    if len(a) <= n:
        return a
    return a[np.unique(np.round(np.linspace(0, len(a) - 1, n)).astype(int))]


# =============================================================================== references
@dataclass
class RefMesh:
    """A source mesh of the reference: ``kind`` is skinned / rigid / static; ``used`` marks the
    vertices its faces draw."""

    key: str
    label: str
    kind: str
    used: np.ndarray = field(repr=False)

    @property
    def moves(self) -> bool:
        return self.kind in ("skinned", "rigid")


@dataclass
class RefClip:
    """A source clip: ``keys`` in seconds; ``mids`` False when only the keys have truth."""

    name: str
    keys: np.ndarray
    interpolation: str
    mids: bool = True


class Reference:
    """What :func:`compare` needs from a source: meshes, clips, rest hypotheses and poses."""

    format = ""
    up_axis = "Y"
    meters_per_unit = 1.0
    meshes: list
    clips: list
    notes: list

    def rest_hypotheses(self):  # -> [(label, [array per mesh])]
        raise NotImplementedError

    def shown_pose(self):  # -> [array per mesh], for the model size
        raise NotImplementedError

    def pose(self, clip: int, seconds: float):  # -> [array per mesh]
        raise NotImplementedError

    def poses(self, clip: int, seconds):  # -> [[array per mesh] per instant]
        return [self.pose(clip, s) for s in seconds]


class GltfReference(Reference):
    """glTF/GLB by :mod:`.gltf_eval` (weights normalised, as the importer must do)."""

    format = "glTF"

    def __init__(self, path):
        self.doc = gltf_eval.load(path)
        self.meshes, self.notes = [], []
        for p in self.doc.primitives:
            if p.mode not in gltf_eval.TRIANGLE_MODES:
                self.notes.append(f"{p.key}: mode {p.mode} draws no triangles; not compared")
                continue
            kind = "skinned" if p.skinned else ("rigid" if self.doc.moves_with_skeleton(p) else "static")
            self.meshes.append(RefMesh(p.key, p.mesh_name, kind, p.used))
        self._prims = [p for p in self.doc.primitives if p.mode in gltf_eval.TRIANGLE_MODES]
        self._keep = [i for i, p in enumerate(self.doc.primitives) if p.mode in gltf_eval.TRIANGLE_MODES]
        self.clips = []
        morph = [a.name for a in self.doc.animations if a.morph_channels]
        for a in self.doc.animations:
            self.clips.append(RefClip(a.name, a.key_times, "/".join(a.interpolations) or "-"))
        if morph:
            self.notes.append(f"{len(morph)} animations have morph-weight channels (applied: {', '.join(morph[:3])}"
                              f"{', ...' if len(morph) > 3 else ''})")
        for p in self._prims:
            lo, hi = p.weight_sum_range
            if p.skinned and (abs(lo - 1) > 1e-3 or abs(hi - 1) > 1e-3):
                self.notes.append(f"{p.key}: weight sums {lo:.3f}..{hi:.3f} (compared normalised)")
        shaped = [p.key for p in self._prims if p.morph_targets and np.any(self.doc.default_morph_weights(p) != 0)]
        if shaped:
            self.notes.append(f"non-zero default morph weights (applied): {', '.join(shaped)}")
        _, conflicts = self.doc.bind_world()
        if conflicts:
            self.notes.append(f"{conflicts} joints have different inverse binds in different skins")

    def _pick(self, arrays):
        return [arrays[i] for i in self._keep]

    def rest_hypotheses(self):
        return [("bind", self._pick(self.doc.bind_pose())), ("as-written", self._pick(self.doc.pose(None, 0.0)))]

    def shown_pose(self):
        return self._pick(self.doc.pose(None, 0.0))

    def pose(self, clip, seconds):
        return self._pick(self.doc.pose(clip, seconds))

    def poses(self, clip, seconds):
        return [self._pick(p) for p in self.doc.poses(clip, seconds)]


class UsdReference(Reference):
    """USD by :mod:`.usd_eval` (UsdSkel's own skinning).

    Several skeletons that each bind their own animation play together: they form one clip,
    named after the first skeleton's animation."""

    format = "USD"

    def __init__(self, path):
        self.ref = usd_eval.load(path)
        r = self.ref
        self.up_axis, self.meters_per_unit = r.up_axis, r.meters_per_unit
        self.tcps = r.time_codes_per_second
        self.meshes, self.notes, self._keep = [], [], []
        for i, t in enumerate(r.targets):
            if not t.is_mesh:
                if t.kind != "static":
                    self.notes.append(f"{t.path}: {t.kind} {t.type_name} is not a mesh; not compared")
                continue
            self.meshes.append(RefMesh(t.path, t.path.rsplit("/", 1)[-1], t.kind, t.used))
            self._keep.append(i)
        keys = r.key_times()
        self.clips = []
        if r.animations and len(keys):
            name = r.animations[0].rsplit("/", 1)[-1]
            if len(r.animations) > 1:
                self.notes.append(f"{len(r.animations)} skeletons play their own animations together: one clip {name!r}")
            self.clips.append(RefClip(name, keys / self.tcps, "UsdSkel (lerp/slerp)"))
        if r.unbound_animations:
            self.notes.append(f"unbound SkelAnimations (never played): {', '.join(r.unbound_animations)}")
        t0 = float(keys[0]) if len(keys) else Usd.TimeCode.EarliestTime().GetValue()
        self._t0 = t0

    def _pick(self, arrays):
        return [arrays[i] for i in self._keep]

    def rest_hypotheses(self):
        return [("bind", self._pick(self.ref.pose(self._t0, at_bind=True)))]

    def shown_pose(self):
        return self.rest_hypotheses()[0][1]

    def pose(self, clip, seconds):
        return self._pick(self.ref.pose(seconds * self.tcps))


class FbxTruthReference(Reference):
    """The ufbx FBX files by :mod:`.fbx_truth` (Maya's deformed OBJs; keys = the truth frames)."""

    format = "FBX"

    def __init__(self, path):
        self.truth = fbx_truth.load(path)
        t = self.truth
        self.up_axis, self.meters_per_unit = t.up_axis, t.meters_per_unit
        self.meshes = [RefMesh(t.mesh_name or "mesh", t.mesh_name or "mesh", "skinned", t.used)]
        self.notes = []
        if t.rest_spread > 1e-6 * _diag(t.rest):
            self.notes.append(f"skin clusters disagree on the mesh's bind transform by {t.rest_spread:g}")
        names = list(dict.fromkeys(f.clip for f in t.frames))
        # the contract's clip name: FBX "Armature|walk" -> "walk"
        self.clips = [RefClip(n.split("|")[-1], np.array([f.seconds for f in t.frames if f.clip == n]), "Maya", mids=False)
                      for n in names]
        self._stack = {n.split("|")[-1]: n for n in names}

    def rest_hypotheses(self):
        return [("bind", [self.truth.rest])]

    def shown_pose(self):
        return [self.truth.rest]

    def pose(self, clip, seconds):
        name = self._stack[self.clips[clip].name]
        for f in self.truth.frames:
            if f.clip == name and abs(f.seconds - seconds) < 1e-9:
                return [self.truth.pose(f)]
        raise ValueError(f"no Maya truth for clip {name!r} at {seconds} s")


def reference_for(path) -> Reference:
    """The independent reference of a source file (raises :class:`NoReference` when none)."""
    name = os.path.basename(os.fspath(path)).lower()
    if name.endswith((".gltf", ".glb")):
        return GltfReference(path)
    if name.endswith((".usd", ".usda", ".usdc", ".usdz")):
        return UsdReference(path)
    if os.path.basename(os.fspath(path)) in fbx_truth.TRUTH:
        return FbxTruthReference(path)
    raise NoReference(f"{os.path.basename(os.fspath(path))}: no independent reference for this format")


# =============================================================================== the asset
class AssetRig:
    """A colossus asset skinned by plain usd-core.

    Attributes
    ----------
    up_axis : str
    meters_per_unit, time_codes_per_second : float
    clips : list of str
        SkelAnimation prim names in file order.
    """

    def __init__(self, path):
        self.path = os.fspath(path)
        self.stage = Usd.Stage.Open(self.path)
        if self.stage is None:
            raise ValueError(f"{self.path}: usd-core cannot open it")
        st = self.stage
        self.up_axis = str(UsdGeom.GetStageUpAxis(st))
        self.meters_per_unit = float(UsdGeom.GetStageMetersPerUnit(st))
        self.time_codes_per_second = float(st.GetTimeCodesPerSecond())
        self._anims = {}
        for p in st.Traverse():
            if p.IsA(UsdSkel.Animation):
                self._anims.setdefault(p.GetName(), p.GetPath())
        self.clips = list(self._anims)
        self._skels = [p for p in st.Traverse() if p.IsA(UsdSkel.Skeleton)]
        self._bound = None
        self._bind()

    def _bind(self, clip=None):
        """(Re)build the skel cache, with ``clip`` bound as every skeleton's animation source."""
        st = self.stage
        if clip is not None and clip != self._bound:
            with Usd.EditContext(st, st.GetSessionLayer()):
                for sk in self._skels:
                    UsdSkel.BindingAPI.Apply(sk).CreateAnimationSourceRel().SetTargets([self._anims[clip]])
        self._bound = clip
        cache = UsdSkel.Cache()
        self._targets = []
        for p in st.Traverse():
            if p.IsA(UsdSkel.Root):
                root = UsdSkel.Root(p)
                cache.Populate(root, Usd.PrimDefaultPredicate)
                for b in cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate):
                    sq = cache.GetSkelQuery(b.GetSkeleton())
                    for q in b.GetSkinningTargets():
                        if q.GetPrim().IsA(UsdGeom.Mesh) and q.HasJointInfluences():
                            self._targets.append((sq, q, q.GetPrim()))
        if not self._targets:
            raise ValueError(f"{self.path}: no skinned mesh")

    def clip_times(self, clip) -> np.ndarray:
        """Sorted time samples of a clip's joint transforms (time codes)."""
        anim = UsdSkel.Animation(self.stage.GetPrimAtPath(self._anims[clip]))
        t = set()
        for a in (anim.GetTranslationsAttr(), anim.GetRotationsAttr(), anim.GetScalesAttr()):
            t.update(a.GetTimeSamples())
        return np.array(sorted(t), dtype=np.float64)

    def points(self, clip, time_codes, at_bind=False) -> np.ndarray:
        """``(T, V, 3)`` float64 world points of every skinned mesh (concatenated in traversal
        order) with ``clip`` bound, at each time code; ``at_bind``: identity skinning transforms."""
        if clip is not None and clip != self._bound:
            self._bind(clip)
        out = []
        for tc in np.atleast_1d(time_codes):
            t = Usd.TimeCode(float(tc))
            xf = UsdGeom.XformCache(t)
            frame = []
            for sq, q, prim in self._targets:
                if at_bind:
                    x = Vt.Matrix4dArray([Gf.Matrix4d(1.0)] * len(sq.GetJointOrder()))
                else:
                    x = sq.ComputeSkinningTransforms(t)
                pts = UsdGeom.Mesh(prim).GetPointsAttr().Get(t)
                if not at_bind:
                    usd_eval.apply_blend_shapes(sq, q, pts, t)
                if not q.ComputeSkinnedPoints(x, pts, t):
                    raise ValueError(f"{self.path}: UsdSkel cannot skin {prim.GetPath()} at {tc}")
                w = np.array(xf.GetLocalToWorldTransform(sq.GetPrim()), dtype=np.float64).reshape(4, 4).T
                frame.append(_apply(w, np.asarray(pts, dtype=np.float64).reshape(-1, 3)))
            out.append(np.concatenate(frame))
        return np.array(out)

    def rest(self) -> np.ndarray:
        """``(V, 3)`` float64 world points at the bind pose, as the source binds them: where the
        importer folded the skeleton's scale over its bind into the points (the provenance's
        ``pointScale``, ``r``: the asset's bind points are ``r`` times the source's about the
        skeleton's origin, and skin to the same points) they are divided by it."""
        pts = self.points(None, [Usd.TimeCode.EarliestTime().GetValue()], at_bind=True)[0]
        r = 1.0
        for _, _, prim in self._targets:
            v = (prim.GetCustomDataByKey("colossus") or {}).get("pointScale")
            if isinstance(v, (int, float)) and v > 0:
                r = float(v)
        if r != 1.0:
            sq = self._targets[0][0]
            t = np.array(UsdGeom.XformCache().GetLocalToWorldTransform(sq.GetPrim()), dtype=np.float64)[3, :3]
            pts = (pts - t) / r + t
        return pts


# =============================================================================== comparison
@dataclass
class ClipReport:
    """Per clip: errors are x model size; ``None`` where nothing was compared."""

    name: str
    asset_clip: str | None
    name_matched: bool
    keys: int
    interpolation: str
    on_grid: bool | None
    key_instants: int = 0
    mid_instants: int = 0
    err_keys: float | None = None
    err_mid: float | None = None
    worst: str = ""
    asset_frames: int = 0

    def problems(self, tol=TOL, off_grid_tol=OFF_GRID_TOL) -> list:
        if self.asset_clip is None:
            return [f"clip {self.name!r}: not in the asset"]
        out = []
        if not self.name_matched:
            out.append(f"clip {self.name!r}: the asset calls it {self.asset_clip!r}")
        bound = tol if self.on_grid else off_grid_tol
        for what, e in (("keys", self.err_keys), ("mid-keys", self.err_mid)):
            if e is not None and not (e <= bound):
                out.append(f"clip {self.name!r}: {e:.2e} x size at {what} > {bound:g} ({self.worst})")
        return out


@dataclass
class FileReport:
    """The comparison of one source with its asset (see :func:`compare`)."""

    source: str
    format: str
    asset: str | None = None
    size: float = 0.0
    clips: list = field(default_factory=list)
    reference_vertices: int = 0
    missing: int = 0
    missing_meshes: dict = field(default_factory=dict)  # label -> count
    ambiguous: int = 0
    static_present: dict = field(default_factory=dict)  # label -> (present, total) for static meshes
    rest_used: dict = field(default_factory=dict)  # label -> hypothesis
    extra_asset_clips: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    failure: str | None = None

    def problems(self, tol=TOL, off_grid_tol=OFF_GRID_TOL) -> list:
        if self.failure:
            return [f"import failed: {self.failure}"]
        out = []
        if self.missing:
            out.append(f"{self.missing} of {self.reference_vertices} reference vertices missing "
                       f"({', '.join(f'{k}: {v}' for k, v in self.missing_meshes.items())})")
        for c in self.clips:
            out.extend(c.problems(tol, off_grid_tol))
        return out

    def brief(self, tol=TOL, off_grid_tol=OFF_GRID_TOL) -> str:
        """The problems in one short line (``ok`` when none)."""
        if self.failure:
            return self.failure
        parts = []
        if self.missing:
            parts.append(f"{self.missing} of {self.reference_vertices} vertices missing")
        absent = [c.name for c in self.clips if c.asset_clip is None]
        renamed = [c for c in self.clips if c.asset_clip is not None and not c.name_matched]
        if absent:
            parts.append(f"{len(absent)} clips not in the asset ({', '.join(absent[:3])}{', ...' if len(absent) > 3 else ''})")
        if renamed:
            parts.append(f"{len(renamed)} clips misnamed ({renamed[0].name!r} -> {renamed[0].asset_clip!r}{', ...' if len(renamed) > 1 else ''})")
        over = [c for c in self.clips if c.asset_clip is not None and any("x size" in p for p in c.problems(tol, off_grid_tol))]
        if over:
            w = max(over, key=lambda c: max(e for e in (c.err_keys, c.err_mid) if e is not None))
            parts.append(f"{len(over)} of {len(self.clips)} clips over tolerance (worst {w.name!r}: "
                         f"{max(e for e in (w.err_keys, w.err_mid) if e is not None):.1e} at {w.worst})")
        return "; ".join(parts) or "ok"

    @property
    def err_keys(self):
        e = [c.err_keys for c in self.clips if c.err_keys is not None]
        return max(e) if e else None

    @property
    def err_mid(self):
        e = [c.err_mid for c in self.clips if c.err_mid is not None]
        return max(e) if e else None


def compare(source, asset, max_instants: int = MAX_INSTANTS, reference: Reference | None = None) -> FileReport:
    """Compare the motion of a colossus asset with the independent reference of its source.

    Parameters
    ----------
    source : path of the corpus source file.
    asset : path of the asset written from it.
    max_instants : int
        Cap on compared instants per clip (half keys, half mid-keys; all when 0 or negative).
    reference : Reference, optional
        An already-loaded reference of ``source``.

    Returns
    -------
    FileReport
    """
    ref = reference or reference_for(source)
    rep = FileReport(os.path.basename(os.fspath(source)), ref.format, os.fspath(asset), notes=list(ref.notes))
    rig = AssetRig(asset)
    c = axis_scale(ref.up_axis, ref.meters_per_unit, rig.up_axis, rig.meters_per_unit)
    moving = [i for i, m in enumerate(ref.meshes) if m.moves]
    static = [i for i, m in enumerate(ref.meshes) if not m.moves]

    def gather(arrays, which):
        return np.concatenate([_apply(c, arrays[i][ref.meshes[i].used]) for i in which]) if which else np.zeros((0, 3))

    rep.size = _diag(gather(ref.shown_pose(), moving))
    asset_rest = rig.rest()
    tree = cKDTree(asset_rest)
    k = min(CANDIDATES, len(asset_rest))

    # ---- match every reference vertex to asset vertices at the same rest position ------------
    hyps = ref.rest_hypotheses()
    hyp_tol = [MATCH_TOL * _diag(gather(h, moving)) for _, h in hyps]
    cand_rows, owner = [], []
    for i in moving + static:
        m = ref.meshes[i]
        best = None
        for (label, h), tol in zip(hyps, hyp_tol):
            d, idx = tree.query(_apply(c, h[i][m.used]), k=k, distance_upper_bound=tol)
            d, idx = d.reshape(len(d), -1), idx.reshape(len(idx), -1)
            hit = np.isfinite(d[:, 0])
            if best is None or hit.sum() > best[0].sum():
                best = (hit, idx, label)
        hit, idx, label = best
        idx = np.where(idx < len(asset_rest), idx, -1)
        if m.moves:
            rep.rest_used[m.label] = label
            miss = int((~hit).sum())
            if miss:
                rep.missing_meshes[m.label] = rep.missing_meshes.get(m.label, 0) + miss
            rep.missing += miss
            rep.reference_vertices += len(hit)
            cand_rows.append(idx)
            owner.extend([m.label] * len(hit))
        else:
            pres, tot = rep.static_present.get(m.label, (0, 0))
            rep.static_present[m.label] = (pres + int(hit.sum()), tot + len(hit))
    cand = np.concatenate(cand_rows) if cand_rows else np.zeros((0, k), dtype=np.int64)
    owner = np.array(owner)
    matched = cand[:, 0] >= 0
    rep.ambiguous = int(np.count_nonzero((cand[matched] >= 0).sum(axis=1) > 1))

    # ---- clips ---------------------------------------------------------------------------------
    used_assets = set()
    tcps = rig.time_codes_per_second
    for ci, clip in enumerate(ref.clips):
        # a USD prim name cannot hold '.', '-', ' ' ...: the valid identifier of the name counts as the name
        valid = Tf.MakeValidIdentifier(clip.name)
        name_ok = valid in rig.clips
        aname = valid if name_ok else (rig.clips[ci] if ci < len(rig.clips) and rig.clips[ci] not in ref_names(ref) else None)
        cr = ClipReport(clip.name, aname, name_ok, len(clip.keys), clip.interpolation, None)
        rep.clips.append(cr)
        if aname is None:
            continue
        used_assets.add(aname)
        frames = rig.clip_times(aname)
        cr.asset_frames = len(frames)
        ktc = clip.keys * tcps
        cr.on_grid = bool(np.all(np.abs(ktc - np.round(ktc)) <= GRID_TOL))
        half = max_instants // 2 if max_instants > 0 else 10 ** 9
        keys = _subsample(clip.keys, half)
        mids = _subsample((clip.keys[:-1] + clip.keys[1:]) / 2, half) if clip.mids and len(clip.keys) > 1 else np.zeros(0)
        instants = np.concatenate([keys, mids])
        is_key = np.arange(len(instants)) < len(keys)
        refp = np.array([gather(p, moving) for p in ref.poses(ci, instants)])  # (T, R, 3)
        got = rig.points(aname, instants * tcps)  # (T, V, 3)
        if not matched.any():
            continue
        cm, rm = cand[matched], refp[:, matched]
        gm = got[:, np.where(cm >= 0, cm, 0)]  # (T, R, k, 3)
        dist = np.linalg.norm(gm - rm[:, :, None, :], axis=-1)  # (T, R, k)
        dist = np.where((cm >= 0)[None], dist, np.inf)
        # per reference vertex, the best-moving candidate at the key instants, where the asset
        # must agree exactly (co-located vertices with other weights are the other candidates;
        # choosing over the mid-key instants too would let their larger errors pick a wrong twin)
        sel = dist[is_key] if is_key.any() else dist
        choose = np.argmin(sel.max(axis=0), axis=1)
        err = np.take_along_axis(dist, choose[None, :, None], axis=2)[..., 0] / rep.size  # (T, R)
        per_t = err.max(axis=1)
        cr.key_instants, cr.mid_instants = int(is_key.sum()), int((~is_key).sum())
        if is_key.any():
            cr.err_keys = float(per_t[is_key].max())
        if (~is_key).any():
            cr.err_mid = float(per_t[~is_key].max())
        t, v = np.unravel_index(np.argmax(err), err.shape)
        cr.worst = f"t={instants[t]:.4f}s, {owner[matched][v]}"
    rep.extra_asset_clips = [n for n in rig.clips if n not in used_assets]
    return rep


def ref_names(ref) -> set:
    """The valid USD identifiers of the reference's clip names."""
    return {Tf.MakeValidIdentifier(c.name) for c in ref.clips}


def format_table(reports) -> str:
    """The diagnosis table (one row per clip, file columns on its first row)."""
    head = ("file", "fmt", "clip", "keys", "grid", "err@keys", "err@mid", "missing", "note")
    rows = []

    def fe(e):
        return "-" if e is None else f"{e:.1e}"

    for r in reports:
        miss = f"{r.missing}/{r.reference_vertices}" + (f" ({', '.join(f'{k}:{v}' for k, v in r.missing_meshes.items())})" if r.missing_meshes else "")
        if r.failure:
            rows.append((r.source, r.format, "-", "-", "-", "-", "-", "-", r.failure))
            continue
        if not r.clips:
            rows.append((r.source, r.format, "(no clip)", "-", "-", "-", "-", miss, "; ".join(r.notes)[:80]))
        for j, c in enumerate(r.clips):
            note = "" if c.name_matched else (f"asset calls it {c.asset_clip!r}" if c.asset_clip else "not in asset")
            rows.append((r.source if j == 0 else "", r.format if j == 0 else "", c.name[:28], str(c.keys),
                         {True: "yes", False: "NO", None: "-"}[c.on_grid], fe(c.err_keys), fe(c.err_mid),
                         miss if j == 0 else "", note))
    widths = [max(len(str(x)) for x in col) for col in zip(head, *rows)] if rows else [len(h) for h in head]
    widths[-1] = 0
    line = lambda r: "  ".join(str(x).ljust(w) for x, w in zip(r, widths)).rstrip()  # noqa: E731
    return "\n".join([line(head), line(tuple("-" * w for w in widths[:-1]) + ("----",))] + [line(r) for r in rows])
