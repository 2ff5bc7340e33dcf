"""FBX through **ufbx**, evaluated as the authoring tools evaluate it.

Why ufbx and not assimp for FBX: assimp composes every FBX model as ``RSrs`` and ignores inherit
types, pivots' full semantics, geometric transforms in skin binding, ``transform_skin`` and the
skinning type; ufbx (a single-file C loader, https://github.com/ufbx/ufbx, MIT / public domain)
evaluates all of them and is tested against Maya's, 3ds Max's and MotionBuilder's own deformed
meshes.  Measured on ``corpus/dcc`` (tests/references/dcc_errors.py, error / size at the tools'
truth frames): 3ds Max's geometric / pivot transforms 0.66 -> 5.2e-5 (the OBJ's 4 decimals),
Maya's transform_skin 0.58 -> 1.9e-7, Maya's blended skin 0.118 -> 0.040 (its stated bound
0.044).  The registry's ``ufbx`` wheel (0.0.5, by ufbx's author) is the binding.  Its element
lists hand out wrappers without a reference and its evaluated scenes crash at garbage collection,
so every ufbx call runs in a forked child (:func:`_extract_contained`) that takes one reference per
element it reads (:func:`_safe`), keeps every scene alive and leaves by ``os._exit``; only plain
numpy data crosses back.  Arrays are copied out by iteration (its buffer protocol crashes).

What is read and how
--------------------
* **Transforms**: the file loaded with ``inherit_mode_handling = HELPER_NODES`` (ufbx inserts
  scale helper nodes so that every world transform is its parent's times its own ``T R S``, pivots,
  offsets, pre/post rotation and rotation order folded in); each node's local ``T R S`` is
  evaluated by ufbx at every frame of every animation stack on the file's own frame grid
  (``frames_per_second``) and goes to the node-graph builder (:mod:`.scene.build`) as keys at
  those frames.
* **Skins**: a cluster's ``geometry_to_bone`` (mesh geometry space, geometric transform included,
  to bone space at bind time) is the joint's inverse bind; a skinned point is
  ``sum_j w_j W_j(t) @ geometry_to_bone_j @ p`` as ufbx and the FBX SDK skin it.  ``SkinningType``
  DualQuaternion is UsdSkel's dual-quaternion skinning; Maya's per-vertex Blend has no UsdSkel
  form: the nearer method, bounded (:func:`_skinning_method`).
* **Maya's ``transform_skin``**: Maya moves a skinned mesh by its node's change since binding,
  ``C(t) = N(t) @ inv(N_bind)`` (``N``: the mesh node's world transform; ``N_bind`` its bind pose:
  the cluster's bone bind times ``mesh_node_to_bone``).  For a file whose original application is
  Maya, with one skinned mesh node and no rigid mesh under a bone, ``C(t)`` is folded into every
  node's world transform (``sum_j w_j C W_j G_j p = C sum_j w_j W_j G_j p``: the weights sum to
  one).  Elsewhere a ``C(t)`` that is not the identity is not carried (``fbx_transform_skin``,
  bounded).
* **Axes and units**: a right-handed Y-up or Z-up file keeps its axes (``up_axis``); any other
  axis system is converted by ufbx to Y-up at the root.  ``meters_per_unit`` is the file's
  ``UnitScaleFactor`` (ufbx's ``unit_meters``).
* **Geometry**: control points; triangles as they are, quads split at their reflex corner, larger
  polygons by ear clipping in their best-fit plane.

Fail closed
-----------
The keys are checked against an independent evaluation: the file loaded a second time *without*
helper nodes (inherit types evaluated natively, clusters on the real bones), skinned from ufbx's
own node transforms at rest and at :data:`CHECK_FRAMES` frames of every stack; the largest vertex
difference is one ``fbx_evaluation`` record when over :data:`EVAL_TOLERANCE` x the posed size.
Halfway between those frames the same evaluation measures how far the file's curves leave the
keys' lerp / slerp: a resampling bound stated in the summary.  What the collider cannot carry yet
(blend shapes, constraints) is named by :mod:`.fbx_checks` with its bound; more than one instance
of a skinned mesh is ``fbx_instanced_skin`` (the first instance is taken).
"""

from __future__ import annotations

import os

import numpy as np

from .. import notcarried
from ..errors import InputError
from ..model import skel_transforms
from ..xforms import compose_trs, decompose_trs, degenerate, slerp
from . import bounds, fbx_checks, fbx_doc
from .common import AllocationBudget, check_finite, check_input_file
from .scene import Animation, Channel, Scene, SceneMesh, Skin
from .scene.build import build
from .scene.graph import _BAD_XFORM

#: Frames of each clip (evenly spread, ends included) at which the result is checked against
#: ufbx's evaluation, besides the rest pose.
CHECK_FRAMES = 16
#: A difference from ufbx's evaluation larger than this (x the model size) is not carried.
EVAL_TOLERANCE = 1e-6
#: Between frames, a gap from the file's curves larger than this (x the model size, the motion
#: tolerance the references use) is stated in the summary (a resampling bound, not a record).
BETWEEN_TOLERANCE = 1e-4
#: A local transform that changes less than this (relative to its largest entry) over a clip is
#: float32 noise of the stored curves, not motion (the check below still measures it).
MOVED = 1e-7
#: The oldest FBX version ufbx reads (FBX 3.0).
OLDEST_READ = 3000


def available() -> bool:
    """True when the ufbx binding imports."""
    try:
        import ufbx  # noqa: F401
    except Exception:  # noqa: BLE001 - any failure to import means: use the assimp path
        return False
    return True


