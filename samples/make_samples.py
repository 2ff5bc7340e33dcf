"""Generate colossus's Blender sample exports (glTF binary, FBX, USDA).

Run with a Python that has the ``bpy`` module (Blender as a Python module)::

    /work/bpyenv/.venv311/bin/python samples/make_samples.py [--out DIR]

Every scene is built from scratch (empty factory settings); the geometry,
weights and animation are computed analytically, so the output is
deterministic. Writes, into DIR (default: this script's folder):

    limb.glb limb.fbx limb.usda
    creature.glb creature.fbx creature.usda
    limb_flipped.glb
    samples.json   (Blender-side ground truth: counts, bones, actions, fps)

Conventions
-----------
* Each action is keyed on frames 0..N (N = its "frame count" in samples.json),
  so its duration is N / fps seconds and its first key is at t = 0.
* Every action keys location + rotation_quaternion of *every* bone, so any
  single action fully defines the pose.
* Actions are stashed as one single-strip NLA track each (named after the
  action). For the glTF export no action is active (so each track becomes one
  glTF animation named after its action, no duplicates); for the FBX export
  "all actions" mode makes one take per action; for USD (which only writes the
  active action) the first action is made active.
* The armature's rest pose is the bind pose (the mesh is modelled in rest
  pose, weights are assigned in rest pose, nothing is applied afterwards).
"""

import argparse
import datetime
import json
import math
import os
import sys

# The FBX exporter derives object ids from Python's (salted) str hash: pin the
# hash seed so that re-running gives byte-identical files.
if __name__ == "__main__" and os.environ.get("PYTHONHASHSEED") != "0":
    os.environ["PYTHONHASHSEED"] = "0"
    os.execv(sys.executable, [sys.executable] + sys.argv)

import bpy  # must come before bmesh / mathutils
import bmesh
from mathutils import Euler, Matrix, Quaternion, Vector

FPS = 24


# ---------------------------------------------------------------------------
# Geometry helpers (pure python, deterministic)
# ---------------------------------------------------------------------------

