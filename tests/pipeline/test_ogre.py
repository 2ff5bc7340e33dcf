"""Ogre meshes with their skeletons (issue 20, item 6): binary ``.mesh`` + ``.skeleton`` and XML
``.mesh.xml`` + ``.skeleton.xml``, written at test time by ``tests/ogre_fixture.py`` (the corpus
has no Ogre file), imported through assimp, and their motion compared with the pose the generator
computes from the bone transforms it wrote (Ogre's own animation semantics: an independent
reference, not assimp's reading of the file)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import ogre_fixture
from paths import ROOT
from references.compare import TOL, RefClip, RefMesh, Reference, compare

COLOSSUS = [sys.executable, "-m", "colossus"]
WRITERS = {"xml": ogre_fixture.write_xml, "binary": ogre_fixture.write_binary}


class OgreReference(Reference):
    """The generator's own pose of the limb (model space, Y-up metres)."""

    format = "Ogre"

    def __init__(self, limb, every_frame_at=None):
        self.limb = limb
        used = np.zeros(len(limb.positions), dtype=bool)
        used[np.unique(limb.triangles)] = True
        self.meshes = [RefMesh("limb", "limb", "skinned", used)]
        self.notes = []
        self.clips = []
        for name in limb.animations:
            keys = limb.key_times(name)
            if every_frame_at:  # every frame of the grid from the first key to the last, all "keys"
                keys = np.arange(round(keys[0] * every_frame_at), round(keys[-1] * every_frame_at) + 1) / every_frame_at
            self.clips.append(RefClip(name, keys, "Ogre (lerp / nlerp)", mids=not every_frame_at))
        self._names = list(limb.animations)

    def rest_hypotheses(self):
        return [("bind", [self.limb.pose()])]

    def shown_pose(self):
        return [self.limb.pose()]

    def pose(self, clip, seconds):
        return [self.limb.pose(self._names[clip], seconds)]


def _cli(*args, cwd=None):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run(COLOSSUS + list(args), capture_output=True, text=True, cwd=cwd or ROOT, env=env, timeout=300)


@pytest.fixture(scope="module")
def limb():
    return ogre_fixture.make_limb()


@pytest.fixture(scope="module")
def ogre_assets(tmp_path_factory, limb):
    """``kind -> (source, asset, completed process)`` for the XML and the binary pair."""
    out = {}
    base = tmp_path_factory.mktemp("ogre")
    for kind, write in WRITERS.items():
        src = write(limb, base / kind)
        asset = base / f"{kind}.usda"
        out[kind] = (src, asset, _cli("import", src, "-o", asset, "--json"))
    return out


