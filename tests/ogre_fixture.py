"""A small skinned Ogre limb written at test time, XML (``.mesh.xml`` + ``.skeleton.xml``) and
binary (``.mesh`` + ``.skeleton``, serializer versions ``[MeshSerializer_v1.8]`` /
``[Serializer_v1.80]``), with the pose it must show at any instant computed here from the bone
transforms written (the independent reference of the Ogre tests).

There are no Ogre files in the corpus, so the files are written from the public descriptions of
the formats (OgreXMLConverter's XML layout; the binary serializers' chunk ids: a chunk is
``uint16 id, uint32 length`` including those 6 bytes, strings end with ``\\n``, little-endian).

Ogre's animation semantics, which the reference follows (``NodeAnimationTrack::applyToNode``): a
bone starts from its binding state (position ``p``, orientation ``q``, scale ``s``), then a key's
translate is added in the parent's space (``p + t``), its rotation is applied locally
(``q * r``) and its scale multiplies (``s * k``).  Between keys: translate and scale linearly,
rotation by normalised lerp along the shortest path (Ogre's default ``RIM_LINEAR``).  Skinning
is linear with the bone assignments' weights (normalised per vertex).
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field

import numpy as np

from synth import tube_geometry


# ------------------------------------------------------------------------------ quaternions (x, y, z, w)
def quat(axis, degrees):
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    h = np.radians(degrees) / 2
    return np.array([*(a * np.sin(h)), np.cos(h)])


def qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def qmat(q):
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def trs(t, q, s):
    m = np.eye(4)
    m[:3, :3] = qmat(q) * np.asarray(s, dtype=np.float64)[None, :]
    m[:3, 3] = t
    return m


def axis_angle(q):
    """(axis, radians) of a unit quaternion, as Ogre's XML ``<rotate angle><axis/></rotate>``."""
    q = q / np.linalg.norm(q)
    s = np.linalg.norm(q[:3])
    if s < 1e-12:
        return np.array([1.0, 0.0, 0.0]), 0.0
    return q[:3] / s, 2 * np.arctan2(s, q[3])


# ------------------------------------------------------------------------------ the limb
@dataclass
class Key:
    time: float
    translate: np.ndarray
    rotate: np.ndarray  # quaternion (x, y, z, w)
    scale: np.ndarray


@dataclass
class Limb:
    names: list
    parents: list
    position: np.ndarray  # (B, 3) binding position in the parent bone's space
    rotation: np.ndarray  # (B, 4)
    scale: np.ndarray     # (B, 3)
    positions: np.ndarray  # (V, 3) vertices in model space at bind
    triangles: np.ndarray  # (F, 3)
    assignments: list      # [(vertex, bone, weight)]
    animations: dict = field(default_factory=dict)  # name -> (length, {bone: [Key]})

    # ---- the reference --------------------------------------------------------------------
    def local(self, b, anim=None, seconds=0.0):
        p, q, s = self.position[b].copy(), self.rotation[b].copy(), self.scale[b].copy()
        if anim is not None:
            length, tracks = self.animations[anim]
            keys = tracks.get(b)
            if keys:
                t, r, k = _sample(keys, seconds, length)
                p, q, s = p + t, qmul(q, r), s * k
        return trs(p, q, s)

    def world(self, anim=None, seconds=0.0):
        out = []
        for b, p in enumerate(self.parents):
            m = self.local(b, anim, seconds)
            out.append(m if p < 0 else out[p] @ m)
        return np.array(out)

    def pose(self, anim=None, seconds=0.0):
        """Skinned vertex positions (model space) at ``seconds`` of ``anim`` (None: the bind pose)."""
        skin = self.world(anim, seconds) @ np.linalg.inv(self.world())
        v = np.zeros_like(self.positions)
        tot = np.zeros(len(self.positions))
        h = np.c_[self.positions, np.ones(len(self.positions))]
        for vi, b, w in self.assignments:
            v[vi] += w * (skin[b] @ h[vi])[:3]
            tot[vi] += w
        return v / tot[:, None]

    def key_times(self, anim):
        """Every key time of the animation, and its length (where Ogre's clip ends)."""
        length, tracks = self.animations[anim]
        return np.unique(np.concatenate([[k.time for k in ks] for ks in tracks.values()] + [[length]]))


