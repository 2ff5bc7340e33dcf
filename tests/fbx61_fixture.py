"""A small skinned, animated limb written at test time as an FBX 6.1 ASCII document (the format
of FBX SDK 2006-2010 and of Blender's 2.7x exporter), with the pose it must show at any instant
computed here from the transforms written: the independent reference of the FBX 6.1 test.

Layout (the public FBX 6.1 ASCII structure): ``FBXHeaderExtension`` (``FBXVersion: 6100``),
``Objects`` holding ``Model`` nodes with ``Properties60`` (``Lcl Translation``, ``Lcl
Rotation`` in degrees, ``Lcl Scaling``) and, for the mesh, its ``Vertices`` and
``PolygonVertexIndex`` (the last corner of a polygon stored as ``-(i + 1)``); a ``Skin``
deformer with one ``Cluster`` sub-deformer per bone (``Indexes``, ``Weights``, ``Transform`` = the
mesh's bind matrix relative to the bone's, ``TransformLink`` = the bone's bind world matrix;
matrices as 16 numbers with the translation in 12..14); ``Connections`` by name (``"OO"``); and
``Takes`` of per-model ``Channel: "Transform"`` curves (``T``/``R``/``S`` x ``X``/``Y``/``Z``,
``KeyVer: 4005``, keys ``time,value,L`` with time in FBX ticks, 46186158000 per second).

Semantics the reference follows (no pivots, offsets or pre-rotations are written): a model's local
matrix is ``T @ R @ S`` with ``R = Rz @ Ry @ Rx`` (rotation order XYZ, the default); curves are
interpolated linearly per Euler component ("L" keys); linear blend skinning with the clusters'
weights (normalised).  Units: ``UnitScaleFactor`` 1, centimetres; Y up.
"""

from __future__ import annotations

import os

import numpy as np

from synth import tube_geometry

TICKS = 46186158000


def _rx(d):
    a = np.radians(d)
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(d):
    a = np.radians(d)
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(d):
    a = np.radians(d)
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def local(t, r, s):
    m = np.eye(4)
    m[:3, :3] = _rz(r[2]) @ _ry(r[1]) @ _rx(r[0]) @ np.diag(s)
    m[:3, 3] = t
    return m


