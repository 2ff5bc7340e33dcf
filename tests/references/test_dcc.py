"""Issue 20's first "done when": every file in ``corpus/dcc`` within 1e-4 x model size of its
authoring tool's own deformed mesh at every truth time (:mod:`references.dcc_errors` measures:
the asset skinned by plain usd-core against Maya's / 3ds Max's OBJ), or, where the collider
cannot carry what the file asks for yet, within the bound its not-carried record states.

* ``maya_transformed_skin``: Maya's transform_skin (the mesh node moved after binding).
* ``max_transformed_skin``: 3ds Max geometric / pivot transforms.  Its OBJ truths are written with
  4 decimals and in another vertex order: the bar is ufbx's own test's for this file, an absolute
  0.01 file units (centimetres); 1e-4 x size as well where that is larger.
* ``maya_dq_weights``: Maya's blended linear / dual-quaternion skin.  The collider skins linearly
  (issue 21): the error stays within the ``fbx_skinning_type`` bound the import states.
"""

from __future__ import annotations

import json
import os

import pytest
from click.testing import CliRunner

from references.dcc_errors import DCC, FILES, header, measure

pytestmark = pytest.mark.skipif(not os.path.isdir(DCC), reason="corpus/dcc not present")


def _import(name, tmp_path):
    from paths import fbx_road
    if fbx_road() != "ufbx":
        pytest.skip("FBX goes through assimp here: its DCC errors are named, not matched (test_not_carried)")
    from colossus.cli import main
    out = tmp_path / (name + ".usda")
    r = CliRunner().invoke(main, ["import", os.path.join(DCC, name), "-o", str(out), "--json"], prog_name="colossus")
    assert r.exit_code == 0, r.output
    return out, json.loads(r.stdout)


@pytest.mark.parametrize("name", ["maya_transformed_skin_7700_binary.fbx", "max_transformed_skin_7500_binary.fbx"])
def test_dcc_file_matches_its_tools_own_mesh(name, tmp_path):
    out, summary = _import(name, tmp_path)
    assert summary.get("not_carried", []) == []
    errs = measure(os.path.join(DCC, name), str(out))
    assert len(errs) == len(FILES[name][1])
    if name.startswith("max_"):
        # error / size -> file units: the OBJ's own extent (measure's size) in centimetres
        from references.compare import AssetRig
        from references.fbx_truth import load_obj
        import numpy as np
        pts = np.concatenate([load_obj(os.path.join(DCC, obj))[0] for _, obj in FILES[name][1]])
        size_cm = float(np.linalg.norm(pts.max(0) - pts.min(0)))
        up, mpu = header(os.path.join(DCC, name))
        rig = AssetRig(str(out))
        assert rig.up_axis in ("Y", "Z") and mpu > 0
        for sec, err, _ in errs:
            assert err * size_cm <= max(0.01, 1e-4 * size_cm), (sec, err)
    else:
        for sec, err, _ in errs:
            assert err <= 1e-4, (sec, err)


def test_dcc_blended_dq_skin_is_within_its_stated_bound(tmp_path):
    name = "maya_dq_weights_7500_binary.fbx"
    out, summary = _import(name, tmp_path)
    items = summary["not_carried"]
    assert [x["what"] for x in items] == ["fbx_skinning_type"]
    bound = items[0]["bound_relative"]
    errs = measure(os.path.join(DCC, name), str(out))
    # the truth's size (measure's) is within a few % of the posed size the bound is relative to
    assert all(err <= bound for _, err, _ in errs), (errs, bound)
    assert max(err for _, err, _ in errs) > 1e-3  # the blend is real: this is not a pass by accident