def _sample(keys, t, length):
    """A track at ``t`` seconds as Ogre samples it: the first key held before it; after the last
    key, interpolated towards the first key placed at ``length + first time`` (Ogre wraps)."""
    times = np.array([k.time for k in keys])
    if t <= times[0] or len(keys) == 1:
        k = keys[0]
        return k.translate, k.rotate, k.scale
    if t >= times[-1]:
        a, b = keys[-1], keys[0]
        t0, t1 = times[-1], length + times[0]
        if t1 <= t0:
            return a.translate, a.rotate, a.scale
    else:
        i = int(np.searchsorted(times, t, side="right")) - 1
        a, b = keys[i], keys[i + 1]
        t0, t1 = a.time, b.time
    u = (t - t0) / (t1 - t0)
    rb = b.rotate if np.dot(a.rotate, b.rotate) >= 0 else -b.rotate  # shortest path
    r = (1 - u) * a.rotate + u * rb
    return (1 - u) * a.translate + u * b.translate, r / np.linalg.norm(r), (1 - u) * a.scale + u * b.scale


def make_limb(around=12, rings=9, length=3.0, radius=0.35) -> Limb:
    """A capped tube along +Y skinned to root -> upper -> lower -> hand, with two animations:
    ``bend`` (every bone keyed every 0.2 s: the root slides, the upper arm bends and slides
    along its own rotated axes, the forearm bends and twists) and ``wave`` (the forearm keyed every 0.4 s to the
    length, 1.6 s; the hand's track ends at 0.8 s, so Ogre swings it back towards its first key
    over the rest of the length)."""
    pos, tris = tube_geometry(around, rings, length, radius)
    names = ["root", "upper", "lower", "hand"]
    parents = [-1, 0, 1, 2]
    seg = length / 3
    rz = quat((0, 0, 1), 20.0)   # the upper arm is bound turned 20 degrees ...
    position = np.array([[0.0, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, seg, 0.0], [0.0, seg, 0.0]])
    rotation = np.array([quat((0, 1, 0), 0.0), rz, quat((0, 0, 1), -20.0), quat((0, 1, 0), 15.0)])  # ... the forearm back
    scale = np.ones((4, 3))
    limb = Limb(names, parents, position, rotation, scale, pos, tris, [])
    world = limb.world()
    # weights: the two nearest of upper / lower / hand by height, blended smoothly (Gaussians)
    heights = np.array([world[b][1, 3] for b in (1, 2, 3)]) + seg / 2
    for vi, y in enumerate(pos[:, 1]):
        g = np.exp(-(((y - heights) / (seg / 2)) ** 2))
        top = np.argsort(-g)[:2]
        w = g[top] / g[top].sum()
        limb.assignments += [(vi, int(top[0]) + 1, float(w[0])), (vi, int(top[1]) + 1, float(w[1]))]
    ident = np.array([0.0, 0.0, 0.0, 1.0])
    one = np.ones(3)
    zero = np.zeros(3)
    ts = np.round(np.arange(7) * 0.2, 6)
    bend = {
        0: [Key(t, np.array([0.3 * t, 0.0, -0.1 * t]), quat((0, 1, 0), 25 * t), one) for t in ts],
        1: [Key(t, np.array([0.2 * t, 0.05 * t, 0.0]), quat((0, 0, 1), 50 * t), one) for t in ts],
        2: [Key(t, zero, qmul(quat((1, 0, 0), 40 * t), quat((0, 0, 1), 30 * t)), one) for t in ts],
        3: [Key(t, zero, ident, one) for t in ts],
    }
    wave = {
        2: [Key(t, zero, quat((0, 0, 1), 30 * np.sin(np.pi * t / 1.6)), one) for t in (0.0, 0.4, 0.8, 1.2, 1.6)],
        3: [Key(t, zero, quat((1, 0, 0), 25 * t), one) for t in (0.0, 0.4, 0.8)],  # ends before the length
    }
    limb.animations = {"bend": (1.2, bend), "wave": (1.6, wave)}
    return limb


# ------------------------------------------------------------------------------ XML
def _v(tag, v, **extra):
    more = "".join(f' {k}="{val}"' for k, val in extra.items())
    return f'<{tag} x="{v[0]:.9g}" y="{v[1]:.9g}" z="{v[2]:.9g}"{more}/>'