def _safe(x):
    """Work around ufbx 0.0.5's element lists, which hand out their cached wrappers without a new
    reference (each access would free one): take one reference per access, never released."""
    import ctypes

    import ufbx
    if isinstance(x, ufbx.Element):
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(x))
    return x


def _items(lst) -> list:
    return [_safe(x) for x in lst]


def _m44(m) -> np.ndarray:
    """ufbx Matrix (four column vectors of an affine 3x4) -> 4x4 float64, column-vector convention."""
    out = np.eye(4)
    out[:3, :] = np.asarray(m, dtype=np.float64).reshape(4, 3).T
    return out


def _vec3s(lst) -> np.ndarray:
    return np.array([tuple(v) for v in lst], dtype=np.float64).reshape(-1, 3)


def _u32s(lst) -> np.ndarray:
    return np.fromiter(iter(lst), dtype=np.int64, count=len(lst))


def _reals(lst) -> np.ndarray:
    return np.fromiter(iter(lst), dtype=np.float64, count=len(lst))


def _triangulate(corners: np.ndarray, pts: np.ndarray) -> list:
    """Triangles (control point indices) of one polygon: a fan when convex, else ear clipping in
    the polygon's best-fit plane (Newell normal)."""
    n = len(corners)
    if n < 3:
        return []
    if n == 3:
        return [tuple(corners)]
    p = pts[corners]
    normal = np.zeros(3)
    for i in range(n):
        a, b = p[i], p[(i + 1) % n]
        normal += np.array([(a[1] - b[1]) * (a[2] + b[2]), (a[2] - b[2]) * (a[0] + b[0]), (a[0] - b[0]) * (a[1] + b[1])])
    nn = np.linalg.norm(normal)
    if not np.isfinite(nn) or nn == 0:
        return [(corners[0], corners[i], corners[i + 1]) for i in range(1, n - 1)]
    normal /= nn
    u = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    q = np.c_[p @ u, p @ v]

    def cross(o, a, b):
        return (q[a, 0] - q[o, 0]) * (q[b, 1] - q[o, 1]) - (q[a, 1] - q[o, 1]) * (q[b, 0] - q[o, 0])

    if all(cross(i, (i + 1) % n, (i + 2) % n) >= 0 for i in range(n)):
        return [(corners[0], corners[i], corners[i + 1]) for i in range(1, n - 1)]
    idx = list(range(n))
    out = []
    guard = 0
    while len(idx) > 3 and guard < 4 * n * n:
        guard += 1
        m = len(idx)
        for k in range(m):
            a, b, c = idx[k - 1], idx[k], idx[(k + 1) % m]
            if cross(a, b, c) <= 0:
                continue
            inside = False
            for o in idx:
                if o in (a, b, c):
                    continue
                if cross(a, b, o) >= 0 and cross(b, c, o) >= 0 and cross(c, a, o) >= 0:
                    inside = True
                    break
            if not inside:
                out.append((corners[a], corners[b], corners[c]))
                idx.pop(k)
                break
        else:  # no ear (degenerate or self-intersecting): a fan of what is left
            break
    out += [(corners[idx[0]], corners[idx[i]], corners[idx[i + 1]]) for i in range(1, len(idx) - 1)]
    return out


