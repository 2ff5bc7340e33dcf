"""What an FBX file says about how it deforms that the assimp path does not carry (fail closed).

:func:`check` reads the file's document tree (:mod:`.fbx_doc`, binary and ASCII) and returns one
:mod:`pipeline.notcarried` record per class it finds, each checked so that it fires only where
the import really differs from the file:

* ``fbx_skinning_type``: a Skin deformer whose ``SkinningType`` is ``DualQuaternion``, or
  ``Blend`` with a non-zero per-vertex ``BlendWeights`` (``Linear`` and ``Rigid`` are linear
  blend skinning, what we do; ``Blend`` with every weight 0 is linear too).  Bound: the largest
  distance between linear and dual-quaternion skinning of the imported mesh over its frames,
  times the largest blend weight.
* ``fbx_inherit_type``: a model of the skeleton's or the meshes' hierarchy with ``InheritType``
  0 (RrSs; the FBX default where neither the model nor its template says otherwise) below a
  model whose scale is not uniform at rest or in a clip.  assimp composes every model as RSrs
  (1), which differs exactly there (Rrs, 2, is handled by the reader).  No bound.
* ``fbx_transform_skin``: a skinned mesh's model whose world transform (without its geometric
  transform), at rest or in a clip, differs from its BindPose matrix: Maya moves the skinned
  result by that change since binding (``G(t) @ inv(B)``), assimp does not.  Bound: the largest
  ``|(G(t) inv(B) - I) p|`` over the mesh's skinned points ``p`` at the clip frames.
* ``fbx_geometric_transform``: ``GeometricTranslation`` / ``Rotation`` / ``Scaling`` on a skinned
  mesh's model (3ds Max's object offset); assimp's skin binding misplaces such a mesh (measured
  on ``corpus/dcc/max_transformed_skin_7500_binary.fbx``).  Bound: the largest distance the
  geometric transform moves a vertex, in world units (exact through rigid joints).
* ``fbx_instanced_skin``: one skinned geometry used by several models.  No bound.
* ``fbx_constraints``: constraint objects acting on the hierarchy (their effect is in the
  file's keys only if the animation was baked).  No bound.
* ``fbx_curve_interpolation``: FBX curves of the hierarchy's models with cubic or constant
  segments that span frames of the grid and do not follow the straight line there (assimp
  interpolates every curve linearly between its keys).  Bound: first order, from the largest
  gap at the grid frames between the curve and the line (angles times the reach of the model's
  vertices, translations times the parent scale).

:func:`refusal` names FBX versions assimp does not read (before 7.1).
"""

from __future__ import annotations

import numpy as np

from .. import notcarried
from ..model import SkinnedMesh
from . import bounds
from .fbx_doc import Document, object_name

#: Oldest FBX version assimp's importer reads (FBX 2011); older files it refuses.
OLDEST_READ = 7100
#: A matrix or value difference this small (relative) is round-off, not a finding.
SAME = 1e-6
#: FBX time units per second.
KTIME = 46186158000


def refusal(version: int | None) -> str | None:
    """The one-line reason an FBX file of ``version`` is not read, or None when it is."""
    if version is None or version >= OLDEST_READ or version <= 0:
        return None
    major, minor = divmod(version, 1000)
    return (f"FBX version {version} (FBX {major}.{minor // 100}) is not read: assimp's FBX importer reads FBX 7.1 "
            f"(2011) to 7.7 only; re-export the file as FBX 2011 or later")


