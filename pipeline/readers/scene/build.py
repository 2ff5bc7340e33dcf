"""The one way a :class:`Scene` becomes a :class:`~colossus.pipeline.model.SkinnedMesh`:
:func:`build`, as the steps it takes in order (one function each)::

    _animated_nodes    nodes whose local transform moves in some animation
    _skin_bones        the bones of every skin, and every node under one
    _choose_meshes     the meshes that move with the skeleton (``--mesh``)
    _joints            the joints: bones, animated nodes above them, nodes between two joints
    _bind_transforms   bind and rest transforms of every joint
    _geometry          the chosen meshes in skeleton space at bind time, with their weights
    _clips             every animation sampled on the frame grid (:func:`_grid_clip`)
    _skinned_mesh      the result, with its provenance

What each step decides is described in :mod:`colossus.pipeline.readers.scene`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...errors import InputError
from ...model import Clip, SkinnedMesh
from ...tolerances import GRID_KEY_FRAMES, SOURCE_WEIGHT_SUM, model_scale
from ...xforms import decompose_trs
from ..common import clip_name, pack_influences
from .graph import Scene, _ancestors, _world, check_scene
from .timeline import (MAX_FRAMES, _joint_locals, _off_grid, _resampling_bound, _weights_resampling_bound,
                       choose_fps, grid_frames)


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
    check_scene(scene, path)
    names, parents, nlocal = scene.names, np.asarray(scene.parents, dtype=np.int64), scene.local
    nworld = _world(nlocal, parents, scene.no_parent_scale)
    notes = list(scene.notes)
    all_meshes = [m for m in scene.meshes]
    if not all_meshes:
        raise InputError(path, "the scene has no mesh")
    animated = _animated_nodes(scene, nlocal)
    skinned, bone_nodes, under_bone = _skin_bones(all_meshes, parents)
    chosen = _choose_meshes(all_meshes, skinned, under_bone, meshes, path, notes)
    skel, unweighted = _joints(scene, all_meshes, chosen, parents, animated, bone_nodes, notes)
    bind, rest = _bind_transforms(all_meshes, chosen, skel, parents, nworld, path)
    positions, triangles, ji, jw, mesh_info, weights_normalised, shapes, shape_of = _geometry(
        all_meshes, chosen, names, skel, unweighted, parents, nworld, bind, budget, notes)
    clips, clip_info, rate = _clips(scene, path, fps, budget, skel, parents, rest, bind, positions, ji, jw,
                                    shape_of, len(shapes), shapes)
    return _skinned_mesh(scene, source, all_meshes, chosen, skel, bind, rest, positions, triangles, ji, jw,
                         mesh_info, weights_normalised, clips, clip_info, rate, notes, shapes)


class _Skeleton(NamedTuple):
    """The joints :func:`_joints` chose (unpacked as ``jn, jpos, jparents, jnames, ghost``)."""
    nodes: list        #: scene node of each joint made from a node, parents-first
    index: dict        #: scene node -> its joint
    parents: np.ndarray  #: (b,) int32 parent joint, -1 for roots (ghost joints last)
    names: list        #: (b,) joint names
    ghost: dict        #: bone name -> joint, for bones with no node in the scene


def _animated_nodes(scene: Scene, nlocal) -> set:
    """Nodes whose local transform moves in some animation: a channel with keys that differ, or
    one constant key that differs from the rest pose."""
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
    return animated


def _skin_bones(all_meshes, parents):
    """``(skinned, bone_nodes, under_bone)``: the skinned meshes (with weights and faces), the
    nodes of their bones, and for each node whether it is a bone or lies under one."""
    k = len(parents)
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
    return skinned, bone_nodes, under_bone


def _choose_meshes(all_meshes, skinned, under_bone, meshes, path, notes) -> list:
    """Indices of the meshes that move with the skeleton: those named by ``meshes``, else every
    skinned mesh and every mesh under a bone; meshes without faces are skipped (noted)."""
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
    return chosen


def _joints(scene: Scene, all_meshes, chosen, parents, animated, bone_nodes, notes):
    """``(_Skeleton, unweighted)``: the joints (every bone of the chosen skins, the bone or animated
    nodes above each rigid mesh, animated nodes above a joint, plain nodes between two joints,
    bones without a node as ghost root joints), and ``{mesh index: vertices of a skinned mesh
    with no weight}`` where the format makes those follow the mesh's node."""
    names, nlocal = scene.names, scene.local
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
    jparents = np.array(jparents, dtype=np.int32)
    return _Skeleton(jn, jpos, jparents, jnames, ghost), unweighted