def _triangles(faces: np.ndarray, vidx: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(m, 3) triangles of every polygon (``faces``: (begin, count) into ``vidx``): triangles as
    they are, quads in one vectorised pass (split at their reflex corner when concave), larger
    polygons by :func:`_triangulate`."""
    begin, count = faces[:, 0], faces[:, 1]
    out = [vidx[begin[count == 3, None] + np.arange(3)]]
    q = np.flatnonzero(count == 4)
    if len(q):
        c = vidx[begin[q, None] + np.arange(4)]                       # (Q, 4)
        p = pts[c]                                                     # (Q, 4, 3)
        e = np.roll(p, -1, axis=1) - p                                 # edge i: corner i -> i + 1
        normal = np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])        # the quad's normal (diagonals)
        turn = np.einsum("qij,qj->qi", np.cross(np.roll(e, 1, axis=1), e), normal)  # at each corner
        reflex = np.where(turn.min(axis=1) < 0, np.argmin(turn, axis=1), 0)
        r = (reflex[:, None] + np.arange(4)) % 4                       # start the fan at the reflex corner
        c = np.take_along_axis(c, r, axis=1)
        out += [c[:, [0, 1, 2]], c[:, [0, 2, 3]]]
    big = np.flatnonzero(count > 4)
    if len(big):
        out.append(np.array([t for i in big for t in _triangulate(vidx[begin[i]:begin[i] + count[i]], pts)],
                            dtype=np.int64).reshape(-1, 3))
    return np.concatenate(out).reshape(-1, 3) if out else np.zeros((0, 3), np.int64)


def _load(path, **opts):
    import ufbx

    def load(**kw):
        try:
            return ufbx.load_file(path, load_external_files=False, **opts, **kw)
        except Exception as exc:  # ufbx reports every parse failure as its own error type
            msg = " ".join(str(exc).split()) or type(exc).__name__
            if "memory" in msg.lower() and "limit" not in msg.lower():
                raise MemoryError(msg) from None
            raise InputError(path, f"not a readable FBX file: {msg}") from None

    scene = load()
    A = ufbx.CoordinateAxis
    axes = scene.settings.axes
    frame = (axes.right, axes.up, axes.front)
    if frame == (A.POSITIVE_X, A.POSITIVE_Y, A.POSITIVE_Z):
        return scene, "Y", "FBX axes: right-handed Y-up"
    if frame == (A.POSITIVE_X, A.POSITIVE_Z, A.NEGATIVE_Y):
        return scene, "Z", "FBX axes: right-handed Z-up"
    scene = load(target_axes=ufbx.CoordinateAxes(A.POSITIVE_X, A.POSITIVE_Y, A.POSITIVE_Z),
                 space_conversion=ufbx.SpaceConversion.TRANSFORM_ROOT)
    return scene, "Y", (f"FBX axes right={axes.right.name} up={axes.up.name} front={axes.front.name}, "
                        "converted to right-handed Y-up by ufbx")


#: Every ufbx scene read stays referenced for the life of the process: the 0.0.5 binding's element
#: wrappers (leaked on purpose, :func:`_safe`) must never outlive the scene they point into.
_KEEP = []


def _local(tr) -> np.ndarray:
    """ufbx Transform (translation, rotation quaternion x y z w, scale) -> 4x4 ``T R S``; all NaN
    when ufbx could not make a rotation of it (a non-finite Euler curve value): refused later as a
    degenerate transform, in one line."""
    q = np.array(tuple(tr.rotation), dtype=np.float64)
    with np.errstate(all="ignore"):
        n = float(np.linalg.norm(q))
    if not (np.isfinite(n) and n > 1e-12):
        return np.full((4, 4), np.nan)
    return compose_trs(np.array(tuple(tr.translation)), q / n, np.array(tuple(tr.scale)))


class _Graph:
    """Nodes parents-first with their world transforms: composing and splitting (plain numpy)."""

    def __init__(self, names, parents, world, theirs):
        self.names, self.parents, self.world, self.theirs = names, parents, world, theirs

    def compose(self, local) -> np.ndarray:
        """World transforms (..., k, 4, 4) of local ones (:func:`pipeline.model.skel_transforms`)."""
        return skel_transforms(local, self.parents)

    def locals_of_many(self, worlds) -> np.ndarray:
        return np.array([self.locals_of(w) for w in worlds]).reshape(worlds.shape)

    def locals_of(self, world) -> np.ndarray:
        out = world.copy()
        p = self.parents
        has = p >= 0
        if np.any(has):
            with np.errstate(all="ignore"):
                out[has] = np.linalg.solve(world[p[has]], world[has])
        return out


class _Read(_Graph):
    """The ufbx scene walked once: nodes parents-first, their world transforms, the meshes.

    The scene is loaded with ``inherit_mode_handling = HELPER_NODES``: ufbx inserts scale helper
    nodes where a model does not inherit its parent's scale the normal way, so that every world
    transform is its parent's times its local ``T R S`` (pivots, offsets and pre/post rotations
    folded in by ufbx); :meth:`worlds_at` composes them, and the rest pose is checked against
    ufbx's own ``node_to_world``.
    """

    def __init__(self, path, scene, budget):
        self.path, self.scene = path, scene
        nodes = _items(scene.nodes)
        budget.claim(len(nodes) * 2000, f"{len(nodes)} nodes")
        index = {n.typed_id: i for i, n in enumerate(nodes)}
        parents = []
        for i, n in enumerate(nodes):
            p = n.parent
            q = index.get(_safe(p).typed_id, -1) if p is not None else -1
            if q >= i:
                raise InputError(path, "the node hierarchy is not ordered parents first (corrupt file?)")
            parents.append(q)
        self.nodes = nodes
        self.parents = np.array(parents, dtype=np.int64)
        self.index = index
        self.names = [n.name or ("RootNode" if n.is_root else f"node{i}") for i, n in enumerate(nodes)]
        self.helpers = {i for i, n in enumerate(nodes) if n.is_scale_helper or n.is_geometry_transform_helper}
        self.world = self.compose(np.array([_local(n.local_transform) for n in nodes]))
        check_finite(path, "node transforms", self.world.reshape(len(nodes), 16))
        #: ufbx's own world transforms at rest (the reference the composition is checked against)
        self.theirs = np.array([_m44(n.node_to_world) for n in nodes]).reshape(-1, 4, 4)

    def worlds_at(self, anim, t: float) -> np.ndarray:
        import ufbx
        return self.compose(np.array([_local(ufbx.evaluate_transform(anim, n, t)) for n in self.nodes]))


def _mesh_records(r: _Read, budget, notes, items):
    """(SceneMesh list, skinned info list) of every mesh instance ufbx found."""
    meshes, skinned = [], []
    for node_i, node in enumerate(r.nodes):
        mesh = node.mesh
        if mesh is None:
            continue
        mesh = _safe(mesh)
        nv = int(mesh.num_vertices)
        budget.claim(nv * 200 + int(mesh.num_indices) * 60, f"mesh {node.name!r} ({nv} vertices)")
        pts = _vec3s(mesh.vertices)
        check_finite(r.path, f"mesh {node.name!r} positions", pts)
        vidx = _u32s(mesh.vertex_indices)
        if len(vidx) and vidx.max() >= nv:
            raise InputError(r.path, f"mesh {node.name!r}: a face index is out of range for {nv} vertices")
        faces = np.array([tuple(f) for f in mesh.faces], dtype=np.int64).reshape(-1, 2)
        tri = _triangles(faces, vidx, pts)
        instances = _items(mesh.instances)
        skins = _items(mesh.skin_deformers)
        skin = None
        to_world = _m44(node.geometry_to_world)
        if skins:
            if instances and instances[0].typed_id != node.typed_id:
                continue  # a later instance of a skinned mesh: fbx_instanced_skin below
            if len(instances) > 1:
                items.append(notcarried.item(
                    "fbx_instanced_skin", [n.name for n in instances],
                    f"skinned mesh {node.name!r} is instanced by {len(instances)} models; the first is taken"))
            if len(skins) > 1:
                items.append(notcarried.item(
                    "fbx_skin_deformers", node.name,
                    f"mesh {node.name!r} has {len(skins)} skin deformers; the first is taken"))
            sk = skins[0]
            clusters = _items(sk.clusters)
            joints, ibms, names, vv, jj, ww = [], [], [], [], [], []
            for ci, c in enumerate(clusters):
                bone = c.bone_node
                ids = _u32s(c.vertices)
                w = _reals(c.weights)
                if len(ids) != len(w) or (len(ids) and ids.max() >= nv):
                    raise InputError(r.path, f"skin cluster {c.name!r}: vertex indices and weights do not match the mesh")
                check_finite(r.path, f"skin cluster {c.name!r} weights", w[:, None])
                if len(w) and w.min() < 0:
                    raise InputError(r.path, f"skin cluster {c.name!r} has negative weights")
                g2b = _m44(c.geometry_to_bone)
                check_finite(r.path, f"skin cluster {c.name!r} bind matrix", g2b.reshape(1, 16))
                if ci == 0:  # the mesh geometry's world transform at bind time (its bone's bind
                    # pose times geometry_to_bone; the cluster's geometry_to_world is not that)
                    to_world = _m44(c.bind_to_world) @ g2b
                joints.append(r.index.get(_safe(bone).typed_id, -1) if bone is not None else -1)
                ibms.append(g2b)
                names.append(bone.name if bone is not None else c.name)
                vv.append(ids)
                jj.append(np.full(len(ids), ci, dtype=np.int64))
                ww.append(w)
            if clusters:
                skin = Skin(np.array(joints, dtype=np.int64), np.array(ibms), names,
                            np.concatenate(vv), np.concatenate(jj), np.concatenate(ww))
                method = sk.skinning_method.name
                dq = np.full(nv, 1.0 if method == "DUAL_QUATERNION" else 0.0)
                if method == "BLENDED_DQ_LINEAR":
                    dv, dw = _u32s(sk.dq_vertices), _reals(sk.dq_weights)
                    if len(dv) == len(dw) and (not len(dv) or dv.max() < nv):
                        dq[dv] = np.clip(dw, 0.0, 1.0)
                skinned.append({"node": node_i, "name": node.name, "mesh": mesh.name or node.name, "points": pts,
                                "skin": skin, "method": method, "dq": dq,
                                "bind_world": _m44(clusters[0].bind_to_world) @ _m44(clusters[0].mesh_node_to_bone)})
        shapes = sum(len(_items(bd.channels)) for bd in _items(mesh.blend_deformers))
        meshes.append(SceneMesh(name=mesh.name or node.name, node=node_i, positions=pts, triangles=tri, to_world=to_world,
                                skin=skin, morph_targets=shapes, shapes=_blend_shapes(r.path, mesh, nv)))
    return meshes, skinned


def _blend_channels(mesh) -> list:
    """The mesh's blend channels (every blend deformer's, in order) that have keyframes."""
    out = []
    for bd in _items(mesh.blend_deformers):
        for ch in _items(_safe(bd).channels):
            if _items(ch.keyframes):
                out.append(_safe(ch))
    return out


def _blend_shapes(path, mesh, nv) -> list:
    """FBX blend channels as :class:`model.BlendShape` (mesh space, control points): a channel's
    keyframes (its target shapes at ``FullWeights`` / 100, ufbx's ``target_weight``) are the knots
    of UsdSkel's piecewise-linear interpolation, the last one the primary shape at weight 1 (the
    others in-betweens at ``target_weight / last``, and the channel's ``DeformPercent`` / 100
    divided by the last one is the UsdSkel weight: :func:`_stack_shape_weights`); every keyframe's
    offsets on the union of their vertices (0 where a shape does not move one)."""
    from ..model import BlendShape

    out = []
    for ch in _blend_channels(mesh):
        kfs = sorted(_items(ch.keyframes), key=lambda k: float(k.target_weight))
        tws = np.array([float(k.target_weight) for k in kfs])
        last = tws[-1]
        if not (np.isfinite(tws).all() and last > 0 and (tws > 0).all() and len(np.unique(tws)) == len(tws)):
            raise InputError(path, f"blend channel {ch.name!r}: in-between weights {tws.tolist()} (expected "
                             "distinct positive FullWeights)")
        per = []
        for k in kfs:
            sh = _safe(k.shape)
            idx = _u32s(sh.offset_vertices).astype(np.int64)
            off = _vec3s(sh.position_offsets) if len(idx) else np.zeros((0, 3))
            if len(idx) != len(off) or (len(idx) and idx.max() >= nv):
                raise InputError(path, f"blend shape {sh.name!r}: offsets do not match the mesh's {nv} control points")
            check_finite(path, f"blend shape {sh.name!r} offsets", off if len(off) else np.zeros((1, 3)))
            per.append((idx, off))
        union = np.unique(np.concatenate([i for i, _ in per])) if per else np.zeros(0, np.int64)
        pos = {int(v): n for n, v in enumerate(union)}

        def dense(idx, off):
            d = np.zeros((len(union), 3))
            d[[pos[int(v)] for v in idx]] = off
            return d
        knots = [dense(i, o) for i, o in per]
        out.append(BlendShape(ch.name or f"channel_{len(out)}", union, knots[-1],
                              tuple((float(t / last), kn) for t, kn in zip(tws[:-1], knots[:-1]))))
    return out


def _stack_shape_weights(r, scene_meshes, stacks) -> list:
    """Per stack, ``{scene mesh index: (f, S) weights}``: each blend channel's DeformPercent as
    ufbx evaluates it at the stack's frames (``evaluate_blend_weight``), over its last keyframe's
    target weight (the UsdSkel weight of :func:`_blend_shapes`)."""
    import ufbx

    by_stack = {st.name: st for st in _items(r.scene.anim_stacks)}
    out = []
    for name, _, seconds, _ in stacks:
        st = by_stack.get(name)
        per = {}
        for mi, sm in enumerate(scene_meshes):
            if not sm.shapes or st is None:
                continue
            mesh = _safe(r.nodes[sm.node].mesh)
            chans = _blend_channels(mesh)
            last = np.array([max(float(k.target_weight) for k in _items(c.keyframes)) for c in chans])
            w = np.array([[float(ufbx.evaluate_blend_weight(st.anim, c, float(t))) for c in chans] for t in seconds])
            check_finite(r.path, f"blend weights of mesh {sm.name!r} in {name!r}", w.reshape(len(seconds), -1))
            per[mi] = w / last[None]
        out.append(per)
    return out


def _shape_channels(x, si, seconds) -> list:
    """Stack ``si``'s blend weights (:func:`_stack_shape_weights`) as weight channels, one per
    scene mesh, sampled on the stack's frames (lerped between them, as UsdSkel does)."""
    per = x.shape_weights[si] if getattr(x, "shape_weights", None) else {}
    return [Channel(mi, "w", np.asarray(seconds, dtype=np.float64), w, "LINEAR") for mi, w in per.items()]


