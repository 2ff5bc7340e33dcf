"""Reader for every other format assimp reads (FBX, Collada, DirectX ``.x``, MD5, ...), through ``assimp-py``.

The file becomes a :class:`~pipeline.readers.scene.Scene` (assimp's node graph, meshes with their
bones' offset matrices, animation channels); :func:`~pipeline.readers.scene.build.build` chooses the
meshes and joints and samples the clips on the frame grid, as for every node-graph format.

* A mesh's bind-time mesh-to-world transform is its node's world transform; a bone's offset
  matrix is its inverse bind in mesh space (``bind_j = G @ inv(offset_j)``).
* FBX pivot helper nodes (``*_$AssimpFbx$_*``) are never joints by themselves; they fold into
  their neighbours.
* Keys are assimp's (FBX curves and Collada samplers as assimp bakes them), interpolated the way
  assimp intends: translation and scale linearly, rotation slerped.  Times are ticks at
  ``ticks_per_second`` (for FBX without one, the header's frame rate).
* Units and axes: for FBX the header's ``UpAxis`` and ``UnitScaleFactor`` (centimetres per unit),
  which assimp does not apply, are read from the file.  Other formats are taken as Y-up metres
  unless the caller says otherwise.
* A bone with no node in the scene (``anim_test.x``: weights on ``joint3``/``joint4`` but no frame)
  is kept as an unanimated root joint at its bind pose: assimp has nothing that could move it,
  so its vertices keep their bind position relative to it, as in assimp's own skinning.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import InputError
from .common import AllocationBudget, check_finite, check_input_file
from .fbx_header import read_anim_stacks, read_global_settings, read_inherit_types, read_morph_geometry
from . import fbx_checks, fbx_doc, ogre
from .collada_xml import read_clips, read_skins
from .scene import Animation, Channel, Scene, SceneMesh, Skin
from .scene.build import build

FBX_HELPER = "_$AssimpFbx$_"


def _extension(path) -> str:
    """The file's extension as the reader table keys it (``.mesh.xml`` whole)."""
    low = os.path.basename(os.fspath(path)).lower()
    return ".mesh.xml" if low.endswith(".mesh.xml") else os.path.splitext(low)[1]


def assimp_flags():
    """The post-processing steps this reader asks assimp for (triangulate, sort by primitive type,
    validate the data structure)."""
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


def _mv(mv, dtype, width):
    """An assimp-py memoryview as ``(n, width)`` (``(n,)`` for width 1), empty when None."""
    if mv is None:
        return np.zeros((0, width) if width > 1 else 0, dtype=dtype)
    a = np.frombuffer(mv, dtype=dtype) if not isinstance(mv, np.ndarray) else mv
    return a.reshape(-1, width) if width > 1 else a.reshape(-1)


def _source_frame(path, ext, fbx_settings):
    """(up_axis, meters_per_unit, notes) of assimp's output space for this file."""
    if ext == ".fbx":
        up = {1: "Y", 2: "Z"}.get(int(fbx_settings.get("UpAxis", 1)), "Y")
        usf = float(fbx_settings.get("UnitScaleFactor", 1.0) or 1.0)
        return up, usf / 100.0, f"FBX header: UpAxis={up}, UnitScaleFactor={usf:g} cm per unit"
    return "Y", 1.0, "assumed Y-up metres (override with --source-up-axis / --source-meters-per-unit)"


#: FbxTime::EMode -> frames per second (14 is eCustom: ``CustomFrameRate``).
_FBX_RATES = {1: 120.0, 2: 100.0, 3: 60.0, 4: 50.0, 5: 48.0, 6: 30.0, 7: 30.0, 8: 29.97, 9: 29.97, 10: 25.0,
              11: 24.0, 12: 1000.0, 13: 23.976, 15: 96.0, 16: 72.0, 17: 59.94}


def _fbx_rate(fbx) -> float | None:
    """The FBX header's frame rate: ``TimeMode`` (FbxTime::EMode), or ``CustomFrameRate`` in custom mode."""
    mode = fbx.get("TimeMode")
    if mode is not None and int(mode) in _FBX_RATES:
        return _FBX_RATES[int(mode)]
    custom = float(fbx.get("CustomFrameRate", 0) or 0)
    return custom if custom > 0 else None


