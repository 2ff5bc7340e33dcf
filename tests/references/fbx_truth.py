"""Maya's own deformed meshes for the ufbx FBX test files, as an independent motion reference.

The ufbx repository ships, next to some of its FBX test scenes, OBJ files that Maya exported of
the deformed mesh at given frames (``corpus/realworld/truth/*.obj``).  They are in
**centimetres**, in Maya world space (Y-up), and their vertex order is the FBX control-point
order of the mesh (``corpus/realworld/README.md``).  ufbx's own tests compare its skinning with
them at the times listed in :data:`TRUTH` (``test/test_scenes.h`` ``maya_kenney_character`` and
``test/test_skin.h`` ``maya_game_sausage``, suffix ``combined``).

To match those vertices with another mesh one also needs where each control point sits at the
bind pose.  A small reader of the binary FBX node tree (FBX 7.x, only what is needed: the
geometry's ``Vertices`` and ``PolygonVertexIndex``, its skin clusters' ``Transform`` and
``TransformLink`` matrices, ``GlobalSettings`` and the animation stacks) gives them: an FBX
cluster's ``TransformLink`` is the bone's world transform at bind time and its ``Transform`` is
``inv(TransformLink) @ meshWorldAtBind`` (Blender's and Autodesk's exporters write it so), hence a
control point ``v`` sits at ``TransformLink @ Transform @ v`` in the bind pose.

Times: global scene time in seconds (FBX stacks placed one after another on the timeline keep
their own start, e.g. the sausage's ``wiggle`` stack starts at 1/24 s).
"""

from __future__ import annotations

import os
import struct
import zlib
from dataclasses import dataclass

import numpy as np

#: FBX time unit: ticks per second (FBX SDK ``FbxTime``).
FBX_TICKS_PER_SECOND = 46_186_158_000

#: fbx file name -> [(stack name, global time in seconds, truth OBJ file name)], from the corpus
#: README ("kenney frames 4 and 9 at 24 fps"; sausage "wiggle t = 10/24 and 18/24 s, spin 27/24 and
#: 35/24 s, deform 48/24 and 55/24 s", global scene time).
TRUTH = {
    "ufbx_maya_kenney_character_7700_binary.fbx": [
        ("Take 001", 4 / 24, "ufbx_maya_kenney_character_4.obj"),
        ("Take 001", 9 / 24, "ufbx_maya_kenney_character_9.obj"),
    ],
    "ufbx_maya_game_sausage_7500_binary_combined.fbx": [
        ("wiggle", 10 / 24, "ufbx_maya_game_sausage_wiggle_10.obj"),
        ("wiggle", 18 / 24, "ufbx_maya_game_sausage_wiggle_18.obj"),
        ("spin", 27 / 24, "ufbx_maya_game_sausage_spin_7.obj"),
        ("spin", 35 / 24, "ufbx_maya_game_sausage_spin_15.obj"),
        ("deform", 48 / 24, "ufbx_maya_game_sausage_deform_8.obj"),
        ("deform", 55 / 24, "ufbx_maya_game_sausage_deform_15.obj"),
    ],
}


def load_obj(path):
    """Vertices and face count of an OBJ file.

    Returns
    -------
    vertices : (n, 3) float64
        The ``v`` lines in file order.
    faces : int
        Number of ``f`` lines.
    """
    verts, faces = [], 0
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if line.startswith("v "):
                verts.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                faces += 1
    return np.array(verts, dtype=np.float64).reshape(-1, 3), faces


# ------------------------------------------------------------------------ binary FBX tree
@dataclass
class Node:
    name: str
    props: list
    children: list

    def child(self, name):
        return next((c for c in self.children if c.name == name), None)

    def all(self, name):
        return [c for c in self.children if c.name == name]


_ARRAY = {"f": "<f4", "d": "<f8", "l": "<i8", "i": "<i4", "b": "u1"}
_SCALAR = {"Y": "<h", "C": "<?", "I": "<i", "F": "<f", "D": "<d", "L": "<q"}