def _bind_transforms(all_meshes, chosen, skel: _Skeleton, parents, nworld, path):
    """``(bind, rest)`` (b, 4, 4): bones from their inverse binds, other joints from the
    hierarchy relative to the nearest bone above them."""
    jn, jpos, jparents, jnames, ghost = skel
    nj = len(jnames)
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
    return bind, rest


def _geometry(all_meshes, chosen, names, skel: _Skeleton, unweighted, parents, nworld, bind, budget, notes):
    """``(positions, triangles, joint_indices, joint_weights, mesh_info, weights_normalised)``: the
    chosen meshes in skeleton space at bind time, one mesh, influences packed and normalised."""
    jn, jpos, jparents, jnames, ghost = skel
    pos_list, tri_list, vj, jj, ww = [], [], [], [], []
    mesh_info = []
    shapes, shape_of = [], {}  # merged blend shapes; (scene mesh, its shape) -> merged index
    shape_names = set()
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
            lin = (g[:3, :3], None)
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
            lin = (np.eye(3) if q is p else g[:3, :3], None)
            vj.append(s.vertex + base)
            jj.append(sj_of[s.joint])
            ww.append(s.weight)
            if i in unweighted:
                n = m.node
                owner = n if n in jpos else next(a for a in _ancestors(parents, n) if a in jpos)
                gu = bind[jpos[owner]] @ np.linalg.solve(nworld[owner], m.to_world)
                u = unweighted[i]
                q[u] = p[u] @ gu[:3, :3].T + gu[:3, 3]
                lin = (lin[0], (u, gu[:3, :3]))
                vj.append(u + base)
                jj.append(np.full(len(u), jpos[owner]))
                ww.append(np.ones(len(u)))
                notes.append(f"{len(u)} vertices of mesh {m.name!r} have no skin weight: they follow its node "
                             f"{names[n]!r} (bound to joint {names[owner]!r}), as the source application moves them")
            mesh_info.append({"name": m.name, "kind": "skinned", "vertices": nv})
        pos_list.append(q)
        tri_list.append(m.triangles + base)
        _merge_shapes(i, m, lin, base, shapes, shape_of, shape_names, len(chosen) > 1)
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
    return positions, triangles, ji, jw, mesh_info, weights_normalised, shapes, shape_of


def _merge_shapes(i, m, lin, base, shapes, shape_of, taken, prefix):
    """Scene mesh ``i``'s blend shapes into the merged mesh: its offsets moved into skeleton
    space by the linear part of the affine map its points took (``lin = (A, (u, A_u) or None)``:
    ``A`` for the mesh, ``A_u`` for its unweighted vertices ``u``; a shape displaces before the
    map, so ``G (p + d) = G p + A d``), indices shifted by ``base``, names made unique (prefixed
    by the mesh's name when several meshes are merged)."""
    from ...model import BlendShape
    from ..common import unique_name

    if not m.shapes:
        return
    A, over = lin
    for s, sh in enumerate(m.shapes):
        name = unique_name(f"{m.name}_{sh.name}" if prefix else sh.name, taken)
        taken.add(name)

        def mv(o, idx=sh.indices):
            out = np.asarray(o, dtype=np.float64) @ np.asarray(A).T
            if over is not None:
                hit = np.isin(idx, over[0])
                out[hit] = np.asarray(o, dtype=np.float64)[hit] @ over[1].T
            return out.astype(np.float32)
        shape_of[(i, s)] = len(shapes)
        shapes.append(BlendShape(name, sh.indices.astype(np.int64) + base, mv(sh.offsets),
                                 tuple((w, mv(o)) for w, o in sh.inbetweens)))