# ------------------------------------------------------------------------------ the graph
class _Graph:
    def __init__(self, doc: Document):
        self.doc = doc
        objs = doc.top("Objects")
        self.objects = {}
        for n in (objs.children if objs is not None else []):
            if len(n.props) >= 2 and isinstance(n.props[0], int):
                self.objects[n.props[0]] = n
        self.parents, self.children, self.prop_links = {}, {}, []
        conns = doc.top("Connections")
        for c in (conns.children if conns is not None else []):
            if c.name != "C" or len(c.props) < 3:
                continue
            kind, a, b = c.props[0], c.props[1], c.props[2]
            if kind == "OO":
                self.parents.setdefault(a, []).append(b)
                self.children.setdefault(b, []).append(a)
            elif kind == "OP" and len(c.props) >= 4:
                self.prop_links.append((a, b, str(c.props[3])))
        self.templates = self._templates()

    def _templates(self) -> dict:
        out = {}
        d = self.doc.top("Definitions")
        for ot in (d.all("ObjectType") if d is not None else []):
            if not ot.props:
                continue
            for t in ot.all("PropertyTemplate"):
                out.setdefault(str(ot.props[0]), {}).update(self.doc.properties(t))
        return out

    def kind(self, oid):
        n = self.objects.get(oid)
        return (n.name, str(n.props[2]) if len(n.props) > 2 else "") if n is not None else (None, None)

    def name(self, oid) -> str:
        n = self.objects.get(oid)
        return object_name(n.props[1]) if n is not None else str(oid)

    def props(self, oid) -> dict:
        n = self.objects.get(oid)
        if n is None:
            return {}
        return {**self.templates.get(n.name, {}), **self.doc.properties(n)}

    def models(self):
        return [i for i, n in self.objects.items() if n.name == "Model"]

    def model_parent(self, oid):
        return next((p for p in self.parents.get(oid, []) if self.kind(p)[0] == "Model"), None)

    def ancestors(self, oid):
        out, p, seen = [], self.model_parent(oid), {oid}
        while p is not None and p not in seen:
            out.append(p)
            seen.add(p)
            p = self.model_parent(p)
        return out


def _vec(v, default):
    try:
        a = np.array(v if isinstance(v, (list, tuple)) else [v], dtype=np.float64).reshape(-1)
        return a[:3] if len(a) >= 3 else np.array(default, dtype=np.float64)
    except (TypeError, ValueError):
        return np.array(default, dtype=np.float64)


def _euler(deg, order: int = 0) -> np.ndarray:
    """3x3 of FBX Euler angles (degrees) in ``RotationOrder`` (0 XYZ: ``Rz @ Ry @ Rx``)."""
    x, y, z = np.radians(deg)
    cx, sx, cy, sy, cz, sz = np.cos(x), np.sin(x), np.cos(y), np.sin(y), np.cos(z), np.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    m = {"x": rx, "y": ry, "z": rz}
    seq = {0: "xyz", 1: "xzy", 2: "yzx", 3: "yxz", 4: "zxy", 5: "zyx"}.get(int(order), "xyz")
    out = np.eye(3)
    for a in seq:  # the first axis is applied first
        out = m[a] @ out
    return out


def _geometric(p: dict) -> np.ndarray:
    g = np.eye(4)
    t = _vec(p.get("GeometricTranslation", 0), [0, 0, 0])
    r = _vec(p.get("GeometricRotation", 0), [0, 0, 0])
    s = _vec(p.get("GeometricScaling", 1), [1, 1, 1])
    g[:3, :3] = _euler(r) @ np.diag(s)
    g[:3, 3] = t
    return g


# ------------------------------------------------------------------------------ the checks
def check(doc: Document | None, mesh: SkinnedMesh, scene=None, only=None) -> list:
    """The :mod:`pipeline.notcarried` records of an FBX file read through assimp (see the module
    docstring).  ``mesh`` is the reader's result (source space), ``scene`` the
    :class:`~pipeline.readers.scene.Scene` it was built from (for the mesh nodes' motion);
    ``only`` names the checks to run (default all of them: the assimp path)."""
    if doc is None:
        return []
    try:
        g = _Graph(doc)
        ctx = _Context(g, mesh, scene)
    except MALFORMED as e:
        return [unchecked("the file's object graph", e)]
    out = []
    for fn in (_skinning_type, _inherit_type, _transform_skin, _geometric_transform, _instanced_skin,
               _constraints, _curve_interpolation):
        if only is not None and fn.__name__.strip("_") not in only:
            continue
        try:
            out += fn(ctx)
        except MALFORMED as e:  # fail closed: what could not be checked is said, never a crash
            out.append(unchecked(fn.__name__.strip("_").replace("_", " "), e))
    return out


#: What malformed FBX data raises in the checks (a hostile or corrupt file: arrays cut short,
#: values of the wrong type or size).
MALFORMED = (ValueError, TypeError, IndexError, KeyError, OverflowError, ZeroDivisionError,
              AttributeError, np.linalg.LinAlgError)


#: The checks that still apply to the ufbx reader, which evaluates inherit types, pivots,
#: geometric transforms and every curve at every frame itself, and carries the skinning type
#: (:mod:`.ufbx_reader`).
UFBX_CHECKS = ("constraints",)