def _bones_below(parents, meshes) -> bool:
    """True when an unskinned mesh hangs under a bone of a skin (it would move rigidly)."""
    bones = {int(j) for m in meshes if m.skin is not None for j in m.skin.joints if j >= 0}
    for m in meshes:
        if m.skin is not None:
            continue
        a = parents[m.node]
        while a >= 0:
            if a in bones:
                return True
            a = parents[a]
    return False


def _sample_stacks(r: _Read, fps: float, budget):
    """``[(name, span, seconds, worlds (f, k, 4, 4))]`` of every animation stack, on its frame grid."""
    out = []
    for st in _items(r.scene.anim_stacks):
        t0, t1 = float(st.time_begin), float(st.time_end)
        if not (np.isfinite(t0) and np.isfinite(t1)) or t1 < t0:
            continue
        n = int(np.floor((t1 - t0) * fps + 1e-6)) + 1
        budget.claim(n * len(r.nodes) * 16 * 8 * 4, f"animation {st.name!r} ({n} frames)")
        seconds = t0 + np.arange(n) / fps
        anim = st.anim
        worlds = np.array([r.worlds_at(anim, float(t)) for t in seconds])
        check_finite(r.path, f"animation {st.name!r} transforms", worlds.reshape(-1, 16))
        out.append((st.name, (t0, t1), seconds, worlds))
    return out


