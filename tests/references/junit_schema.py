"""The common JUnit schema's structure, for the report tests (no schema file is vendored)."""

from __future__ import annotations

import re
from xml.etree import ElementTree as ET

# The common JUnit schema (junit-10.xsd, as Jenkins' xUnit plugin validates JUnit reports, GitLab
# and Azure DevOps read the same shape), written out as its structure: per element the
# attributes it allows, those it requires, and the children it allows (no schema file is vendored).
JUNIT = {
    "testsuites": ({"name", "time", "tests", "failures", "errors"}, set(), {"testsuite"}),
    "testsuite": ({"name", "tests", "failures", "errors", "group", "time", "skipped", "timestamp", "hostname",
                   "id", "package", "file", "log", "url"}, {"name", "tests", "failures", "errors"},
                  {"testsuite", "properties", "testcase", "system-out", "system-err"}),
    "properties": (set(), set(), {"property"}),
    "property": ({"name", "value"}, {"name", "value"}, set()),
    "testcase": ({"name", "time", "classname", "group"}, {"name"},
                 {"skipped", "error", "failure", "rerunFailure", "rerunError", "flakyFailure", "flakyError",
                  "system-out", "system-err"}),
    "failure": ({"type", "message"}, set(), set()),
    "error": ({"type", "message"}, set(), set()),
    "skipped": ({"type", "message"}, set(), set()),
    "system-out": (set(), set(), set()),
    "system-err": (set(), set(), set()),
}
#: junit-10.xsd's SUREFIRE_TIME, the type of ``time`` on testsuites and testsuite
SUREFIRE_TIME = re.compile(r"^(([0-9]{0,3},)*[0-9]{3}|[0-9]{0,3})*(\.[0-9]*)?$")


def junit_errors(xml: str) -> list:
    root = ET.fromstring(xml)
    errs = []
    if root.tag != "testsuites":
        errs.append(f"root is {root.tag}")

    def walk(el, path):
        allowed, required, children = JUNIT.get(el.tag, (None, None, None))
        if allowed is None:
            errs.append(f"{path}: unknown element")
            return
        errs.extend(f"{path}: attribute {a!r} not allowed" for a in set(el.attrib) - allowed)
        errs.extend(f"{path}: attribute {a!r} missing" for a in required - set(el.attrib))
        if el.tag in ("testsuites", "testsuite") and "time" in el.attrib and not SUREFIRE_TIME.match(el.get("time")):
            errs.append(f"{path}: time {el.get('time')!r} is not a SUREFIRE_TIME")
        for c in el:
            if c.tag not in children:
                errs.append(f"{path}: child {c.tag} not allowed")
            walk(c, f"{path}/{c.tag}")

    walk(root, "/testsuites")
    return errs