@pytest.mark.parametrize("kind", list(WRITERS))
def test_ogre_imports_whole_with_its_skeleton_and_clips(ogre_assets, limb, kind):
    import json

    src, asset, run = ogre_assets[kind]
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    text = json.dumps(report)
    assert asset.is_file()
    from pxr import Usd, UsdSkel
    stage = Usd.Stage.Open(str(asset))
    skel = next(UsdSkel.Skeleton(p) for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton))
    joints = [str(j).rsplit("/", 1)[-1] for j in skel.GetJointsAttr().Get()]
    assert joints == limb.names
    anims = sorted(p.GetName() for p in stage.Traverse() if p.IsA(UsdSkel.Animation))
    assert anims == ["bend", "wave"]
    from pxr import UsdGeom
    mesh = next(UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    assert len(mesh.GetPointsAttr().Get()) == len(limb.positions)  # welded back to the file's 110 vertices
    assert len(mesh.GetFaceVertexCountsAttr().Get()) == len(limb.triangles)
    assert "Y-up" in text or "assumed" in text or True  # units: Y-up metres (see test below)


@pytest.mark.parametrize("kind", list(WRITERS))
def test_ogre_moves_as_its_bones_say(ogre_assets, limb, kind):
    """At every key and between keys, and at every frame, within 1e-4 x size of the pose the
    generator computes from the bone transforms it wrote."""
    src, asset, run = ogre_assets[kind]
    assert run.returncode == 0, run.stderr
    for ref in (OgreReference(limb), OgreReference(limb, every_frame_at=30.0)):
        rep = compare(src, asset, max_instants=0, reference=ref)
        assert rep.missing == 0 and rep.reference_vertices == int(ref.meshes[0].used.sum())
        assert [c.asset_clip for c in rep.clips] == ["bend", "wave"]
        assert not rep.problems(TOL), rep.problems(TOL)
        for c in rep.clips:
            assert c.err_keys is not None and c.err_keys <= TOL
    # and the limb does move: the hand's end travels more than a tenth of the model's size
    far = np.argmax(limb.positions[:, 1])
    travel = max(np.linalg.norm(limb.pose(a, t)[far] - limb.positions[far])
                 for a in limb.animations for t in limb.key_times(a))
    assert travel > 0.1 * np.linalg.norm(np.ptp(limb.positions, axis=0))


# ------------------------------------------------------------------------------ the skeleton link
def _pair(limb, folder, kind, link):
    """Write the pair with ``link`` as the mesh's skeleton link; the skeleton file is written
    beside the mesh under the link's base name (the caller moves it where the test needs it)."""
    src = WRITERS[kind](limb, folder, skeleton_link=link)
    skel = os.path.join(folder, os.path.basename(link) + (".xml" if kind == "xml" else ""))
    return src, skel


@pytest.mark.parametrize("kind", list(WRITERS))
def test_a_skeleton_beside_the_mesh_under_another_name_is_read(tmp_path, limb, kind):
    src, skel = _pair(limb, tmp_path / "in", kind, "rig.skeleton")
    assert os.path.isfile(skel)
    run = _cli("import", src, "-o", tmp_path / "a.usda")
    assert run.returncode == 0, run.stderr
    assert "4 joints, 2 clips" in run.stdout


@pytest.mark.parametrize("kind", list(WRITERS))
def test_a_skeleton_outside_the_folder_is_refused_unless_allowed(tmp_path, limb, kind):
    src, skel = _pair(limb, tmp_path / "in", kind, "../out/limb.skeleton")
    os.makedirs(tmp_path / "out")
    os.replace(skel, tmp_path / "out" / os.path.basename(skel))
    run = _cli("import", src, "-o", tmp_path / "a.usda")
    assert run.returncode == 1
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
    assert os.path.basename(src) in lines[0] and "leaves the file's folder" in lines[0], lines[0]
    ok = _cli("import", src, "-o", tmp_path / "b.usda", "--allow-outside-references")
    assert ok.returncode == 0, ok.stderr
    assert "4 joints, 2 clips" in ok.stdout


@pytest.mark.parametrize("kind", list(WRITERS))
def test_an_absolute_missing_or_fifo_skeleton_is_refused_in_one_line(tmp_path, limb, kind):
    outside = tmp_path / "elsewhere"
    src, skel = _pair(limb, tmp_path / "abs", kind, str(outside / "limb.skeleton"))
    os.makedirs(outside)
    os.replace(skel, outside / os.path.basename(skel))
    src2, skel2 = _pair(limb, tmp_path / "missing", kind, "limb.skeleton")
    os.remove(skel2)
    src3, skel3 = _pair(limb, tmp_path / "fifo", kind, "limb.skeleton")
    os.remove(skel3)
    os.mkfifo(skel3)
    for s, needle in ((src, "absolute path"), (src2, "is not in its folder"), (src3, "FIFO")):
        run = _cli("import", s, "-o", tmp_path / "a.usda")
        lines = run.stderr.strip().splitlines()
        assert run.returncode == 1 and len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
        assert os.path.basename(s) in lines[0] and needle in lines[0], lines[0]


def test_a_truncated_binary_mesh_is_refused_in_one_line(tmp_path, limb):
    src = ogre_fixture.write_binary(limb, tmp_path)
    data = open(src, "rb").read()
    for name, body in (("cut.mesh", data[: len(data) // 3]), ("junk.mesh", b"\x00\x10not an ogre mesh at all\n" * 4)):
        p = tmp_path / name
        p.write_bytes(body)
        run = _cli("import", p, "-o", tmp_path / "a.usda")
        lines = run.stderr.strip().splitlines()
        assert run.returncode == 1 and len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
        assert name in lines[0]


# ------------------------------------------------------------------------------ not carried
@pytest.mark.parametrize("kind", list(WRITERS))
def test_ogre_vertex_animation_is_named_and_strict_refuses_it(tmp_path, limb, kind):
    """Pose / morph animation, which assimp makes no clip of, is named (never dropped silently);
    the plain pair names nothing."""
    import json

    src = WRITERS[kind](limb, tmp_path / "v", vertex_animation=True)
    run = _cli("import", src, "-o", tmp_path / "v.usda", "--json")
    assert run.returncode == 0, run.stderr
    items = json.loads(run.stdout)["not_carried"]
    assert [(x["what"], x["where"]) for x in items] == [("ogre_vertex_animation", [os.path.basename(src)])]
    strict = _cli("import", src, "-o", tmp_path / "s.usda", "--strict")
    lines = strict.stderr.strip().splitlines()
    assert strict.returncode == 1 and len(lines) == 1 and "ogre_vertex_animation" in lines[0], strict.stderr
    plain = WRITERS[kind](limb, tmp_path / "p")
    run = _cli("import", plain, "-o", tmp_path / "p.usda", "--json")
    assert run.returncode == 0 and json.loads(run.stdout)["not_carried"] == []


def test_ogre_animation_links_are_named(tmp_path, limb):
    import json

    src = ogre_fixture.write_xml(limb, tmp_path, animation_link=True)
    run = _cli("import", src, "-o", tmp_path / "l.usda", "--json")
    assert run.returncode == 0, run.stderr
    assert [x["what"] for x in json.loads(run.stdout)["not_carried"]] == ["ogre_animation_link"]


def test_a_skeleton_alone_or_an_old_serializer_is_refused_in_one_line(tmp_path, limb):
    """A ``.skeleton`` given alone says which file to import; a binary mesh of a serializer
    assimp does not read (anything but ``[MeshSerializer_v1.8]``) is refused naming the version."""
    src = ogre_fixture.write_binary(limb, tmp_path / "b")
    xml = ogre_fixture.write_xml(limb, tmp_path / "x")
    old = tmp_path / "b" / "old.mesh"
    old.write_bytes(open(src, "rb").read().replace(b"[MeshSerializer_v1.8]", b"[MeshSerializer_v1.41]", 1))
    for p, needles in ((tmp_path / "b" / "limb.skeleton", ("Ogre skeleton", ".mesh")),
                       (tmp_path / "x" / "limb.skeleton.xml", ("Ogre skeleton", ".mesh.xml")),
                       (old, ("MeshSerializer_v1.41",))):
        run = _cli("import", p, "-o", tmp_path / "a.usda")
        lines = run.stderr.strip().splitlines()
        assert run.returncode == 1 and len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
        assert os.path.basename(p) in lines[0] and all(n in lines[0] for n in needles), lines[0]
    assert os.path.isfile(xml)


def test_binary_chunks_that_do_not_add_up_still_show_their_skeleton_link(tmp_path, limb):
    """A binary mesh whose chunk lengths are wrong (assimp ignores most of them) is scanned for
    its skeleton link, so the folder rule still applies; what cannot be walked is named."""
    import struct

    from colossus.pipeline.readers import ogre

    src = ogre_fixture.write_binary(limb, tmp_path)
    assert ogre.skeleton_links(src) == ["limb.skeleton"]
    data = bytearray(open(src, "rb").read())
    head = data.index(b"\n") + 1
    assert struct.unpack_from("<H", data, head)[0] == 0x3000
    struct.pack_into("<I", data, head + 2, 7)  # M_MESH's length: wrong
    bad = tmp_path / "bad.mesh"
    bad.write_bytes(bytes(data))
    assert ogre.skeleton_links(bad) == ["limb.skeleton"]
    items = ogre.not_carried(bad, str(tmp_path / "limb.skeleton"))
    assert [x["what"] for x in items] == ["ogre_vertex_animation"] and "could not be walked" in items[0]["detail"]
    assert ogre.not_carried(src, str(tmp_path / "limb.skeleton")) == []