def _channels(r: _Read, rest_local, seconds, local):
    """Translation / rotation / scale keys of every node whose local transform ``local``
    (f, k, 4, 4) leaves its rest value at some frame, and the locals those keys recompose to (for
    the check)."""
    # moved: beyond float32 noise of the file's own values (curves are stored in float32)
    scale = 1.0 + np.maximum(np.abs(rest_local).max(axis=(1, 2)), np.abs(local).max(axis=(0, 2, 3)))
    moved = np.abs(local - rest_local[None]).max(axis=(0, 2, 3)) > MOVED * scale
    chans, trs = [], {}
    recomposed = np.broadcast_to(rest_local, local.shape).copy()
    for k in np.flatnonzero(moved):
        t, q, s = decompose_trs(local[:, k])
        # one hemisphere from key to key, so that slerp between frames takes the short way
        for i in range(1, len(q)):
            if np.dot(q[i], q[i - 1]) < 0:
                q[i] = -q[i]
        recomposed[:, k] = compose_trs(t, q, s)
        trs[int(k)] = (t, q, s)
        chans += [Channel(int(k), "t", seconds, t, "LINEAR"), Channel(int(k), "r", seconds, q, "LINEAR"),
                  Channel(int(k), "s", seconds, s, "LINEAR")]
    return chans, recomposed, trs


def _halfway(rest_local, trs, f) -> np.ndarray:
    """Local transforms halfway between frames ``f`` and ``f + 1`` as UsdSkel interpolates the keys
    (lerp translations and scales, slerp rotations)."""
    out = rest_local.copy()
    for k, (t, q, s) in trs.items():
        out[k] = compose_trs(0.5 * (t[f] + t[f + 1]), slerp(q[f], q[f + 1], 0.5), 0.5 * (s[f] + s[f + 1]))
    return out


def _lbs(info, world) -> np.ndarray:
    """Exact skinned points of one skin at node worlds ``world`` (k, 4, 4)."""
    s = info["skin"]
    p = np.c_[info["points"], np.ones(len(info["points"]))]
    out = np.zeros((len(p), 3))
    tot = np.zeros(len(p))
    for ci in range(len(s.joints)):
        sel = s.joint == ci
        if not np.any(sel) or s.joints[ci] < 0:
            continue
        m = world[s.joints[ci]] @ s.inverse_binds[ci]
        v = s.vertex[sel]
        np.add.at(out, v, s.weight[sel, None] * (p[v] @ m[:3, :].T))
        np.add.at(tot, v, s.weight[sel])
    live = tot > 0
    out[live] /= tot[live, None]
    return out[live]