def _sample_weights(a, frames, rate, shape_of, S, key_tol):
    """(f, S) blend-shape weights of animation ``a`` on the grid ``frames``, each channel with its
    own interpolation (:func:`timeline.sample_channel`, clamped at its ends; shapes no channel
    drives are 0)."""
    from .timeline import sample_channel

    W = np.zeros((len(frames), S))
    for ch in a.weights:
        if not len(ch.times):
            continue
        vals = sample_channel(ch, frames / rate, key_tol)
        for s in range(vals.shape[1]):
            k = shape_of.get((ch.node, s))
            if k is not None:
                W[:, k] = vals[:, s]
    return W


def _clips(scene: Scene, path, fps, budget, skel: _Skeleton, parents, rest, bind, positions, ji, jw,
           shape_of=None, S=0, shapes=()):
    """``(clips, clip_info, rate)``: every animation with keys sampled on the one frame grid of
    ``rate`` frames per second, with its summary row (and its resampling error bound when keys
    fall between frames)."""
    jn, jpos, jparents, jnames, ghost = skel
    nlocal, k, nj = scene.local, len(scene.names), len(jnames)
    keyed = []
    for a in scene.animations:
        chans = [c for c in a.channels if len(c.times) and not c.static]
        chans += [c for c in a.weights if len(c.times) and not c.static and S]
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
        with np.errstate(all="ignore"):
            span = float(keys.max() - keys.min()) * rate
        if not span <= MAX_FRAMES:  # before the grid is allocated (NaN too)
            raise InputError(path, f"animation {a.name!r} spans {span:.3g} frames at {rate:g} fps; refusing")
        frames = grid_frames(keys, rate)
        if budget is not None:
            budget.claim(len(frames) * (len(sub) + nj) * 16 * 8 * 3, f"animation {a.name!r} ({len(frames)} frames)")
        seconds = frames / rate
        chans = [c for c in a.channels if len(c.times) and need[c.node]]
        jl = _joint_locals(seconds, chans, nlocal, static_t, static_q, static_s, sub, sub_of, sub_parents,
                           jsub, jparents, len(ghost), rest, sub_rrs, GRID_KEY_FRAMES / rate,
                           path=path, clip=name, jnames=jnames)
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
                                    sub_parents, jsub, jparents, len(ghost), rest, sub_rrs, GRID_KEY_FRAMES / rate,
                                    path=path, clip=name, jnames=jnames)
            info["error_bound"] = _resampling_bound(frames, rate, jl, off_keys, jl_keys, jparents, bind,
                                                    positions, ji, jw)
        W = _sample_weights(a, frames, rate, shape_of or {}, S, GRID_KEY_FRAMES / rate) if S else None
        if W is not None and len(off_keys):  # the weights' resampling error adds to the joints'
            W_keys = _sample_weights(a, off_keys * rate, rate, shape_of or {}, S, GRID_KEY_FRAMES / rate)
            info["error_bound"] += _weights_resampling_bound(frames, W, off_keys * rate, W_keys, shapes,
                                                             len(positions), jl_keys, jparents, bind)
        clips.append(_grid_clip(name, frames, jl, W))
        clip_info.append(info)
    if not clips and nj:
        shown = _shown_pose(nlocal, static_t, static_q, static_s, sub, sub_of, sub_parents, jsub, jparents,
                            ghost, rest, sub_rrs, bind, positions, ji, jw, path, jnames, taken, rate)
        if shown is not None:
            clips.append(shown[0])
            clip_info.append(shown[1])
    return clips, clip_info, rate