def unchecked(what: str, e: BaseException):
    return notcarried.item("fbx_unchecked", [], f"{what} could not be checked (malformed data: "
                           f"{type(e).__name__}); what it would say about deformation is not known", None)


class _Context:
    """What the checks share: the graph, the mesh, the models that matter, posed points (lazily)."""

    def __init__(self, g: _Graph, mesh: SkinnedMesh, scene):
        self.g, self.mesh, self.scene = g, mesh, scene
        by_name = {}
        for m in g.models():
            by_name.setdefault(g.name(m), m)
        self.model_by_name = by_name
        chosen = set(mesh.source.get("meshes") or [])
        # skinned geometries: geometry -> its models; and the models of the chosen meshes
        self.skins = []  # (skin id, geometry id, [model ids])
        for oid, n in g.objects.items():
            if n.name == "Deformer" and g.kind(oid)[1] == "Skin":
                for geo in g.parents.get(oid, []):
                    if g.kind(geo)[0] == "Geometry":
                        models = [m for m in g.parents.get(geo, []) if g.kind(m)[0] == "Model"]
                        self.skins.append((oid, geo, models))
        mesh_models = set()
        for _, geo, models in self.skins:
            if any(g.name(m) in chosen or g.name(geo) in chosen for m in models) or not chosen:
                mesh_models.update(models)
        for name in chosen:
            if name in by_name:
                mesh_models.add(by_name[name])
        self.mesh_models = mesh_models
        rel = set(mesh_models)
        for j in mesh.joint_names:
            if j in by_name:
                rel.add(by_name[j])
        for m in list(rel):
            rel.update(g.ancestors(m))
        self.relevant = rel
        self._posed = None

    def posed(self):
        if self._posed is None:
            which = bounds.frames(self.mesh)
            pts = bounds.posed(self.mesh, which)
            self._posed = (which, pts, bounds.posed_size(self.mesh, pts))
        return self._posed

    def size(self) -> float:
        return self.posed()[2]

    def rows_of(self, model_names) -> np.ndarray:
        """Vertex rows of the chosen meshes named in ``model_names`` (all rows when none match)."""
        rows, base = [], 0
        for info in self.mesh.source.get("mesh_info") or []:
            n = int(info["vertices"])
            if info["name"] in model_names:
                rows.append(np.arange(base, base + n))
            base += n
        return np.concatenate(rows) if rows else np.arange(self.mesh.vertex_count)


def morph_records(doc: Document | None, mesh: SkinnedMesh) -> list:
    """The blend-shape record of a read FBX mesh (both roads): ``[]`` or one ``morph_targets``
    record for the live channels (:func:`morph`; an ``fbx_unchecked`` one when the file cannot be
    judged); channels inert everywhere become a note.  Resets ``mesh.source["morph_meshes"]``
    (judged here: live channels only)."""
    if not mesh.source.get("morph_meshes") or doc is None:
        return []
    try:
        item, inert = morph(doc, mesh)
    except MALFORMED as e:  # fail closed: the shapes are said not carried
        item, inert = unchecked("the blend shapes", e), []
    mesh.source["morph_meshes"] = {}
    if inert:
        mesh.source["notes"] = mesh.source.get("notes", []) + [
            f"blend shapes of {', '.join(inert)} have DeformPercent 0 at rest and in every curve: "
            "nothing of them to carry"]
    return [] if item is None else [item]