def _rot(tag, q):
    axis, angle = axis_angle(q)
    return f'<{tag} angle="{angle:.12g}">{_v("axis", axis)}</{tag}>'


def write_xml(limb: Limb, folder, stem="limb", skeleton_link=None, vertex_animation=False,
              animation_link=False) -> str:
    """Write ``stem.mesh.xml`` and ``stem.skeleton.xml`` into ``folder``; the mesh's skeleton
    link is ``skeleton_link`` (default ``stem.skeleton``, Ogre's usual name for the pair).
    ``vertex_animation`` adds a pose and a pose animation to the mesh; ``animation_link`` a link
    to another skeleton's animations."""
    os.makedirs(folder, exist_ok=True)
    link = skeleton_link or f"{stem}.skeleton"
    lines = ['<mesh>', f'  <sharedgeometry vertexcount="{len(limb.positions)}">',
             '    <vertexbuffer positions="true">']
    for p in limb.positions:
        lines.append(f'      <vertex>{_v("position", p)}</vertex>')
    lines += ['    </vertexbuffer>', '  </sharedgeometry>', '  <submeshes>',
              '    <submesh material="skin" usesharedvertices="true" use32bitindexes="false" operationtype="triangle_list">',
              f'      <faces count="{len(limb.triangles)}">']
    for a, b, c in limb.triangles:
        lines.append(f'        <face v1="{a}" v2="{b}" v3="{c}"/>')
    lines += ['      </faces>', '    </submesh>', '  </submeshes>', f'  <skeletonlink name="{link}"/>',
              '  <boneassignments>']
    for vi, b, w in limb.assignments:
        lines.append(f'    <vertexboneassignment vertexindex="{vi}" boneindex="{b}" weight="{w:.9g}"/>')
    lines.append('  </boneassignments>')
    if vertex_animation:
        lines += ['  <poses>', '    <pose target="mesh" index="0" name="bulge">',
                  '      <poseoffset index="0" x="0.1" y="0" z="0"/>', '    </pose>', '  </poses>',
                  '  <animations>', '    <animation name="breathe" length="1">', '      <tracks>',
                  '        <track target="mesh" type="pose">', '          <keyframes>',
                  '            <keyframe time="0"><poseref poseindex="0" influence="0"/></keyframe>',
                  '            <keyframe time="1"><poseref poseindex="0" influence="1"/></keyframe>',
                  '          </keyframes>', '        </track>', '      </tracks>', '    </animation>', '  </animations>']
    lines.append('</mesh>')
    mesh_path = os.path.join(folder, f"{stem}.mesh.xml")
    with open(mesh_path, "w") as fh:
        fh.write("\n".join(lines) + "\n")

    s = ['<skeleton blendmode="average">', '  <bones>']
    for b, name in enumerate(limb.names):
        s += [f'    <bone id="{b}" name="{name}">', f'      {_v("position", limb.position[b])}',
              f'      {_rot("rotation", limb.rotation[b])}', f'      {_v("scale", limb.scale[b])}', '    </bone>']
    s += ['  </bones>', '  <bonehierarchy>']
    for b, p in enumerate(limb.parents):
        if p >= 0:
            s.append(f'    <boneparent bone="{limb.names[b]}" parent="{limb.names[p]}"/>')
    s += ['  </bonehierarchy>', '  <animations>']
    for name, (length, tracks) in limb.animations.items():
        s += [f'    <animation name="{name}" length="{length:.9g}">', '      <tracks>']
        for b, keys in tracks.items():
            s += [f'        <track bone="{limb.names[b]}">', '          <keyframes>']
            for k in keys:
                s += [f'            <keyframe time="{k.time:.9g}">', f'              {_v("translate", k.translate)}',
                      f'              {_rot("rotate", k.rotate)}', f'              {_v("scale", k.scale)}',
                      '            </keyframe>']
            s += ['          </keyframes>', '        </track>']
        s += ['      </tracks>', '    </animation>']
    s.append('  </animations>')
    if animation_link:
        s += ['  <animationlinks>', '    <animationlink skeletonName="other.skeleton" scale="1"/>', '  </animationlinks>']
    s.append('</skeleton>')
    base = link[:-len(".xml")] if link.endswith(".xml") else link
    skel_path = os.path.join(folder, os.path.basename(base) + ".xml")
    with open(skel_path, "w") as fh:
        fh.write("\n".join(s) + "\n")
    return mesh_path