class _Extracted:
    """Everything the reader needs from ufbx, as plain data (picklable: it crosses the fork)."""

    def __init__(self, **kw):
        self.__dict__.update(kw)


def _extract(path, budget) -> _Extracted:
    """Read the file with ufbx (in the contained child: :func:`read_ufbx`)."""
    import ufbx

    scene, up, frame_note = _load(path, inherit_mode_handling=ufbx.InheritModeHandling.HELPER_NODES)
    _KEEP.append(scene)
    r = _Read(path, scene, budget)
    items = []
    scene_meshes, skinned = _mesh_records(r, budget, [], items)
    rate = float(scene.settings.frames_per_second or 0.0)
    if not (np.isfinite(rate) and 0 < rate <= 1000):
        rate = 30.0
    stacks = _sample_stacks(r, rate, budget)
    shape_weights = _stack_shape_weights(r, scene_meshes, stacks)
    exact = _independent(path, skinned, stacks)
    return _Extracted(exact=exact, up=up, frame_note=frame_note, unit_meters=float(scene.settings.unit_meters or 0.01),
                      app=str(scene.metadata.original_application.name or ""), rate=rate, names=r.names,
                      parents=r.parents, helpers=r.helpers, world=r.world, theirs=r.theirs,
                      meshes=scene_meshes, skinned=skinned, items=items, stacks=stacks, shape_weights=shape_weights)


def _independent(path, skinned, stacks) -> dict:
    """``{label: [(points (n, 3), node world (4, 4)) of each skinned mesh]}``: the skinned control
    points (and the mesh node's world transform, for transform_skin) as ufbx's own
    scene evaluates them, with the file loaded again *without* helper nodes (inherit types
    evaluated natively, clusters bound to the real bones): ``sum_j w_j W_j geometry_to_bone_j p``
    at rest and at :func:`_check_frames` of every stack.  The reference the keys are checked
    against.  The evaluated scenes are freed by the process exit (the contained child), never by
    the binding's garbage collection."""
    import gc

    gc.disable()
    scene, _, _ = _load(path)
    _KEEP.append(scene)

    def points(sc):
        by_name = {}
        for n in _items(sc.nodes):
            if n.mesh is not None and _items(n.mesh.skin_deformers):
                by_name.setdefault(n.name, n)
        out = []
        for info in skinned:
            node = by_name.get(info["name"])
            if node is None:
                return None
            mesh = _safe(node.mesh)
            clusters = _items(_items(mesh.skin_deformers)[0].clusters)
            p = np.c_[info["points"], np.ones(len(info["points"]))]
            acc, tot = np.zeros((len(p), 3)), np.zeros(len(p))
            for c in clusters:
                if c.bone_node is None:
                    continue
                m = _m44(_safe(c.bone_node).node_to_world) @ _m44(c.geometry_to_bone)
                v, w = _u32s(c.vertices), _reals(c.weights)
                np.add.at(acc, v, w[:, None] * (p[v] @ m[:3, :].T))
                np.add.at(tot, v, w)
            live = tot > 0
            acc[live] /= tot[live, None]
            out.append((acc[live], _m44(node.node_to_world)))
        return out

    out = {"rest": points(scene)}
    by_name = {st.name: st for st in _items(scene.anim_stacks)}
    for name, _, seconds, _ in stacks:
        st = by_name.get(name)
        if st is None:
            continue
        for f in _check_frames(len(seconds)):
            ev = scene.evaluate(st.anim, float(seconds[f]))
            _KEEP.append(ev)
            out[f"{name} at {seconds[f]:.4g} s"] = points(ev)
            if f + 1 < len(seconds):  # halfway to the next frame: the curves between the samples
                mid = 0.5 * (seconds[f] + seconds[f + 1])
                ev = scene.evaluate(st.anim, float(mid))
                _KEEP.append(ev)
                out[f"{name} between frames at {mid:.4g} s"] = points(ev)
    return {k: v for k, v in out.items() if v is not None}


def _extract_contained(path, budget):
    """:func:`_extract` in a forked child: the binding's memory errors (a crash at garbage
    collection after its scenes are freed) can never reach this process, and the child leaves
    by ``os._exit``.  Inside the import's own contained child this is a second, cheap fork."""
    from .. import isolation
    try:
        return isolation.contained(_extract, path, budget, path=path, timeout=600)
    except isolation.ChildFailed as e:
        raise InputError(path, f"ufbx could not read it ({e.reason})") from None


