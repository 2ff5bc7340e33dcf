"""Reader for USD (``.usd``, ``.usda``, ``.usdc``, ``.usdz``) skinned meshes, through usd-core's UsdSkel.

The stage becomes a :class:`~pipeline.readers.scene.Scene` and goes through the same
:func:`~pipeline.readers.scene.build.build` as every node-graph format:

* Nodes: one per Skeleton prim (its local-to-world transform, animated when the prims above it
  are), with that skeleton's joints under it (their ``restTransforms``, what UsdSkel poses a
  joint with when no animation drives it; the bind pose made joint-local where absent).
  Several skeletons in one file become one skeleton with several roots; ``--mesh`` narrows it.
* Meshes: every ``Mesh`` with joint influences bound to a skeleton, its points put through
  ``geomBindTransform``; constant interpolation (a rigid binding) applies the one set of
  influences to every point.  Each skin's inverse binds are the inverse ``bindTransforms``.
* Clips: the animations bound as ``skel:animationSource`` play together as the first clip (what
  usdview shows); every other ``SkelAnimation`` is a clip of its own, driving the skeleton whose
  joints it names.  Each of ``translations``, ``rotations`` and ``scales`` is a channel with its
  own time samples, interpolated as UsdSkel does (lerp, and slerp for rotations).  Time codes
  become seconds through ``timeCodesPerSecond``.
* Units and axes come from the stage's ``metersPerUnit`` and ``upAxis``.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import InputError, one_line
from ..tolerances import LARGEST_COORDINATE
from ..xforms import decompose_trs, degenerate
from .common import AllocationBudget, check_finite, check_input_file
from .scene import Animation, Channel, Scene, SceneMesh, Skin
from .scene.build import build


def _m44(values) -> np.ndarray:
    """Gf.Matrix4d or VtMatrix4dArray (row-vector) -> column-vector float64 (..., 4, 4)."""
    a = np.array(values, dtype=np.float64)
    return np.swapaxes(a.reshape(-1, 4, 4), -1, -2) if a.ndim != 2 else a.T


#: Layers a source's composition may bring in at most (a bound on the walk of :func:`_check_arcs`).
MAX_LAYERS = 1000


def _check_arcs(path) -> None:
    """Refuse, before anything is composed, a source whose sublayers, references, payloads or
    value clips name a file outside its folder, a FIFO, a device or a directory
    (:mod:`runtime.references`; ``--allow-outside-references`` lifts the folder rule).  Each
    referenced layer is read with ``Sdf`` alone and checked the same way, recursively.  Members of
    a ``.usdz`` package are inside it by construction: only absolute paths, URIs and '..' escapes
    are refused there."""
    from pxr import Tf

    from colossus.runtime.references import OutsideReference, layer_references, resolve

    todo, seen = [os.path.abspath(path)], set()
    while todo:
        layer = todo.pop()
        if layer in seen:
            continue
        seen.add(layer)
        if len(seen) > MAX_LAYERS:
            raise InputError(path, f"its composition names more than {MAX_LAYERS} layers")
        try:
            refs = layer_references(layer, composition_only=True)
        except Tf.ErrorException as exc:
            if layer == os.path.abspath(path):  # never composed: usd-core would follow the arcs
                # it parsed of a broken layer before failing (a FIFO sublayer hung it)
                raise InputError(path, f"not a readable USD file: {one_line(exc, 200)}") from None
            raise InputError(path, f"a layer it references cannot be read: {os.path.basename(layer)}") from None
        packaged = layer.lower().endswith(".usdz")
        for ref in refs:
            what = f"layer {os.path.basename(layer)!r} references" if layer != os.path.abspath(path) else "reference"
            if packaged and not (os.path.isabs(ref) or ".." in ref.replace("\\", "/").split("/") or ":" in ref.split("/")[0]):
                continue
            try:
                target = resolve(layer, ref, what)
            except OutsideReference as e:
                raise InputError(path, str(e)) from None
            if os.path.realpath(target) == os.path.realpath(layer):
                # USD composes a file's reference to itself as a second copy of its prims (a
                # self-referencing arc doubled an import's geometry): never what an export means
                raise InputError(path, f"{what} {ref!r}: the file itself (its prims would be composed twice)")
            todo.append(target)


def _open(path):
    from pxr import Tf, Usd
    _check_arcs(path)
    try:
        stage = Usd.Stage.Open(path, Usd.Stage.LoadAll)
    except Tf.ErrorException as exc:  # one_line: usd-core's reason only, cut, even if not UTF-8
        raise InputError(path, f"not a readable USD file: {one_line(exc, 200)}") from None
    if stage is None:
        raise InputError(path, "not a readable USD file")
    errors = stage.GetCompositionErrors()
    if errors:  # what validate reports as COL101 is a refusal here, never a silent partial stage
        more = f" (+{len(errors) - 1} more)" if len(errors) > 1 else ""
        raise InputError(path, f"its composition fails: {one_line(str(errors[0]), 200)}{more}")
    return stage


def _triangulate(counts: np.ndarray, indices: np.ndarray, path, name) -> np.ndarray:
    """Fan-triangulate polygons given face vertex counts and indices -> (m, 3)."""
    if len(counts) == 0:
        return np.zeros((0, 3), dtype=np.int64)
    if counts.min() < 3:
        raise InputError(path, f"mesh {name}: a face has fewer than 3 vertices")
    if int(counts.sum()) != len(indices):
        raise InputError(path, f"mesh {name}: faceVertexCounts sum to {int(counts.sum())} but there are {len(indices)} faceVertexIndices")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    ntri = counts - 2
    face = np.repeat(np.arange(len(counts)), ntri)
    k = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    s = starts[face]
    return np.stack([indices[s], indices[s + k + 1], indices[s + k + 2]], axis=1)


def read_usd(path, meshes=None, fps=None):
    """Read every UsdSkel skinned mesh of a stage (:func:`_read_usd`); usd-core's own error on
    a value it cannot decode (a corrupt crate file) is one :class:`InputError` naming the file."""
    from pxr import Tf
    try:
        return _read_usd(path, meshes, fps)
    except Tf.ErrorException as exc:
        raise InputError(path, f"corrupt USD data: {one_line(exc, 200)}") from None


def _read_usd(path, meshes=None, fps=None):
    """Read every UsdSkel skinned mesh of a stage and every SkelAnimation (see the module docstring).

    Parameters
    ----------
    path : str or PathLike
    meshes : list of str, optional
        Names (prim names or paths) of the meshes to take; default every mesh bound to a
        skeleton, merged.
    fps : float, optional
        Frame grid rate; default the stage's ``timeCodesPerSecond`` when every sample falls on
        a whole time code.
    """
    from pxr import Usd, UsdGeom, UsdSkel

    path = os.fspath(path)
    size = check_input_file(path)
    budget = AllocationBudget(path, size)
    stage = _open(path)
    up = str(UsdGeom.GetStageUpAxis(stage))
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    tcps = float(stage.GetTimeCodesPerSecond())
    if not (tcps > 0):
        raise InputError(path, f"timeCodesPerSecond is {tcps:g}")
    early = Usd.TimeCode.EarliestTime()

    cache = UsdSkel.Cache()
    bindings = []
    for prim in stage.Traverse():
        if prim.IsA(UsdSkel.Root):
            root = UsdSkel.Root(prim)
            cache.Populate(root, Usd.PrimDefaultPredicate)
            bindings.extend(cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate))
    targets = []
    for b in bindings:
        for q in b.GetSkinningTargets():
            p = q.GetPrim()
            if not p.IsA(UsdGeom.Mesh) or not q.HasJointInfluences():
                continue
            if meshes and p.GetName() not in meshes and str(p.GetPath()) not in meshes:
                continue
            targets.append((b.GetSkeleton(), q))
    if meshes:
        found = {t[1].GetPrim().GetName() for t in targets} | {str(t[1].GetPrim().GetPath()) for t in targets}
        missing = [m for m in meshes if m not in found]
        if missing:
            avail = sorted(str(p.GetPath()) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
            raise InputError(path, f"no skinned mesh named {missing[0]!r} (meshes: {', '.join(avail) or 'none'})")
    if not targets:
        if not any(p.IsA(UsdGeom.Mesh) for p in stage.Traverse()):
            raise InputError(path, "the stage has no mesh")
        raise InputError(path, "no skinned mesh: no Mesh is bound to a Skeleton with joint influences inside a SkelRoot (a mesh with no skin cannot be animated)")
    # guide-purpose gprims (a colossus asset's part spheres) are not the body: not even noted
    gprims = sorted({str(q.GetPrim().GetPath()) for b in bindings for q in b.GetSkinningTargets()
                     if not q.GetPrim().IsA(UsdGeom.Mesh) and q.GetPrim().IsA(UsdGeom.Gprim)
                     and UsdGeom.Imageable(q.GetPrim()).ComputePurpose() != UsdGeom.Tokens.guide})

    # ---- skeletons as nodes: one node per Skeleton prim, its joints below it ------------------
    skels, skel_of = [], {}
    for s, _ in targets:
        key = str(s.GetPrim().GetPath())
        if key not in skel_of:
            skel_of[key] = len(skels)
            skels.append(s)
    names, parents, local, node_path = [], [], [], []
    skel_node, joint_node, skel_joints, skel_bind, skel_w0 = [], [], [], [], []
    xf0 = UsdGeom.XformCache(early)
    for s in skels:
        sq = cache.GetSkelQuery(s)
        if not sq:
            raise InputError(path, f"skeleton {s.GetPrim().GetPath()} is invalid (check its joints)")
        joints = [str(j) for j in sq.GetJointOrder()]
        if not joints:
            raise InputError(path, f"skeleton {s.GetPrim().GetPath()} has no joints")
        topo = sq.GetTopology()
        ok, why = topo.Validate()
        if not ok:
            raise InputError(path, f"skeleton {s.GetPrim().GetPath()}: joints are not a valid hierarchy: {why}")
        jparents = np.array(topo.GetParentIndices(), dtype=np.int64)
        nj = len(joints)
        bind_attr = s.GetBindTransformsAttr().Get()
        if bind_attr is None or len(bind_attr) != nj:
            raise InputError(path, f"skeleton {s.GetPrim().GetPath()} has {0 if bind_attr is None else len(bind_attr)} bindTransforms for {nj} joints")
        bind = _m44(bind_attr)
        check_finite(path, "bind transforms", bind.reshape(nj, -1))
        bad = np.flatnonzero(degenerate(bind))
        if len(bad):  # inverted for the skin's inverse binds
            raise InputError(path, f"skeleton {s.GetPrim().GetPath()}: the bind transform of joint "
                             f"{joints[bad[0]]!r} is not invertible (zero scale?) or huge")
        rest_attr = s.GetRestTransformsAttr().Get()
        if rest_attr is not None and len(rest_attr) == nj:
            rest = _m44(rest_attr)
            check_finite(path, "rest transforms", rest.reshape(nj, -1))
        else:  # the bind pose made joint-local
            rest = np.empty_like(bind)
            for k, p in enumerate(jparents):
                rest[k] = bind[k] if p < 0 else np.linalg.solve(bind[p], bind[k])
        w0 = _m44(xf0.GetLocalToWorldTransform(s.GetPrim()))
        sn = len(names)
        names.append(s.GetPrim().GetName())
        parents.append(-1)
        local.append(w0)
        node_path.append(s.GetPrim())
        base = len(names)
        # UsdSkel joint order is parents first (Topology.Validate checked it)
        for k, j in enumerate(joints):
            names.append(j.split("/")[-1])
            parents.append(sn if jparents[k] < 0 else base + int(jparents[k]))
            local.append(rest[k])
            node_path.append(None)
        skel_node.append(sn)
        joint_node.append(np.arange(base, base + nj))
        skel_joints.append(joints)
        skel_bind.append(bind)
        skel_w0.append(w0)
    parents = np.array(parents, dtype=np.int64)
    local = np.array(local)

    # ---- geometry -----------------------------------------------------------------------------
    scene_meshes = []
    for s, q in targets:
        si = skel_of[str(s.GetPrim().GetPath())]
        joints = skel_joints[si]
        nj = len(joints)
        prim = q.GetPrim()
        mesh = UsdGeom.Mesh(prim)
        name = str(prim.GetPath())
        pts = mesh.GetPointsAttr().Get(early)
        if pts is None or len(pts) == 0:
            raise InputError(path, f"mesh {name} has no points")
        nv = len(pts)
        budget.claim(nv * 200, f"mesh {name} ({nv} points)")
        p = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
        check_finite(path, f"mesh {name} points", p)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
        idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
        budget.claim(len(idx) * 40, f"mesh {name} faces")
        tri = _triangulate(counts, idx, path, name)
        if len(tri) and (tri.max() >= nv or tri.min() < 0):
            raise InputError(path, f"mesh {name}: face vertex index out of range for {nv} points")
        if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
            tri = tri[:, ::-1]
        g = _m44(q.GetGeomBindTransform(early))
        if degenerate(g) or not np.all(np.abs(p) <= LARGEST_COORDINATE):
            raise InputError(path, f"mesh {name}: its points or geomBindTransform are not finite, huge or degenerate")
        p = p @ g[:3, :3].T + g[:3, 3]  # into skeleton space at bind time
        inf = q.ComputeJointInfluences(early)
        if not inf:
            raise InputError(path, f"mesh {name}: joint influences cannot be read")
        ji_flat, jw_flat = inf
        k = q.GetNumInfluencesPerComponent()
        ji = np.asarray(ji_flat, dtype=np.int64)
        jw = np.asarray(jw_flat, dtype=np.float64)
        if q.GetInterpolation() == UsdGeom.Tokens.constant:
            ji = np.tile(ji, nv)
            jw = np.tile(jw, nv)
        if len(ji) != nv * k or len(jw) != nv * k:
            raise InputError(path, f"mesh {name}: {len(ji)} joint indices / {len(jw)} weights for {nv} points x {k} influences")
        mapper = q.GetJointMapper()
        if mapper and not mapper.IsIdentity():
            local_joints = [str(j) for j in q.GetJointOrder()]
            lut = np.array([joints.index(j) if j in joints else -1 for j in local_joints], dtype=np.int64)
            if len(ji) and (ji.max() >= len(lut) or ji.min() < 0):
                raise InputError(path, f"mesh {name}: joint index out of range for its {len(lut)} skel:joints")
            ji = lut[ji]
        if len(ji) and (ji.max() >= nj or ji.min() < 0):  # UsdSkel refuses these even at weight 0
            raise InputError(path, f"mesh {name}: joint index {int(ji.max()) if ji.max() >= nj else int(ji.min())} out of range for {nj} joints")
        live = jw > 0
        check_finite(path, f"mesh {name} joint weights", jw[:, None])
        if np.any(jw < 0):
            raise InputError(path, f"mesh {name}: negative joint weights")
        blend = UsdSkel.BindingAPI(prim).GetBlendShapesAttr().Get()
        skin = Skin(joint_node[si], np.linalg.inv(skel_bind[si]), [j.split("/")[-1] for j in joints],
                    np.repeat(np.arange(nv), k)[live], ji[live], jw[live])
        scene_meshes.append(SceneMesh(name=prim.GetName(), node=skel_node[si], positions=p, triangles=tri,
                                      to_world=skel_w0[si], skin=skin, morph_targets=len(blend or []),
                                      shapes=_blend_shapes(path, prim, nv, g)))

    # ---- clips ----------------------------------------------------------------------------------
    def channels_of(anim_prim, si):
        aq = cache.GetAnimQuery(UsdSkel.Animation(anim_prim))
        if not aq:
            return []
        a = UsdSkel.Animation(anim_prim)
        anim_joints = [str(j) for j in (a.GetJointsAttr().Get() or [])]
        lut = {j: i for i, j in enumerate(skel_joints[si])}
        cols = np.array([lut.get(j, -1) for j in anim_joints], dtype=np.int64)
        out = []
        for attr, code, width in ((a.GetTranslationsAttr(), "t", 3), (a.GetRotationsAttr(), "r", 4),
                                  (a.GetScalesAttr(), "s", 3)):
            times = attr.GetTimeSamples() if attr else []
            static = not times
            if times:
                vals = [attr.Get(Usd.TimeCode(t)) for t in times]
            elif attr and attr.HasAuthoredValue():
                times, vals = [0.0], [attr.Get()]
            else:
                continue
            budget.claim(len(times) * len(anim_joints) * width * 8 * 2, f"animation {anim_prim.GetName()!r}")
            arr = []
            for t, v in zip(times, vals):
                if v is None or len(v) != len(anim_joints):
                    raise InputError(path, f"animation {anim_prim.GetPath()}: {attr.GetName()} at time {t:g} has "
                                     f"{0 if v is None else len(v)} values for {len(anim_joints)} joints")
                arr.append(np.array(v, dtype=np.float64).reshape(len(anim_joints), -1))
            arr = np.array(arr)  # (k, joints, width); quaternions come (x, y, z, w)
            check_finite(path, f"animation {anim_prim.GetName()!r} {attr.GetName()}", arr.reshape(len(times), -1))
            if code == "r":
                nrm = np.linalg.norm(arr, axis=2, keepdims=True)
                if np.any(nrm < 1e-12):
                    raise InputError(path, f"animation {anim_prim.GetPath()}: a zero rotation quaternion")
                arr = arr / nrm
            secs = np.array(times, dtype=np.float64) / tcps
            for c, col in enumerate(cols):
                if col >= 0:
                    out.append(Channel(int(joint_node[si][col]), code, secs, arr[:, c], static=static))
        return out

    def skel_motion(si, seconds):
        """Channels of the skeleton prim's own world transform when the prims above it move."""
        prim = skels[si].GetPrim()
        times = set()
        p = prim
        while p and not p.IsPseudoRoot():
            if p.IsA(UsdGeom.Xformable):
                for op in UsdGeom.Xformable(p).GetOrderedXformOps():
                    times.update(op.GetTimeSamples())
            p = p.GetParent()
        if len(times) < 2:
            return []
        ts = np.array(sorted(times))
        w = np.array([_m44(UsdGeom.XformCache(Usd.TimeCode(t)).GetLocalToWorldTransform(prim)) for t in ts])
        bad = np.flatnonzero(degenerate(w))
        if len(bad):
            raise InputError(path, f"skeleton {prim.GetPath()}: its transform at time {ts[bad[0]]:g} is not "
                             "finite, not invertible (zero scale?) or huge")
        t_, q_, s_ = decompose_trs(w)
        secs = ts / tcps
        node = skel_node[si]
        return [Channel(node, "t", secs, t_), Channel(node, "r", secs, q_), Channel(node, "s", secs, s_)]

    anims, used = [], set()
    bound = []
    for si, s in enumerate(skels):
        src = cache.GetSkelQuery(s).GetAnimQuery()
        if src:
            bound.append((si, src.GetPrim()))
    if bound:
        chans = []
        for si, prim in bound:
            chans += channels_of(prim, si)
            used.add(str(prim.GetPath()))
        anims.append(Animation(bound[0][1].GetName(), chans, weights=_weight_channels(bound[0][1], targets, tcps)))
    for prim in stage.Traverse():
        if not prim.IsA(UsdSkel.Animation) or str(prim.GetPath()) in used:
            continue
        a = UsdSkel.Animation(prim)
        aj = set(str(j) for j in (a.GetJointsAttr().Get() or []))
        si = next((i for i, js in enumerate(skel_joints) if aj and aj <= set(js)), None)
        if si is None:
            si = max(range(len(skels)), key=lambda i: len(aj & set(skel_joints[i])))
            if not aj & set(skel_joints[si]):
                continue  # an animation of another skeleton
        anims.append(Animation(prim.GetName(), channels_of(prim, si), weights=_weight_channels(prim, targets, tcps)))
    for a in anims:
        if a.channels:
            for si in range(len(skels)):
                a.channels += skel_motion(si, None)
    anims = [a for a in anims if any(len(c.times) and not c.static for c in a.channels + a.weights)]
    scene = Scene(names=names, parents=parents, local=local, meshes=scene_meshes, animations=anims,
                  fps_hint=tcps, sampling_note="UsdSkel time samples, lerp / slerp between")
    notes = []
    if gprims:
        notes.append(f"{len(gprims)} implicit gprims bound to the skeleton are not meshes and were left out: "
                     + ", ".join(g.rsplit('/', 1)[-1] for g in gprims[:5]))
    mesh = build(scene, path, meshes=None, fps=fps, budget=budget,
                 source={"file": os.path.basename(path), "format": os.path.splitext(path)[1].lstrip(".").lower(),
                         "reader": "usd", "frame": f"USD stage: upAxis={up}, metersPerUnit={mpu:g}"})
    mesh.source["notes"] = notes + mesh.source["notes"]
    method = _skinning_method(path, targets)
    mesh = mesh.replace(skinning_method=method)
    items, inert = _not_carried(stage, cache, targets, mesh, early)
    if mesh.source.get("morph_meshes"):
        mesh.source["morph_meshes"] = {k: v for k, v in mesh.source["morph_meshes"].items() if k not in inert}
    if inert:
        mesh.source["notes"].append(f"blend shapes of {', '.join(inert)} have weight 0 in every animation: "
                                    "nothing of them to carry")
    mesh.source["not_carried"] = items
    return mesh.replace(up_axis=up, meters_per_unit=mpu)