def read_scene(path, budget, fbx, doc=None) -> Scene:
    """Read any file assimp imports into a :class:`Scene`."""
    import assimp_py

    ext = _extension(path)
    try:
        scene = assimp_py.import_file(path, assimp_flags())
    except Exception as exc:  # assimp reports every parse failure as a generic exception
        msg = " ".join(str(exc).split())
        if "bad_alloc" in msg:  # the contained reader's memory cap: the standard line (isolation)
            raise MemoryError(msg) from None
        # assimp's message starts "Assimp error loading '<path>':" and is sometimes nothing more
        # (an FBX whose compressed arrays do not inflate): the reason is ours then
        head = msg.split(":", 1)
        if msg.startswith("Assimp error loading") and len(head) == 2 and "'" in head[0]:
            msg = msg[msg.index("':") + 2:].strip() if "':" in msg else head[1].strip()
        msg = msg or ("assimp gave no reason (corrupt, compressed data it cannot inflate, or a variant of the "
                      "format it does not read)")
        raise InputError(path, f"not a readable {ext.lstrip('.').upper() or 'model'} file: {msg}") from None
    if scene is None or scene.root_node is None:
        raise InputError(path, "assimp returned no scene (empty or unsupported file)")

    notes = []
    names, nparents, nlocal, nmeshes = _flatten(scene.root_node)
    check_finite(path, "node transforms", nlocal.reshape(len(names), 16))
    index_of = {}
    for i, n in enumerate(names):
        index_of.setdefault(n, i)
    nworld = np.empty_like(nlocal)
    for i, p in enumerate(nparents):
        nworld[i] = nlocal[i] if p < 0 else nworld[p] @ nlocal[i]
    mesh_node = {}
    for ni, mlist in enumerate(nmeshes):
        for mi in mlist:
            mesh_node.setdefault(mi, ni)

    morph = read_morph_geometry(doc) if ext == ".fbx" else {}
    collada = read_skins(path) if ext == ".dae" else {}
    mended = []
    meshes = []
    for mi, m in enumerate(scene.meshes):
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
        node = mesh_node.get(mi, -1)
        to_world = nworld[node] if node >= 0 else np.eye(4)
        skin = None
        if m.num_bones:
            joints, ibms, bnames, vv, jj, ww = [], [], [], [], [], []
            for bi, b in enumerate(m.bones):
                ids = _mv(b.weight_vertex_ids, np.uint32, 1).astype(np.int64)
                w = _mv(b.weights, np.float32, 1).astype(np.float64)
                if len(ids) != len(w):
                    raise InputError(path, f"bone {b.name!r}: {len(ids)} vertex ids but {len(w)} weights")
                if len(ids) and ids.max() >= nv:
                    raise InputError(path, f"bone {b.name!r}: vertex index {int(ids.max())} out of range for {nv} vertices")
                check_finite(path, f"bone {b.name!r} weights", w[:, None])
                if len(w) and w.min() < 0:
                    raise InputError(path, f"bone {b.name!r} has negative weights")
                off = np.array(b.offset_matrix, dtype=np.float64).reshape(4, 4)
                check_finite(path, f"bone {b.name!r} offset matrix", off[None].reshape(1, -1))
                bname = b.node_name or b.name
                joints.append(index_of.get(bname, -1))
                ibms.append(off)
                bnames.append(bname)
                vv.append(ids)
                jj.append(np.full(len(ids), bi, dtype=np.int64))
                ww.append(w)
            skin = Skin(np.array(joints, dtype=np.int64), np.array(ibms), bnames,
                        np.concatenate(vv), np.concatenate(jj), np.concatenate(ww))
            if m.name in collada:
                fixed = _collada_influences(collada[m.name], skin, nv)
                if fixed is not None:
                    skin = fixed
                    mended.append(m.name)
        meshes.append(SceneMesh(name=m.name, node=node, positions=v, triangles=tri, to_world=to_world,
                                skin=skin, morph_targets=morph.get(m.name, 0) or morph.get(names[node] if node >= 0 else "", 0)))

    hint = _fbx_rate(fbx) if ext == ".fbx" else None
    stacks = read_anim_stacks(doc) if ext == ".fbx" else {}
    dae_clips = read_clips(path) if ext == ".dae" else []
    anims = []
    is_ogre = ogre.is_ogre(path)  # Ogre plays rotations by nlerp (RIM_LINEAR), assimp's keys are its own
    for ai, a in enumerate(scene.animations):
        tps = float(a.ticks_per_second or 0.0) or hint or 25.0
        span = stacks.get(a.name)
        shift = span[0] if span else 0.0  # assimp starts each FBX stack at 0: back to scene time
        chans = []
        for ch in a.channels:
            if ch.node_name not in index_of:
                continue
            node = index_of[ch.node_name]
            for path_, kt, kv, width in (("t", ch.position_key_times, ch.position_key_values, 3),
                                         ("r", ch.rotation_key_times, ch.rotation_key_values, 4),
                                         ("s", ch.scaling_key_times, ch.scaling_key_values, 3)):
                t = _mv(kt, np.float64, 1)
                v = _mv(kv, np.float32, width).astype(np.float64)  # rotations (x, y, z, w)
                if len(t) != len(v):
                    raise InputError(path, f"animation {a.name!r}, node {ch.node_name!r}: {len(t)} key times but {len(v)} values")
                if not len(t):
                    continue
                check_finite(path, f"animation {a.name!r} keys", v)
                check_finite(path, f"animation {a.name!r} key times", t[:, None])
                order = np.argsort(t, kind="stable")
                t, v = t[order], v[order]
                keep = np.r_[True, np.diff(t) > 0]  # assimp may repeat a time: the first key wins
                t, v = t[keep], v[keep]
                if path_ == "r":
                    nrm = np.linalg.norm(v, axis=1)
                    if np.any(nrm < 1e-12):
                        raise InputError(path, f"animation {a.name!r}, node {ch.node_name!r}: a zero rotation quaternion")
                    v = v / nrm[:, None]
                chans.append(Channel(node, path_, t / tps + shift, v, "NLERP" if is_ogre else "LINEAR"))
        name = a.name
        if is_ogre and float(a.duration or 0.0) > 0.0:  # Ogre plays a track's gap to the length as a wrap
            length = float(a.duration) / tps
            chans = ogre.wrap_to_length(chans, length)
            span = (0.0, length)
        if dae_clips and len(dae_clips) == len(scene.animations) and a.name == f"combinedAnim_{ai}":
            # assimp's name for the i-th <animation_clip>: the file's name and window instead
            name, lo, hi = dae_clips[ai]
            if np.isfinite(hi) and hi >= lo:
                span = (lo, hi)
        anims.append(Animation(name, chans, span))
    if is_ogre:  # Ogre adds a key's translation in the parent's space; assimp does not
        ogre.mend_translations(nlocal, [a.channels for a in anims])
    helpers = {i for i, n in enumerate(names) if FBX_HELPER in n}
    if mended:
        notes.append(f"assimp's skin weights of {', '.join(mended)} did not follow the file's <vertex_weights> "
                     "(a known assimp error on Collada <polygons>): the file's own weights were used")
    rrs = _segment_scale_nodes(names, nparents, read_inherit_types(doc)) if ext == ".fbx" else {}
    return Scene(names=[n.split(FBX_HELPER)[0] for n in names], parents=nparents, local=nlocal, meshes=meshes,
                 notes=notes,
                 animations=anims, helpers=helpers, fps_hint=hint, unweighted_follow_node=True,
                 no_parent_scale=rrs,
                 sampling_note="keys as assimp bakes them, lerp / slerp between")


