"""A source file's scene graph, and the one way it becomes a :class:`~pipeline.model.SkinnedMesh`.

The node-graph readers (glTF, and every format assimp reads) describe what the file holds as a
:class:`Scene`: nodes with their rest local transforms, meshes (skinned or not) attached to
nodes, and animation channels with their own key times, values and interpolation.
:func:`build` then decides, in one place for every format:

* **which meshes move with the skeleton**: every skinned mesh, and every mesh whose node lies
  under a joint (rigid skinning through the hierarchy: bound with weight 1 to the nearest joint
  above it), unless ``--mesh`` names them;
* **the joints**: the union of every chosen skin's bones (several skins become one skeleton;
  several roots are fine in UsdSkel), plain nodes lying between two joints, and every *animated*
  node above a joint or on a rigid mesh's path, so that each joint's local motion is one node's
  own interpolated TRS (composing two animated nodes into one joint would not interpolate like
  the source between frames);
* **skeleton space** is the scene's world space; every vertex is placed there in the bind pose,
  so ``geom_bind`` is identity;
* **the frame grid**: every clip is sampled on one regular grid, ``fps`` frames per second (the
  caller's ``--fps``; else the first rate of :data:`GRID_RATES` on which every key of every clip
  falls; else the rate holding the most clips; else 30), from the frame at or before its first key
  to the frame at or after its last, time zero kept.  Each channel is sampled with its own
  interpolation (LINEAR: lerp, slerp for rotations; STEP; CUBICSPLINE Hermite), so every key that
  falls on the grid keeps its exact pose, and the first and last keys' poses are held.  A clip
  whose keys fall off the grid gets a resampling error bound (:func:`_resampling_bound`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..model import Clip, SkinnedMesh
from ..tolerances import GRID_KEY_FRAMES, SOURCE_WEIGHT_SUM, model_scale
from ..xforms import compose_trs, decompose_trs, slerp
from .common import pack_influences

#: Frame rates tried, in order, for a file's own grid: the first on which every key falls wins.
GRID_RATES = (24.0, 30.0, 25.0, 60.0, 48.0, 50.0, 120.0, 23.976, 29.97, 59.94, 90.0, 100.0, 240.0,
              12.0, 15.0, 10.0, 8.0)
#: The grid's rate when no rate holds the keys (the contract's default).
DEFAULT_FPS = 30.0
INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")


@dataclass
class Skin:
    """A mesh's skin.

    Attributes
    ----------
    joints : (b,) int64
        Node index of each skin joint (``-1``: a bone with no node in the scene).
    inverse_binds : (b, 4, 4) float64
        Mesh space at bind time -> joint space (glTF ``inverseBindMatrices``, assimp offsets).
    names : list of str
        Name of each skin joint (used for bones without a node).
    vertex, joint : (e,) int64, weight : (e,) float64
        Flat influences: ``joint`` indexes ``joints``.
    """

    joints: np.ndarray
    inverse_binds: np.ndarray
    names: list
    vertex: np.ndarray
    joint: np.ndarray
    weight: np.ndarray


@dataclass
class SceneMesh:
    """One mesh of the scene.

    Attributes
    ----------
    name : str
    node : int
        Node holding the mesh (-1: none).
    positions : (n, 3) float64
        In mesh space.
    triangles : (m, 3) int64
    to_world : (4, 4) float64
        Mesh space -> world space at bind time (for a skinned mesh the transform its skin's
        inverse binds are relative to: identity for glTF, whose skinned meshes ignore their
        node's transform; the node's world transform otherwise).
    skin : Skin or None
    morph_targets : int
        Number of morph targets / shape keys (not carried into the collider).
    """

    name: str
    node: int
    positions: np.ndarray
    triangles: np.ndarray
    to_world: np.ndarray
    skin: Skin | None = None
    morph_targets: int = 0


@dataclass
class Channel:
    """The keys of one node's translation (``"t"``), rotation (``"r"``, x y z w) or scale (``"s"``).

    ``values`` is ``(k, c)``, or ``(k, 3, c)`` for CUBICSPLINE (in-tangent, value, out-tangent).
    ``times`` are seconds.
    """

    node: int
    path: str
    times: np.ndarray
    values: np.ndarray
    interpolation: str = "LINEAR"
    static: bool = False  #: a single unanimated value (USD default): no key time of the clip


@dataclass
class Animation:
    """One animation: its channels, and optionally its own span ``(start, stop)`` in seconds
    (an FBX stack's range; keys outside it are not part of the clip)."""

    name: str
    channels: list
    span: tuple | None = None


@dataclass
class Scene:
    """What a node-graph reader found in the file.

    Attributes
    ----------
    names : list of str
    parents : (k,) int64, parents first (each parent index lower than its child), -1 for roots
    local : (k, 4, 4) float64 rest local transforms
    meshes : list of SceneMesh
    animations : list of Animation
    helpers : set of int
        Nodes never made joints by themselves (FBX pivot helpers), folded into their neighbours.
    unweighted_follow_node : bool
        The format's rule for a skinned mesh's vertices without any weight: they stay with the
        mesh's node (FBX, Collada: an armature deforms only weighted vertices), bound rigidly to
        the joint that node moves with.  Otherwise they are left unweighted for ``bind`` to judge.
    no_parent_scale : dict
        ``{node: scale node}``: nodes that do not inherit their parent's scale (FBX
        ``InheritType`` 2, Maya's segment scale compensation): ``world = parent_world @ T @
        inv(S_parent) @ R @ S``, with ``S_parent`` the scale of the ``scale node``'s local transform.
    fps_hint : float or None
        The file's own declared frame rate (FBX header), tried first for the grid.
    sampling_note : str
        How the reader obtained the keys (for the summary).
    notes : list of str
        The reader's own findings, for the import's warnings.
    """

    names: list
    parents: np.ndarray
    local: np.ndarray
    meshes: list
    animations: list
    helpers: set = field(default_factory=set)
    fps_hint: float | None = None
    sampling_note: str = ""
    unweighted_follow_node: bool = False
    no_parent_scale: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)