# ------------------------------------------------------------------------------ binary
def _chunk(cid, body: bytes) -> bytes:
    return struct.pack("<HI", cid, 6 + len(body)) + body


def _str(s: str) -> bytes:
    return s.encode() + b"\n"


def _f(*v) -> bytes:
    return struct.pack(f"<{len(v)}f", *v)


def write_binary(limb: Limb, folder, stem="limb", skeleton_link=None, vertex_animation=False) -> str:
    """Write ``stem.mesh`` and ``stem.skeleton`` (binary) into ``folder`` (``vertex_animation``:
    a pose and a pose animation too)."""
    os.makedirs(folder, exist_ok=True)
    link = skeleton_link or f"{stem}.skeleton"
    nv = len(limb.positions)
    # geometry: one buffer (source 0) of float3 positions (VET_FLOAT3 = 2, VES_POSITION = 1)
    decl = _chunk(0x5100, _chunk(0x5110, struct.pack("<5H", 0, 2, 1, 0, 0)))
    vbuf = _chunk(0x5200, struct.pack("<2H", 0, 12) + _chunk(0x5210, limb.positions.astype("<f4").tobytes()))
    geometry = _chunk(0x5000, struct.pack("<I", nv) + decl + vbuf)
    idx = limb.triangles.astype("<u2").reshape(-1)
    submesh = _chunk(0x4000, _str("skin") + struct.pack("<?I?", True, len(idx), False) + idx.tobytes()
                     + _chunk(0x4010, struct.pack("<H", 4)))  # OT_TRIANGLE_LIST
    body = struct.pack("<?", True) + geometry + submesh + _chunk(0x6000, _str(link))
    for vi, b, w in limb.assignments:
        body += _chunk(0x7000, struct.pack("<IHf", vi, b, w))
    if vertex_animation:  # M_POSES > M_POSE > M_POSE_VERTEX; M_ANIMATIONS > M_ANIMATION > track > pose keys
        pose = _chunk(0xC100, _str("bulge") + struct.pack("<H?", 0, False)
                      + _chunk(0xC111, struct.pack("<I", 0) + _f(0.1, 0.0, 0.0)))
        body += _chunk(0xC000, pose)
        keys = b"".join(_chunk(0xD112, _f(t) + _chunk(0xD113, struct.pack("<Hf", 0, t))) for t in (0.0, 1.0))
        body += _chunk(0xD000, _chunk(0xD100, _str("breathe") + _f(1.0) + _chunk(0xD110, struct.pack("<2H", 2, 0) + keys)))
    mesh = struct.pack("<H", 0x1000) + _str("[MeshSerializer_v1.8]") + _chunk(0x3000, body)
    mesh_path = os.path.join(folder, f"{stem}.mesh")
    with open(mesh_path, "wb") as fh:
        fh.write(mesh)

    skel = struct.pack("<H", 0x1000) + _str("[Serializer_v1.80]") + _chunk(0x1010, struct.pack("<H", 0))
    for b, name in enumerate(limb.names):  # scale always written (the length tells a reader it is there)
        skel += _chunk(0x2000, _str(name) + struct.pack("<H", b) + _f(*limb.position[b]) + _f(*limb.rotation[b])
                       + _f(*limb.scale[b]))
    for b, p in enumerate(limb.parents):
        if p >= 0:
            skel += _chunk(0x3000, struct.pack("<2H", b, p))
    for name, (length, tracks) in limb.animations.items():
        body = _str(name) + _f(length)
        for b, keys in tracks.items():
            kb = b"".join(_chunk(0x4110, _f(k.time) + _f(*k.rotate) + _f(*k.translate) + _f(*k.scale)) for k in keys)
            body += _chunk(0x4100, struct.pack("<H", b) + kb)
        skel += _chunk(0x4000, body)
    skel_path = os.path.join(folder, os.path.basename(link))
    with open(skel_path, "wb") as fh:
        fh.write(skel)
    return mesh_path