class Limb61:
    """Three bones up a tube (``root`` -> ``mid`` -> ``tip``) and two takes, ``bend`` (keys every
    0.2 s on every bone: the root slides and turns, the mid bends about Z and X, the tip about Z)
    and ``wave`` (the tip alone, keys every 0.4 s)."""

    def __init__(self, around=12, rings=9, length=30.0, radius=3.5):
        self.positions, self.triangles = tube_geometry(around, rings, length, radius)
        self.names = ["root", "mid", "tip"]
        self.parents = [-1, 0, 1]
        seg = length / 3
        self.t = np.array([[0.0, 0.0, 0.0], [0.0, seg, 0.0], [0.0, seg, 0.0]])
        self.r = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 10.0], [0.0, 0.0, -10.0]])
        self.s = np.ones((3, 3))
        centers = np.array([0.5, 1.5, 2.5]) * seg
        g = np.exp(-(((self.positions[:, 1:2] - centers[None]) / (0.6 * seg)) ** 2))
        g[g < np.sort(g, axis=1)[:, -2:-1]] = 0.0  # the two nearest bones of each vertex
        self.weights = g / g.sum(axis=1, keepdims=True)  # (V, 3)
        ts = np.round(np.arange(7) * 0.2, 6)
        self.takes = {
            "bend": {0: {"T": [(t, (2.0 * t, 0.0, -1.0 * t)) for t in ts], "R": [(t, (0.0, 25 * t, 0.0)) for t in ts]},
                     1: {"R": [(t, (30 * t, 0.0, 10 + 50 * t)) for t in ts]},
                     2: {"R": [(t, (0.0, 0.0, -10 + 40 * t)) for t in ts]}},
            "wave": {2: {"R": [(t, (20 * t, 0.0, -10 + 30 * np.sin(np.pi * t / 1.6))) for t in (0.0, 0.4, 0.8, 1.2, 1.6)]}},
        }

    # ---- the reference ---------------------------------------------------------------------
    def _trs(self, b, take=None, seconds=0.0):
        vals = {"T": self.t[b].copy(), "R": self.r[b].copy(), "S": self.s[b].copy()}
        if take is not None:
            for ch, keys in self.takes[take].get(b, {}).items():
                times = np.array([k[0] for k in keys])
                values = np.array([k[1] for k in keys], dtype=np.float64)
                vals[ch] = np.array([np.interp(seconds, times, values[:, c]) for c in range(3)])
        return vals["T"], vals["R"], vals["S"]

    def world(self, take=None, seconds=0.0):
        out = []
        for b, p in enumerate(self.parents):
            m = local(*self._trs(b, take, seconds))
            out.append(m if p < 0 else out[p] @ m)
        return np.array(out)

    def pose(self, take=None, seconds=0.0):
        skin = self.world(take, seconds) @ np.linalg.inv(self.world())
        h = np.c_[self.positions, np.ones(len(self.positions))]
        moved = np.einsum("bij,vj->vbi", skin, h)[..., :3]  # (V, B, 3)
        return np.einsum("vb,vbi->vi", self.weights, moved)

    def key_times(self, take):
        return np.unique(np.concatenate([[k[0] for k in keys] for chans in self.takes[take].values()
                                         for keys in chans.values()]))

    # ---- the document ----------------------------------------------------------------------
    def write(self, path) -> str:
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        nums = lambda a: ",".join(f"{float(x):.15g}" for x in np.asarray(a).reshape(-1))  # noqa: E731
        mat = lambda m: nums(np.asarray(m).T.reshape(-1))  # noqa: E731  (translation at 12..14)
        out = ["; FBX 6.1.0 project file", "; written by colossus tests (fbx61_fixture)", "",
               "FBXHeaderExtension:  {", "\tFBXHeaderVersion: 1003", "\tFBXVersion: 6100",
               '\tCreator: "colossus tests"', "}", 'Creator: "colossus tests"', "",
               "Definitions:  {", "\tVersion: 100", f"\tCount: {3 + 1 + 1 + 3 + 1}",
               '\tObjectType: "Model" {', "\t\tCount: 4", "\t}", '\tObjectType: "Deformer" {', "\t\tCount: 4", "\t}",
               '\tObjectType: "GlobalSettings" {', "\t\tCount: 1", "\t}", "}", "", "Objects:  {"]

        def model(name, kind, t, r, s, extra=()):
            lines = [f'\tModel: "Model::{name}", "{kind}" {{', "\t\tVersion: 232", "\t\tProperties60:  {",
                     f'\t\t\tProperty: "Lcl Translation", "Lcl Translation", "A+",{nums(t)}',
                     f'\t\t\tProperty: "Lcl Rotation", "Lcl Rotation", "A+",{nums(r)}',
                     f'\t\t\tProperty: "Lcl Scaling", "Lcl Scaling", "A+",{nums(s)}',
                     '\t\t\tProperty: "RotationOrder", "enum", "",0',
                     '\t\t\tProperty: "InheritType", "enum", "",1',
                     "\t\t}", "\t\tMultiLayer: 0", "\t\tMultiTake: 1", "\t\tShading: Y", '\t\tCulling: "CullingOff"']
            return lines + list(extra) + ["\t}"]

        for b, name in enumerate(self.names):
            out += model(name, "Limb", self.t[b], self.r[b], self.s[b], ['\t\tTypeFlags: "Skeleton"'])
        poly = self.triangles.copy()
        poly[:, 2] = -poly[:, 2] - 1
        out += model("limb", "Mesh", (0, 0, 0), (0, 0, 0), (1, 1, 1),
                     [f"\t\tVertices: {nums(self.positions)}", f"\t\tPolygonVertexIndex: {','.join(map(str, poly.reshape(-1)))}",
                      "\t\tGeometryVersion: 124"])
        out += ['\tDeformer: "Deformer::Skin limb", "Skin" {', "\t\tVersion: 100", "\t\tMultiLayer: 0", '\t\tType: "Skin"',
                "\t\tProperties60:  {", "\t\t}", "\t\tLink_DeformAcuracy: 50", "\t}"]
        bind = self.world()
        for b, name in enumerate(self.names):
            idx = np.nonzero(self.weights[:, b] > 0)[0]
            out += [f'\tDeformer: "SubDeformer::Cluster limb {name}", "Cluster" {{', "\t\tVersion: 100", "\t\tMultiLayer: 0",
                    '\t\tType: "Cluster"', "\t\tProperties60:  {", '\t\t\tProperty: "SrcModel", "object", ""',
                    '\t\t\tProperty: "SrcModelReference", "object", ""', "\t\t}", '\t\tUserData: "", ""',
                    f"\t\tIndexes: {','.join(map(str, idx))}", f"\t\tWeights: {nums(self.weights[idx, b])}",
                    f"\t\tTransform: {mat(np.linalg.inv(bind[b]))}", f"\t\tTransformLink: {mat(bind[b])}", "\t}"]
        out += ["\tGlobalSettings:  {", "\t\tVersion: 1000", "\t\tProperties60:  {",
                '\t\t\tProperty: "UpAxis", "int", "",1', '\t\t\tProperty: "UpAxisSign", "int", "",1',
                '\t\t\tProperty: "FrontAxis", "int", "",2', '\t\t\tProperty: "FrontAxisSign", "int", "",1',
                '\t\t\tProperty: "CoordAxis", "int", "",0', '\t\t\tProperty: "CoordAxisSign", "int", "",1',
                '\t\t\tProperty: "UnitScaleFactor", "double", "",1', '\t\t\tProperty: "TimeMode", "enum", "",6',
                "\t\t}", "\t}", "}", "", "Connections:  {",
                '\tConnect: "OO", "Model::limb", "Model::Scene"', '\tConnect: "OO", "Model::root", "Model::Scene"',
                '\tConnect: "OO", "Deformer::Skin limb", "Model::limb"']
        for b, name in enumerate(self.names):
            out += [f'\tConnect: "OO", "SubDeformer::Cluster limb {name}", "Deformer::Skin limb"',
                    f'\tConnect: "OO", "Model::{name}", "SubDeformer::Cluster limb {name}"']
            if self.parents[b] >= 0:
                out.append(f'\tConnect: "OO", "Model::{name}", "Model::{self.names[self.parents[b]]}"')
        out += ["}", "", "Takes:  {", f'\tCurrent: "{next(iter(self.takes))}"']
        for take, models in self.takes.items():
            stop = int(round(float(self.key_times(take)[-1]) * TICKS))
            out += [f'\tTake: "{take}" {{', f'\t\tFileName: "{take}.tak"', f"\t\tLocalTime: 0,{stop}",
                    f"\t\tReferenceTime: 0,{stop}"]
            for b, chans in models.items():
                out += [f'\t\tModel: "Model::{self.names[b]}" {{', "\t\t\tVersion: 1.1", '\t\t\tChannel: "Transform" {']
                for ch, layer in (("T", 1), ("R", 2), ("S", 3)):
                    if ch not in chans:
                        continue
                    keys = chans[ch]
                    out.append(f'\t\t\t\tChannel: "{ch}" {{')
                    for c, axis in enumerate("XYZ"):
                        ks = ",".join(f"{int(round(t * TICKS))},{float(v[c]):.15g},L" for t, v in keys)
                        out += [f'\t\t\t\t\tChannel: "{axis}" {{', f"\t\t\t\t\t\tDefault: {float(keys[0][1][c]):.15g}",
                                "\t\t\t\t\t\tKeyVer: 4005", f"\t\t\t\t\t\tKeyCount: {len(keys)}", f"\t\t\t\t\t\tKey: {ks}",
                                "\t\t\t\t\t\tColor: 1,0,0", "\t\t\t\t\t}"]
                    out += [f"\t\t\t\t\tLayerType: {layer}", "\t\t\t\t}"]
                out += ["\t\t\t}", "\t\t}"]
            out.append("\t}")
        out += ["}", "", "Version5:  {", "\tSettings:  {", '\t\tFrameRate: "30"', "\t\tTimeFormat: 1", "\t}", "}", ""]
        with open(path, "w") as fh:
            fh.write("\n".join(out))
        return os.fspath(path)
