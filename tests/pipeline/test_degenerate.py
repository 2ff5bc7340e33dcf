"""Never write what our own validator rejects (issue 20 item 5).

* The ``degenerate`` stage drops the zero-area triangles COL204 flags, by the rule's own test
  (``runtime.schema.zero_area_faces``) with a margin: a real glTF holding zero-area triangles
  imports (exit 0, the count in the summary) into an asset that validates clean.
* The command line runs the validator's error rules on the written file before its rename: an
  asset that would still fail one is refused (exit 1, one line naming the rule, nothing written).
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from click.testing import CliRunner

from colossus.bench.synth import tube, write_glb
from colossus.pipeline.stages import StageReport
from colossus.pipeline.stages.degenerate import degenerate, zero_area
from colossus.pipeline.tolerances import DEGENERATE_MARGIN
from colossus.runtime import schema

import synth

SEG = 11  # write_glb(triangles=600): 11 vertices a ring (bench.synth.tube)


def colossus(*args):
    from colossus.cli import main
    return CliRunner().invoke(main, [str(a) for a in args], prog_name="colossus")


def glb_with_triangles(tmp_path, name, extra, copies=()):
    """The benchmark tube (bench.synth.write_glb) as a real .glb, with the triangles ``extra``
    (k, 3) appended to its index accessor, after new vertices ``copies``: ``(vertex, joints (4,),
    weights (4,))`` each, a vertex at the position of ``vertex`` with those influences (numbered
    from the tube's vertex count on).  Every accessor that grows is rewritten at the end of the BIN
    chunk."""
    from fuzz.mutators import glb_join, glb_split

    pos, _ = tube(600)
    assert np.count_nonzero(pos[:, 1] == pos[0, 1]) == SEG + 1  # one ring and the cap's centre
    plain = tmp_path / f"plain-{name}"
    write_glb(plain, triangles=600, bones=4, clips=1, frames=12)
    doc, chunks = glb_split(plain.read_bytes())
    plain.unlink()
    binary = bytearray(chunks[1][1])
    prim = doc["meshes"][0]["primitives"][0]

    def read(i, dtype, width):
        acc = doc["accessors"][i]
        view = doc["bufferViews"][acc["bufferView"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        n = acc["count"] * width * np.dtype(dtype).itemsize
        return np.frombuffer(bytes(binary[start:start + n]), dtype=dtype).reshape(acc["count"], width)

    def append(i, rows, target):
        nonlocal binary
        acc = dict(doc["accessors"][i])
        data = np.vstack([read(i, rows.dtype, rows.shape[1]), rows])
        binary += b"\0" * (-len(binary) % 4)
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(binary), "byteLength": data.nbytes,
                                   "target": target})
        binary += data.tobytes()
        acc.update(bufferView=len(doc["bufferViews"]) - 1, count=int(len(data)))
        acc.pop("byteOffset", None)
        if "min" in acc:
            acc["min"], acc["max"] = data.min(0).tolist(), data.max(0).tolist()
        doc["accessors"].append(acc)
        return len(doc["accessors"]) - 1

    attrs = prim["attributes"]
    if copies:
        p = read(attrs["POSITION"], np.float32, 3)
        attrs["POSITION"] = append(attrs["POSITION"], p[[c[0] for c in copies]], 34962)
        attrs["JOINTS_0"] = append(attrs["JOINTS_0"], np.array([c[1] for c in copies], np.uint16), 34962)
        attrs["WEIGHTS_0"] = append(attrs["WEIGHTS_0"], np.array([c[2] for c in copies], np.float32), 34962)
    assert doc["accessors"][prim["indices"]]["componentType"] == 5125
    prim["indices"] = append(prim["indices"], np.asarray(extra, dtype=np.uint32).reshape(-1, 1), 34963)
    doc["buffers"][0]["byteLength"] = len(binary)
    chunks[0] = (chunks[0][0], json.dumps(doc).encode())
    chunks[1] = (chunks[1][0], bytes(binary))
    src = tmp_path / name
    src.write_bytes(glb_join(chunks))
    return src


#: Two zero-area triangles of distinct, far-apart vertices (three consecutive rings of one column
#: of the tube are collinear), the kind an FBX2glTF export carried: weld cannot see them.
COLLINEAR = [(0 * SEG + 0, 1 * SEG + 0, 2 * SEG + 0), (3 * SEG + 5, 4 * SEG + 5, 5 * SEG + 5)]


#: Vertex 299 (the tube has 299): at vertex 40's position but bound to joint 3 alone (vertex 40
#: is not): weld keeps the two apart, so the triangle (40, 299, 41) keeps zero area after it.
COINCIDENT = [(40, (3, 0, 0, 0), (1.0, 0.0, 0.0, 0.0))]


def test_zero_area_glb_imports_counted_and_validates_clean(tmp_path):
    src = glb_with_triangles(tmp_path, "slivers.glb", COLLINEAR)
    out = tmp_path / "slivers.usda"
    r = colossus("import", src, "-o", out, "--json")
    assert r.exit_code == 0, r.output
    assert r.stderr == ""
    s = json.loads(r.stdout)
    assert s["degenerate_dropped"] == 2
    assert s["stages"]["degenerate"]["counts"]["dropped"] == 2
    assert s["stages"]["degenerate"]["counts"]["repeated_index"] == 0
    assert s["faces_in"] == s["faces_out"] + 2
    v = colossus("validate", out, "--source", src)
    assert v.exit_code == 0, v.output
    assert v.stdout.splitlines()[0] == f"{out}: PASS (0 errors, 0 warnings)"
    # the text summary says it too
    r = colossus("import", src, "-o", tmp_path / "again.usda")
    assert r.exit_code == 0, r.output
    line = next(ln for ln in r.stdout.splitlines() if ln.split()[:1] == ["degenerate"])
    assert "2 zero-area triangles dropped" in line
    assert "zero-area triangles dropped 2" in r.stdout


def test_proxy_is_tested_again(tmp_path):
    """A simplified proxy (its collapses move vertices) gets the test again: counted apart
    (``dropped_after_simplify``), and the proxy validates."""
    src = glb_with_triangles(tmp_path, "slivers.glb", COLLINEAR)
    out = tmp_path / "proxy.usda"
    r = colossus("import", src, "-o", out, "--target-faces", "300", "--json")
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    counts = s["stages"]["degenerate"]["counts"]
    assert counts["dropped"] == 2 and counts["dropped_after_simplify"] >= 0
    assert s["degenerate_dropped"] == 2 + counts["dropped_after_simplify"]
    assert s["faces_out"] <= 300
    v = colossus("validate", out)
    assert v.exit_code == 0, v.output


@pytest.mark.parametrize("option", [("--max-influences", "8"), ("--max-deviation", "2%")])
def test_check_takes_the_import_options(tmp_path, option):
    """The rules run with the options the import implies, as `validate` takes them: eight
    influences are the asset's elementSize (COL301 with the default 4 would refuse every such
    import); a proxy's stored deviation is held to --max-deviation (COL701)."""
    from paths import SAMPLES

    out = tmp_path / "limb.usda"
    r = colossus("import", SAMPLES / "limb.glb", "-o", out, *option)
    assert r.exit_code == 0, r.output
    v = colossus("validate", out, *option)
    assert v.exit_code == 0, v.output