def _blend_shapes(path, prim, nv, g):
    """The mesh prim's UsdSkel blend shapes as :class:`model.BlendShape` (mesh space: the scene
    builder moves them with the points), read by the runtime's own reader
    (:func:`runtime.asset.read_shapes`: what it refuses, the import refuses).  ``g`` is the
    geomBindTransform already applied to the points: offsets in mesh space go through its linear
    part here (the scene mesh's points are in skeleton space)."""
    from colossus.runtime.asset import read_shapes
    from colossus.runtime.errors import ColliderError

    from ..model import BlendShape

    try:
        sh = read_shapes(prim, nv)
    except ColliderError as e:
        raise InputError(path, f"blend shapes: {e}") from None
    out = []
    A = np.asarray(g, dtype=np.float64)[:3, :3]
    for s, name in enumerate(sh.names):
        k, o = sh.knots[s], sh.knot_offsets[s] @ A.T
        one = int(np.flatnonzero(k == 1.0)[0])
        out.append(BlendShape(name, sh.indices[s], o[one],
                              tuple((float(k[j]), o[j]) for j in range(len(k)) if k[j] not in (0.0, 1.0))))
    return out


def _weight_channels(anim_prim, targets, tcps):
    """The SkelAnimation's ``blendShapeWeights`` as one weight :class:`Channel` per scene mesh
    (``node`` = the mesh's index in ``targets``, columns in the mesh's ``skel:blendShapes`` order;
    UsdSkel maps them by name, a shape the animation does not name is 0), linear between samples
    as UsdSkel interpolates them."""
    from pxr import UsdSkel

    a = UsdSkel.Animation(anim_prim)
    names = [str(n) for n in (a.GetBlendShapesAttr().Get() or [])] if a.GetBlendShapesAttr() else []
    attr = a.GetBlendShapeWeightsAttr()
    if not names or not attr or not attr.HasAuthoredValue():
        return []
    times = list(attr.GetTimeSamples())
    static = not times
    raw = [attr.Get(t) for t in times] if times else [attr.Get()]
    times = times or [0.0]
    if any(v is None or len(v) != len(names) for v in raw):
        raise InputError(anim_prim.GetStage().GetRootLayer().identifier,
                         f"animation {anim_prim.GetPath()}: blendShapeWeights do not have one weight per blendShapes name")
    vals = np.array([np.asarray(v, dtype=np.float64) for v in raw]).reshape(len(times), len(names))
    col = {n: c for c, n in enumerate(names)}
    out = []
    for i, (_, q) in enumerate(targets):
        mesh_names = [str(n) for n in (UsdSkel.BindingAPI(q.GetPrim()).GetBlendShapesAttr().Get() or [])]
        if not mesh_names or not any(n in col for n in mesh_names):
            continue
        v = np.zeros((len(times), len(mesh_names)))
        for s, n in enumerate(mesh_names):
            if n in col:
                v[:, s] = vals[:, col[n]]
        out.append(Channel(i, "w", np.asarray(times, dtype=np.float64) / tcps, v, static=static))
    return out