# ------------------------------------------------------------------------------ sampling
def sample_channel(ch: Channel, seconds: np.ndarray, key_tolerance: float = 0.0) -> np.ndarray:
    """The channel's value at ``seconds`` (clamped to its first and last key), with its own
    interpolation.  Returns ``(f, c)`` float64; rotations are unit quaternions (x, y, z, w).

    A sample within ``key_tolerance`` seconds of a key takes that key's value exactly (no
    interpolation round-off; a file's float32 key times are never bit-equal to ``frame / fps``)."""
    t = np.asarray(ch.times, dtype=np.float64)
    v = np.asarray(ch.values, dtype=np.float64)
    cubic = ch.interpolation == "CUBICSPLINE"
    vals = v[:, 1] if cubic else v
    seconds = np.asarray(seconds, dtype=np.float64)
    if len(t) == 1:
        return np.repeat(vals[:1], len(seconds), axis=0)
    j = np.minimum(np.searchsorted(t, seconds - key_tolerance), len(t) - 1)
    on = np.abs(t[j] - seconds) <= key_tolerance
    if np.all(on):
        return vals[j]
    out = np.empty((len(seconds), vals.shape[1]))
    out[on] = vals[j[on]]
    x = seconds[~on]
    i = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 2)
    t0, t1 = t[i], t[i + 1]
    dt = np.where(t1 > t0, t1 - t0, 1.0)
    u = np.clip((x - t0) / dt, 0.0, 1.0)
    if ch.interpolation == "STEP":
        res = np.where((u >= 1.0)[:, None], vals[i + 1], vals[i])
    elif cubic:  # glTF 2.0 spec, Appendix C: Hermite spline with tangents scaled by the key interval
        u2, u3 = u * u, u * u * u
        h00, h10 = 2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u
        h01, h11 = -2 * u3 + 3 * u2, u3 - u2
        res = (h00[:, None] * v[i, 1] + (h10 * dt)[:, None] * v[i, 2]
               + h01[:, None] * v[i + 1, 1] + (h11 * dt)[:, None] * v[i + 1, 0])
        if ch.path == "r":
            res = res / np.linalg.norm(res, axis=1, keepdims=True)
    elif ch.path == "r":
        res = slerp(vals[i], vals[i + 1], u)
    else:
        res = vals[i] + (vals[i + 1] - vals[i]) * u[:, None]
    out[~on] = res
    return out


def _off_grid(seconds: np.ndarray, fps: float) -> np.ndarray:
    f = np.asarray(seconds, dtype=np.float64) * fps
    return np.abs(f - np.round(f)) > GRID_KEY_FRAMES