def capsule(p0, p1, radius, segments, rings, radius_fn=None, phase=0.0):
    """Closed capsule between points p0 and p1 (body rings + hemispherical caps).

    Returns (verts, faces) with faces as tuples of vertex indices (quads + the
    triangle fans around the two poles). ``rings`` is the number of vertex rings
    (caps included, poles excluded). ``radius_fn(t)`` optionally scales the
    radius along the axis (t in [0, 1] from p0 to p1). Outward facing, CCW.
    """
    p0 = Vector(p0)
    p1 = Vector(p1)
    axis = p1 - p0
    length = axis.length
    z = axis.normalized()
    # any vector not parallel to z
    helper = Vector((1.0, 0.0, 0.0)) if abs(z.x) < 0.9 else Vector((0.0, 1.0, 0.0))
    x = z.cross(helper).normalized()
    y = z.cross(x)

    rf = radius_fn or (lambda t: 1.0)
    r0 = radius * rf(0.0)
    r1 = radius * rf(1.0)
    # Split the rings among: bottom cap, body, top cap
    cap_rings = max(2, rings // 6)
    body_rings = rings - 2 * cap_rings
    assert body_rings >= 2

    ring_params = []  # (axial position along axis from p0 (may be <0 or >length), ring radius)
    for i in range(cap_rings):  # bottom cap (excluding pole, excluding equator)
        a = (math.pi / 2) * (i + 1) / (cap_rings + 1)  # angle from pole
        ring_params.append((-r0 * math.cos(a), r0 * math.sin(a)))
    for i in range(body_rings):
        t = i / (body_rings - 1)
        ring_params.append((t * length, radius * rf(t)))
    for i in range(cap_rings):  # top cap
        a = (math.pi / 2) * (cap_rings - i) / (cap_rings + 1)
        ring_params.append((length + r1 * math.cos(a), r1 * math.sin(a)))

    verts = [tuple(p0 - z * r0)]  # bottom pole
    for k, (h, r) in enumerate(ring_params):
        for s in range(segments):
            ang = 2.0 * math.pi * s / segments + phase
            v = p0 + z * h + (x * math.cos(ang) + y * math.sin(ang)) * r
            verts.append(tuple(v))
    verts.append(tuple(p1 + z * r1))  # top pole
    top = len(verts) - 1

    def ring_index(k, s):
        return 1 + k * segments + (s % segments)

    faces = []
    nr = len(ring_params)
    for s in range(segments):  # bottom fan (normal pointing -z)
        faces.append((0, ring_index(0, s + 1), ring_index(0, s)))
    for k in range(nr - 1):
        for s in range(segments):
            faces.append((ring_index(k, s), ring_index(k, s + 1),
                          ring_index(k + 1, s + 1), ring_index(k + 1, s)))
    for s in range(segments):  # top fan
        faces.append((ring_index(nr - 1, s), ring_index(nr - 1, s + 1), top))
    return verts, faces


def ellipsoid(center, radii, segments, rings, rot=None):
    """Closed UV ellipsoid (poles along local z), optionally rotated."""
    c = Vector(center)
    m = rot.to_matrix() if rot is not None else Matrix.Identity(3)
    verts = [tuple(c + m @ Vector((0.0, 0.0, -radii[2])))]
    for k in range(rings):
        th = math.pi * (k + 1) / (rings + 1)  # from bottom pole
        zz = -math.cos(th)
        rr = math.sin(th)
        for s in range(segments):
            ang = 2.0 * math.pi * s / segments
            local = Vector((radii[0] * rr * math.cos(ang), radii[1] * rr * math.sin(ang), radii[2] * zz))
            verts.append(tuple(c + m @ local))
    verts.append(tuple(c + m @ Vector((0.0, 0.0, radii[2]))))
    top = len(verts) - 1

    def ri(k, s):
        return 1 + k * segments + (s % segments)

    faces = []
    for s in range(segments):
        faces.append((0, ri(0, s + 1), ri(0, s)))
    for k in range(rings - 1):
        for s in range(segments):
            faces.append((ri(k, s), ri(k, s + 1), ri(k + 1, s + 1), ri(k + 1, s)))
    for s in range(segments):
        faces.append((ri(rings - 1, s), ri(rings - 1, s + 1), top))
    return verts, faces


def seg_dist(p, a, b):
    ab = b - a
    t = max(0.0, min(1.0, (p - a).dot(ab) / ab.length_squared))
    return (p - (a + ab * t)).length


def distance_weights(p, bone_segs, allowed, max_infl=4, power=6.0, min_w=0.02):
    """Smooth weights from inverse distance to bone segments (top ``max_infl``)."""
    ds = []
    for name in allowed:
        a, b = bone_segs[name]
        ds.append((seg_dist(p, a, b), name))
    ds.sort()
    dmin = max(ds[0][0], 1e-4)
    ws = [((dmin / max(d, 1e-4)) ** power, n) for d, n in ds[:max_infl]]
    tot = sum(w for w, _ in ws)
    ws = [(w / tot, n) for w, n in ws]
    ws = [(w, n) for w, n in ws if w >= min_w]
    tot = sum(w for w, _ in ws)
    return [(n, w / tot) for w, n in ws]


# ---------------------------------------------------------------------------
# Blender scene helpers
# ---------------------------------------------------------------------------

def reset_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = FPS
    scene.render.fps_base = 1.0
    scene.frame_start = 0
    scene.frame_end = FPS
    scene.frame_set(0)
    return scene


def make_armature(name, bone_defs, obj_loc=(0, 0, 0), obj_rot_z=0.0):
    """bone_defs: list of (name, head, tail, parent, connected). Order is kept."""
    arm_data = bpy.data.armatures.new(name)
    arm_obj = bpy.data.objects.new(name, arm_data)
    bpy.context.scene.collection.objects.link(arm_obj)
    arm_obj.location = obj_loc
    arm_obj.rotation_mode = 'XYZ'
    arm_obj.rotation_euler = (0.0, 0.0, obj_rot_z)
    bpy.context.view_layer.objects.active = arm_obj
    arm_obj.select_set(True)
    bpy.ops.object.mode_set(mode='EDIT')
    ebs = {}
    for bname, head, tail, parent, connected in bone_defs:
        eb = arm_data.edit_bones.new(bname)
        eb.head = head
        eb.tail = tail
        eb.roll = 0.0
        eb.use_deform = True
        if parent:
            eb.parent = ebs[parent]
            eb.use_connect = connected
        ebs[bname] = eb
    bpy.ops.object.mode_set(mode='OBJECT')
    for pb in arm_obj.pose.bones:
        pb.rotation_mode = 'QUATERNION'
    return arm_obj


def make_mesh(name, verts, faces, weights, arm_obj, bone_names, mesh_offset=(0, 0, 0)):
    """Create a mesh object skinned to arm_obj.

    verts are in *armature space*; the mesh object is parented to the armature
    with local location ``mesh_offset`` and the vertices are stored relative to
    it, so that in rest pose the surface sits where it was modelled.
    weights: list (per vertex) of [(bone_name, weight), ...].
    """
    off = Vector(mesh_offset)
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(Vector(v) - off) for v in verts], [], faces)
    me.validate(verbose=True)
    me.update()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    ob.parent = arm_obj
    ob.parent_type = 'OBJECT'
    ob.matrix_parent_inverse = Matrix.Identity(4)
    ob.location = off
    groups = {b: ob.vertex_groups.new(name=b) for b in bone_names}
    for vi, wl in enumerate(weights):
        for b, w in wl:
            groups[b].add([vi], w, 'REPLACE')
    mod = ob.modifiers.new("Armature", 'ARMATURE')
    mod.object = arm_obj
    mod.use_vertex_groups = True
    mod.use_bone_envelopes = False
    return ob