def morph(doc: Document | None, mesh: SkinnedMesh):
    """``(record or None, inert)``: the ``morph_targets`` record of the chosen meshes' blend shape
    channels that can move a vertex (``DeformPercent`` not 0 at rest or in a curve), bound by the
    sum over channels of the largest percentage / 100 times the largest shape offset (mesh space),
    and the names of the meshes whose channels are all inert."""
    if doc is None:
        return None, []
    g = _Graph(doc)
    chosen = set(mesh.source.get("meshes") or [])
    live, inert, total = [], [], 0.0
    per_mesh = {}
    for oid, n in g.objects.items():
        if g.kind(oid) != ("Deformer", "BlendShapeChannel"):
            continue
        geos = [geo for bs in g.parents.get(oid, []) for geo in g.parents.get(bs, []) if g.kind(geo)[0] == "Geometry"]
        names = set()
        for geo in geos:
            names.add(g.name(geo))
            names.update(g.name(m) for m in g.parents.get(geo, []) if g.kind(m)[0] == "Model")
        hit = sorted(names & chosen)
        if not hit:
            continue
        pct = [abs(float(_vec(g.props(oid).get("DeformPercent", 0), [0, 0, 0])[0]))]
        for cn in [a for a, b, p in g.prop_links if b == oid and p == "DeformPercent"]:
            for c in [a for a, b, _ in g.prop_links if b == cn and g.kind(a)[0] == "AnimationCurve"]:
                kv = g.objects[c].value("KeyValueFloat")
                if kv is not None and len(kv):
                    pct.append(float(np.abs(kv).max()))
        reach = 0.0
        for shape in g.children.get(oid, []):
            v = g.objects[shape].value("Vertices") if g.kind(shape)[0] == "Geometry" else None
            if v is not None and len(v) >= 3:
                reach = max(reach, float(np.linalg.norm(np.asarray(v).reshape(-1, 3), axis=1).max()))
        d = per_mesh.setdefault(hit[0], [0, 0.0, False])
        d[0] += 1
        d[1] += max(pct) / 100.0 * reach
        d[2] |= max(pct) > 0
    for name, (count, b, on) in per_mesh.items():
        (live if on else inert).append((name, count))
        if on:
            total += b
    if not live:
        return None, [f"{n} ({c})" for n, c in inert]
    from .bounds import posed_size
    return notcarried.item(
        "morph_targets", [n for n, _ in live],
        "morph targets / shape keys are not carried into the collider (it follows the skeleton only): "
        + ", ".join(f"{n} ({c})" for n, c in live) + " (bound: largest DeformPercent times largest shape offset, "
        "mesh space)", total / posed_size(mesh)), [f"{n} ({c})" for n, c in inert]


def _skinning_type(ctx) -> list:
    g, out = ctx.g, []
    for skin, geo, models in ctx.skins:
        if not models or not (set(models) & ctx.mesh_models):
            continue
        n = g.objects[skin]
        st = str(n.value("SkinningType", "Linear") or "Linear")
        bw = n.value("BlendWeights")
        if st == "DualQuaternion":
            b, what = 1.0, "dual-quaternion skinning"
        elif st == "Blend" and bw is not None and len(bw) and float(np.max(np.abs(bw))) > 0:
            b = float(np.max(np.abs(bw)))
            nz = int(np.count_nonzero(bw))
            what = f"blended linear / dual-quaternion skinning (per-vertex BlendWeights, {nz} non-zero, up to {b:.3g})"
        else:
            continue
        names = [g.name(m) for m in models]
        which, _, size = ctx.posed()
        gap = bounds.dq_lbs_gap(ctx.mesh, which, ctx.rows_of(set(names)))
        bound = b * float(gap.max()) / size if len(gap) else None
        out.append(notcarried.item(
            "fbx_skinning_type", names,
            f"Skin SkinningType {st}: {what}; the collider is skinned linearly (bound: the largest linear vs "
            "dual-quaternion gap at the frames times the largest blend weight)", bound))
    return out


def _scale_values(ctx, oid) -> list:
    """Every scale a model has: at rest, and at each key time of its scaling curves (the three
    components together, each curve interpolated linearly at the others' key times)."""
    g = ctx.g
    p = g.props(oid)
    rest = _vec(p.get("Lcl Scaling", 1), [1, 1, 1])
    vals = [rest]
    for comps in _curve_nodes(g, oid, "Lcl Scaling").values():
        curves = {}
        for axis, curve in comps.items():
            n = g.objects.get(curve) if curve is not None else None
            kt = n.value("KeyTime") if n is not None else None
            kv = n.value("KeyValueFloat") if n is not None else None
            if kt is not None and kv is not None and len(kt) == len(kv) and len(kt):
                curves[axis] = (np.asarray(kt, dtype=np.float64), np.asarray(kv, dtype=np.float64))
        if not curves:
            continue
        times = np.unique(np.concatenate([t for t, _ in curves.values()]))
        s3 = np.tile(rest, (len(times), 1))
        for axis, (t, v) in curves.items():
            s3[:, "XYZ".index(axis)] = np.interp(times, t, v)
        vals.extend(s3)
    return vals