def choose_fps(key_seconds: list, hint: float | None = None) -> float:
    """The grid rate for clips whose keys are at ``key_seconds`` (one array per clip).

    The file's declared rate ``hint`` if every key falls on it, else the first of
    :data:`GRID_RATES` that holds every key, else the one holding the most clips (ties: earlier
    in the list), else :data:`DEFAULT_FPS`.
    """
    clips = [np.asarray(k, dtype=np.float64) for k in key_seconds if len(k) > 1]
    rates = ((float(hint),) if hint and hint > 0 else ()) + GRID_RATES
    if not clips:
        return float(hint) if hint and hint > 0 else 24.0
    best, best_n = None, 0
    for r in rates:
        n = sum(not np.any(_off_grid(k, r)) for k in clips)
        if n == len(clips):
            return r
        if n > best_n:
            best, best_n = r, n
    return best if best is not None else DEFAULT_FPS


def grid_frames(seconds: np.ndarray, fps: float) -> np.ndarray:
    """Whole frame numbers from the frame at or before the first key to the one at or after the last."""
    f = np.asarray(seconds, dtype=np.float64) * fps
    f0 = int(np.floor(f.min() + GRID_KEY_FRAMES))
    f1 = int(np.ceil(f.max() - GRID_KEY_FRAMES))
    return np.arange(f0, max(f0, f1) + 1, dtype=np.float64)


# ------------------------------------------------------------------------------ building
def _world(local, parents, no_parent_scale=None):
    """World transforms of nodes in parents-first order; ``local`` is (..., k, 4, 4).

    ``no_parent_scale`` ``{node: scale node}``: those nodes compose as
    ``parent_world @ T @ inv(S) @ (R S)`` with ``S`` the scale of ``local[scale node]`` (FBX
    segment scale compensation), i.e. their local's 3x3 left-multiplied by ``inv(S)``."""
    out = np.empty_like(local)
    rrs = no_parent_scale or {}
    for i, p in enumerate(parents):
        m = local[..., i, :, :]
        if i in rrs:
            s = np.linalg.norm(local[..., rrs[i], :3, :3], axis=-2)  # (..., 3) axis scales of the parent's local
            m = m.copy()
            m[..., :3, :3] = m[..., :3, :3] / s[..., :, None]
        out[..., i, :, :] = m if p < 0 else out[..., p, :, :] @ m
    return out


def _ancestors(parents, i):
    out = []
    p = parents[i]
    while p >= 0:
        out.append(int(p))
        p = parents[p]
    return out


