"""Reporters (after flake8's ``BaseFormatter``): every format renders the same list of
:class:`~validators.findings.AssetReport`."""

from __future__ import annotations

import json
import os
import tempfile
from xml.etree import ElementTree as ET

from .findings import SEVERITY_RANK
from .registry import all_rules


def summary_line(reports) -> str:
    n = len(reports)
    passed = sum(r.passed for r in reports)
    return f"{n} assets, {passed} passed, {n - passed} failed"


def format_text(reports, verbose: bool = False) -> str:
    """Grouped by asset; within an asset rules with errors first, each with its worst location."""
    out = []
    for r in reports:
        errors = sum(f.severity == "error" for f in r.findings)
        warnings = sum(f.severity == "warning" for f in r.findings)
        out.append(f"{r.path}: {'PASS' if r.passed else 'FAIL'} ({errors} errors, {warnings} warnings)")
        groups = {}
        for f in r.findings:
            groups.setdefault(f.code, []).append(f)
        for code, fs in sorted(groups.items(), key=lambda kv: (SEVERITY_RANK[kv[1][0].severity], kv[0])):
            worst = max(fs, key=lambda f: f.sort_key) if any(f.sort_key for f in fs) else fs[0]
            more = f" [{len(fs)} findings, worst shown]" if len(fs) > 1 else ""
            out.append(f"  {code} {worst.severity:<7} {worst.rule}: {worst.message}{more}")
            where = worst.where()
            if where:
                out.append(f"        at {where}")
            if verbose:
                for f in fs:
                    if f is not worst:
                        out.append(f"        also: {f.message}")
        fpp = r.stats.get("frameproof")
        if fpp:
            for c in fpp.get("checked", []):
                out.append(f"  checked: {c}")
            for c in fpp.get("not_checked", []):
                out.append(f"  not checked: {c}")
        by_reason = {}
        for code, why in sorted(r.skipped.items()):
            by_reason.setdefault(why, []).append(code)
        for why, codes in by_reason.items():
            out.append(f"  skipped {', '.join(codes)}: {why}")
    out.append(summary_line(reports))
    return "\n".join(out) + "\n"


def format_json(reports) -> str:
    """The contract's shape: ``{"assets": [{"path", "passed", "findings": [...], "stats"}]}``."""
    return json.dumps({"assets": [r.to_dict() for r in reports]}, indent=2, default=_jsonable) + "\n"


def _jsonable(o):
    try:
        return o.item()  # numpy scalars
    except AttributeError:
        return str(o)


def format_junit(reports) -> str:
    """JUnit XML: one ``testsuite`` per asset, one ``testcase`` per rule that ran or was skipped.
    Error findings are ``<failure>``; a crashed rule (COL002) or an unreadable asset is an
    ``<error>``; warnings and info go to ``<system-out>``; a rule that could not run is
    ``<skipped>``."""
    suites = ET.Element("testsuites", name="colossus validate")
    rules = {r.code: r for r in all_rules()}
    t_tests = t_fail = t_err = t_skip = 0
    for rep in reports:
        suite = ET.SubElement(suites, "testsuite", name=rep.path)
        by_code = {}
        for f in rep.findings:
            by_code.setdefault(f.code, []).append(f)
        codes = sorted(set(rep.rules_run) | set(by_code) | set(rep.skipped))
        tests = fails = errs = skips = 0
        for code in codes:
            name = f"{code} {rules[code].name}" if code in rules else code
            case = ET.SubElement(suite, "testcase", classname=rep.path, name=name)
            case.set("time", "0")
            tests += 1
            fs = by_code.get(code, [])
            bad = [f for f in fs if f.severity == "error"]
            if bad:
                text = "\n".join(f"{f.message} ({f.where()})" if f.where() else f.message for f in bad)
                tag = "error" if code in ("COL001", "COL002", "COL003") else "failure"
                el = ET.SubElement(case, tag, message=bad[0].message[:500], type=code)
                el.text = text
                if tag == "error":
                    errs += 1
                else:
                    fails += 1
            elif code in rep.skipped:
                ET.SubElement(case, "skipped", message=rep.skipped[code])
                skips += 1
            other = [f for f in fs if f.severity != "error"]
            if other:
                ET.SubElement(case, "system-out").text = "\n".join(f"{f.severity}: {f.message}" for f in other)
        suite.set("tests", str(tests))
        suite.set("failures", str(fails))
        suite.set("errors", str(errs))
        suite.set("skipped", str(skips))
        suite.set("time", str(rep.stats.get("seconds", 0)))
        t_tests, t_fail, t_err, t_skip = t_tests + tests, t_fail + fails, t_err + errs, t_skip + skips
    suites.set("tests", str(t_tests))
    suites.set("failures", str(t_fail))
    suites.set("errors", str(t_err))
    suites.set("skipped", str(t_skip))
    ET.indent(suites)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(suites, encoding="unicode") + "\n"


def format_html(reports) -> str:
    """One self-contained HTML page with pictures (:mod:`validators.htmlreport`)."""
    from .htmlreport import format_html as _html
    return _html(reports)


FORMATS = {"text": format_text, "json": format_json, "junit": format_junit, "html": format_html}


def write_atomic(path: str, text: str) -> None:
    """Write ``text`` to ``path`` via a temporary file in the same directory and a rename."""
    d = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".colossus-", suffix=".tmp", dir=d)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
