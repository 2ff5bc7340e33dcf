"""Many inputs, --jobs, --scheduler (Dask LocalCluster): same reports as --jobs 1, no result
lost when a worker dies, Ctrl-C leaves a partial report marked incomplete."""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
from click.testing import CliRunner

from colossus.pipeline.batch import output_names
from colossus.pipeline.engine import expand_inputs, local_cluster
from references.usd_fixture import open_copy

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "samples"


def needs_dask():
    """Skip (only) the tests that drive a Dask cluster when the [dask] extra is absent; CI
    installs it (Makefile: .[test,bench,dask]), so there nothing is skipped."""
    pytest.importorskip("distributed")


def _scale_radii(src, dst, factor):
    s = open_copy(src)
    attr = next(a for p in s.Traverse() for a in p.GetAttributes() if a.GetName() == "colossus:parts:radii")
    attr.Set([r * factor for r in attr.Get()])
    s.GetRootLayer().Export(str(dst))


@pytest.fixture(scope="module")
def lib(tmp_path_factory, imported):
    """Imported samples, copies with shrunk (COL403) and grown (COL404) part radii, a few
    generated 3-clip assets, a corrupt file, in two directories."""
    from colossus.bench.validate import make_library
    d = tmp_path_factory.mktemp("scale")
    (d / "b").mkdir()
    for name, ext in (("creature", "glb"), ("limb", "glb"), ("limb_flipped", "glb"), ("creature", "fbx")):
        _, out = imported(name, ext)
        shutil.copy(out, d / f"{name}-{ext}.usda")
    _scale_radii(d / "creature-glb.usda", d / "b" / "creature-shrunk.usda", 0.9)
    _scale_radii(d / "limb-glb.usda", d / "b" / "limb-shrunk.usdc", 0.8)
    _scale_radii(d / "limb-glb.usda", d / "b" / "limb-slack.usda", 3.0)
    make_library(d / "gen", count=3, triangles=2000, bones=6, clips=3, frames=12)
    (d / "b" / "corrupt.usd").write_bytes(b"\x00PXR-USDC" + os.urandom(200))
    return d


@pytest.fixture(scope="module")
def cluster():
    """A 2-worker LocalCluster; its workers can import the tests' fault injectors (``faults``,
    which die on assets named *crashme* always and on *crashonce* the first time)."""
    needs_dask()
    c = local_cluster(2, env={"PYTHONPATH": str(ROOT / "tests")})
    yield c
    c.close()


def validate(*args):
    from colossus.cli.validate import validate_cmd
    return CliRunner().invoke(validate_cmd, [str(a) for a in args])


def strip_times(report_json):
    data = json.loads(report_json)
    for a in data["assets"]:
        a["stats"].pop("seconds", None)
        a["stats"].pop("load_seconds", None)
        a["stats"].get("frameproof", {}).pop("seconds", None)
    return data


def strip_junit_times(xml):
    root = ET.fromstring(xml.split("\n", 1)[1])
    for el in root.iter():
        el.attrib.pop("time", None)
    return ET.tostring(root, encoding="unicode")


@pytest.fixture(scope="module")
def reference(lib):
    """--jobs 1 reports of the library: json, text, junit."""
    out = {}
    for fmt in ("json", "text", "junit"):
        r = validate(lib, "--format", fmt, "--subframes", "1")
        assert r.exit_code == 1, r.output  # corrupt.usd and the shrunk ones fail
        out[fmt] = r.stdout
    return out


# ------------------------------------------------------------------------------ units
def test_output_names_predictable_and_collision_free():
    srcs = ["x/boss.glb", "x/boss.fbx", "x/limb.glb", "a/tail.glb", "b/tail.glb"]
    names = output_names(srcs)
    assert names == ["boss.glb.usda", "boss.fbx.usda", "limb.usda", "a_tail.glb.usda", "b_tail.glb.usda"]
    assert output_names(list(reversed(srcs))) == list(reversed(names))  # independent of order


def test_expand_inputs_dirs_globs_missing(lib):
    files, missing = expand_inputs([lib / "b", str(lib / "gen" / "*.usda"), str(lib / "zz*.usda"), lib / "nope"],
                                   (".usd", ".usda", ".usdc"))
    names = [Path(f).name for f in files]
    assert names == ["corrupt.usd", "creature-shrunk.usda", "limb-shrunk.usdc", "limb-slack.usda",
                     "asset0000.usda", "asset0001.usda", "asset0002.usda"]
    assert [Path(m).name for m in missing] == ["zz*.usda", "nope"]