def build(scene: Scene, path, meshes=None, fps=None, budget=None, source: dict | None = None) -> SkinnedMesh:
    """Turn ``scene`` into the skinned mesh of every mesh that moves with its skeleton.

    Parameters
    ----------
    scene : Scene
    path : str
        The source file (for error messages).
    meshes : list of str, optional
        Names of the meshes to take (``--mesh``); default every skinned mesh and every mesh
        under a joint.
    fps : float, optional
        Grid rate (``--fps``); default see :func:`choose_fps`.
    budget : AllocationBudget, optional
    source : dict, optional
        Extra provenance (file, format, reader, frame note), completed here with ``meshes``,
        ``mesh_info``, ``clip_info``, ``weights_normalised``, ``morph_meshes``, ``notes``.

    Returns
    -------
    SkinnedMesh
        Positions in skeleton (world) space at bind time, ``geom_bind`` identity, clips on the grid.
    """
    names, parents, nlocal = scene.names, np.asarray(scene.parents, dtype=np.int64), scene.local
    k = len(names)
    nworld = _world(nlocal, parents, scene.no_parent_scale)
    notes = list(scene.notes)
    all_meshes = [m for m in scene.meshes]
    if not all_meshes:
        raise InputError(path, "the scene has no mesh")

    # ---- animated nodes -------------------------------------------------------------------
    animated = set()
    for a in scene.animations:
        for ch in a.channels:
            if len(ch.times) > 1 and not np.allclose(ch.values, ch.values[:1], rtol=0, atol=0):
                animated.add(ch.node)
            elif len(ch.times):  # a constant channel that differs from the rest pose also moves the node
                rest_t, rest_q, rest_s = decompose_trs(nlocal[ch.node])
                val = ch.values[0, 1] if ch.interpolation == "CUBICSPLINE" else ch.values[0]
                ref = {"t": rest_t, "s": rest_s}.get(ch.path)
                same = (np.allclose(val, ref, atol=1e-9) if ref is not None
                        else abs(abs(float(np.dot(val / np.linalg.norm(val), rest_q))) - 1) < 1e-12)
                if not same:
                    animated.add(ch.node)

    # ---- bones of every skin --------------------------------------------------------------
    skinned = [i for i, m in enumerate(all_meshes) if m.skin is not None and len(m.skin.weight)
               and len(m.triangles)]
    bone_nodes = set()
    for i in skinned:
        bone_nodes.update(int(j) for j in all_meshes[i].skin.joints if j >= 0)
    # every node under a bone moves with the skeleton
    under_bone = np.zeros(k, dtype=bool)
    for i in range(k):
        p = parents[i]
        under_bone[i] = i in bone_nodes or (p >= 0 and under_bone[p])

    # ---- choose meshes --------------------------------------------------------------------
    def rigid_ok(m):
        return m.skin is None and m.node >= 0 and under_bone[m.node]

    if meshes:
        chosen = []
        for want in meshes:
            hit = [i for i, m in enumerate(all_meshes) if m.name == want]
            if not hit:
                avail = sorted({m.name for m in all_meshes})
                raise InputError(path, f"no mesh named {want!r} (meshes: {', '.join(avail)})")
            for i in hit:
                m = all_meshes[i]
                if m.skin is None and not rigid_ok(m):
                    raise InputError(path, f"mesh {want!r} has no skin and is not parented to a joint: "
                                     "it does not move with the skeleton")
            chosen.extend(hit)
        chosen = sorted(set(chosen))
    else:
        if not skinned:
            raise InputError(path, f"no skinned mesh: none of the {len(all_meshes)} meshes has bone weights "
                             "(a mesh with no skin cannot be animated)")
        chosen = [i for i, m in enumerate(all_meshes)
                  if (i in skinned or rigid_ok(m)) and len(m.triangles) and len(m.positions)]
    empty = [all_meshes[i].name for i in chosen if not len(all_meshes[i].triangles)]
    chosen = [i for i in chosen if len(all_meshes[i].triangles)]
    if not chosen:
        raise InputError(path, f"the chosen meshes have no faces ({', '.join(empty)})")
    if empty:
        notes.append(f"{len(empty)} meshes without faces skipped: {', '.join(empty[:5])}")

    # ---- joints ---------------------------------------------------------------------------
    used_bones = set()
    missing_bones = []  # (mesh index, skin joint index) of bones with no node
    for i in chosen:
        s = all_meshes[i].skin
        if s is None:
            continue
        live = np.flatnonzero(np.bincount(s.joint[s.weight > 0], minlength=len(s.joints)))
        for j in live:
            if s.joints[j] >= 0:
                used_bones.add(int(s.joints[j]))
        used_bones.update(int(j) for j in s.joints if j >= 0)
        missing_bones.extend((i, int(j)) for j in range(len(s.joints)) if s.joints[j] < 0)
    joint_nodes = set(used_bones)
    rigid = [i for i in chosen if all_meshes[i].skin is None]
    unweighted = {}  # mesh index -> vertices of a skinned mesh with no weight (they follow the mesh's node)
    if scene.unweighted_follow_node:
        for i in chosen:
            s = all_meshes[i].skin
            if s is not None and all_meshes[i].node >= 0:
                has = np.zeros(len(all_meshes[i].positions), dtype=bool)
                has[s.vertex[s.weight > 0]] = True
                if not has.all():
                    unweighted[i] = np.flatnonzero(~has)
                    rigid.append(i)  # its node's path is walked like a rigid mesh's
    # nearest bone above each rigid mesh, animated nodes on its path become joints
    for i in rigid:
        n = all_meshes[i].node
        path_nodes = [n] + _ancestors(parents, n)
        for x in path_nodes:
            if x in used_bones or x in bone_nodes:
                joint_nodes.add(x)  # the bone it is bound to (a bone of a skin left out by --mesh too)
                break
            if x in animated and x not in scene.helpers:
                joint_nodes.add(x)
    # animated nodes above a joint become joints; plain nodes between two joints too
    changed = True
    while changed:
        changed = False
        for j in sorted(joint_nodes):
            anc = _ancestors(parents, j)
            for depth, a in enumerate(anc):
                if a in joint_nodes:
                    add = {x for x in anc[:depth] if x not in scene.helpers}
                    break
            else:
                add = set()
                # the highest animated ancestor and everything below it up to j
                anim_anc = [d for d, a in enumerate(anc) if a in animated]
                if anim_anc:
                    add = {x for x in anc[:max(anim_anc) + 1] if x not in scene.helpers}
            if add - joint_nodes:
                joint_nodes |= add
                changed = True
    for i in unweighted:  # a node under no joint becomes a (static) root joint of its own
        n = all_meshes[i].node
        if not any(x in joint_nodes for x in [n] + _ancestors(parents, n)):
            joint_nodes.add(n)
    jn = sorted(joint_nodes)  # node order is parents-first
    jpos = {n: q for q, n in enumerate(jn)}
    jparents = []
    for n in jn:
        jparents.append(next((jpos[a] for a in _ancestors(parents, n) if a in jpos), -1))
    # A joint that does not inherit its parent joint's scale (FBX segment scale compensation)
    # cannot be a UsdSkel child of a scaled joint: its local transform would shear.  Its world
    # transform has no shear, so it hangs from the parent joint's own parent instead.
    scaled = _scaled_nodes(scene, nlocal)
    for q, n in enumerate(jn):
        p = jparents[q]
        if p < 0:
            continue
        chain = [n] + [a for a in _ancestors(parents, n)[:_ancestors(parents, n).index(jn[p])]]
        if any(c in scene.no_parent_scale and scene.no_parent_scale[c] in scaled for c in chain):
            jparents[q] = jparents[p]
    jnames = [names[n] for n in jn]
    # bones without a node: unanimated root joints at their bind pose
    ghost = {}
    for i, sj in missing_bones:
        nm = all_meshes[i].skin.names[sj]
        if nm not in ghost:
            ghost[nm] = len(jn) + len(ghost)
            jparents.append(-1)
            jnames.append(nm)
    if ghost:
        notes.append(f"{len(ghost)} bones have no node in the scene ({', '.join(list(ghost)[:4])}): kept as "
                     "unanimated root joints at their bind pose")
    nj = len(jnames)
    jparents = np.array(jparents, dtype=np.int32)

    # ---- bind transforms: bones from their inverse binds, other joints from the hierarchy ----
    bind = np.full((nj, 4, 4), np.nan)
    for i in chosen:
        s = all_meshes[i].skin
        if s is None:
            continue
        for sj, node in enumerate(s.joints):
            q = jpos.get(int(node)) if node >= 0 else ghost[s.names[sj]]
            if q is None or not np.isnan(bind[q, 0, 0]):
                continue
            try:
                bind[q] = all_meshes[i].to_world @ np.linalg.inv(s.inverse_binds[sj])
            except np.linalg.LinAlgError:
                raise InputError(path, f"joint {s.names[sj]!r} has a singular inverse bind matrix") from None
    bind_of_node = {}

    def node_bind(n):
        """Bind-pose world transform of node ``n``: its bone's bind, or its rest transform
        relative to the nearest bone above it, put onto that bone's bind."""
        if n in bind_of_node:
            return bind_of_node[n]
        q = jpos.get(n)
        if q is not None and not np.isnan(bind[q, 0, 0]):
            out = bind[q]
        else:
            anc = next((a for a in _ancestors(parents, n) if a in jpos and not np.isnan(bind[jpos[a], 0, 0])), None)
            if anc is None:
                out = nworld[n]
            else:
                out = node_bind(anc) @ np.linalg.solve(nworld[anc], nworld[n])
        bind_of_node[n] = out
        return out

    for q, n in enumerate(jn):
        if np.isnan(bind[q, 0, 0]):
            bind[q] = node_bind(n)
    if not np.all(np.isfinite(bind)):
        raise InputError(path, "bind transforms contain NaN or infinite values")
    rest = np.empty_like(bind)
    for q, p in enumerate(jparents):
        rest[q] = bind[q] if p < 0 else np.linalg.solve(bind[p], bind[q])

    # ---- geometry in skeleton space at bind time ------------------------------------------
    pos_list, tri_list, vj, jj, ww = [], [], [], [], []
    mesh_info = []
    base = 0
    bind_spread = 0.0
    for i in chosen:
        m = all_meshes[i]
        nv = len(m.positions)
        if budget is not None:
            budget.claim(nv * 200 + len(m.triangles) * 40, f"mesh {m.name!r} ({nv} vertices)")
        p = m.positions
        s = m.skin
        if s is None:
            n = m.node
            owner = n if n in jpos else next(a for a in _ancestors(parents, n) if a in jpos)
            g = bind[jpos[owner]] @ np.linalg.solve(nworld[owner], m.to_world)
            q = p @ g[:3, :3].T + g[:3, 3]
            vj.append(np.arange(nv) + base)
            jj.append(np.full(nv, jpos[owner]))
            ww.append(np.ones(nv))
            mesh_info.append({"name": m.name, "kind": "rigid", "vertices": nv, "joint": names[owner]})
        else:
            sj_of = np.array([jpos[int(x)] if x >= 0 else ghost[s.names[t]] for t, x in enumerate(s.joints)],
                             dtype=np.int64)
            # the skin's own bind pose put into the skeleton's: G = bind_j @ inverse_bind_j (one per
            # joint; they agree when the skin was bound in the skeleton's bind pose)
            g_all = bind[sj_of] @ s.inverse_binds
            live = np.flatnonzero(np.bincount(s.joint[s.weight > 0], minlength=len(s.joints)))
            g = g_all[live[0]] if len(live) else m.to_world
            if len(live) > 1:
                diff = np.abs(g_all[live] - g)[:, :3, :]
                if diff.max() > 1e-12:
                    ref = model_scale(p) or 1.0
                    spread = float(np.max(diff * np.r_[np.ones(3), 1.0 / ref][None, None, :]))
                    bind_spread = max(bind_spread, spread)
            q = p if np.allclose(g, np.eye(4), rtol=0, atol=1e-12) else p @ g[:3, :3].T + g[:3, 3]
            vj.append(s.vertex + base)
            jj.append(sj_of[s.joint])
            ww.append(s.weight)
            if i in unweighted:
                n = m.node
                owner = n if n in jpos else next(a for a in _ancestors(parents, n) if a in jpos)
                gu = bind[jpos[owner]] @ np.linalg.solve(nworld[owner], m.to_world)
                u = unweighted[i]
                q[u] = p[u] @ gu[:3, :3].T + gu[:3, 3]
                vj.append(u + base)
                jj.append(np.full(len(u), jpos[owner]))
                ww.append(np.ones(len(u)))
                notes.append(f"{len(u)} vertices of mesh {m.name!r} have no skin weight: they follow its node "
                             f"{names[n]!r} (bound to joint {names[owner]!r}), as the source application moves them")
            mesh_info.append({"name": m.name, "kind": "skinned", "vertices": nv})
        pos_list.append(q)
        tri_list.append(m.triangles + base)
        base += nv
    if bind_spread > 1e-6:
        notes.append(f"skins were bound in different poses (inverse binds disagree by {bind_spread:.2g} "
                     "relative); vertices are placed by their first joint's bind")
    positions = np.concatenate(pos_list)
    triangles = np.concatenate(tri_list)
    vflat, jflat, wflat = np.concatenate(vj), np.concatenate(jj), np.concatenate(ww)
    ji, jw = pack_influences(base, vflat, jflat, wflat)
    total = jw.astype(np.float64).sum(axis=1)
    off = (total > 0) & (np.abs(total - 1.0) > SOURCE_WEIGHT_SUM)
    weights_normalised = {"vertices": int(off.sum()),
                          "min_sum": round(float(total[off].min()), 4) if off.any() else 1.0,
                          "max_sum": round(float(total[off].max()), 4) if off.any() else 1.0}
    jw = np.where(total[:, None] > 0, jw / np.where(total > 0, total, 1.0)[:, None], jw).astype(np.float32)
    if budget is not None:
        budget.claim(ji.nbytes + jw.nbytes, "skin weights")

    # ---- clips on the grid ------------------------------------------------------------------
    keyed = []
    for a in scene.animations:
        chans = [c for c in a.channels if len(c.times) and not c.static]
        keys = np.unique(np.concatenate([c.times for c in chans])) if chans else np.zeros(0)
        if a.span is not None and len(keys):
            lo, hi = a.span
            eps = GRID_KEY_FRAMES / 1000.0
            keys = np.unique(np.r_[keys[(keys >= lo - eps) & (keys <= hi + eps)], lo, hi])
        keyed.append(keys)
    rate = float(fps) if fps else choose_fps(keyed, scene.fps_hint)
    static_t, static_q, static_s = decompose_trs(nlocal)
    need = np.zeros(k, dtype=bool)  # nodes whose world transform the joints need
    for n in jn:
        need[n] = True
        need[_ancestors(parents, n)] = True
    sub = np.flatnonzero(need)
    sub_of = {n: q for q, n in enumerate(sub)}
    sub_parents = np.array([sub_of.get(int(parents[n]), -1) for n in sub], dtype=np.int64)
    jsub = np.array([sub_of[n] for n in jn], dtype=np.int64)
    sub_rrs = {sub_of[c]: sub_of[sn] for c, sn in scene.no_parent_scale.items() if c in sub_of and sn in sub_of}
    clips, clip_info, taken = [], [], set()
    for ai, (a, keys) in enumerate(zip(scene.animations, keyed)):
        name = _clip_name(a.name, ai, taken)
        if len(keys) == 0:
            continue  # nothing to sample
        frames = grid_frames(keys, rate)
        if len(frames) > 10_000_000:
            raise InputError(path, f"animation {a.name!r} spans {len(frames)} frames; refusing")
        if budget is not None:
            budget.claim(len(frames) * (len(sub) + nj) * 16 * 8 * 3, f"animation {a.name!r} ({len(frames)} frames)")
        seconds = frames / rate
        chans = [c for c in a.channels if len(c.times) and need[c.node]]
        jl = _joint_locals(seconds, chans, nlocal, static_t, static_q, static_s, sub, sub_of, sub_parents,
                           jsub, jparents, len(ghost), rest, sub_rrs, GRID_KEY_FRAMES / rate)
        interp = sorted({c.interpolation for c in a.channels if len(c.times) and not c.static})
        off_keys = keys[_off_grid(keys, rate)]
        info = {"name": name, "source_name": a.name, "source_keys": int(len(keys)),
                "interpolation": "/".join(interp) or "LINEAR", "frames": int(len(frames)),
                "fps": rate, "keys_on_grid": bool(len(off_keys) == 0),
                "first_frame": float(frames[0]), "last_frame": float(frames[-1])}
        info["sampling"] = (f"{info['interpolation']} keys sampled at {rate:g} fps"
                            + ("" if not len(off_keys) else f" ({len(off_keys)} of {len(keys)} keys between frames)"))
        if len(off_keys):
            jl_keys = _joint_locals(off_keys, chans, nlocal, static_t, static_q, static_s, sub, sub_of,
                                    sub_parents, jsub, jparents, len(ghost), rest, sub_rrs, GRID_KEY_FRAMES / rate)
            info["error_bound"] = _resampling_bound(frames, rate, jl, off_keys, jl_keys, jparents, bind,
                                                    positions, ji, jw)
        clips.append(Clip(name, frames, jl))
        clip_info.append(info)

    size = model_scale(positions)
    for info in clip_info:
        if "error_bound" in info:
            info["error_bound_relative"] = float(info["error_bound"] / size)
    src = dict(source or {})
    src.update({"meshes": [all_meshes[i].name for i in chosen], "mesh_info": mesh_info,
                "clip_info": clip_info, "weights_normalised": weights_normalised,
                "morph_meshes": {m.name: m.morph_targets for m in (all_meshes[i] for i in chosen) if m.morph_targets},
                "notes": notes, "sampling_note": scene.sampling_note,
                "meshes_left_out": [m.name for i, m in enumerate(all_meshes) if i not in chosen and len(m.triangles)]})
    return SkinnedMesh(
        positions=positions.astype(np.float32), triangles=triangles, joint_indices=ji, joint_weights=jw,
        joint_names=jnames, parents=jparents, bind_transforms=bind, rest_transforms=rest,
        geom_bind=np.eye(4), clips=tuple(clips), time_codes_per_second=rate, source=src)