def read_ufbx(path, meshes=None, fps=None):
    """Read a skinned mesh and all its clips from an FBX file through ufbx (module docstring)."""
    path = os.fspath(path)
    size = check_input_file(path)
    budget = AllocationBudget(path, size)
    version = fbx_doc.file_version(path)
    if version is not None and 0 < version < OLDEST_READ:
        raise InputError(path, f"FBX version {version} is not read (ufbx reads FBX 3.0 and later)")
    x = _extract_contained(path, budget)
    budget.claim(sum(w.nbytes for *_, w in x.stacks), "the sampled animation")
    items, notes = list(x.items), []
    scene_meshes, skinned, stacks, app = x.meshes, x.skinned, x.stacks, x.app
    if not scene_meshes:
        raise InputError(path, "the scene has no mesh")
    r = _Graph(x.names, x.parents, x.world, x.theirs)
    # a transform no joint can take (not finite, huge, zero or collapsed scale) on a mesh's or a
    # bone's chain: refused here, before anything inverts or decomposes it, as check_scene refuses
    # it for the other readers (a node elsewhere may scale to 0: a prop hidden that way)
    chain = set()
    for m in scene_meshes:
        for n in [m.node, *([int(j) for j in m.skin.joints if j >= 0] if m.skin is not None else [])]:
            while n >= 0 and n not in chain:
                chain.add(n)
                n = int(x.parents[n])
    chain = np.array(sorted(chain), dtype=np.int64)
    stack_locals = []  # each stack's local transforms, computed once: checked here, keyed below
    for label, worlds in [("at rest", x.world[None])] + [(f"in animation {n!r}", w) for n, _, _, w in x.stacks]:
        with np.errstate(all="ignore"):
            local = r.locals_of_many(worlds)
            bad = np.argwhere(degenerate(worlds[:, chain]) | degenerate(local[:, chain]))
        if len(bad):
            raise InputError(path, f"the transform of node {x.names[chain[bad[0][1]]]!r} {label} {_BAD_XFORM}")
        stack_locals.append(local)
    stack_locals = stack_locals[1:]

    # transform_skin: C = N @ inv(N_bind) of the one skinned mesh node, at rest and at every frame
    fold, moved_by = False, 0.0
    if len(skinned) == 1:
        info = skinned[0]
        try:
            inv_bind = np.linalg.inv(info["bind_world"])
        except np.linalg.LinAlgError:
            raise InputError(path, f"skinned mesh {info['name']!r} has a singular bind transform") from None
        c_rest = r.world[info["node"]] @ inv_bind
        c_frames = [worlds[:, info["node"]] @ inv_bind for _, _, _, worlds in stacks]
        moves = not all(np.allclose(c, np.eye(4), rtol=0, atol=1e-9 * (1 + np.abs(info["bind_world"]).max()))
                        for c in [c_rest, *[x for cf in c_frames for x in cf]])
        if moves and "maya" in app.lower() and not _bones_below(r.parents, scene_meshes):
            fold = True
            r.world, r.theirs = c_rest @ r.world, c_rest @ r.theirs
            stacks = [(n, sp, sec, cf[:, None] @ w) for (n, sp, sec, w), cf in zip(stacks, c_frames)]
            roots = r.parents < 0  # C moves the roots' locals only: a child's is its parent's inverse times its own
            for local, cf in zip(stack_locals, c_frames):
                local[:, roots] = cf[:, None] @ local[:, roots]
        elif moves:
            worst = 0.0
            for world, c in [(r.world, c_rest)] + [
                    (w[f], cf[f]) for (n, _, _, w), cf in zip(stacks, c_frames) for f in _check_frames(len(w))]:
                a = _lbs(info, world)
                if len(a):
                    worst = max(worst, float(np.max(np.linalg.norm(a @ c[:3, :3].T + c[:3, 3] - a, axis=1))))
            moved_by = worst
    rest_local = r.locals_of(r.world)

    anims = []
    between = []
    checks = [("rest", r.compose(rest_local))]
    for si, (name, span, seconds, worlds) in enumerate(stacks):
        chans, recomposed, trs = _channels(r, rest_local, seconds, stack_locals[si])
        anims.append(Animation(name, chans, span, weights=_shape_channels(x, si, seconds)))
        for f in _check_frames(len(seconds)):
            label = f"{name} at {seconds[f]:.4g} s"
            checks.append((label, r.compose(recomposed[f])))
            if f + 1 < len(seconds):
                mid = f"{name} between frames at {0.5 * (seconds[f] + seconds[f + 1]):.4g} s"
                between.append((mid, r.compose(_halfway(rest_local, trs, f))))

    sc = Scene(names=x.names, parents=x.parents, local=rest_local, meshes=scene_meshes, animations=anims,
               notes=notes, helpers=x.helpers, fps_hint=x.rate, unweighted_follow_node=True,
               sampling_note=f"FBX evaluated by ufbx at every frame of {x.rate:g} fps; lerp / slerp between")
    mesh = build(sc, path, meshes=meshes, fps=fps, budget=budget,
                 source={"file": os.path.basename(path), "format": "fbx", "reader": "ufbx",
                         "frame": f"{x.frame_note}, {x.unit_meters:g} m per unit"
                                  + (f"; {app}'s transform_skin applied (the skin moves with its node)" if fold else "")})

    # fail closed: the keys against the exact evaluation; the bounds relative to the posed size
    size_ref = bounds.posed_size(mesh) or 1.0
    if moved_by / size_ref > EVAL_TOLERANCE:
        items.append(notcarried.item(
            "fbx_transform_skin", skinned[0]["name"],
            f"the skinned mesh's node moved after binding; {app or 'the authoring tool'} may move the skin "
            "with it (Maya does), the FBX SDK does not: taken as the FBX SDK", moved_by / size_ref))
    # Maya's transform_skin on the reference side: its own mesh node's change since binding
    def transform_skin(label, info, node_world):
        return node_world @ np.linalg.inv(info["bind_world"]) if fold else None

    worst, where = _largest_gap(checks, x.exact, skinned, size_ref, transform_skin)
    # between frames: the file's curves against the keys' lerp / slerp (a resampling error, the
    # same for every reader that samples curves on a grid; stated when over the motion tolerance)
    gap, gap_at = _largest_gap(between, x.exact, skinned, size_ref, transform_skin, missing=0.0)
    mesh.source["between_frames"] = {"bound_relative": gap, "where": gap_at}
    if gap > BETWEEN_TOLERANCE:
        mesh.source["notes"] = mesh.source.get("notes", []) + [
            f"between its {x.rate:g} fps frames the file's curves are up to {gap:.2g} x the model size off the "
            f"frames' lerp / slerp ({gap_at}); engines that sample FBX animation per frame play the frames' "
            "interpolation too; a higher --fps follows the curves closer"]
    if worst > EVAL_TOLERANCE:
        items.append(notcarried.item(
            "fbx_evaluation", where, "the joint keys cannot hold the file's transforms exactly (shear, or a "
            "transform ufbx composes differently from its parent's times its own)",
            worst if np.isfinite(worst) else None))

    mesh, method_items = _skinning_method(mesh, skinned)
    items = method_items + items
    doc = fbx_doc.read_document(path)
    items = fbx_checks.check(doc, mesh, None, only=fbx_checks.UFBX_CHECKS) + items
    mesh.source["not_carried"] = fbx_checks.morph_records(doc, mesh) + items
    return mesh.replace(up_axis=x.up, meters_per_unit=x.unit_meters)