def _curve_nodes(g, oid, prop) -> dict:
    """``{curve node id: {"X": curve id or None, "Y": ..., "Z": ...}}`` animating ``prop`` of model ``oid``."""
    out = {}
    for a, b, p in g.prop_links:
        if b == oid and p == prop and g.kind(a)[0] == "AnimationCurveNode":
            out[a] = {"X": None, "Y": None, "Z": None}
    for a, b, p in g.prop_links:
        if b in out and g.kind(a)[0] == "AnimationCurve":
            axis = p.split("|")[-1][:1].upper()
            if axis in out[b]:
                out[b][axis] = a
    return out


def _nonuniform(vals) -> bool:
    for s in vals:
        a = np.abs(s)
        if a.max() > 0 and (a.max() - a.min()) > SAME * a.max():
            return True
    return False


def _inherit_type(ctx) -> list:
    g = ctx.g
    hits = []
    scaled = {}
    for m in ctx.relevant:
        if int(float(g.props(m).get("InheritType", 0) or 0)) != 0:
            continue
        par = g.ancestors(m)
        bad = []
        for a in par:
            if a not in scaled:
                scaled[a] = _nonuniform(_scale_values(ctx, a))
            if scaled[a]:
                bad.append(a)
        if bad:
            hits.append((m, bad[0]))
    if not hits:
        return []
    names = [g.name(m) for m, _ in hits]
    return [notcarried.item(
        "fbx_inherit_type", names[:8] + ([f"... {len(names)} models"] if len(names) > 8 else []),
        f"InheritType 0 (RrSs: the parent's scale applied after the child's rotation) below non-uniformly scaled "
        f"{g.name(hits[0][1])!r}; assimp composes RSrs (InheritType 1)", None)]


def _bind_poses(g) -> dict:
    out = {}
    for oid, n in g.objects.items():
        if n.name != "Pose" or str(n.value("Type", "")) != "BindPose":
            continue
        for pn in n.all("PoseNode"):
            node, mat = pn.value("Node"), pn.value("Matrix")
            if isinstance(node, int) and mat is not None and len(mat) == 16:
                out.setdefault(node, np.asarray(mat, dtype=np.float64).reshape(4, 4).T)
    return out


def _node_world(scene, node, anim, seconds) -> np.ndarray:
    """(f, 4, 4) world transform of scene node ``node`` at ``seconds`` in ``anim`` (None: rest)."""
    from ..xforms import compose_trs, decompose_trs
    from .scene import sample_channel
    chain = [node]
    while scene.parents[chain[-1]] >= 0:
        chain.append(int(scene.parents[chain[-1]]))
    f = len(seconds)
    world = np.broadcast_to(np.eye(4), (f, 4, 4)).copy()
    by = {}
    if anim is not None:
        for c in anim.channels:
            by.setdefault(c.node, {})[c.path] = c
    for n in reversed(chain):
        loc = np.broadcast_to(scene.local[n], (f, 4, 4))
        if n in by:
            t, q, s = decompose_trs(scene.local[n])
            ch = by[n]
            T = sample_channel(ch["t"], seconds) if "t" in ch else np.broadcast_to(t, (f, 3))
            R = sample_channel(ch["r"], seconds) if "r" in ch else np.broadcast_to(q, (f, 4))
            S = sample_channel(ch["s"], seconds) if "s" in ch else np.broadcast_to(s, (f, 3))
            loc = compose_trs(T, R, S)
        world = world @ loc
    return world