def _scaled_nodes(scene, nlocal) -> set:
    """Nodes whose scale is not 1 at rest or in some animation (what segment scale compensation
    has to undo)."""
    out = set()
    if not scene.no_parent_scale:
        return out
    wanted = set(scene.no_parent_scale.values())
    for n in wanted:
        if not np.allclose(np.linalg.norm(nlocal[n, :3, :3], axis=0), 1.0, atol=1e-9):
            out.add(n)
    for a in scene.animations:
        for c in a.channels:
            if c.path == "s" and c.node in wanted and not np.allclose(c.values, 1.0, atol=1e-9):
                out.add(c.node)
    return out


def _clip_name(raw, index, taken):
    """A clip's name: FBX ``Armature|walk`` becomes ``walk``; unnamed: ``animation_<index>``."""
    from .common import clip_name
    name = (raw or "").split("|")[-1].strip()
    return clip_name(name or f"animation_{index}", taken)


def _joint_locals(seconds, chans, nlocal, static_t, static_q, static_s, sub, sub_of, sub_parents, jsub,
                  jparents, n_ghost, rest, sub_rrs=None, key_tol=0.0):
    """(f, b, 4, 4) joint-local transforms at ``seconds``: node locals sampled, composed to world,
    made relative to each joint's parent joint (ghost joints hold their rest)."""
    f = len(seconds)
    loc = np.broadcast_to(nlocal[sub], (f, len(sub), 4, 4)).copy()
    by_node = {}
    for c in chans:
        by_node.setdefault(c.node, {})[c.path] = c
    if by_node:  # every animated node's TRS sampled, then composed in one call
        nodes = list(by_node)
        T = np.empty((f, len(nodes), 3))
        R = np.empty((f, len(nodes), 4))
        S = np.empty((f, len(nodes), 3))
        for x, node in enumerate(nodes):
            paths = by_node[node]
            T[:, x] = sample_channel(paths["t"], seconds, key_tol) if "t" in paths else static_t[node]
            R[:, x] = sample_channel(paths["r"], seconds, key_tol) if "r" in paths else static_q[node]
            S[:, x] = sample_channel(paths["s"], seconds, key_tol) if "s" in paths else static_s[node]
        loc[:, [sub_of[n] for n in nodes]] = compose_trs(T, R, S)
    world = _world(loc, sub_parents, sub_rrs)
    jw_ = world[:, jsub]
    b = len(jsub) + n_ghost
    out = np.empty((f, b, 4, 4))
    nb = len(jsub)
    par = np.asarray(jparents[:nb])
    out[:, :nb] = jw_
    kids = np.flatnonzero(par >= 0)
    if len(kids):
        out[:, kids] = np.linalg.solve(jw_[:, par[kids]], jw_[:, kids])
    for q in range(len(jsub), b):
        out[:, q] = rest[q]
    return out


