"""Reader for every format assimp reads (glTF/GLB, FBX, Collada, ...), through ``assimp-py``.

How the source maps onto :class:`~pipeline.model.SkinnedMesh`:

* Skeleton space is assimp's scene-root ("world") space.  Joints are the nodes that are bones
  of the chosen meshes, plus plain nodes lying between two bones; FBX pivot helper nodes
  (``*_$AssimpFbx$_*``) are folded into their neighbours.  A root joint's local transform is its
  full world transform, so armature-object transforms are kept.
* Bind transforms come from the bones' offset matrices: ``bind_j = G @ inv(offset_j)`` and
  ``geom_bind = G``, where ``G`` takes mesh space to world space at bind time: the world transform
  of the mesh's node, except for glTF, whose skinned vertices ignore their node's transform
  (glTF 2.0 spec, "Skins": ``world = sum w * jointWorld @ inverseBind @ p``), so ``G`` is identity.
* Rest transforms are the bind pose expressed joint-local (``inv(bind_parent) @ bind_j``).
* Every animation is one clip, sampled at the union of its key times (the source's own frames):
  translation and scale linearly interpolated, rotation slerped, as assimp intends.
* Units and axes: glTF is Y-up metres by spec.  For FBX the header's ``UpAxis`` and
  ``UnitScaleFactor`` (centimetres per unit), which assimp does not apply, are read from the file.
  Other formats are taken as Y-up metres unless the caller says otherwise.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import InputError
from ..model import Clip, SkinnedMesh
from ..xforms import compose_trs, decompose_trs, slerp
from .common import AllocationBudget, check_finite, check_input_file, clip_name, infer_fps, pack_influences
from .fbx_header import read_global_settings

FBX_HELPER = "_$AssimpFbx$_"


def _flags():
    import assimp_py as A
    return A.Process_Triangulate | A.Process_SortByPType | A.Process_ValidateDataStructure


def _flatten(root):
    """Nodes in depth-first (parents-first) order: names, parent indices, local (k, 4, 4), meshes."""
    names, parents, local, meshes = [], [], [], []
    stack = [(root, -1)]
    while stack:
        node, parent = stack.pop()
        idx = len(names)
        names.append(node.name)
        parents.append(parent)
        local.append(np.array(node.transformation, dtype=np.float64).reshape(4, 4))
        meshes.append(list(node.mesh_indices))
        for child in reversed(node.children):
            stack.append((child, idx))
    return names, np.array(parents, dtype=np.int64), np.array(local), meshes


def _world(local, parents):
    """World transforms of nodes in parents-first order; ``local`` is (..., k, 4, 4)."""
    out = np.empty_like(local)
    for i, p in enumerate(parents):
        out[..., i, :, :] = local[..., i, :, :] if p < 0 else out[..., p, :, :] @ local[..., i, :, :]
    return out


def _mv(mv, dtype, width):
    if mv is None:
        return np.zeros((0, width), dtype=dtype)
    a = np.frombuffer(mv, dtype=dtype) if not isinstance(mv, np.ndarray) else mv
    return a.reshape(-1, width) if width > 1 else a


def _sample(times, key_t, key_v, kind):
    """Sample keys at ``times`` (clamped outside the key range)."""
    if len(key_t) == 1:
        return np.repeat(key_v[:1], len(times), axis=0)
    i = np.clip(np.searchsorted(key_t, times, side="right") - 1, 0, len(key_t) - 2)
    t0, t1 = key_t[i], key_t[i + 1]
    u = np.clip((times - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0, 1.0)
    if kind == "rot":
        return slerp(key_v[i], key_v[i + 1], u)
    return key_v[i] + (key_v[i + 1] - key_v[i]) * u[:, None]


def _source_frame(path, ext, fbx_settings):
    """(up_axis, meters_per_unit, notes) of assimp's output space for this file."""
    if ext in (".gltf", ".glb"):
        return "Y", 1.0, "glTF: Y-up metres by specification"
    if ext == ".fbx":
        up = {1: "Y", 2: "Z"}.get(int(fbx_settings.get("UpAxis", 1)), "Y")
        usf = float(fbx_settings.get("UnitScaleFactor", 1.0) or 1.0)
        return up, usf / 100.0, f"FBX header: UpAxis={up}, UnitScaleFactor={usf:g} cm per unit"
    return "Y", 1.0, "assumed Y-up metres (override with --source-up-axis / --source-meters-per-unit)"