def test_without_the_stage_the_asset_is_refused_before_the_rename(tmp_path, monkeypatch):
    """The same file with the stage switched off: the written asset fails COL204, so the import
    is refused by the check on the temporary file: exit 1, one line naming the rule, no output
    and no temporary file left."""
    import colossus.pipeline.run as run

    monkeypatch.setattr(run, "drop_degenerate", lambda m: (m, StageReport("degenerate", counts={
        "faces_in": m.face_count, "dropped": 0, "repeated_index": 0, "faces_out": m.face_count,
        "vertices_unreferenced": 0, "area_threshold": 0.0, "model_size": 1.0})))
    src = glb_with_triangles(tmp_path, "slivers.glb", COLLINEAR)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / "slivers.usda"
    r = colossus("import", src, "-o", out)
    assert r.exit_code == 1, r.output
    assert r.stdout == ""
    err = r.stderr.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith(f"error: {src}: COL204: 2 triangles have zero area"), err
    assert not out.exists() and os.listdir(out_dir) == []
    # the library call without a check writes it, and the validator rejects it: what the CLI prevents
    res = run.import_asset(src, out)
    assert res.summary()["degenerate_dropped"] == 0
    v = colossus("validate", out)
    assert v.exit_code == 1 and "COL204" in v.stdout