def read_fbx_tree(path) -> Node:
    """Parse a binary FBX (7.x) file into a tree of :class:`Node` (name, properties, children)."""
    with open(path, "rb") as fh:
        data = fh.read()
    if not data.startswith(b"Kaydara FBX Binary  \x00"):
        raise ValueError(f"{path}: not a binary FBX file")
    version = struct.unpack_from("<I", data, 23)[0]
    head = struct.Struct("<QQQB" if version >= 7500 else "<IIIB")

    def props(pos, count):
        out = []
        for _ in range(count):
            t = chr(data[pos])
            pos += 1
            if t in _SCALAR:
                fmt = _SCALAR[t]
                out.append(struct.unpack_from(fmt, data, pos)[0])
                pos += struct.calcsize(fmt)
            elif t in "SR":
                n = struct.unpack_from("<I", data, pos)[0]
                raw = data[pos + 4:pos + 4 + n]
                out.append(raw.decode("utf-8", "replace") if t == "S" else raw)
                pos += 4 + n
            elif t in _ARRAY:
                n, enc, clen = struct.unpack_from("<III", data, pos)
                raw = data[pos + 12:pos + 12 + clen]
                if enc == 1:
                    raw = zlib.decompress(raw)
                out.append(np.frombuffer(raw, dtype=_ARRAY[t], count=n).copy())
                pos += 12 + clen
            else:
                raise ValueError(f"{path}: unknown FBX property type {t!r} at byte {pos - 1}")
        return out

    def nodes(pos, end):
        out = []
        while pos + head.size <= end:
            end_off, nprops, plen, nlen = head.unpack_from(data, pos)
            if end_off == 0:
                break
            name = data[pos + head.size:pos + head.size + nlen].decode("ascii", "replace")
            pat = pos + head.size + nlen
            out.append(Node(name, props(pat, nprops), nodes(pat + plen, end_off)))
            pos = end_off
        return out

    return Node("", [], nodes(27, len(data)))


def _properties70(node) -> dict:
    p70 = node.child("Properties70") if node is not None else None
    out = {}
    for p in (p70.all("P") if p70 else []):
        if p.props and isinstance(p.props[0], str):
            vals = p.props[4:]
            out[p.props[0]] = vals[0] if len(vals) == 1 else vals
    return out


def _m44(arr) -> np.ndarray:
    """16 FBX doubles (column-major, translation last) -> (4, 4) column-vector float64."""
    return np.asarray(arr, dtype=np.float64).reshape(4, 4).T


@dataclass(frozen=True)
class TruthFrame:
    clip: str
    seconds: float
    obj: str