def _collada_influences(entry, skin, nv):
    """``skin`` with the influences the Collada file itself gives each of assimp's vertices (one
    per corner, in document order), when they differ from assimp's; None when they agree or
    cannot be mapped (corner count, a joint assimp has no bone for)."""
    corners = entry["corners"]
    if len(corners) != nv or (len(corners) and (corners.min() < 0 or corners.max() >= entry["vertices"])):
        return None
    bone_of = {}
    for j, cands in enumerate(entry["joints"]):
        hit = next((b for b, name in enumerate(skin.names) if name in cands), None)
        if hit is not None:
            bone_of[j] = hit
    live = entry["weight"] > 0
    if any(int(j) not in bone_of for j in np.unique(entry["joint"][live])):
        return None
    # file influences of each Collada vertex, then of each corner
    order = np.argsort(entry["vertex"], kind="stable")
    xv, xj, xw = entry["vertex"][order], entry["joint"][order], entry["weight"][order]
    start = np.searchsorted(xv, np.arange(entry["vertices"] + 1))
    counts = np.diff(start)[corners]
    corner = np.repeat(np.arange(nv), counts)
    src = np.repeat(start[corners], counts) + (np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts))
    lut = np.array([bone_of.get(j, -1) for j in range(len(entry["joints"]))], dtype=np.int64)
    vj, jj, ww = corner, lut[xj[src]], xw[src]
    keep = (ww > 0) & (jj >= 0)
    vj, jj, ww = vj[keep], jj[keep], ww[keep]
    nb = len(skin.names)
    mine = np.zeros((nv, nb))
    np.add.at(mine, (skin.vertex, skin.joint), skin.weight)
    file_ = np.zeros((nv, nb))
    np.add.at(file_, (vj, jj), ww)
    if np.max(np.abs(mine - file_)) <= 1e-6:
        return None
    return Skin(skin.joints, skin.inverse_binds, skin.names, vj, jj, ww)