def check_mesh(me, name):
    """Assert closed 2-manifold, no coincident vertices; return counts."""
    bm = bmesh.new()
    bm.from_mesh(me)
    for e in bm.edges:
        assert len(e.link_faces) == 2, f"{name}: edge {e.index} has {len(e.link_faces)} faces"
    # consistent winding: each edge used once in each direction
    directed = set()
    for f in bm.faces:
        vs = [v.index for v in f.verts]
        for i in range(len(vs)):
            directed.add((vs[i], vs[(i + 1) % len(vs)]))
    consistent = all((b, a) in directed for (a, b) in directed)
    keys = {tuple(round(c, 6) for c in v.co) for v in bm.verts}
    assert len(keys) == len(bm.verts), f"{name}: coincident vertices"
    tris = sum(len(f.verts) - 2 for f in bm.faces)
    bm.free()
    return len(me.vertices), len(me.polygons), tris, consistent


def key_action(arm_obj, action_name, frames, pose_fn, step):
    """Create an action keyed at frames 0, step, ..., frames with pose_fn(frame)
    -> {bone: (loc (x,y,z), quat (w,x,y,z))}; every bone keyed; then stash it in
    its own NLA track named after the action."""
    ad = arm_obj.animation_data or arm_obj.animation_data_create()
    act = bpy.data.actions.new(action_name)
    act.use_fake_user = True
    ad.action = act
    keys = list(range(0, frames + 1, step))
    if keys[-1] != frames:
        keys.append(frames)
    for f in keys:
        pose = pose_fn(f)
        for pb in arm_obj.pose.bones:
            loc, q = pose.get(pb.name, ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)))
            pb.location = loc
            pb.rotation_quaternion = Quaternion(q).normalized()
            pb.keyframe_insert("location", frame=f, group=pb.name)
            pb.keyframe_insert("rotation_quaternion", frame=f, group=pb.name)
    act.use_frame_range = True
    act.frame_start = 0
    act.frame_end = frames
    slot = ad.action_slot
    ad.action = None
    track = ad.nla_tracks.new()
    track.name = action_name
    strip = track.strips.new(action_name, 0, act)
    if strip.action_slot is None:
        strip.action_slot = slot
    # back to rest pose
    for pb in arm_obj.pose.bones:
        pb.location = (0.0, 0.0, 0.0)
        pb.rotation_quaternion = (1.0, 0.0, 0.0, 0.0)
    return act