def _transform_skin(ctx) -> list:
    g, mesh, scene = ctx.g, ctx.mesh, ctx.scene
    if scene is None:
        return []
    binds = _bind_poses(g)
    out = []
    info = {c["name"]: c for c in mesh.source.get("clip_info") or []}
    for m in sorted(ctx.mesh_models):
        if m not in binds or not any(m in models for _, _, models in ctx.skins):
            continue
        name = g.name(m)
        nodes = [sm.node for sm in scene.meshes if sm.skin is not None and sm.node >= 0 and scene.names[sm.node] == name]
        if not nodes:
            continue
        node = nodes[0]
        geo_inv = np.linalg.inv(_geometric(g.props(m)))
        b_inv = np.linalg.inv(binds[m])
        # assimp's root node may hold an axis conversion of its own: BindPose matrices are in the
        # file's space, below it
        top = node
        while scene.parents[top] >= 0:
            top = int(scene.parents[top])
        root = scene.local[top] if top != node and scene.names[top] == "RootNode" else np.eye(4)
        which = bounds.frames(mesh)
        ds = []
        for ci, fi in which:
            if ci < 0:
                anim, sec = None, np.zeros(1)
            else:
                clip = mesh.clips[ci]
                src = info.get(clip.name, {}).get("source_name", clip.name)
                anim = next((a for a in scene.animations if a.name == src), None)
                sec = np.array([clip.times[fi] / mesh.time_codes_per_second])
            w = _node_world(scene, node, anim, sec)[0]
            ds.append(root @ (np.linalg.solve(root, w) @ geo_inv @ b_inv) @ np.linalg.inv(root) - np.eye(4))
        ds = np.array(ds)
        reach = float(np.abs(mesh.positions).max()) + 1.0
        if np.abs(ds[:, :3, :3]).max() * reach + np.abs(ds[:, :3, 3]).max() <= 1e-9 * reach:
            continue  # the node is where it was bound, at every frame: nothing to pose
        which, pts, size = ctx.posed()
        rows = ctx.rows_of({name} | {sm.name for sm in scene.meshes if sm.node == node})
        worst, at = 0.0, ""
        for k, (ci, fi) in enumerate(which):
            d = ds[k]
            e = float(np.linalg.norm(pts[k][rows] @ d[:3, :3].T + d[:3, 3], axis=1).max())
            if e > worst:
                worst, at = e, ("rest" if ci < 0 else f"clip {mesh.clips[ci].name!r} frame {mesh.clips[ci].times[fi]:g}")
        if worst > SAME * size:
            out.append(notcarried.item(
                "fbx_transform_skin", [name],
                f"the skinned mesh's node has moved since binding (its transform differs from its BindPose matrix); "
                f"Maya moves the skinned mesh by that change, the collider does not (largest at {at})",
                worst / size))
    return out


def _geometric_transform(ctx) -> list:
    g, mesh, out = ctx.g, ctx.mesh, []
    for m in sorted(ctx.mesh_models):
        if not any(m in models for _, _, models in ctx.skins):
            continue
        geo = _geometric(g.props(m))
        if np.abs(geo - np.eye(4)).max() <= SAME * max(1.0, np.abs(geo[:3, 3]).max()):
            continue
        name = g.name(m)
        rows = ctx.rows_of({name})
        # our vertices are (node world incl. geometric) @ control point: the geometric
        # transform's own move of each vertex, in world units
        scene = ctx.scene
        wnode = None
        if scene is not None:
            hit = [sm for sm in scene.meshes if sm.node >= 0 and scene.names[sm.node] == name]
            wnode = hit[0].to_world if hit else None
        if wnode is None:
            bound = None
        else:
            p = mesh.positions[rows].astype(np.float64)
            local = (p - wnode[:3, 3]) @ np.linalg.inv(wnode[:3, :3]).T  # control points (geometry space)
            w_no = wnode @ np.linalg.inv(geo)  # the node's world without its geometric transform
            moved = (local @ (w_no[:3, :3] @ (np.eye(3) - np.linalg.inv(geo)[:3, :3])).T
                     - (w_no[:3, :3] @ np.linalg.inv(geo)[:3, 3]))  # world(geo p) - world(p)
            bound = float(np.linalg.norm(moved, axis=1).max()) / ctx.size()
        p = g.props(m)
        what = ", ".join(k for k in ("GeometricTranslation", "GeometricRotation", "GeometricScaling") if k in p)
        out.append(notcarried.item(
            "fbx_geometric_transform", [name],
            f"{what} on a skinned mesh's node (3ds Max object offset): assimp's skin binding does not place the mesh "
            "through it (bound: how far it moves a vertex, through rigid joints)", bound))
    return out


def _instanced_skin(ctx) -> list:
    g, out = ctx.g, []
    for skin, geo, models in ctx.skins:
        if len(models) > 1 and set(models) & ctx.mesh_models:
            out.append(notcarried.item(
                "fbx_instanced_skin", [g.name(m) for m in models],
                f"one skinned geometry ({g.name(geo) or geo}) is instanced by {len(models)} models; assimp skins "
                "one copy, the others do not move as the file shows", None))
    return out