def test_a_flipped_asset_is_refused_with_its_rule(tmp_path, monkeypatch):
    """Any error rule refuses, not only COL204: with ``orient`` switched off, the flipped limb
    sample would be written with inconsistent winding (COL208)."""
    import colossus.pipeline.run as run
    from paths import SAMPLES

    monkeypatch.setattr(run, "orient", lambda m: (m, StageReport("orient", counts={
        "faces_flipped": 0, "shells": 1, "closed_shells": 1, "nonmanifold_edges": 0})))
    out = tmp_path / "flipped.usda"
    r = colossus("import", SAMPLES / "limb_flipped.glb", "-o", out)
    assert r.exit_code == 1, r.output
    err = r.stderr.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f"error: {SAMPLES / 'limb_flipped.glb'}: COL20"), err
    assert not out.exists() and os.listdir(tmp_path) == []


def test_batch_import_refuses_too(tmp_path, monkeypatch):
    import colossus.pipeline.run as run

    monkeypatch.setattr(run, "drop_degenerate", lambda m: (m, StageReport("degenerate", counts={
        "faces_in": m.face_count, "dropped": 0, "repeated_index": 0, "faces_out": m.face_count,
        "vertices_unreferenced": 0, "area_threshold": 0.0, "model_size": 1.0})))
    src = glb_with_triangles(tmp_path, "slivers.glb", COLLINEAR)
    out_dir = tmp_path / "out"
    r = colossus("import", src, tmp_path / "missing.glb", "-o", out_dir)
    assert r.exit_code == 1
    line = next(ln for ln in r.stderr.splitlines() if ln.startswith(f"error: {src}: "))
    assert "COL204: 2 triangles have zero area" in line, r.stderr
    assert os.listdir(out_dir) == []


def test_corners_weld_keeps_apart(tmp_path):
    """Two corners at one position with different skin weights (weld keeps them apart, rightly)
    make a zero-area triangle after weld; a triangle naming one vertex twice is weld's own
    (``degenerate_faces_removed``).  The stage drops the first; the asset validates."""
    import colossus.pipeline.run as run

    assert run.STAGES.index("degenerate") == run.STAGES.index("weld") + 1
    src = glb_with_triangles(tmp_path, "seam.glb", [(40, 299, 41), (7, 7, 8)], copies=COINCIDENT)
    out = tmp_path / "seam.usda"
    r = colossus("import", src, "-o", out, "--json")
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["vertices_in"] == 300 and s["faces_in"] == 596
    assert s["stages"]["weld"]["counts"]["degenerate_faces_removed"] == 1
    assert s["stages"]["weld"]["counts"]["weight_conflicts"] >= 1
    assert s["degenerate_dropped"] == 1 and s["faces_out"] == 594
    # the vertex only the dropped triangle used stays, unused (COL205 is a warning), as weld does
    assert s["stages"]["degenerate"]["counts"]["vertices_unreferenced"] == 1
    v = colossus("validate", out)
    assert v.exit_code == 0, v.output
    assert "COL205" in v.stdout and "COL204" not in v.stdout


# ---- the stage against the rule, in memory ------------------------------------------------
def _rule_flags(mesh, linear=None):
    """COL204's verdict on ``mesh`` as written: float32 points, model size of the bind points."""
    p = mesh.positions.astype(np.float32).astype(np.float64)
    g = mesh.geom_bind if linear is None else linear
    size = schema.bind_model_size(p @ g[:3, :3].T + g[:3, 3])
    return schema.zero_area_faces(p, mesh.triangles, g, size)