def qaxis(axis, angle):
    return tuple(Quaternion(Vector(axis), angle))


def qmul(*qs):
    r = Quaternion((1.0, 0.0, 0.0, 0.0))
    for q in qs:
        r = r @ Quaternion(q)
    return tuple(r)


# ---------------------------------------------------------------------------
# Exports
# ---------------------------------------------------------------------------

FIXED_TIME = datetime.datetime(2000, 1, 1, 0, 0, 0)


def pin_fbx_timestamp():
    """The FBX exporter stamps CreationTimeStamp with now(); pin it."""
    from io_scene_fbx import export_fbx_bin
    orig = getattr(export_fbx_bin.fbx_header_elements, "_colossus_orig", export_fbx_bin.fbx_header_elements)

    def fbx_header_elements(root, scene_data, time=None):
        return orig(root, scene_data, FIXED_TIME)
    fbx_header_elements._colossus_orig = orig
    export_fbx_bin.fbx_header_elements = fbx_header_elements


def export_all(out_dir, stem, arm_obj, actions, formats=("glb", "fbx", "usda")):
    files = []
    ad = arm_obj.animation_data
    bpy.context.scene.frame_set(0)
    if "glb" in formats:
        ad.action = None  # every action lives in its own NLA track -> one animation each
        path = os.path.join(out_dir, stem + ".glb")
        bpy.ops.export_scene.gltf(
            filepath=path,
            export_format='GLB',
            export_texcoords=False,
            export_normals=False,
            export_materials='NONE',
            export_vertex_color='NONE',
            export_attributes=False,
            export_cameras=False,
            export_lights=False,
            export_yup=True,
            export_apply=False,
            export_skins=True,
            export_influence_nb=4,
            export_def_bones=False,
            export_leaf_bone=False,
            export_rest_position_armature=True,
            export_reset_pose_bones=True,
            export_animations=True,
            export_animation_mode='ACTIONS',
            export_nla_strips=True,
            export_force_sampling=True,
            export_anim_slide_to_zero=False,
            export_frame_range=False,
            export_optimize_animation_size=False,
            export_morph=False,
            export_extras=False,
        )
        files.append(os.path.basename(path))
    if "fbx" in formats:
        ad.action = None
        path = os.path.join(out_dir, stem + ".fbx")
        pin_fbx_timestamp()
        bpy.ops.export_scene.fbx(
            filepath=path,
            object_types={'ARMATURE', 'MESH'},
            use_mesh_modifiers=True,
            mesh_smooth_type='OFF',
            colors_type='NONE',
            use_tspace=False,
            add_leaf_bones=False,
            use_armature_deform_only=False,
            bake_anim=True,
            bake_anim_use_all_bones=True,
            bake_anim_use_nla_strips=False,
            bake_anim_use_all_actions=True,
            bake_anim_force_startend_keying=True,
            bake_anim_step=1.0,
            bake_anim_simplify_factor=0.0,
            path_mode='STRIP',
            embed_textures=False,
        )
        files.append(os.path.basename(path))
    if "usda" in formats:
        first = actions[0]
        ad.action = first
        if ad.action_slot is None and len(first.slots):
            ad.action_slot = first.slots[0]
        scene = bpy.context.scene
        scene.frame_start = 0
        scene.frame_end = int(first.frame_end)
        scene.frame_set(0)
        path = os.path.join(out_dir, stem + ".usda")
        bpy.ops.wm.usd_export(
            filepath=path,
            selected_objects_only=False,
            export_animation=True,
            export_armatures=True,
            only_deform_bones=False,
            export_meshes=True,
            export_uvmaps=False,
            export_normals=False,
            export_materials=False,
            export_mesh_colors=False,
            export_shapekeys=False,
            export_lights=False,
            export_cameras=False,
            export_custom_properties=False,
            generate_preview_surface=False,
            convert_world_material=False,
            evaluation_mode='RENDER',
            export_subdivision='IGNORE',
            triangulate_meshes=False,
        )
        files.append(os.path.basename(path))
        ad.action = None
        scene.frame_set(0)
    return files


# ---------------------------------------------------------------------------
# Models
# ---------------------------------------------------------------------------