def _segment_scale_nodes(names, parents, inherit) -> dict:
    """``{top node of a model: node holding its parent model's scale}`` for FBX models with
    ``InheritType`` 2 (no parent scale: Maya's segment scale compensation).

    assimp splits a model with pivots into a chain ``M_$AssimpFbx$_Translation -> ... -> M``; its
    top node is where the parent's scale must be undone, and a parent's scale sits in its
    ``_$AssimpFbx$_Scaling`` helper when it has one, else in the model's own node."""
    model_of = [n.split(FBX_HELPER)[0] for n in names]
    out = {}
    for i, n in enumerate(names):
        if inherit.get(model_of[i]) != 2:
            continue
        p = parents[i]
        if p < 0 or model_of[p] == model_of[i]:
            continue  # not the top of its chain
        parent_model = model_of[p]
        scale_node = next((k for k, m in enumerate(names) if m == f"{parent_model}{FBX_HELPER}Scaling"), p)
        out[i] = scale_node
    return out


def read_assimp(path, meshes=None, fps=None):
    """Read a skinned mesh (and the meshes parented to its joints) and all its clips from any
    file assimp imports.

    Parameters
    ----------
    path : str or PathLike
    meshes : list of str, optional
        Names of the meshes to take; default every skinned mesh and every mesh under a joint.
    fps : float, optional
        Frame grid rate; default the file's own (the FBX header's when every key falls on it).
    """
    path = os.fspath(path)
    size = check_input_file(path)
    budget = AllocationBudget(path, size)
    ext = _extension(path)
    if ext == ".fbx":
        why = fbx_checks.refusal(fbx_doc.file_version(path))
        if why:
            raise InputError(path, why)
    doc = fbx_doc.read_document(path) if ext == ".fbx" else None  # one parse for every FBX read here
    fbx = read_global_settings(doc) if ext == ".fbx" else {}
    skeleton = None
    if ogre.is_ogre(path):  # the skeleton it names: inside its folder, and present (assimp drops a missing one)
        skeleton = ogre.check_skeleton(path)
    scene = read_scene(path, budget, fbx, doc)
    up, mpu, note = _source_frame(path, ext, fbx)
    mesh = build(scene, path, meshes=meshes, fps=fps, budget=budget,
                 source={"file": os.path.basename(path), "format": ext.lstrip("."), "reader": "assimp",
                         "frame": note})
    if ext == ".fbx":  # what the file says about deforming that assimp does not carry (fail closed)
        mesh.source["not_carried"] = fbx_checks.morph_records(doc, mesh) + fbx_checks.check(doc, mesh, scene)
    if ogre.is_ogre(path):  # pose / morph animation, animation links: named, never dropped silently
        mesh.source["not_carried"] = ogre.not_carried(path, skeleton)
    return mesh.replace(up_axis=up, meters_per_unit=mpu)