def _constraints(ctx) -> list:
    g = ctx.g
    cons = [oid for oid, n in g.objects.items() if n.name == "Constraint"]
    if not cons:
        return []
    acting = []
    for c in cons:
        linked = {a for a, b, _ in g.prop_links if b == c} | {b for a, b, _ in g.prop_links if a == c}
        linked |= set(g.parents.get(c, [])) | set(g.children.get(c, []))
        if not linked or linked & ctx.relevant:
            acting.append(c)
    if not acting:
        return []
    names = [f"{g.name(c)} ({g.kind(c)[1] or 'constraint'})" for c in acting]
    return [notcarried.item(
        "fbx_constraints", names[:8] + ([f"... {len(names)} constraints"] if len(names) > 8 else []),
        f"{len(acting)} constraint(s) act on the skeleton or the meshes; the import plays only the file's keys "
        "(right only if the constraints were baked into them)", None)]


def _curve_value(kt, kv, flags, data, seconds):
    """(value by the curve, value by the straight line between its keys) at ``seconds`` inside
    ``[kt[0], kt[-1]]``; ``kt`` in seconds."""
    i = np.clip(np.searchsorted(kt, seconds, side="right") - 1, 0, len(kt) - 2)
    t0, t1 = kt[i], kt[i + 1]
    dt = np.where(t1 > t0, t1 - t0, 1.0)
    u = np.clip((seconds - t0) / dt, 0.0, 1.0)
    v0, v1 = kv[i], kv[i + 1]
    line = v0 + (v1 - v0) * u
    curve = line.copy()
    for x, k in enumerate(i):
        fl = int(flags[k])
        if fl & 0x02:  # constant: holds the key (or the next key with eConstantNext 0x100)
            curve[x] = v1[x] if (fl & 0x100 and u[x] < 1) else (v1[x] if u[x] >= 1 else v0[x])
        elif fl & 0x08:  # cubic: Bezier with the keys' slopes and weights
            d = data[k] if k < len(data) else np.zeros(4)
            sr, sl = float(d[0]), float(d[1])
            wr, wl = 1.0 / 3.0, 1.0 / 3.0
            if fl & 0x03000000:
                raw = float(d[2])  # two 16-bit weights: the float's bits (binary), or that integer (ASCII)
                packed = int(raw) if abs(raw) >= 1 and raw == int(raw) else int(np.float32(raw).view(np.int32))
                if fl & 0x01000000:
                    wr = (packed & 0xFFFF) / 9999.0
                if fl & 0x02000000:
                    wl = ((packed >> 16) & 0xFFFF) / 9999.0
            h = float(dt[x])
            p0, p1, p2, p3 = float(v0[x]), float(v0[x]) + sr * wr * h, float(v1[x]) - sl * wl * h, float(v1[x])
            c0, c1, c2, c3 = 0.0, wr, 1.0 - wl, 1.0
            s = np.linspace(0.0, 1.0, 257)  # the Bezier's time is monotone for weights in [0, 1]
            bt = (1 - s) ** 3 * c0 + 3 * (1 - s) ** 2 * s * c1 + 3 * (1 - s) * s ** 2 * c2 + s ** 3 * c3
            bv = (1 - s) ** 3 * p0 + 3 * (1 - s) ** 2 * s * p1 + 3 * (1 - s) * s ** 2 * p2 + s ** 3 * p3
            curve[x] = float(np.interp(u[x], bt, bv))
    return curve, line