class FbxTruth:
    """The truth of one ufbx FBX file: bind-pose control points and Maya's deformed frames.

    Parameters
    ----------
    fbx_path : str or PathLike
        One of the files named in :data:`TRUTH`.
    truth_dir : str, optional
        Folder of the OBJs (default ``truth/`` next to the FBX).

    Attributes
    ----------
    mesh_name : str
    control_points : (n, 3) float64
        The geometry's ``Vertices`` (geometry space).
    rest : (n, 3) float64
        Control points at the bind pose in scene (world) space, file units.
    rest_spread : float
        Largest disagreement between the clusters' ``TransformLink @ Transform`` (should be ~0).
    used : (n,) bool
        Control points referenced by polygons.
    unit_scale_factor : float
        ``GlobalSettings`` ``UnitScaleFactor`` (centimetres per file unit).
    up_axis : str
    frame_rate : float or None
    stacks : dict
        ``{name: (start seconds, stop seconds)}`` from each stack's ``LocalStart``/``LocalStop``.
    frames : list of TruthFrame
    """

    def __init__(self, fbx_path, truth_dir=None):
        self.path = os.fspath(fbx_path)
        base = os.path.basename(self.path)
        if base not in TRUTH:
            raise KeyError(f"no truth known for {base}")
        self.truth_dir = truth_dir or os.path.join(os.path.dirname(self.path), "truth")
        root = read_fbx_tree(self.path)
        gs = _properties70(root.child("GlobalSettings"))
        self.unit_scale_factor = float(gs.get("UnitScaleFactor", 1.0))
        self.up_axis = {0: "X", 1: "Y", 2: "Z"}[int(gs.get("UpAxis", 1))]
        mode = int(gs.get("TimeMode", 0))
        rates = {1: 120.0, 2: 100.0, 3: 60.0, 4: 50.0, 5: 48.0, 6: 30.0, 7: 30.0, 8: 29.97, 9: 29.97,
                 10: 25.0, 11: 24.0, 13: 23.976, 15: 96.0, 16: 72.0, 17: 59.94}
        self.frame_rate = float(gs["CustomFrameRate"]) if mode == 14 and "CustomFrameRate" in gs else rates.get(mode)
        objects = root.child("Objects")
        by_id = {}
        for n in objects.children:
            if n.props and isinstance(n.props[0], int):
                by_id[n.props[0]] = n
        parents = {}
        for c in root.child("Connections").all("C"):
            if c.props[0] == "OO":
                parents.setdefault(c.props[1], []).append(c.props[2])
        geoms = [n for n in objects.all("Geometry") if len(n.props) > 2 and n.props[2] == "Mesh"]
        if len(geoms) != 1:
            raise ValueError(f"{self.path}: expected one mesh geometry, found {len(geoms)}")
        g = geoms[0]
        self.mesh_name = g.props[1].split("\x00\x01")[0]
        self.control_points = g.child("Vertices").props[0].reshape(-1, 3).astype(np.float64)
        pvi = g.child("PolygonVertexIndex").props[0].astype(np.int64)
        pvi = np.where(pvi < 0, ~pvi, pvi)
        self.used = np.zeros(len(self.control_points), dtype=bool)
        self.used[pvi] = True
        gid = g.props[0]
        skins = [i for i, n in by_id.items() if n.name == "Deformer" and n.props[2] == "Skin" and gid in parents.get(i, [])]
        mats = []
        for cid, n in by_id.items():
            if n.name == "Deformer" and n.props[2] == "Cluster" and any(s in parents.get(cid, []) for s in skins):
                if n.child("Transform") is not None and n.child("TransformLink") is not None:
                    mats.append(_m44(n.child("TransformLink").props[0]) @ _m44(n.child("Transform").props[0]))
        if not mats:
            raise ValueError(f"{self.path}: the mesh has no skin cluster")
        mats = np.array(mats)
        self.rest_spread = float(np.abs(mats - mats[0]).max())
        m = mats[0]
        self.rest = self.control_points @ m[:3, :3].T + m[:3, 3]
        self.stacks = {}
        for n in objects.all("AnimationStack"):
            p = _properties70(n)
            start = p.get("LocalStart", p.get("ReferenceStart", 0))
            stop = p.get("LocalStop", p.get("ReferenceStop", 0))
            self.stacks[n.props[1].split("\x00\x01")[0]] = (start / FBX_TICKS_PER_SECOND, stop / FBX_TICKS_PER_SECOND)
        self.frames = [TruthFrame(c, s, o) for c, s, o in TRUTH[base]]

    @property
    def meters_per_unit(self) -> float:
        """Metres per file unit (``UnitScaleFactor`` is centimetres per unit)."""
        return self.unit_scale_factor / 100.0

    def pose(self, frame: TruthFrame) -> np.ndarray:
        """``(n, 3)`` float64 Maya-deformed control points of ``frame``, file units (cm)."""
        v, _ = load_obj(os.path.join(self.truth_dir, frame.obj))
        if len(v) != len(self.control_points):
            raise ValueError(f"{frame.obj}: {len(v)} vertices, the FBX mesh has {len(self.control_points)} control points")
        return v


def load(fbx_path, truth_dir=None) -> FbxTruth:
    return FbxTruth(fbx_path, truth_dir)
