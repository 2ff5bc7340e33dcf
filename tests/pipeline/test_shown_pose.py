"""A file without animation keeps the pose it shows (issue 20 item 3): its nodes as written, not
the bind pose, as a one-frame clip named in the summary; judged against the glTF specification
evaluator (tests/references/gltf_eval.py), which shares no code with the importer."""

from __future__ import annotations

import json
import math
import struct

import numpy as np
from scipy.spatial import cKDTree

from colossus.pipeline.run import ImportSettings, import_asset
from paths import SAMPLES
from references.gltf_eval import GltfDocument
from references.usd_reference import UsdSkelReference


def _glb_without_animation(path, turn_radians):
    """The limb sample with its animations removed and its second joint turned about x."""
    data = (SAMPLES / "limb.glb").read_bytes()
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    rest = data[20 + n:]
    doc.pop("animations", None)
    j = doc["skins"][0]["joints"][1]
    doc["nodes"][j]["rotation"] = [math.sin(turn_radians / 2), 0.0, 0.0, math.cos(turn_radians / 2)]
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    path.write_bytes(struct.pack("<III", 0x46546C67, 2, 20 + len(js) + len(rest))
                     + struct.pack("<II", len(js), 0x4E4F534A) + js + rest)
    return path


def test_posed_file_without_animation_keeps_its_pose(tmp_path):
    src = _glb_without_animation(tmp_path / "posed.glb", math.radians(60))
    out = tmp_path / "posed.usda"
    res = import_asset(src, out, ImportSettings())
    assert [c.name for c in res.mesh.clips] == ["pose"]
    info = res.mesh.source["clip_info"][0]
    assert info["shown_pose"] and info["frames"] == 1 and info["shown_pose_moves_relative"] > 0.1
    ref = UsdSkelReference(out).use_clip("pose")
    got = ref.points(ref.times("pose")[0])
    want = np.concatenate(GltfDocument(str(src)).pose(None, 0.0))
    size = float(np.linalg.norm(want.max(0) - want.min(0)))
    d = max(cKDTree(want).query(got)[0].max(), cKDTree(got).query(want)[0].max())
    assert d <= 1e-5 * size, d / size
    # the bind pose, which the import used to write, is far from it
    bind = UsdSkelReference(out).use_clip(None).points(0.0)
    assert cKDTree(want).query(bind)[0].max() > 0.1 * size


def test_file_in_its_bind_pose_gets_no_clip(tmp_path):
    src = _glb_without_animation(tmp_path / "bind.glb", 0.0)
    res = import_asset(src, tmp_path / "bind.usda", ImportSettings())
    assert res.mesh.clips == () and not res.mesh.source["clip_info"]