def _interp_locals(frames, rate, jl, seconds):
    """Joint locals at ``seconds`` as UsdSkel interpolates the grid samples ``jl`` (lerp of
    translation and scale, slerp of rotation between the two neighbouring frames)."""
    t, q, s = decompose_trs(jl)
    x = np.asarray(seconds) * rate
    i = np.clip(np.searchsorted(frames, x, side="right") - 1, 0, len(frames) - 2) if len(frames) > 1 else np.zeros(len(x), int)
    if len(frames) == 1:
        return compose_trs(t[i], q[i], s[i])
    u = np.clip(x - frames[i], 0.0, 1.0)
    uu = np.broadcast_to(u[:, None], (len(u), jl.shape[1]))
    tt = t[i] + (t[i + 1] - t[i]) * uu[..., None]
    ss = s[i] + (s[i + 1] - s[i]) * uu[..., None]
    qq = slerp(q[i], q[i + 1], uu)
    return compose_trs(tt, qq, ss)


def _resampling_bound(frames, rate, jl, key_seconds, jl_keys, parents, bind, positions, ji, jw) -> float:
    """Upper bound, in skeleton units, of how far any vertex is from the source's pose at the
    source key times that fall between frames.

    Between two frames the asset interpolates each joint's TRS; the source interpolates between
    its own keys.  Both are smooth between their breakpoints, so the largest gap sits at a source
    key (for translations and scales, piecewise-linear, it is exactly there).  At each such key,
    a vertex skinned by joints ``j`` with weights summing to 1 is off by at most
    ``max_j |D_j p|`` with ``D_j`` the difference of the two skinning matrices; over the joint's
    vertices that is at most ``||D_j[:3, :3]||_2 * r_j + |D_j c_j|`` for a sphere ``(c_j, r_j)``
    around them.
    """
    from ..model import skel_transforms
    asset = skel_transforms(_interp_locals(frames, rate, jl, key_seconds), parents)
    src = skel_transforms(jl_keys, parents)
    inv_bind = np.linalg.inv(bind)
    d = (asset - src) @ inv_bind  # (f, b, 4, 4)
    p = positions.astype(np.float64)
    bound = 0.0
    for j in range(len(bind)):
        rows = np.flatnonzero(np.any((ji == j) & (jw > 0), axis=1))
        if not len(rows):
            continue
        pts = p[rows]
        c = 0.5 * (pts.min(0) + pts.max(0))
        r = float(np.linalg.norm(pts - c, axis=1).max())
        dj = d[:, j]
        lin = np.linalg.norm(dj[:, :3, :3], ord=2, axis=(1, 2))
        off = np.linalg.norm(dj[:, :3, :3] @ c + dj[:, :3, 3], axis=1)
        bound = max(bound, float(np.max(lin * r + off)))
    return bound
