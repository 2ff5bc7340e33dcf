"""``colossus validate``: formats, exit status, many paths, jobs; and the rule catalog doc."""

from __future__ import annotations

import json
import os
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest
from click.testing import CliRunner

from references.usd_fixture import open_copy, write_test_asset
from colossus.cli.validate import validate_cmd

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    """A small library: good.usda, sub/slack.usdc (warning only), sub/bad.usda (error), corrupt.usd."""
    d = tmp_path_factory.mktemp("lib")
    good = write_test_asset(d / "good.usda")
    (d / "sub").mkdir()
    s = open_copy(good)
    a = s.GetPrimAtPath("/Tube/Collider").GetAttribute("colossus:parts:radii")
    a.Set([r * 3 for r in a.Get()])
    s.GetRootLayer().Export(str(d / "sub" / "slack.usdc"))
    s = open_copy(good)
    s.GetPrimAtPath("/Tube/bend").GetAttribute("translations").Set(
        [(0, 0, 0), (0, 1, 0), (0, 3, 0)], 10)
    s.GetRootLayer().Export(str(d / "sub" / "bad.usda"))
    (d / "corrupt.usd").write_bytes(b"\x00PXR-USDC" + os.urandom(300))
    (d / "notes.txt").write_text("not an asset")
    return d


def run(*args):
    return CliRunner().invoke(validate_cmd, [str(a) for a in args])


def test_exit_0_text_summary(lib):
    r = run(lib / "good.usda")
    assert r.exit_code == 0, r.output
    assert r.output.strip().splitlines()[-1] == "1 assets, 1 passed, 0 failed"
    assert "certified for every time in [first, last] of every clip" in r.output
    assert "not checked" not in r.output


def test_warning_only_passes(lib):
    r = run(lib / "sub" / "slack.usdc")
    assert r.exit_code == 0 and "COL404" in r.output


def test_directory_recursion_json_and_exit_1(lib):
    r = run(lib, "--format", "json")
    assert r.exit_code == 1
    data = json.loads(r.stdout)
    assert list(data) == ["version", "tool", "summary", "assets"]
    paths = [Path(a["path"]).name for a in data["assets"]]
    assert paths == ["corrupt.usd", "good.usda", "bad.usda", "slack.usdc"]
    by = {Path(a["path"]).name: a for a in data["assets"]}
    assert by["good.usda"]["passed"] and by["slack.usdc"]["passed"]
    assert [f["code"] for f in by["corrupt.usd"]["findings"]] == ["COL001"]
    bad = by["bad.usda"]
    assert not bad["passed"]
    f = next(f for f in bad["findings"] if f["code"] == "COL403")
    for key in ("clip", "time", "frame", "part", "joint", "vertex", "excess", "severity", "message"):
        assert key in f
    assert f["clip"] == "bend" and f["time"] == 10
    assert "frameproof" in bad["stats"]


def test_text_groups_errors_first_and_counts(lib):
    r = run(lib / "sub")
    assert r.exit_code == 1
    lines = r.output.splitlines()
    assert lines[-1] == "2 assets, 1 passed, 1 failed"
    bad_block = lines[lines.index(next(l for l in lines if l.endswith("FAIL (1 errors, 0 warnings)") or "bad.usda: FAIL" in l)):]
    assert "COL403 error" in bad_block[1]
    assert "at clip=bend time=10 frame=10" in bad_block[2]


def test_junit_is_valid_xml(lib, tmp_path):
    out = tmp_path / "report.xml"
    r = run(lib / "good.usda", lib / "sub" / "bad.usda", lib / "corrupt.usd", "--format", "junit", "-o", out)
    assert r.exit_code == 1 and r.stdout == ""
    root = ET.parse(out).getroot()
    assert root.tag == "testsuites"
    suites = root.findall("testsuite")
    assert len(suites) == 3
    good, bad, corrupt = suites
    assert good.get("failures") == "0" and int(good.get("tests")) > 30
    assert bad.get("failures") == "1"
    case = next(c for c in bad.findall("testcase") if c.get("name").startswith("COL403"))
    assert case.find("failure") is not None
    assert corrupt.find("testcase/error") is not None
    assert int(root.get("tests")) == sum(int(s.get("tests")) for s in suites)
    assert not list(tmp_path.glob(".colossus-*"))  # atomic write left no temp file


def test_missing_path_exit_2_others_still_checked(lib):
    r = run(lib / "good.usda", lib / "nope.usda", "--format", "json")
    assert r.exit_code == 2
    data = json.loads(r.stdout)
    assert [a["passed"] for a in data["assets"]] == [True, False]
    assert data["assets"][1]["findings"][0]["code"] == "COL003"
    assert "nope.usda" in r.stderr


def test_usage_errors_exit_2(lib):
    assert run().exit_code == 2
    assert run(lib / "good.usda", "--select", "COL9").exit_code == 2
    assert run(lib / "good.usda", "--format", "xml").exit_code == 2
    assert run(lib / "good.usda", "--severity", "COL404=fatal").exit_code == 2


def test_select_ignore_and_severity(lib):
    p = lib / "sub" / "bad.usda"
    assert run(p, "--ignore", "COL403").exit_code == 0
    assert run(p, "--select", "COL4", "--ignore", "COL40").exit_code == 0
    assert run(p, "--select", "COL1,COL2").exit_code == 0
    assert run(lib / "sub" / "slack.usdc", "--severity", "COL404=error").exit_code == 1


def test_list_rules():
    r = run("--list-rules")
    assert r.exit_code == 0
    assert "COL403" in r.output and "holds-on-all-frames" in r.output
    assert len(r.output.splitlines()) >= 45


def test_jobs_in_parallel_processes(lib):
    r = run(lib, "--jobs", "2", "--format", "json", "--max-influences", "4", "--subframes", "1")
    assert r.exit_code == 1
    data = json.loads(r.stdout)
    assert [Path(a["path"]).name for a in data["assets"]] == ["corrupt.usd", "good.usda", "bad.usda", "slack.usdc"]
    good = data["assets"][1]
    assert good["stats"]["frameproof"]["subframe_times"] == 23 + 11


def test_rules_doc_is_current():
    from colossus.validators.catalog import render
    doc = (ROOT / "docs" / "rules.md").read_text()
    assert doc == render(), "docs/rules.md is stale: run `python -m colossus.validators.catalog > docs/rules.md`"


def test_every_rule_has_what_why_example():
    from colossus.validators import all_rules
    for r in all_rules():
        for label in ("What:", "Why:", "Example:"):
            assert label in r.doc, (r.code, label)
        assert r.summary and r.name and r.severity in ("error", "warning", "info")


@pytest.mark.parametrize("where", ["sys", "missing-folder"])
def test_unwritable_report_is_exit_2_before_any_check(lib, tmp_path, where):
    """``-o`` where nothing can be written (a read-only or permission-less filesystem: /sys for
    root too; a folder that does not exist) is the environment, not the
    assets: exit 2, one line naming the report, nothing written, no "internal error"."""
    out = {"sys": "/sys/colossus-report.json", "missing-folder": str(tmp_path / "no" / "r.json")}[where]
    r = CliRunner().invoke(validate_cmd, [str(lib / "good.usda"), "--format", "json", "-o", out])
    assert r.exit_code == 2, r.output
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: cannot write the report {out}: "), r.stderr
    assert r.stdout == "" and not os.path.exists("/sys/colossus-report.json")