# ------------------------------------------------------------------------------ same reports
def test_cluster_gives_the_same_report_as_jobs_1(lib, cluster, reference):
    addr = cluster.scheduler_address
    # --split-above 0: every provable asset with 2+ clips is proven one clip per task, then merged
    for fmt in ("json", "text", "junit"):
        r = validate(lib, "--format", fmt, "--subframes", "1", "--scheduler", addr, "--split-above", "0")
        assert r.exit_code == 1, r.output
        if fmt == "json":
            got = strip_times(r.stdout)
            assert got == strip_times(reference["json"])
            paths = [a["path"] for a in got["assets"]]
            assert paths == sorted(paths) and len(paths) == 11  # a directory: sorted by path
            by = {Path(a["path"]).name: a for a in got["assets"]}
            assert "COL403" in {f["code"] for f in by["creature-shrunk.usda"]["findings"]}
            assert not by["limb-shrunk.usdc"]["passed"] and by["limb-slack.usda"]["passed"]
            assert by["asset0000.usda"]["stats"]["frameproof"]["subframe_times"] == 3 * 11
        elif fmt == "junit":
            assert strip_junit_times(r.stdout) == strip_junit_times(reference["junit"])
        else:
            assert r.stdout == reference["text"]
    from colossus.validators.parallel import check_many, comparable
    res = check_many([lib], scheduler=addr, split_bytes=0, subframes=1)
    assert [Path(p).name for p in res.split] == ["creature-shrunk.usda", "creature-fbx.usda", "creature-glb.usda",
                                                 "asset0000.usda", "asset0001.usda", "asset0002.usda"]
    assert comparable(res.reports) == strip_times(reference["json"])["assets"]


@pytest.mark.parametrize("fmt", ["json", "text", "junit"])
def test_jobs_2_gives_the_same_report_as_jobs_1(lib, reference, fmt):
    r = validate(lib, "--format", fmt, "--subframes", "1", "--jobs", "2", "--split-above", "0")
    assert r.exit_code == 1, r.output  # corrupt.usd and the shrunk ones fail, as with --jobs 1
    if fmt == "json":
        got = strip_times(r.stdout)
        assert got == strip_times(reference["json"])
        failed = sorted(Path(a["path"]).name for a in got["assets"] if not a["passed"])
        assert len(got["assets"]) == 11
        assert {"corrupt.usd", "creature-shrunk.usda", "limb-shrunk.usdc"} <= set(failed), failed
        assert not [n for n in failed if n.endswith(("-glb.usda", "-fbx.usda", "-slack.usda"))], failed
    elif fmt == "junit":
        assert strip_junit_times(r.stdout) == strip_junit_times(reference["junit"])
    else:
        assert r.stdout == reference["text"]


# ------------------------------------------------------------------------------ faults
@pytest.fixture()
def crashlib(lib, tmp_path):
    """Part of the library plus an asset that kills its worker every time and one that kills it
    once (a retry succeeds)."""
    d = tmp_path / "crash"
    d.mkdir()
    for f in ("limb-glb.usda", "limb_flipped-glb.usda", "b/limb-shrunk.usdc", "gen/asset0000.usda", "gen/asset0001.usda"):
        shutil.copy(lib / f, d / Path(f).name)
    shutil.copy(lib / "limb-glb.usda", d / "crashme.usda")
    shutil.copy(lib / "gen" / "asset0002.usda", d / "crashonce.usda")
    return d


def _check_crash_report(d, stdout):
    got = strip_times(stdout)
    ref = strip_times(validate(d, "--format", "json").stdout)  # --jobs 1: the hook never fires in-process
    names = [Path(a["path"]).name for a in got["assets"]]
    assert names == [Path(a["path"]).name for a in ref["assets"]]
    for a, b in zip(got["assets"], ref["assets"]):
        if Path(a["path"]).name == "crashme.usda":
            assert not a["passed"]
            assert [f["code"] for f in a["findings"]] == ["COL001"]
            assert "died twice" in a["findings"][0]["message"]
        else:  # every other result kept, the crash-once asset included (its retry succeeded)
            assert a == b


def _dying_units(monkeypatch):
    """The validators' work units replaced by ones that kill their worker (tests/faults.py)."""
    import faults
    from colossus.validators import parallel
    for name, fn in faults.WORKER_UNITS.items():
        monkeypatch.setattr(parallel, name, fn)


def test_cluster_worker_death_retried_once_then_a_finding(crashlib, cluster, monkeypatch):
    _dying_units(monkeypatch)
    r = validate(crashlib, "--format", "json", "--scheduler", cluster.scheduler_address, "--split-above", "0")
    assert r.exit_code == 1, r.output
    _check_crash_report(crashlib, r.stdout)
    assert (crashlib / "crashonce.usda.crashed").exists()


