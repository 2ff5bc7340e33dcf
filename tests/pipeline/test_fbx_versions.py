"""FBX versions (issue 20, item 6): an FBX 6.1 ASCII skinned, animated limb written at test time
(``tests/fbx61_fixture.py``; the corpus has FBX 7.x only) imports through ufbx and moves as the
transforms written say (an independent reference: the generator's own Euler-XYZ, linear-key
evaluation), at keys, between keys and at every frame.  The assimp road (FBX 7.1 .. 7.7 only)
refuses it in one line naming the version."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

import fbx61_fixture
from paths import fbx_road
from references.compare import TOL, RefClip, RefMesh, Reference, compare


class Fbx61Reference(Reference):
    format = "FBX 6.1"
    up_axis = "Y"
    meters_per_unit = 0.01  # UnitScaleFactor 1: centimetres

    def __init__(self, limb, every_frame_at=None):
        self.limb = limb
        self.meshes = [RefMesh("limb", "limb", "skinned", np.ones(len(limb.positions), dtype=bool))]
        self.notes = []
        self.clips = []
        for take in limb.takes:
            keys = limb.key_times(take)
            if every_frame_at:
                keys = np.arange(round(keys[0] * every_frame_at), round(keys[-1] * every_frame_at) + 1) / every_frame_at
            self.clips.append(RefClip(take, keys, "FBX L keys (Euler lerp)", mids=not every_frame_at))
        self._takes = list(limb.takes)

    def rest_hypotheses(self):
        return [("bind", [self.limb.pose()])]

    def shown_pose(self):
        return [self.limb.pose()]

    def pose(self, clip, seconds):
        return [self.limb.pose(self._takes[clip], seconds)]


def _cli(*args):
    from colossus.cli import main
    return CliRunner().invoke(main, [str(a) for a in args], prog_name="colossus")


@pytest.fixture(scope="module")
def fbx61(tmp_path_factory):
    limb = fbx61_fixture.Limb61()
    base = tmp_path_factory.mktemp("fbx61")
    return limb, limb.write(base / "limb_6100_ascii.fbx"), base


def test_fbx61_ascii_imports_and_moves_as_written(fbx61):
    if fbx_road() != "ufbx":
        pytest.skip("FBX 6.1 is read on the ufbx road only")
    limb, src, base = fbx61
    out = base / "limb61.usda"
    r = _cli("import", src, "-o", out)
    assert r.exit_code == 0, r.output
    assert "3 joints, 2 clips" in r.output and "110 vertices, 216 triangles" in r.output
    for ref in (Fbx61Reference(limb), Fbx61Reference(limb, every_frame_at=30.0)):
        rep = compare(src, out, max_instants=0, reference=ref)
        assert rep.missing == 0 and rep.reference_vertices == len(limb.positions)
        assert [c.asset_clip for c in rep.clips] == ["bend", "wave"]
        assert rep.problems(TOL) == [], rep.problems(TOL)
        assert all(c.err_keys is not None for c in rep.clips)
    far = np.argmax(limb.positions[:, 1])
    travel = max(np.linalg.norm(limb.pose(t, s)[far] - limb.positions[far]) for t in limb.takes for s in limb.key_times(t))
    assert travel > 0.1 * np.linalg.norm(np.ptp(limb.positions, axis=0))


def test_fbx61_on_the_assimp_road_is_refused_naming_the_version(fbx61, monkeypatch):
    limb, src, base = fbx61
    monkeypatch.setenv("COLOSSUS_FBX_READER", "assimp")
    r = _cli("import", src, "-o", base / "assimp.usda")
    assert r.exit_code == 1
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert "limb_6100_ascii.fbx" in lines[0] and "6100" in lines[0], lines[0]
