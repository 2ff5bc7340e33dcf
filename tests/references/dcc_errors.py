"""Today's import of the ``corpus/dcc`` FBX files against the authoring tools' own deformed meshes.

For each truth OBJ (Maya / 3ds Max's export of the deformed mesh at a time, ``dcc/README.md``),
the asset written by ``colossus import`` is skinned by plain usd-core (:class:`.compare.AssetRig`)
at that time and compared with it, in the asset's units and axes (the OBJs are in the FBX file's
own space: centimetres, the header's up axis).

* Maya files: the OBJ's vertices are the FBX control points in order; each control point's bind
  position (``TransformLink @ Transform @ point`` of its clusters) is matched to the asset vertex
  at the same bind position, and the error is the largest distance of a matched pair.
* The 3ds Max file: the OBJ's vertex order differs (ufbx ``bad_order``), and where the asset's
  bind pose is not the skin's (the bind positions do not match), the error is the largest
  distance under the best one-to-one assignment between the asset's distinct points and the
  OBJ's (Hungarian; at least the symmetric Hausdorff distance, printed too).

Errors are relative to the model size: the diagonal of the truth's bounding box over the truth
frames.  Usage::

    python tests/references/dcc_errors.py [colossus] [-- import options]
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from references.compare import AssetRig, axis_scale  # noqa: E402
from references.fbx_truth import _m44, _properties70, load_obj, read_fbx_tree  # noqa: E402
from paths import CORPUS  # noqa: E402

DCC = os.fspath(CORPUS / "dcc")

#: file -> (frame rate, [(frame, OBJ)], OBJ vertices in control-point order)
FILES = {
    "maya_dq_weights_7500_binary.fbx": (24.0, [(10, "maya_dq_weights_10.obj"), (18, "maya_dq_weights_18.obj")], True),
    "max_transformed_skin_7500_binary.fbx": (30.0, [(5, "max_transformed_skin_5.obj"), (15, "max_transformed_skin_15.obj")], False),
    "maya_transformed_skin_7700_binary.fbx": (24.0, [(0, "maya_transformed_skin_0.obj"), (4, "maya_transformed_skin_4.obj"),
                                                      (8, "maya_transformed_skin_8.obj")], True),
}


def bind_points(fbx) -> np.ndarray:
    """(n, 3) control points at bind time in the file's space (the first cluster's bind)."""
    root = read_fbx_tree(fbx)
    objs = root.child("Objects")
    g = next(n for n in objs.all("Geometry") if n.props[2] == "Mesh")
    cp = g.child("Vertices").props[0].reshape(-1, 3).astype(np.float64)
    cl = next(n for n in objs.all("Deformer") if n.props[2] == "Cluster" and n.child("TransformLink") is not None)
    m = _m44(cl.child("TransformLink").props[0]) @ _m44(cl.child("Transform").props[0])
    return cp @ m[:3, :3].T + m[:3, 3]


def header(fbx):
    gs = _properties70(read_fbx_tree(fbx).child("GlobalSettings"))
    return {1: "Y", 2: "Z"}[int(gs.get("UpAxis", 1))], float(gs.get("UnitScaleFactor", 1.0)) / 100.0


def measure(fbx, asset) -> list:
    """``[(time seconds, error / size, hausdorff / size or None)]`` for each truth OBJ of ``fbx``."""
    rate, frames, ordered = FILES[os.path.basename(fbx)]
    rig = AssetRig(asset)
    up, mpu = header(fbx)
    c = axis_scale(up, mpu, rig.up_axis, rig.meters_per_unit)
    truths = [(f / rate, load_obj(os.path.join(DCC, obj))[0] @ c[:3, :3].T) for f, obj in frames]
    allp = np.concatenate([t for _, t in truths])
    size = float(np.linalg.norm(allp.max(0) - allp.min(0)))
    out = []
    if ordered:
        rest_t = bind_points(fbx) @ c[:3, :3].T
        rest_a = rig.rest()
        d, idx = cKDTree(rest_a).query(rest_t)
        if d.max() > 1e-4 * size:  # the asset's bind pose is not the skin's: match one to one instead
            ordered = False
    for sec, truth in truths:
        got = rig.points(rig.clips[0], [sec * rig.time_codes_per_second])[0]
        if ordered:
            out.append((sec, float(np.linalg.norm(got[idx] - truth, axis=1).max() / size), None))
        else:
            pts = np.unique(np.round(got, 9), axis=0)
            cost = np.linalg.norm(pts[:, None] - truth[None], axis=2)
            r, k = linear_sum_assignment(cost)
            haus = max(cKDTree(truth).query(pts)[0].max(), cKDTree(pts).query(truth)[0].max())
            out.append((sec, float(cost[r, k].max() / size), float(haus / size)))
    return out


def main(argv):
    colossus = argv[0] if argv and argv[0] != "--" else os.path.join(os.path.dirname(sys.executable), "colossus")
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    with tempfile.TemporaryDirectory() as tmp:
        for name in FILES:
            fbx = os.path.join(DCC, name)
            out = os.path.join(tmp, name + ".usda")
            p = subprocess.run([colossus, "import", fbx, "-o", out, "--json", *extra], capture_output=True, text=True)
            if p.returncode:
                print(f"{name}: import exit {p.returncode}: {p.stderr.strip()}")
                continue
            import json
            s = json.loads(p.stdout)
            items = s.get("not_carried", [])
            for sec, err, haus in measure(fbx, out):
                h = f" (Hausdorff {haus:.3g})" if haus is not None else ""
                print(f"{name}: t={sec:.4f}s error {err:.3g} x size{h}")
            print(f"{name}: not_carried: " + ("; ".join(f"{i['what']} ({i['where']}, bound {i['bound_relative']})" for i in items) or "none"))


if __name__ == "__main__":
    main(sys.argv[1:])