def test_process_pool_worker_death_retried_once_then_a_finding(crashlib, monkeypatch):
    _dying_units(monkeypatch)
    r = validate(crashlib, "--format", "json", "--jobs", "2")
    assert r.exit_code == 1, r.output
    _check_crash_report(crashlib, r.stdout)


def test_ctrl_c_writes_partial_report_marked_incomplete(lib, tmp_path, monkeypatch):
    import colossus.validators.parallel as par
    real, seen = par.unit_check, []

    def interrupted_on_third(path, kw):
        seen.append(path)
        if len(seen) == 3:
            raise KeyboardInterrupt
        return real(path, kw)
    monkeypatch.setattr(par, "unit_check", interrupted_on_third)
    out = tmp_path / "report.json"
    r = validate(lib / "b", "--format", "json", "-o", out)
    assert r.exit_code == 130
    assert "INCOMPLETE" in r.stderr
    data = json.loads(out.read_text())
    assert data["incomplete"] is True
    assert [Path(a["path"]).name for a in data["assets"]] == ["corrupt.usd", "creature-shrunk.usda"]
    assert [Path(p).name for p in data["not_checked"]] == ["limb-shrunk.usdc", "limb-slack.usda"]
    seen.clear()
    r = validate(lib / "b", "--format", "junit")
    assert r.exit_code == 130
    root = ET.fromstring(r.stdout.split("\n", 1)[1])
    last = root.findall("testsuite")[-1]  # the schema allows no "incomplete" attribute on <testsuites>
    assert last.get("name") == "not checked (interrupted)"
    assert last.find("properties/property").attrib == {"name": "incomplete", "value": "true"}
    seen.clear()
    r = validate(lib / "b")
    assert r.exit_code == 130 and "INCOMPLETE: interrupted; 2 asset(s) not checked" in r.stdout


# ------------------------------------------------------------------------------ import
def import_cli(*args):
    from colossus.cli.import_ import import_cmd
    return CliRunner().invoke(import_cmd, [str(a) for a in args])


def test_import_many_jobs_2(tmp_path):
    srcs = [SAMPLES / "limb.glb", SAMPLES / "limb.fbx", SAMPLES / "limb_flipped.glb"]
    r = import_cli(*srcs, "-o", tmp_path / "j2", "--jobs", "2")
    assert r.exit_code == 0, r.output
    names = sorted(p.name for p in (tmp_path / "j2").iterdir())
    assert names == ["limb.fbx.usda", "limb.glb.usda", "limb_flipped.usda"]
    assert r.stdout.splitlines()[-1] == "3 inputs, 3 imported, 0 failed"


def test_import_many_cluster(tmp_path, cluster):
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"glTF garbage")
    r = import_cli(str(SAMPLES / "limb*.glb"), bad, "-o", tmp_path / "dask", "--scheduler",
                   cluster.scheduler_address, "--json")
    assert r.exit_code == 1, r.output
    rows = json.loads(r.stdout)["imports"]
    assert [(Path(x["source"]).name, x["ok"]) for x in rows] == [("limb.glb", True), ("limb_flipped.glb", True),
                                                                 ("bad.glb", False)]
    assert sorted(p.name for p in (tmp_path / "dask").iterdir()) == ["limb.usda", "limb_flipped.usda"]
    assert "bad.glb" in r.stderr


def test_import_many_output_must_be_a_directory(tmp_path):
    r = import_cli(SAMPLES / "limb.glb", SAMPLES / "limb.fbx", "-o", tmp_path / "x.usda")
    assert r.exit_code == 2 and "directory" in r.stderr


def test_unreachable_scheduler_exit_2(lib, monkeypatch):
    needs_dask()
    t0 = time.perf_counter()
    monkeypatch.setattr("colossus.pipeline.engine.CONNECT_TIMEOUT", 2.0)
    r = validate(lib / "limb-glb.usda", "--scheduler", "tcp://127.0.0.1:9")
    assert r.exit_code == 2 and "cannot reach the Dask scheduler" in r.stderr
    assert time.perf_counter() - t0 < 20


def test_import_many_ctrl_c_marks_incomplete(tmp_path, monkeypatch):
    import colossus.pipeline.batch as batch
    real = batch._import_unit

    def interrupted_on_second(src, out, settings, *rest):
        if "limb.fbx" in src:
            raise KeyboardInterrupt
        return real(src, out, settings, *rest)
    monkeypatch.setattr(batch, "_import_unit", interrupted_on_second)
    r = import_cli(SAMPLES / "limb.glb", SAMPLES / "limb.fbx", "-o", tmp_path, "--json")
    assert r.exit_code == 130
    doc = json.loads(r.stdout)
    assert doc["incomplete"] is True
    assert [x["ok"] for x in doc["imports"]] == [True, None]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["limb.glb.usda"]