#: A file without animation whose node pose moves a vertex more than this (x the model size) off
#: the bind pose keeps that pose as a one-frame clip (float noise between the two stays out).
SHOWN_POSE_RELATIVE = 1e-6


def _shown_pose(nlocal, static_t, static_q, static_s, sub, sub_of, sub_parents, jsub, jparents, ghost, rest,
                sub_rrs, bind, positions, ji, jw, path, jnames, taken, rate):
    """``(clip, info)`` of the pose a file without animation shows (its nodes as written: what the
    authoring tool, assimp's scene and a glTF viewer display), when it differs from the bind pose
    by more than :data:`SHOWN_POSE_RELATIVE` x the model size; else None.  The difference is
    bounded as :func:`_resampling_bound` bounds a pose difference (per joint: the skinning
    difference's norm over a sphere round the joint's vertices)."""
    jl = _joint_locals(np.zeros(1), [], nlocal, static_t, static_q, static_s, sub, sub_of, sub_parents, jsub,
                       jparents, len(ghost), rest, sub_rrs, 0.0, path=path, clip="the shown pose", jnames=jnames)
    size = model_scale(positions)
    moved = _resampling_bound(np.zeros(1), 1.0, np.broadcast_to(rest, (1,) + rest.shape).copy(), np.zeros(1), jl,
                              jparents, bind, positions, ji, jw)
    if not (size > 0 and moved > SHOWN_POSE_RELATIVE * size):
        return None
    name = clip_name("pose", taken)
    info = {"name": name, "source_name": "", "source_keys": 0, "interpolation": "STEP", "frames": 1, "fps": rate,
            "keys_on_grid": True, "first_frame": 0.0, "last_frame": 0.0, "shown_pose": True,
            "shown_pose_moves_relative": float(moved / size),
            "sampling": "the pose the file shows (no animation): one frame"}
    return _grid_clip(name, np.zeros(1), jl), info


def _grid_clip(name, frames, local, shape_weights=None) -> Clip:
    """The clip as the asset stores it: the joint locals ``local`` (f, b, 4, 4) on the grid ``frames``
    (and the blend-shape weights (f, S) there)."""
    return Clip(name, frames, local, shape_weights)


def _skinned_mesh(scene: Scene, source, all_meshes, chosen, skel: _Skeleton, bind, rest, positions, triangles,
                  ji, jw, mesh_info, weights_normalised, clips, clip_info, rate, notes, shapes=()) -> SkinnedMesh:
    """The built mesh, and its provenance (``source`` completed)."""
    jn, jpos, jparents, jnames, ghost = skel
    size = model_scale(positions)
    for info in clip_info:
        if "error_bound" in info:
            info["error_bound_relative"] = float(info["error_bound"] / size)
    src = dict(source or {})
    src.update({"meshes": [all_meshes[i].name for i in chosen], "mesh_info": mesh_info,
                "clip_info": clip_info, "weights_normalised": weights_normalised,
                # morph targets a reader found but did not carry (carried ones are blend_shapes)
                "morph_meshes": {m.name: m.morph_targets for m in (all_meshes[i] for i in chosen)
                                 if m.morph_targets and not m.shapes},
                "notes": notes, "sampling_note": scene.sampling_note,
                "meshes_left_out": [m.name for i, m in enumerate(all_meshes) if i not in chosen and len(m.triangles)]})
    return SkinnedMesh(
        positions=positions.astype(np.float32), triangles=triangles, joint_indices=ji, joint_weights=jw,
        joint_names=jnames, parents=jparents, bind_transforms=bind, rest_transforms=rest,
        geom_bind=np.eye(4), clips=tuple(clips), time_codes_per_second=rate, source=src,
        blend_shapes=tuple(shapes))


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
    name = (raw or "").split("|")[-1].strip()
    return clip_name(name or f"animation_{index}", taken)
