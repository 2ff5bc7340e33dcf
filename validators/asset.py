"""The loaded asset: read once with usd-core into numpy arrays, shared by every rule.

Reading never raises for a malformed asset: a missing or malformed piece is ``None`` (or an
empty array), :meth:`LoadedAsset.ready` says whether what a rule needs is usable, and the
structure rules report why it is not.

Conventions (as ``pipeline.model``): matrices are ``float64`` 4x4 in the **column-vector**
convention ``p' = M @ p`` (``Gf.Matrix4d`` is the transpose); geometry is ``float32``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel

from colossus.runtime import asset as runtime_asset
from colossus.runtime import schema
from colossus.runtime.errors import ColliderError

from . import tolerances as tol

CLIP_ATTRS = ("translations", "rotations", "scales")


def _mats(value) -> np.ndarray | None:
    """A ``VtMatrix4dArray`` -> ``(b, 4, 4)`` float64 column-vector (:mod:`runtime.schema`), or None."""
    m = schema.matrices_from_usd(value)
    return m if m is not None and m.ndim == 3 else None


def _mat(value) -> np.ndarray:
    return schema.matrices_from_usd(value)


@dataclass
class Clip:
    """One SkelAnimation prim.

    Attributes
    ----------
    name : str
    prim : Usd.Prim
    times : (f,) float64
        Its frames: the sorted union of the time samples of translations, rotations, scales.
    joints : list of str
        The animation's ``joints``.
    """

    name: str
    prim: Usd.Prim
    times: np.ndarray
    joints: list


def _bad_values(attr: str, vals: np.ndarray) -> np.ndarray:
    """``(n, A)`` bool: which joint values of ``(n, A, w)`` samples are not finite (or, for
    rotations, a zero quaternion)."""
    with np.errstate(invalid="ignore", over="ignore"):
        bad = ~np.isfinite(vals).all(axis=-1)
        if attr == "rotations":
            bad |= ~(np.linalg.norm(vals, axis=-1) >= 1e-12)
    return bad


def open_layer(path: str) -> Sdf.Layer:
    """The root layer of ``path``, read fresh (a layer usd-core already holds is reloaded), raising
    on failure.  Holding it while the references are listed and the stage is opened
    (:func:`open_stage`) makes the file parsed once, not once per step."""
    layer = Sdf.Layer.Find(path)
    if layer is not None:
        layer.Reload(force=True)
    else:
        layer = Sdf.Layer.FindOrOpen(path)
    if layer is None:
        raise RuntimeError(f"usd-core could not open {path}")
    return layer


def open_stage(path: str, layer: Sdf.Layer | None = None) -> Usd.Stage:
    """Open ``path`` fresh (on ``layer`` from :func:`open_layer` when given), raising on failure."""
    stage = Usd.Stage.Open(layer if layer is not None else open_layer(path), Usd.Stage.LoadAll)
    if stage is None:
        raise RuntimeError(f"usd-core could not open {path}")
    return stage


class LoadedAsset:
    """A collider asset read into numpy arrays.

    Attributes (each ``None`` when absent or malformed)
    ----------
    stage : Usd.Stage
    skel_roots, skeletons, meshes, animations : list of Usd.Prim found anywhere on the stage
    root : Usd.Prim          the SkelRoot (the default prim if it is one, else the first)
    skeleton : Usd.Prim      the Skeleton under ``root``
    mesh : Usd.Prim          the collider Mesh under ``root`` (named ``Collider`` if several)
    joints : list of str, length b
    parents : (b,) int32     parent joint index, -1 for roots (from ``UsdSkel.Topology``)
    bind : (b, 4, 4) float64 joint -> skeleton space at bind time
    rest : (b, 4, 4) float64 joint-local rest transforms
    skel_world : (4, 4) float64  the Skeleton prim's local-to-world transform
    points : (n, 3) float32
    face_counts : (F,) int32, face_indices : (sum,) int32
    tris : (F, 3) int32      only when every face is a triangle with in-range indices
    jidx : (n, k) int32, jw : (n, k) float32, k : int  skin influences
    geom_bind : (4, 4) float64
    part_joints : list of str, part_centers : (P, 3) float32, part_radii : (P,) float32,
    part_offsets : (P + 1,) int64, part_faces : (sum,) int64
    clips : list of Clip     SkelAnimation prims that are direct children of ``root``
    """

    def __init__(self, stage: Usd.Stage, path: str = ""):
        self.stage = stage
        self.path = path or stage.GetRootLayer().identifier
        self._read_prims()
        self._read_skeleton()
        self._read_mesh()
        self._read_skin()
        self._read_parts()
        self._read_clips()

    # -- reading ---------------------------------------------------------------------------
    def _read_prims(self):
        self.skel_roots, self.skeletons, self.meshes, self.animations = [], [], [], []
        for prim in self.stage.Traverse():
            if prim.IsA(UsdSkel.Root):
                self.skel_roots.append(prim)
            elif prim.IsA(UsdSkel.Skeleton):
                self.skeletons.append(prim)
            elif prim.IsA(UsdGeom.Mesh):
                self.meshes.append(prim)
            elif prim.IsA(UsdSkel.Animation):
                self.animations.append(prim)
        dp = self.stage.GetDefaultPrim()
        if dp and dp.IsA(UsdSkel.Root):
            self.root = dp
        else:
            self.root = self.skel_roots[0] if self.skel_roots else None
        under = (lambda p: self.root is not None and p.GetPath().HasPrefix(self.root.GetPath()))
        skels = [p for p in self.skeletons if under(p)]
        self.skeleton = skels[0] if skels else None
        meshes = [p for p in self.meshes if under(p)]
        named = [p for p in meshes if p.GetName() == schema.COLLIDER_NAME]
        self.mesh = named[0] if named else (meshes[0] if meshes else None)

    def _read_skeleton(self):
        self.joints = self.parents = self.bind = self.rest = None
        self.topology_error = None
        self.skel_world = np.eye(4)
        if self.skeleton is None:
            return
        skel = UsdSkel.Skeleton(self.skeleton)
        joints = skel.GetJointsAttr().Get()
        self.joints = [str(j) for j in joints] if joints is not None else None
        self.bind = _mats(skel.GetBindTransformsAttr().Get())
        self.rest = _mats(skel.GetRestTransformsAttr().Get())
        if self.joints is not None:
            topo = UsdSkel.Topology(self.joints)
            ok, why = topo.Validate()
            self.parents = np.array(topo.GetParentIndices(), dtype=np.int32)
            if not ok:
                self.topology_error = why
        self.skel_world = _mat(UsdGeom.Xformable(self.skeleton).ComputeLocalToWorldTransform(
            Usd.TimeCode.Default()))

    def _read_mesh(self):
        self.points = self.face_counts = self.face_indices = self.tris = None
        if self.mesh is None:
            return
        m = UsdGeom.Mesh(self.mesh)
        pts = m.GetPointsAttr().Get()
        if pts is not None:
            a = np.array(pts, dtype=np.float32)
            self.points = a.reshape(-1, 3) if a.size else np.zeros((0, 3), np.float32)
        c = m.GetFaceVertexCountsAttr().Get()
        i = m.GetFaceVertexIndicesAttr().Get()
        self.face_counts = np.array(c, dtype=np.int64) if c is not None else None
        self.face_indices = np.array(i, dtype=np.int64) if i is not None else None
        self.orientation = m.GetOrientationAttr().Get()
        if (self.points is not None and self.face_counts is not None and self.face_indices is not None
                and np.all(self.face_counts == 3) and len(self.face_indices) == 3 * len(self.face_counts)
                and (len(self.face_indices) == 0 or (self.face_indices.min() >= 0
                                                     and self.face_indices.max() < len(self.points)))):
            self.tris = self.face_indices.reshape(-1, 3).astype(np.int32)

    def _read_skin(self):
        self.jidx = self.jw = None
        self.k = 0
        self.skin_error = None
        self.geom_bind = np.eye(4)
        self.mesh_skeleton_targets = []
        if self.mesh is None:
            return
        b = UsdSkel.BindingAPI(self.mesh)
        rel = b.GetSkeletonRel()
        self.mesh_skeleton_targets = [str(t) for t in rel.GetTargets()] if rel else []
        gb = b.GetGeomBindTransformAttr()
        if gb and gb.HasAuthoredValue():
            self.geom_bind = _mat(gb.Get())
        ip, wp = b.GetJointIndicesPrimvar(), b.GetJointWeightsPrimvar()
        if not (ip and ip.HasAuthoredValue()) or not (wp and wp.HasAuthoredValue()):
            self.skin_error = "primvars:skel:jointIndices / jointWeights are missing"
            return
        ji = np.array(ip.Get(), dtype=np.int32)
        jw = np.array(wp.Get(), dtype=np.float32)
        k = ip.GetElementSize()
        n = len(self.points) if self.points is not None else 0
        if wp.GetElementSize() != k:
            self.skin_error = f"jointIndices elementSize {k} != jointWeights elementSize {wp.GetElementSize()}"
        elif ip.GetInterpolation() != UsdGeom.Tokens.vertex or wp.GetInterpolation() != UsdGeom.Tokens.vertex:
            self.skin_error = (f"interpolation must be 'vertex', got {ip.GetInterpolation()!r} / "
                               f"{wp.GetInterpolation()!r}")
        elif k < 1 or len(ji) != n * k or len(jw) != n * k:
            self.skin_error = (f"expected {n} vertices x elementSize {k} = {n * k} entries, got "
                               f"{len(ji)} indices and {len(jw)} weights")
        else:
            self.k = k
            self.jidx = ji.reshape(n, k)
            self.jw = jw.reshape(n, k)
        mj = b.GetJointsAttr()
        if mj and mj.HasAuthoredValue():
            self.skin_error = "the mesh authors its own skel:joints order, which this contract does not use"
            self.jidx = self.jw = None

    def _read_parts(self):
        self.part_joints = self.part_centers = self.part_radii = None
        self.part_offsets = self.part_faces = None
        self.parts_attr_errors = {}
        if self.mesh is None:
            return
        values, self.parts_attr_errors = schema.read_parts(self.mesh)
        self.part_joints, self.part_centers, self.part_radii = values["joints"], values["centers"], values["radii"]
        self.part_offsets, self.part_faces = values["face_offsets"], values["faces"]

    def _read_clips(self):
        self.clips = []
        if self.root is None:
            return
        for prim in self.root.GetChildren():
            if not prim.IsA(UsdSkel.Animation):
                continue
            anim = UsdSkel.Animation(prim)
            times = set()
            for a in CLIP_ATTRS:
                times.update(prim.GetAttribute(a).GetTimeSamples() if prim.GetAttribute(a) else ())
            j = anim.GetJointsAttr().Get()
            self.clips.append(Clip(prim.GetName(), prim, np.array(sorted(times), dtype=np.float64),
                                   [str(x) for x in j] if j is not None else []))

    # -- derived ---------------------------------------------------------------------------
    @property
    def n(self) -> int:
        return 0 if self.points is None else len(self.points)

    @cached_property
    def bind_points(self) -> np.ndarray:
        """(n, 3) float64 points in stage space at bind time: world @ geomBind @ p."""
        m = self.skel_world @ self.geom_bind
        return self.points.astype(np.float64) @ m[:3, :3].T + m[:3, 3]

    @cached_property
    def model_size(self) -> float:
        """Diagonal of the bind-pose bounding box (1.0 when empty or degenerate)."""
        if self.points is None or len(self.points) == 0:
            return 1.0
        return schema.bind_model_size(self.bind_points)  # the importer's degenerate stage uses it too

    @cached_property
    def joint_index(self) -> dict:
        return {j: i for i, j in enumerate(self.joints or [])}

    @cached_property
    def part_joint_ids(self) -> np.ndarray:
        """(P,) int32 joint index of each part (-1 for unknown joints)."""
        return np.array([self.joint_index.get(j, -1) for j in (self.part_joints or [])], dtype=np.int32)

    @cached_property
    def inv_bind(self) -> np.ndarray:
        return np.linalg.inv(self.bind)

    @cached_property
    def part_vertices(self):
        """CSR ``(offsets (P+1,) int64, vertices int32)`` of the distinct vertices of each part's faces."""
        offsets, verts = schema.part_vertex_csr(self.tris, self.part_offsets, self.part_faces, self.n)
        return offsets, verts.astype(np.int32)

    @cached_property
    def clip_sample_issues(self) -> dict:
        """Every clip's malformed time samples: ``{clip name: [issue, ...]}`` where an issue is
        ``(attr, time, kind, detail)``, ``kind`` ``"length"`` (``detail``: the number of entries,
        not one per clip joint) or ``"nonfinite"`` (``detail``: the first bad joint's name), at
        most one of each kind per attribute; a clip without those has at most one ``"singular"``
        issue (``detail``: ``(joint, why)``, :meth:`_singular`).

        A well-formed clip is judged on :meth:`clip_data` (read once, shared with the frame
        proof); only a malformed one is scanned sample by sample to say where: ``UsdSkel``
        silently poses a sample of the wrong length at identity, so the rules must find it at
        any sample, not only the first.  A value usd-core cannot decode raises
        ``Tf.ErrorException`` (the runner makes it a ``COL001``)."""
        out = {}
        for c in self.clips:
            try:
                d = self.clip_data(c)
            except ColliderError:
                out[c.name] = self._scan_samples(c)
                continue
            issues = []
            for a, times, vals in (("translations", d.tt, d.vt), ("rotations", d.tr, d.vr), ("scales", d.ts, d.vs)):
                bad = _bad_values(a, vals)
                if bad.any():
                    i, j = np.argwhere(bad)[0]
                    issues.append((a, float(times[i]), "nonfinite", self.joints[d.anim_to_skel[j]]))
            if not issues:
                over = self._overflow(c, d)
                if over is not None:
                    issues.append(("composed transforms", over[0], "nonfinite", over[1]))
            if not issues:
                sing = self._singular(c, d)
                if sing is not None:
                    issues.append(sing)
            out[c.name] = issues
        return out

    #: A joint's skeleton-space transform with an entry beyond this is corrupt (no rig is 1e18
    #: units across); the proof's products of such transforms would overflow to inf / NaN.
    COMPOSED_LIMIT = 1e18

    def _overflow(self, c: Clip, d):
        """``(time, joint)`` of the first sample where composing the clip's finite joint values
        down the hierarchy overflows (beyond :data:`COMPOSED_LIMIT`), else None."""
        from colossus.runtime.kernels import pose as PK

        if self.parents is None or self.rest is None or not len(c.times):
            return None
        times = np.asarray(c.times, dtype=np.float64)
        for lo in range(0, len(times), 256):
            with np.errstate(invalid="ignore", over="ignore"):
                skel = self.skel_transforms(PK.locals_at(d, times[lo:lo + 256], self.rest))
                bad = ~(np.abs(skel) <= self.COMPOSED_LIMIT).all(axis=(-2, -1))
            if bad.any():
                i, j = np.argwhere(bad)[0]
                return float(times[lo + i]), self.joints[j]
        return None

    def _singular(self, c: Clip, d):
        """The first place where a joint of clip ``c`` (its finite samples ``d``) has no inverse
        pose, as an issue ``(attr, time, "singular", (joint, why))``, else None: a scale below
        :data:`tolerances.MIN_SCALE` on an axis, a scale that changes sign between two samples
        (UsdSkel lerps it through 0), or a skeleton-space transform on a frame whose 3x3 part has
        |det| <= :data:`tolerances.MIN_DETERMINANT` or that is not affine (a singular or
        non-affine rest transform of a joint the clip leaves unanimated, or a parent's).  The
        frame proof works in each part joint's space, the inverse of its pose (fuzz campaign 12,
        case 1781: a zero scale crashed it with ``LinAlgError: Singular matrix``)."""
        from colossus.runtime.kernels import pose as PK

        if self.parents is None or self.rest is None or not len(c.times):
            return None
        bad_scale = schema.scale_singularity(d, tol.MIN_SCALE)
        if bad_scale is not None:
            t, j, why = bad_scale
            return ("scales", t, "singular", (self.joints[d.anim_to_skel[j]], why))
        times = np.asarray(c.times, dtype=np.float64)
        for lo in range(0, len(times), 256):
            with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
                skel = self.skel_transforms(PK.locals_at(d, times[lo:lo + 256], self.rest))
                det = np.abs(np.linalg.det(skel[..., :3, :3]))
                affine = (np.abs(skel[..., 3, :] - (0.0, 0.0, 0.0, 1.0)) < 1e-9).all(axis=-1)
                bad = ~((det > tol.MIN_DETERMINANT) & affine)
            if bad.any():
                i, j = np.argwhere(bad)[0]
                why = (f"has a transform that is not invertible (|det| {det[i, j]:.3g}: a zero scale, its own "
                       "or a parent's, or a singular rest transform)" if affine[i, j] else
                       "has a transform that is not affine (a rest transform whose last row is not (0, 0, 0, 1))")
                return ("composed transforms", float(times[lo + i]), "singular", (self.joints[j], why))
        return None

    def _scan_samples(self, c: Clip) -> list:
        issues = []
        for a in CLIP_ATTRS:
            attr = c.prim.GetAttribute(a)
            if not attr:
                continue
            seen = set()
            for t in attr.GetTimeSamples():
                v = attr.Get(Usd.TimeCode(t))
                if v is None:
                    continue
                arr = np.array(v, dtype=np.float64)  # quaternions come as (x, y, z, w): fine here
                if "length" not in seen and len(arr) != len(c.joints):
                    issues.append((a, float(t), "length", len(arr)))
                    seen.add("length")
                if "nonfinite" not in seen and arr.size:
                    bad = _bad_values(a, arr.reshape(1, len(arr), -1))[0]
                    if np.any(bad):
                        j = int(np.argmax(bad))
                        issues.append((a, float(t), "nonfinite", c.joints[j] if j < len(c.joints) else None))
                        seen.add("nonfinite")
                if len(seen) == 2:
                    break
        return issues

    def anim_local(self, clip: Clip, times) -> np.ndarray:
        """(f, b, 4, 4) joint-local transforms of ``clip`` at ``times`` in skeleton joint order,
        evaluated by ``UsdSkel.AnimQuery`` (its interpolation between samples; joints the clip
        does not animate keep their rest transform)."""
        q = self._anim_query(clip)
        b = len(self.joints)
        src, dst = self._anim_map(clip)
        out = np.broadcast_to(self.rest, (len(times), b, 4, 4)).copy()
        for i, t in enumerate(times):
            m = q.ComputeJointLocalTransforms(Usd.TimeCode(float(t)))
            if m is None or len(m) != len(clip.joints):
                raise ValueError(f"clip {clip.name!r}: no joint transforms at time {t}")
            out[i, dst] = np.array(m, dtype=np.float64)[src].transpose(0, 2, 1)
        return out

    def _anim_query(self, clip):
        if not hasattr(self, "_skel_cache"):
            self._skel_cache = UsdSkel.Cache()
            self._queries = {}
        if clip.name not in self._queries:
            self._queries[clip.name] = self._skel_cache.GetAnimQuery(UsdSkel.Animation(clip.prim))
        return self._queries[clip.name]

    def _anim_map(self, clip):
        src = [i for i, j in enumerate(clip.joints) if j in self.joint_index]
        dst = [self.joint_index[clip.joints[i]] for i in src]
        return np.array(src, dtype=np.int64), np.array(dst, dtype=np.int64)

    def skel_transforms(self, local: np.ndarray) -> np.ndarray:
        """Compose ``(f, b, 4, 4)`` joint-local transforms into skeleton space (parents first)."""
        out = np.empty_like(local)
        # a corrupt asset's huge values overflow to inf / NaN here: the clip rules report them
        # (COL503), the composition must not warn
        with np.errstate(invalid="ignore", over="ignore"):
            for j in schema.parents_first(self.parents):
                p = self.parents[j]
                out[:, j] = local[:, j] if p < 0 else out[:, p] @ local[:, j]
        return out

    # -- readiness -------------------------------------------------------------------------
    def ready(self, need: str):
        """``(ok, reason)``: whether what a rule ``need`` s can be read."""
        cache = self.__dict__.setdefault("_ready", {})
        if need not in cache:
            cache[need] = getattr(self, "_ready_" + need)()
        return cache[need]

    def _ready_root(self):
        return (self.root is not None, "no SkelRoot")

    def _ready_skeleton(self):
        if self.skeleton is None:
            return False, "no Skeleton under the SkelRoot"
        b = len(self.joints or [])
        if b == 0:
            return False, "the Skeleton has no joints"
        if self.topology_error:
            return False, f"joint topology is invalid: {self.topology_error}"
        if self.bind is None or len(self.bind) != b:
            return False, "bindTransforms missing or not one per joint"
        if self.rest is None or len(self.rest) != b:
            return False, "restTransforms missing or not one per joint"
        if not (np.all(np.isfinite(self.bind)) and np.all(np.isfinite(self.rest))):
            return False, "bind or rest transforms are not finite"
        return True, ""

    def _ready_mesh_raw(self):
        if self.mesh is None:
            return False, "no collision Mesh under the SkelRoot"
        if self.points is None or self.face_counts is None or self.face_indices is None:
            return False, "the Mesh lacks points, faceVertexCounts or faceVertexIndices"
        if int(self.face_counts.sum()) != len(self.face_indices) or np.any(self.face_counts < 0):
            return False, "faceVertexCounts do not add up to the number of faceVertexIndices"
        return True, ""

    def _ready_mesh(self):
        ok, why = self.ready("mesh_raw")
        if not ok:
            return ok, why
        if self.tris is None:
            return False, "the Mesh is not all triangles with in-range vertex indices"
        return True, ""

    def _ready_skin(self):
        for need in ("mesh", "skeleton"):
            ok, why = self.ready(need)
            if not ok:
                return ok, why
        if self.jidx is None:
            return False, self.skin_error or "no skin influences"
        return True, ""

    def _ready_skin_ok(self):
        """Skin usable for skinning: indices in range, finite weights, invertible binds."""
        ok, why = self.ready("skin")
        if not ok:
            return ok, why
        if self.jidx.size and (self.jidx.min() < 0 or self.jidx.max() >= len(self.joints)):
            return False, "joint indices out of range"
        if not np.all(np.isfinite(self.jw)):
            return False, "joint weights are not finite"
        if np.any(np.abs(np.linalg.det(self.bind[:, :3, :3])) <= tol.MIN_DETERMINANT):
            return False, "a bind transform is not invertible"
        if not np.all(np.abs(self.bind[:, 3] - (0.0, 0.0, 0.0, 1.0)) < 1e-9):  # COL307's test: a non-affine
            return False, "a bind transform is not affine"  # one can be singular with an invertible 3x3
        if not np.all(np.isfinite(self.points)):
            return False, "points are not finite"
        return True, ""

    def _ready_parts(self):
        for need in ("mesh", "skeleton"):
            ok, why = self.ready(need)
            if not ok:
                return ok, why
        if self.parts_attr_errors:
            return False, "parts attributes: " + ", ".join(f"{k} {v}" for k, v in self.parts_attr_errors.items())
        P = len(self.part_joints)
        if len(self.part_centers) != P or len(self.part_radii) != P or len(self.part_offsets) != P + 1:
            return False, "parts attributes have inconsistent lengths"
        o = self.part_offsets
        if o[0] != 0 or o[-1] != len(self.part_faces) or np.any(np.diff(o) < 0):
            return False, "parts faceOffsets are not non-decreasing from 0 to len(faces)"
        if len(self.part_faces) and (self.part_faces.min() < 0 or self.part_faces.max() >= len(self.tris)):
            return False, "parts faces out of range"
        if np.any(self.part_joint_ids < 0):
            return False, "a part names a joint the skeleton does not have"
        return True, ""

    def _ready_spheres(self):
        ok, why = self.ready("parts")
        if not ok:
            return ok, why
        if not (np.all(np.isfinite(self.part_centers)) and np.all(np.isfinite(self.part_radii))
                and np.all(self.part_radii > 0)):
            return False, "a part sphere has a non-finite centre or a non-positive radius"
        return self.ready("skin_ok")

    def _ready_clips(self):
        ok, why = self.ready("skeleton")
        if not ok:
            return ok, why
        if not self.clips:
            return False, "no SkelAnimation clips under the SkelRoot"
        return True, ""

    def _ready_proof(self):
        for need in ("spheres", "clips"):
            ok, why = self.ready(need)
            if not ok:
                return ok, why
        if self.shapes_error:
            return False, f"the mesh's blend shapes cannot be posed ({self.shapes_error}) (COL313)"
        if self.skinning_method not in schema.SKINNING_METHODS:
            return False, f"the mesh's skinning method {self.skinning_method!r} is not one the runtime poses (COL312)"
        try:
            for c in self.clips:
                self.clip_data(c)
        except ColliderError as e:
            return False, f"a clip cannot be read: {e}"
        bad = [(n, issues[0][2]) for n, issues in self.clip_sample_issues.items() if issues]
        if bad:
            name, kind = bad[0]
            what = {"length": "samples with the wrong number of joints (COL505)",
                    "singular": "a joint transform that is not invertible (COL518)"}.get(
                        kind, "joint transforms that are not finite (COL503)")
            return False, f"clip {name!r} has {what}"
        return True, ""

    # -- the certificate's view ----------------------------------------------------------------
    @cached_property
    def blend_shapes(self) -> str:
        """What UsdSkel blend shapes the mesh binds ("" for none): :func:`runtime.asset.blend_shapes`."""
        return runtime_asset.blend_shapes(self.mesh) if self.mesh is not None else ""

    @cached_property
    def _shapes_read(self):
        if self.mesh is None or not self.blend_shapes:
            return None, ""
        try:
            return runtime_asset.read_shapes(self.mesh, len(self.points)), ""
        except ColliderError as e:
            return None, str(e)
        except Exception as e:  # pxr raises Tf errors of its own types
            return None, " ".join(str(e).split())[:200] or type(e).__name__

    @property
    def shapes(self):
        """The mesh's blend shapes (:class:`runtime.kernels.skin.Shapes`) or None (none, or
        unreadable: :attr:`shapes_error`)."""
        return self._shapes_read[0]

    @property
    def shapes_error(self) -> str:
        """Why the mesh's blend shapes cannot be posed as written ("" when they can or it has none)."""
        return self._shapes_read[1]

    def shape_weights(self, clip: Clip, times) -> np.ndarray | None:
        """(T, S) blend-shape weights of ``clip`` at ``times`` as UsdSkel interpolates them, or None
        when the mesh has no shapes."""
        if self.shapes is None or not len(self.shapes):
            return None
        return self.clip_data(clip).shape_weights(times, len(self.shapes))

    def clip_data(self, clip: Clip):
        """The clip's raw samples as :class:`runtime.schema.Clip` (what UsdSkel interpolates
        between frames); raises :class:`runtime.errors.ColliderError` when they are malformed."""
        cache = self.__dict__.setdefault("_clip_data", {})
        if clip.name not in cache:
            shapes = self.shapes
            index = {n: i for i, n in enumerate(shapes.names)} if shapes is not None else None
            cache[clip.name] = runtime_asset.read_clip(clip.prim, self.joint_index, index)
        return cache[clip.name]

    @cached_property
    def skinning_method(self) -> str:
        """The mesh's ``primvars:skel:skinningMethod`` (``classicLinear`` when not authored; any
        other token as authored: :func:`runtime.schema.skinning_method`)."""
        return schema.skinning_method(self.mesh) if self.mesh is not None else "classicLinear"

    @cached_property
    def rig(self):
        """The asset as :class:`runtime.certify.Rig` (needs ``ready("proof")``)."""
        from colossus.runtime.certify import Rig

        poff, pverts = self.part_vertices
        return Rig(self.points, self.jidx, self.jw, self.geom_bind, self.bind, self.rest, self.parents,
                   self.part_joint_ids, self.part_centers, self.part_radii, poff, pverts, self.skel_world,
                   skinning_method=self.skinning_method, shapes=self.shapes)