@pytest.mark.parametrize("far", [0.0, 1e4])
@pytest.mark.parametrize("root_scale", [1.0, 0.01, 3.0])
def test_stage_is_stricter_than_the_rule(far, root_scale):
    """Slivers of every height around the rule's threshold (in the plane x = 0, where float32 holds
    a tiny height exactly), with the rule applied as the asset stores it (the roots' scale moved
    onto the Skeleton: the map to the bind pose rounds differently; the skeleton far from the
    origin or not): whatever the stage keeps, the rule passes; the stage drops the slivers the rule
    would still pass up to its margin, and never a thicker one."""
    mesh = synth.make_tube()
    g = mesh.geom_bind.copy()
    g[:3, 3] += far
    pos = mesh.positions.astype(np.float64)
    size = schema.bind_model_size(pos.astype(np.float32).astype(np.float64) @ g[:3, :3].T + g[:3, 3])
    threshold = (schema.ZERO_AREA_RELATIVE * size) ** 2
    h = (4 * threshold * np.geomspace(1e-3, 1e3, 200)).astype(np.float32)  # area = h / 4
    n0 = len(pos)
    pts = np.zeros((3 * len(h), 3))
    pts[0::3] = (0.0, 1.0, 0.0)
    pts[1::3] = (0.0, 1.5, 0.0)
    pts[2::3, 0], pts[2::3, 1] = h, 1.25
    tris = n0 + np.arange(3 * len(h)).reshape(-1, 3)
    k = mesh.joint_indices.shape[1]
    ji = np.vstack([mesh.joint_indices, np.zeros((len(pts), k), np.int32)])
    jw = np.vstack([mesh.joint_weights, np.tile(np.eye(1, k, dtype=np.float32), (len(pts), 1))])
    mesh = mesh.replace(positions=np.vstack([pos, pts]).astype(np.float32), joint_indices=ji, joint_weights=jw,
                        triangles=np.vstack([mesh.triangles, tris]).astype(np.int32), geom_bind=g)
    assert schema.bind_model_size(mesh.positions.astype(np.float64) @ g[:3, :3].T + g[:3, 3]) == size
    out, rep = degenerate(mesh)
    # the asset: Skeleton scale k, geomBindTransform (1/k) @ g: their product rounds differently
    linear = np.diag([root_scale] * 3 + [1.0]) @ (np.diag([1 / root_scale] * 3 + [1.0]) @ g)
    assert not _rule_flags(out, linear).any()
    dropped = rep.counts["dropped"]
    area = h.astype(np.float64) / 4
    assert int(_rule_flags(mesh).sum()) == int((area <= threshold * (1 + 1e-9)).sum())
    limit = DEGENERATE_MARGIN ** 2 * threshold
    assert int((area < limit * (1 - 1e-9)).sum()) <= dropped <= int((area <= limit * (1 + 1e-9)).sum())
    assert int((area <= threshold * (1 + 1e-9)).sum()) < dropped < len(h)  # stricter, within its margin
    assert out.face_count == mesh.face_count - dropped
    assert rep.counts["vertices_unreferenced"] == 3 * dropped  # kept, as weld keeps them
    assert out.vertex_count == mesh.vertex_count


def test_repeated_index_and_everything_degenerate():
    from colossus.pipeline.errors import InputError

    mesh = synth.make_tube()
    t = mesh.triangles.copy()
    t[5] = (t[5, 0], t[5, 0], t[5, 1])
    out, rep = degenerate(mesh.replace(triangles=t))
    assert rep.counts["dropped"] == 1 and rep.counts["repeated_index"] == 1
    assert zero_area(out)[0].sum() == 0
    flat = mesh.replace(positions=mesh.positions * np.array([1, 1, 0], np.float32))
    flat = flat.replace(positions=flat.positions * np.array([0, 1, 0], np.float32))  # every point on a line
    with pytest.raises(InputError, match="every one of the .* triangles has zero area"):
        degenerate(flat)