#: Most time codes at which dual-quaternion and linear skinning are compared for a bound.
DQ_SAMPLES = 64


def _skinning_method(path, targets) -> str:
    """The one ``primvars:skel:skinningMethod`` of the collision mesh: the chosen meshes' own
    when they agree; where they mix, the method of the most points (the others are listed as not
    carried by :func:`_not_carried`, with usd-core's bound).  A token UsdSkel does not know is
    refused (usd-core cannot skin it either)."""
    from pxr import UsdGeom, UsdSkel

    known = (str(UsdSkel.Tokens.classicLinear), str(UsdSkel.Tokens.dualQuaternion))
    votes = {}
    for _, q in targets:
        m = str(q.GetSkinningMethod())
        if m not in known:
            raise InputError(path, f"mesh {q.GetPrim().GetPath()}: primvars:skel:skinningMethod {m!r} is not a "
                             f"method UsdSkel skins ({', '.join(known)})")
        pts = UsdGeom.Mesh(q.GetPrim()).GetPointsAttr().Get()
        votes[m] = votes.get(m, 0) + (len(pts) if pts is not None else 0)
    return max(known, key=lambda m: (votes.get(m, -1), m == known[0]))


def _not_carried(stage, cache, targets, mesh, early):
    """``(records, inert)``: the :mod:`pipeline.notcarried` records of what UsdSkel says about the
    chosen meshes that the collider does not carry (a ``primvars:skel:skinningMethod`` other than
    the collision mesh's ``mesh.skinning_method``, where the chosen meshes mix methods: bounded by
    usd-core's own dual-quaternion skinning against its linear skinning at up to
    :data:`DQ_SAMPLES` of the animation's time codes; a mesh whose method is carried is not
    listed), and the names of the meshes whose blend shapes have weight 0 in every animation
    (nothing to carry)."""
    from pxr import Usd, UsdGeom, UsdSkel, Vt
    from .. import notcarried
    from .bounds import posed_size

    items, inert, dq = [], [], []
    size = None
    for s, q in targets:
        prim = q.GetPrim()
        shapes = UsdSkel.BindingAPI(prim).GetBlendShapesAttr().Get() or []
        if shapes:
            sq = cache.GetSkelQuery(s)
            aq = sq.GetAnimQuery() if sq else None
            live = False
            anims = [aq.GetPrim()] if aq else []
            anims += [p for p in stage.Traverse() if p.IsA(UsdSkel.Animation)]
            for ap in anims:
                a = UsdSkel.Animation(ap)
                names = list(a.GetBlendShapesAttr().Get() or [])
                attr = a.GetBlendShapeWeightsAttr()
                cols = [names.index(x) for x in shapes if x in names]
                if not cols or not attr:
                    continue
                times = attr.GetTimeSamples() or [Usd.TimeCode.Default()]
                for t in times:
                    w = attr.Get(t)
                    if w is not None and len(w) and np.any(np.abs(np.asarray(w, dtype=np.float64)[cols]) > 0):
                        live = True
                        break
                if live:
                    break
            if not live:
                inert.append(prim.GetName())
        if str(q.GetSkinningMethod()) == mesh.skinning_method:
            continue  # carried
        sq = cache.GetSkelQuery(s)
        times = sorted({t for t in (sq.GetAnimQuery().GetJointTransformTimeSamples() if sq and sq.GetAnimQuery() else [])})
        if len(times) > DQ_SAMPLES:
            times = [times[i] for i in np.unique(np.round(np.linspace(0, len(times) - 1, DQ_SAMPLES)).astype(int))]
        times = [Usd.TimeCode(t) for t in times] or [early]
        pts0 = UsdGeom.Mesh(prim).GetPointsAttr().Get(early)
        inf = q.ComputeJointInfluences(early)
        gap = 0.0
        if pts0 is not None and inf:
            ji, jw = inf
            k = q.GetNumInfluencesPerComponent()
            if q.GetInterpolation() == UsdGeom.Tokens.constant:
                ji, jw = Vt.IntArray(list(ji) * len(pts0)), Vt.FloatArray(list(jw) * len(pts0))
            mapper = q.GetJointMapper()
            for t in times:
                xf = sq.ComputeSkinningTransforms(t)
                if mapper and not mapper.IsIdentity():
                    xf = mapper.RemapTransforms(xf)
                a, b = Vt.Vec3fArray(pts0), Vt.Vec3fArray(pts0)
                g = q.GetGeomBindTransform(t)
                UsdSkel.SkinPoints(UsdSkel.Tokens.classicLinear, g, xf, ji, jw, k, a)
                UsdSkel.SkinPoints(UsdSkel.Tokens.dualQuaternion, g, xf, ji, jw, k, b)
                w = np.array(UsdGeom.XformCache(t).GetLocalToWorldTransform(s.GetPrim()), dtype=np.float64)[:3, :3]
                d = (np.asarray(b, dtype=np.float64) - np.asarray(a, dtype=np.float64)) @ w
                gap = max(gap, float(np.linalg.norm(d, axis=1).max()) if len(d) else 0.0)
        if size is None:
            size = posed_size(mesh)
        dq.append((prim.GetName(), gap / size))
    if dq:
        items.append(notcarried.item(
            "usd_skinning_method", [n for n, _ in dq],
            f'the meshes mix primvars:skel:skinningMethod: the collider is skinned by {mesh.skinning_method!r} '
            "(the method of most points; bound: usd-core's dual-quaternion against its linear skinning at the "
            "animation's time codes)", max(b for _, b in dq)))
    return items, inert