def read_assimp(path, meshes=None, fps=None) -> SkinnedMesh:
    """Read a skinned mesh and all its clips from any file assimp imports.

    Parameters
    ----------
    path : str or PathLike
    meshes : list of str, optional
        Names of the meshes to take; default every mesh skinned to the skeleton, merged.
    fps : float, optional
        Frame rate of the time codes; default the file's own (inferred from key spacing for
        glTF, the header's frame rate for FBX).
    """
    path = os.fspath(path)
    size = check_input_file(path)
    budget = AllocationBudget(path, size)
    ext = os.path.splitext(path)[1].lower()
    import assimp_py

    try:
        scene = assimp_py.import_file(path, _flags())
    except Exception as exc:  # assimp reports every parse failure as a generic exception
        msg = " ".join(str(exc).split()) or type(exc).__name__
        raise InputError(path, f"not a readable {ext.lstrip('.').upper() or 'model'} file: {msg}") from None
    if scene is None or scene.root_node is None:
        raise InputError(path, "assimp returned no scene (empty or unsupported file)")

    names, nparents, nlocal, nmeshes = _flatten(scene.root_node)
    index_of = {}
    for i, n in enumerate(names):
        index_of.setdefault(n, i)
    nworld = _world(nlocal, nparents)

    # ---- choose meshes --------------------------------------------------------------------
    all_meshes = list(scene.meshes)
    if not all_meshes:
        raise InputError(path, "the scene has no mesh")
    if meshes:
        chosen = []
        avail = [m.name for m in all_meshes]
        for want in meshes:
            hit = [i for i, m in enumerate(all_meshes) if m.name == want]
            if not hit:
                raise InputError(path, f"no mesh named {want!r} (meshes: {', '.join(sorted(set(avail)))})")
            chosen.extend(hit)
        chosen = sorted(set(chosen))
    else:
        chosen = [i for i, m in enumerate(all_meshes) if m.num_bones > 0 and m.num_faces > 0]
        if not chosen:
            raise InputError(path, f"no skinned mesh: none of the {len(all_meshes)} meshes has bone weights (a mesh with no skin cannot be animated)")
    mesh_node = {}
    for ni, mlist in enumerate(nmeshes):
        for mi in mlist:
            mesh_node.setdefault(mi, ni)

    # ---- joints ---------------------------------------------------------------------------
    bone_offsets = {}
    for mi in chosen:
        m = all_meshes[mi]
        if m.num_bones == 0:
            raise InputError(path, f"mesh {m.name!r} has no skin (no bone weights)")
        for b in m.bones:
            node = b.node_name or b.name
            if node not in index_of:
                raise InputError(path, f"bone {b.name!r} of mesh {m.name!r} has no node in the scene")
            bone_offsets.setdefault(node, (mi, np.array(b.offset_matrix, dtype=np.float64).reshape(4, 4)))
    bone_nodes = {index_of[n] for n in bone_offsets}

    def ancestors(i):
        out = []
        p = nparents[i]
        while p >= 0:
            out.append(p)
            p = nparents[p]
        return out

    joint_nodes = set(bone_nodes)
    for i in bone_nodes:  # plain nodes lying between two bones become joints too
        anc = ancestors(i)
        for depth, a in enumerate(anc):
            if a in bone_nodes:
                joint_nodes.update(x for x in anc[:depth] if FBX_HELPER not in names[x])
                break
    jn = sorted(joint_nodes)  # node order is parents-first
    jpos = {n: k for k, n in enumerate(jn)}
    jparents = np.full(len(jn), -1, dtype=np.int32)
    for k, n in enumerate(jn):
        for a in ancestors(n):
            if a in jpos:
                jparents[k] = jpos[a]
                break
    jnames = [names[n].split(FBX_HELPER)[0] for n in jn]

    # ---- geometry and skin ----------------------------------------------------------------
    gltf = ext in (".gltf", ".glb")

    def mesh_to_world(mi):
        return np.eye(4) if gltf else nworld[mesh_node.get(mi, 0)]

    geom_bind = mesh_to_world(chosen[0])
    inv_geom = np.linalg.inv(geom_bind)
    pos_list, tri_list, vj, jj, ww = [], [], [], [], []
    base = 0
    for mi in chosen:
        m = all_meshes[mi]
        nv = m.num_vertices
        budget.claim(nv * 200 + m.num_faces * 40, f"mesh {m.name!r} ({nv} vertices)")
        v = _mv(m.vertices, np.float32, 3).astype(np.float64)
        if len(v) != nv:
            raise InputError(path, f"mesh {m.name!r}: vertex buffer holds {len(v)} positions, header says {nv}")
        check_finite(path, f"mesh {m.name!r} positions", v)
        if m.num_indices != 3 * m.num_faces:
            raise InputError(path, f"mesh {m.name!r} is not all triangles after triangulation")
        tri = _mv(m.indices, np.uint32, 3).astype(np.int64)
        if len(tri) and tri.max() >= nv:
            raise InputError(path, f"mesh {m.name!r}: face index {int(tri.max())} out of range for {nv} vertices")
        rel = inv_geom @ mesh_to_world(mi)
        if not np.allclose(rel, np.eye(4), atol=1e-9):
            v = v @ rel[:3, :3].T + rel[:3, 3]
        pos_list.append(v)
        tri_list.append(tri + base)
        for b in m.bones:
            ids = _mv(b.weight_vertex_ids, np.uint32, 1).astype(np.int64)
            w = _mv(b.weights, np.float32, 1).astype(np.float64)
            if len(ids) != len(w):
                raise InputError(path, f"bone {b.name!r}: {len(ids)} vertex ids but {len(w)} weights")
            if len(ids) and ids.max() >= nv:
                raise InputError(path, f"bone {b.name!r}: vertex index {int(ids.max())} out of range for {nv} vertices")
            check_finite(path, f"bone {b.name!r} weights", w[:, None])
            if len(w) and w.min() < 0:
                raise InputError(path, f"bone {b.name!r} has negative weights")
            vj.append(ids + base)
            jj.append(np.full(len(ids), jpos[index_of[b.node_name or b.name]]))
            ww.append(w)
        base += nv
    positions = np.concatenate(pos_list)
    triangles = np.concatenate(tri_list)
    ji, jw = pack_influences(base, np.concatenate(vj), np.concatenate(jj), np.concatenate(ww))
    budget.claim(ji.nbytes + jw.nbytes, "skin weights")

    # ---- bind and rest --------------------------------------------------------------------
    bind = np.empty((len(jn), 4, 4))
    for k, n in enumerate(jn):
        if names[n] in bone_offsets:
            mi, off = bone_offsets[names[n]]
            try:
                bind[k] = mesh_to_world(mi) @ np.linalg.inv(off)
            except np.linalg.LinAlgError:
                raise InputError(path, f"bone {names[n]!r} has a singular offset (inverse bind) matrix") from None
        else:
            bind[k] = nworld[n]
    check_finite(path, "bind transforms", bind.reshape(len(jn), -1))
    rest = np.empty_like(bind)
    for k, p in enumerate(jparents):
        rest[k] = bind[k] if p < 0 else np.linalg.solve(bind[p], bind[k])

    # ---- clips ----------------------------------------------------------------------------
    fbx = read_global_settings(path) if ext == ".fbx" else {}
    raw = []
    steps = []
    for a in scene.animations:
        tps = float(a.ticks_per_second or 0.0) or float(fbx.get("CustomFrameRate", 0) or 0) or 25.0
        chans = {}
        ticks = []
        for ch in a.channels:
            if ch.node_name not in index_of:
                continue
            pt = _mv(ch.position_key_times, np.float64, 1)
            rt = _mv(ch.rotation_key_times, np.float64, 1)
            st = _mv(ch.scaling_key_times, np.float64, 1)
            pv = _mv(ch.position_key_values, np.float32, 3).astype(np.float64)
            rv = _mv(ch.rotation_key_values, np.float32, 4).astype(np.float64)  # (x, y, z, w)
            sv = _mv(ch.scaling_key_values, np.float32, 3).astype(np.float64)
            for kt, kv in ((pt, pv), (rt, rv), (st, sv)):
                if len(kt) != len(kv):
                    raise InputError(path, f"animation {a.name!r}, node {ch.node_name!r}: {len(kt)} key times but {len(kv)} values")
                check_finite(path, f"animation {a.name!r} keys", kv)
                check_finite(path, f"animation {a.name!r} key times", kt[:, None])
            chans[index_of[ch.node_name]] = (pt, pv, rt, rv, st, sv)
            ticks.extend((pt, rt, st))
        t = np.unique(np.concatenate(ticks)) if ticks else np.zeros(0)
        secs = t / tps
        if len(secs) > 1:
            steps.append(np.diff(secs))
        raw.append((a.name, t, secs, chans))
    if fps is None:
        if ext == ".fbx" and fbx.get("CustomFrameRate"):
            fps = float(fbx["CustomFrameRate"])
        else:
            fps = infer_fps(np.concatenate(steps) if steps else [])
    fps = float(fps)

    static_t, static_q, static_s = decompose_trs(nlocal)
    clips, taken = [], set()
    for aname, ticks, secs, chans in raw:
        if len(secs) == 0:
            continue  # reported by the validators as an empty clip; nothing to sample here
        duration_frames = (secs[-1] - secs[0]) * fps
        budget.claim(len(secs) * (len(names) + len(jn)) * 16 * 8 * 2, f"animation {aname!r} ({len(secs)} frames)")
        if duration_frames > 10_000_000:
            raise InputError(path, f"animation {aname!r} spans {duration_frames:.0f} frames; refusing")
        local = np.broadcast_to(nlocal, (len(secs),) + nlocal.shape).copy()
        n = len(secs)
        for node, (pt, pv, rt, rv, st, sv) in chans.items():  # key times are in ticks
            tr = _sample(ticks, pt, pv, "lin") if len(pt) else np.repeat(static_t[node][None], n, 0)
            ro = _sample(ticks, rt, rv, "rot") if len(rt) else np.repeat(static_q[node][None], n, 0)
            sc = _sample(ticks, st, sv, "lin") if len(st) else np.repeat(static_s[node][None], n, 0)
            local[:, node] = compose_trs(tr, ro, sc)
        world = _world(local, nparents)
        jw_ = world[:, jn]
        jl = np.empty_like(jw_)
        for k, p in enumerate(jparents):
            jl[:, k] = jw_[:, k] if p < 0 else np.linalg.solve(jw_[:, p], jw_[:, k])
        times = secs * fps
        r = np.round(times)
        times = np.where(np.abs(times - r) < 1e-3, r, times)
        clips.append(Clip(clip_name(aname, taken), times, jl))

    up, mpu, note = _source_frame(path, ext, fbx)
    return SkinnedMesh(
        positions=positions.astype(np.float32), triangles=triangles, joint_indices=ji, joint_weights=jw,
        joint_names=jnames, parents=jparents, bind_transforms=bind, rest_transforms=rest,
        geom_bind=geom_bind, clips=tuple(clips), up_axis=up, meters_per_unit=mpu,
        time_codes_per_second=fps,
        source={"file": os.path.basename(path), "format": ext.lstrip("."), "reader": "assimp",
                "meshes": [all_meshes[i].name for i in chosen], "frame": note},
    )