def _curve_interpolation(ctx) -> list:
    g, mesh = ctx.g, ctx.mesh
    if not mesh.clips:
        return []
    rate = float(mesh.time_codes_per_second)
    gaps = {}  # model -> {"r": deg, "t": units, "s": relative}
    for a, b, prop in g.prop_links:
        if b not in ctx.relevant or g.kind(a)[0] != "AnimationCurveNode" or prop not in (
                "Lcl Translation", "Lcl Rotation", "Lcl Scaling"):
            continue
        for axis, curve in _curve_nodes(g, b, prop).get(a, {}).items():
            if curve is None:
                continue
            n = g.objects[curve]
            kt, kv, fl = n.value("KeyTime"), n.value("KeyValueFloat"), n.value("KeyAttrFlags")
            if kt is None or kv is None or fl is None or len(kt) < 2 or len(kv) != len(kt):
                continue
            kt = np.asarray(kt, dtype=np.float64) / KTIME
            kv = np.asarray(kv, dtype=np.float64)
            flags = _per_key(n, fl, len(kt))
            data = _per_key(n, n.value("KeyAttrDataFloat"), len(kt), width=4)
            if not np.any(flags[:-1] & 0x0A):
                continue  # linear everywhere: what assimp does
            f0, f1 = np.ceil(kt[0] * rate - 1e-6), np.floor(kt[-1] * rate + 1e-6)
            grid = np.arange(f0, f1 + 1) / rate
            keyed = np.abs(grid[:, None] - kt[None, :]).min(axis=1) <= 1e-6 / rate
            grid = grid[~keyed]
            if not len(grid):
                continue
            curve_v, line_v = _curve_value(kt, kv, flags, data, grid)
            gap = float(np.abs(curve_v - line_v).max())
            key = {"Lcl Translation": "t", "Lcl Rotation": "r", "Lcl Scaling": "s"}[prop]
            if key == "s":
                gap /= max(float(np.abs(kv).min()), 1e-9)
            d = gaps.setdefault(b, {"t": 0.0, "r": 0.0, "s": 0.0})
            d[key] += gap  # components add: an upper bound of the rotation angle / move
    hits = {m: d for m, d in gaps.items() if d["t"] > 0 or d["r"] > 0 or d["s"] > 0}
    if not hits:
        return []
    which, pts, size = ctx.posed()
    bound = 0.0
    joint_of = {n: i for i, n in enumerate(mesh.joint_names)}
    for m, d in hits.items():
        name = g.name(m)
        j = joint_of.get(name)
        if j is None:
            reach = float(np.linalg.norm(pts - pts.mean(axis=(0, 1)), axis=2).max()) * 2  # anything
            scale = 1.0
        else:
            sub = _subtree(mesh.parents, j)
            rows = np.flatnonzero(np.isin(mesh.joint_indices, sub).any(axis=1))
            skel = bounds.skel_at(mesh, which)
            origin = skel[:, j, :3, 3]
            reach = float(np.linalg.norm(pts[:, rows] - origin[:, None], axis=2).max()) if len(rows) else 0.0
            p = mesh.parents[j]
            scale = float(np.linalg.norm(skel[:, p, :3, :3], ord=2, axis=(1, 2)).max()) if p >= 0 else 1.0
        bound += np.radians(d["r"]) * reach + d["t"] * scale + d["s"] * reach
    names = [g.name(m) for m in hits]
    return [notcarried.item(
        "fbx_curve_interpolation", names[:8] + ([f"... {len(names)} models"] if len(names) > 8 else []),
        "cubic or constant FBX curve segments span frames of the grid; assimp interpolates every curve linearly "
        "between its keys (first-order bound from the largest curve-to-line gap at the frames)", bound / size)]


def _per_key(n, arr, k, width=1):
    """A curve's per-key attribute (flags, or 4 data floats) expanded by ``KeyAttrRefCount``."""
    if arr is None:
        return np.zeros((k, width)) if width > 1 else np.zeros(k, dtype=np.int64)
    a = np.asarray(arr)
    refs = n.value("KeyAttrRefCount")
    if width == 1:
        a = a.astype(np.float64).astype(np.int64) if a.dtype != np.int64 else a
    else:
        a = np.asarray(a, dtype=np.float64).ravel()
        a = a[:len(a) // width * width].reshape(-1, width)  # a cut array: whole keys only (fuzz case 48)
    if refs is not None:
        refs = np.asarray(refs, dtype=np.int64)
        if len(refs) == len(a) and refs.sum() >= k:
            a = np.repeat(a, refs, axis=0)
    if len(a) < k:
        a = np.concatenate([a, np.repeat(a[-1:] if len(a) else (np.zeros((1, width)) if width > 1 else np.zeros(1, np.int64)), k - len(a), axis=0)])
    return a[:k]


def _subtree(parents, j) -> np.ndarray:
    inside = np.zeros(len(parents), dtype=bool)
    inside[j] = True
    for i in range(len(parents)):  # parents first
        p = parents[i]
        if p >= 0 and inside[p]:
            inside[i] = True
    return np.flatnonzero(inside)