def _largest_gap(pairs, exact, skinned, size_ref, correction, missing=np.inf):
    """``(largest / size_ref, label)`` of the vertex distance between ufbx's own skinned points
    ``exact[label]`` (moved by ``correction(label, info, node_world)`` when not None: Maya's
    transform_skin) and our keys' ``_lbs(info, ours)`` over ``pairs`` ``[(label, ours)]``; a label
    with no reference counts as ``missing`` (infinite: unchecked)."""
    worst, where = 0.0, ""
    for label, ours in pairs:
        ref = exact.get(label)
        if ref is None:
            if missing > worst:
                worst, where = missing, label
            continue
        for info, (a, node_world) in zip(skinned, ref):
            c = correction(label, info, node_world)
            if c is not None:
                a = a @ c[:3, :3].T + c[:3, 3]
            b = _lbs(info, ours)
            if len(a) and len(a) == len(b):
                d = float(np.max(np.linalg.norm(a - b, axis=1))) / size_ref
                if d > worst:
                    worst, where = d, label
    return worst, where


def _skinning_method(mesh, skinned):
    """``(mesh, records)``: the mesh skinned as its FBX skins say.  ``SkinningType`` Linear / Rigid
    is linear blend skinning; DualQuaternion is UsdSkel's dual-quaternion skinning (exact); Maya's
    Blend mixes the two per vertex (``BlendWeights`` ``w``: ``(1 - w) P_linear + w P_dq``), which
    UsdSkel cannot say: the method nearer over the frames is taken, and the record's bound is what
    it moves a vertex, ``max w |P_dq - P_lin|`` (linear taken) or ``max (1 - w) |P_dq - P_lin|``
    (dual quaternion taken), at the frames, over the posed size."""
    from colossus.runtime.kernels import skin as SK

    w = np.zeros(mesh.vertex_count)
    skinned_rows = np.zeros(mesh.vertex_count, bool)
    by_mesh = {i["mesh"]: i for i in skinned}
    base = 0
    for info in mesh.source.get("mesh_info") or []:
        n = int(info["vertices"])
        if info["name"] in by_mesh and len(by_mesh[info["name"]]["dq"]) == n:
            w[base:base + n] = by_mesh[info["name"]]["dq"]
            skinned_rows[base:base + n] = True
        base += n
    live = w[skinned_rows]
    if not len(live) or np.all(live == 0.0):
        return mesh, []
    if np.all(live == 1.0):
        return mesh.replace(skinning_method=SK.DUAL_QUATERNION), []
    which = bounds.frames(mesh)
    skin = bounds.skel_at(mesh, which) @ np.linalg.inv(mesh.bind_transforms)
    p_lin = SK.skin_frames(mesh.positions, mesh.joint_indices, mesh.joint_weights,
                           SK.fold_method(SK.CLASSIC_LINEAR, skin, mesh.geom_bind), dtype=np.float64)
    p_dq = SK.skin_frames(mesh.positions, mesh.joint_indices, mesh.joint_weights,
                          SK.fold_method(SK.DUAL_QUATERNION, skin, mesh.geom_bind), dtype=np.float64)
    gap = np.linalg.norm(p_dq - p_lin, axis=-1)                       # (f, n)
    size = bounds.posed_size(mesh, p_lin) or 1.0
    err_lin = float(np.max(np.where(skinned_rows, w, 0.0) * gap)) / size
    err_dq = float(np.max(np.where(skinned_rows, 1.0 - w, 0.0) * gap)) / size
    method, err = (SK.CLASSIC_LINEAR, err_lin) if err_lin <= err_dq else (SK.DUAL_QUATERNION, err_dq)
    names = sorted({i["mesh"] for i in skinned if np.any((i["dq"] > 0) & (i["dq"] < 1)) or i["method"] == "BLENDED_DQ_LINEAR"})
    mesh = mesh.replace(skinning_method=method)
    rec = notcarried.item(
        "fbx_skinning_type", names,
        f"Skin SkinningType Blend: per-vertex blended linear / dual-quaternion skinning "
        f"({int(np.count_nonzero(live))} of {len(live)} vertices with a non-zero BlendWeight, up to "
        f"{float(live.max()):.3g}) has no UsdSkel form; skinned as {method}, the nearer (the other: "
        f"{max(err_lin, err_dq):.2g} x size)", err)
    return mesh, [rec]


def _check_frames(n: int) -> np.ndarray:
    return np.unique(np.linspace(0, n - 1, min(CHECK_FRAMES, n)).round().astype(int)) if n else np.zeros(0, int)