LIMB_BONES = ["upper", "middle", "lower"]


def build_limb(flip=False):
    """Capsule of radius 0.25 along +Z from z=0 to z=3, three 1-unit bones."""
    reset_scene()
    bone_defs = [
        ("upper", (0, 0, 0), (0, 0, 1), None, False),
        ("middle", (0, 0, 1), (0, 0, 2), "upper", True),
        ("lower", (0, 0, 2), (0, 0, 3), "middle", True),
    ]
    arm = make_armature("LimbArmature", bone_defs)
    verts, faces = capsule((0, 0, 0), (0, 0, 3), 0.25, segments=16, rings=24)
    weights = []
    for v in verts:
        zc = min(max(v[2], 0.5), 2.5)  # bone centres at 0.5, 1.5, 2.5
        wl = []
        for i, b in enumerate(LIMB_BONES):
            w = max(0.0, 1.0 - abs(zc - (i + 0.5)))
            if w > 1e-6:
                wl.append((b, w))
        tot = sum(w for _, w in wl)
        weights.append([(b, w / tot) for b, w in wl])
    ob = make_mesh("Limb", verts, faces, weights, arm, LIMB_BONES)

    flipped = 0
    if flip:
        bm = bmesh.new()
        bm.from_mesh(ob.data)
        bm.faces.ensure_lookup_table()
        sel = [f for f in bm.faces if f.index % 3 == 1]  # deterministic third
        bmesh.ops.reverse_faces(bm, faces=sel)
        flipped = (len(sel), sum(len(f.verts) - 2 for f in sel))
        bm.to_mesh(ob.data)
        bm.free()
        ob.data.update()

    def bend(f):
        t = f / 24.0
        s = math.sin(math.pi * t)  # 0 -> 1 -> 0
        return {
            "upper": ((0, 0, 0), qaxis((0, 0, 1), 0.5 * s)),
            "middle": ((0, 0, 0), qaxis((1, 0, 0), math.radians(60) * s)),
            "lower": ((0, 0, 0), qaxis((1, 0, 0), math.radians(45) * s)),
        }

    acts = [key_action(arm, "bend", 24, bend, step=2)]
    return arm, ob, acts, flipped


CREATURE_BONES = [
    "spine_0", "spine_1", "spine_2", "neck", "head",
    "tail_0", "tail_1", "tail_2",
    "leg_FL_upper", "leg_FL_lower", "leg_FR_upper", "leg_FR_lower",
    "leg_BL_upper", "leg_BL_lower", "leg_BR_upper", "leg_BR_lower",
]


def build_creature():
    """Quadruped facing -Y, body at z ~ 1, made of a union of closed shapes."""
    reset_scene()
    H = 1.0  # body height
    bone_defs = [
        ("spine_0", (0, 0.6, H), (0, 0.2, H), None, False),
        ("spine_1", (0, 0.2, H), (0, -0.2, H), "spine_0", True),
        ("spine_2", (0, -0.2, H), (0, -0.6, H), "spine_1", True),
        ("neck", (0, -0.6, H), (0, -0.9, H + 0.35), "spine_2", True),
        ("head", (0, -0.9, H + 0.35), (0, -1.35, H + 0.4), "neck", True),
        ("tail_0", (0, 0.6, H), (0, 1.0, H + 0.05), "spine_0", False),
        ("tail_1", (0, 1.0, H + 0.05), (0, 1.4, H), "tail_0", True),
        ("tail_2", (0, 1.4, H), (0, 1.8, H - 0.1), "tail_1", True),
    ]
    legs = {"FL": (0.22, -0.5, "spine_2"), "FR": (-0.22, -0.5, "spine_2"),
            "BL": (0.22, 0.5, "spine_0"), "BR": (-0.22, 0.5, "spine_0")}
    for side, (x, y, parent) in legs.items():
        bone_defs.append((f"leg_{side}_upper", (x, y, H - 0.1), (x, y - 0.03, 0.55), parent, False))
        bone_defs.append((f"leg_{side}_lower", (x, y - 0.03, 0.55), (x, y, 0.08), f"leg_{side}_upper", True))
    assert [b[0] for b in bone_defs] == CREATURE_BONES

    # Armature object: offset + rotation about Z; mesh: small own offset.
    arm = make_armature("CreatureArmature", bone_defs, obj_loc=(1.5, -0.75, 0.0),
                        obj_rot_z=math.radians(30.0))
    segs = {n: (Vector(h), Vector(t)) for n, h, t, _, _ in bone_defs}

    shapes = []  # (verts, faces, allowed bones)
    # torso: tapered capsule along the spine
    shapes.append(capsule((0, 0.75, H), (0, -0.7, H), 0.34, segments=32, rings=56,
                          radius_fn=lambda t: 1.0 - 0.15 * (2 * t - 1) ** 2, phase=0.01)
                  + (["spine_0", "spine_1", "spine_2", "tail_0", "neck"],))
    # neck
    shapes.append(capsule((0, -0.6, H + 0.05), (0, -0.9, H + 0.35), 0.16, segments=16, rings=16, phase=0.02)
                  + (["spine_2", "neck", "head"],))
    # head: ellipsoid, long axis along the head bone
    hdir = (segs["head"][1] - segs["head"][0]).normalized()
    hrot = Vector((0, 0, 1)).rotation_difference(hdir)
    shapes.append(ellipsoid((0, -1.1, H + 0.38), (0.2, 0.17, 0.32), segments=24, rings=18, rot=hrot)
                  + (["neck", "head"],))
    # tail: tapered capsule along the three tail bones (straight approximation)
    shapes.append(capsule((0, 0.62, H), (0, 1.8, H - 0.1), 0.14, segments=16, rings=40,
                          radius_fn=lambda t: 1.0 - 0.7 * t, phase=0.03)
                  + (["spine_0", "tail_0", "tail_1", "tail_2"],))
    # legs
    for i, (side, (x, y, parent)) in enumerate(legs.items()):
        shapes.append(capsule((x, y, H - 0.05), (x, y, 0.1), 0.1, segments=16, rings=30,
                              radius_fn=lambda t: 1.0 - 0.3 * t, phase=0.04 + 0.01 * i)
                      + ([parent, f"leg_{side}_upper", f"leg_{side}_lower"],))

    verts, faces, weights = [], [], []
    for sv, sf, allowed in shapes:
        base = len(verts)
        for v in sv:
            weights.append(distance_weights(Vector(v), segs, allowed, max_infl=4))
        verts.extend(sv)
        faces.extend(tuple(base + i for i in f) for f in sf)
    ob = make_mesh("Creature", verts, faces, weights, arm, CREATURE_BONES, mesh_offset=(0.0, 0.05, 0.02))

    def walk(f):
        ph = 2.0 * math.pi * f / 48.0
        pose = {}
        pose["spine_0"] = ((0.0, 0.0, 0.03 * math.sin(2 * ph)), qaxis((0, 1, 0), 0.04 * math.sin(ph)))
        pose["spine_1"] = ((0, 0, 0), qaxis((0, 0, 1), 0.05 * math.sin(ph)))
        pose["spine_2"] = ((0, 0, 0), qaxis((0, 0, 1), -0.05 * math.sin(ph)))
        pose["neck"] = ((0, 0, 0), qaxis((1, 0, 0), 0.08 * math.sin(2 * ph)))
        pose["head"] = ((0, 0, 0), qaxis((1, 0, 0), -0.06 * math.sin(2 * ph)))
        for i, b in enumerate(["tail_0", "tail_1", "tail_2"]):
            pose[b] = ((0, 0, 0), qaxis((0, 0, 1), 0.25 * math.sin(ph - 0.6 * i)))
        offs = {"FL": 0.0, "BR": 0.0, "FR": math.pi, "BL": math.pi}
        for side, o in offs.items():
            a = math.sin(ph + o)
            pose[f"leg_{side}_upper"] = ((0, 0, 0), qaxis((1, 0, 0), 0.45 * a))
            pose[f"leg_{side}_lower"] = ((0, 0, 0), qaxis((1, 0, 0), -0.35 * max(0.0, math.cos(ph + o))))
        return pose

    def roar(f):
        s = math.sin(math.pi * f / 36.0)  # 0 -> 1 -> 0
        shake = 0.08 * math.sin(2 * math.pi * f / 6.0) * s
        pose = {b: ((0, 0, 0), (1, 0, 0, 0)) for b in CREATURE_BONES}
        pose["spine_0"] = ((0.0, 0.0, 0.1 * s), qaxis((1, 0, 0), -0.15 * s))
        pose["spine_2"] = ((0, 0, 0), qaxis((1, 0, 0), -0.2 * s))
        pose["neck"] = ((0, 0, 0), qmul(qaxis((1, 0, 0), -0.5 * s), qaxis((0, 1, 0), shake)))
        pose["head"] = ((0, 0, 0), qmul(qaxis((1, 0, 0), 0.6 * s), qaxis((0, 0, 1), shake)))
        for i, b in enumerate(["tail_0", "tail_1", "tail_2"]):
            pose[b] = ((0, 0, 0), qaxis((1, 0, 0), -0.3 * s))
        for side in ("FL", "FR"):
            pose[f"leg_{side}_upper"] = ((0, 0, 0), qaxis((1, 0, 0), -0.3 * s))
            pose[f"leg_{side}_lower"] = ((0, 0, 0), qaxis((1, 0, 0), 0.5 * s))
        return pose

    acts = [key_action(arm, "walk", 48, walk, step=2),
            key_action(arm, "roar", 36, roar, step=2)]
    return arm, ob, acts, 0


# ---------------------------------------------------------------------------

def describe(arm, ob, acts, files, flipped=None):
    nv, nf, nt, consistent = check_mesh(ob.data, ob.name)
    infl = [len([g for g in v.groups if g.weight > 0]) for v in ob.data.vertices]
    sums = [sum(g.weight for g in v.groups) for v in ob.data.vertices]
    assert min(infl) >= 1 and all(abs(s - 1.0) < 1e-4 for s in sums), ob.name
    if flipped is None:
        assert consistent, ob.name + ": inconsistent winding"
    d = {
        "blender_vertices": nv,
        "blender_faces": nf,
        "blender_triangles": nt,
        "bones": [b.name for b in arm.data.bones],
        "actions": {a.name: int(round(a.frame_end - a.frame_start)) for a in acts},
        "action_frame_ranges": {a.name: [int(a.frame_start), int(a.frame_end)] for a in acts},
        "fps": FPS,
        "files": files,
        "max_influences": max(infl),
        "armature_object": {"name": arm.name,
                            "location": [round(c, 6) for c in arm.location],
                            "rotation_euler_xyz_deg": [round(math.degrees(c), 6) for c in arm.rotation_euler]},
        "mesh_object": {"name": ob.name, "parent": arm.name,
                        "location": [round(c, 6) for c in ob.location]},
        "blender_version": bpy.app.version_string,
    }
    if flipped is not None:
        d["flipped_faces"], d["flipped_triangles"] = flipped
    return d


def main():
    argv = sys.argv[1:]
    if "--" in argv:
        argv = argv[argv.index("--") + 1:]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.dirname(os.path.abspath(__file__)))
    args = ap.parse_args(argv)
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)

    info = {}
    arm, ob, acts, _ = build_limb()
    files = export_all(out, "limb", arm, acts)
    info["limb"] = describe(arm, ob, acts, files)

    arm, ob, acts, _ = build_creature()
    files = export_all(out, "creature", arm, acts)
    info["creature"] = describe(arm, ob, acts, files)

    arm, ob, acts, flipped = build_limb(flip=True)
    files = export_all(out, "limb_flipped", arm, acts, formats=("glb",))
    info["limb_flipped"] = describe(arm, ob, acts, files, flipped=flipped)

    with open(os.path.join(out, "samples.json"), "w") as fh:
        json.dump(info, fh, indent=2)
        fh.write("\n")
    for k, v in info.items():
        print(k, {kk: v[kk] for kk in ("blender_vertices", "blender_faces", "blender_triangles", "actions", "files")})


if __name__ == "__main__":
    main()
