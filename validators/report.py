"""Reporters (after flake8's ``BaseFormatter``): every format renders the same list of
:class:`~validators.findings.AssetReport`."""

from __future__ import annotations

import json
import os
from xml.etree import ElementTree as ET

from .findings import SEVERITY_RANK, summary_line
from .registry import all_rules

__all__ = ["FORMATS", "render", "summary_line", "format_text", "format_json", "format_junit",
           "write_atomic"]


def render(fmt: str, reports, verbose: bool = False, unchecked=None) -> str:
    """The report of ``reports`` in ``fmt`` (a key of :data:`FORMATS`).  ``unchecked``: the paths
    not checked because the run was interrupted (a list, possibly empty; None for a complete run):
    every format then says the report is INCOMPLETE and lists them."""
    if fmt == "text":
        return format_text(reports, verbose=verbose, unchecked=unchecked)
    return FORMATS[fmt](reports, unchecked=unchecked)


def format_text(reports, verbose: bool = False, unchecked=None) -> str:
    """Grouped by asset; within an asset rules with errors first, each with its worst location;
    an interrupted run ends with ``INCOMPLETE: ...`` and the paths not checked."""
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
    if unchecked is not None:
        out.append(f"INCOMPLETE: interrupted; {len(unchecked)} asset(s) not checked")
        out += [f"  not checked: {p}" for p in unchecked]
    return "\n".join(out) + "\n"


def format_json(reports, unchecked=None) -> str:
    """The contract's shape: ``{"assets": [{"path", "passed", "findings": [...], "stats"}]}``, plus
    ``"incomplete": true, "not_checked": [paths]`` for an interrupted run."""
    doc = {"assets": [r.to_dict() for r in reports]}
    if unchecked is not None:
        doc.update(incomplete=True, not_checked=list(unchecked))
    return json.dumps(doc, indent=2, default=_jsonable) + "\n"


def _jsonable(o):
    try:
        return o.item()  # numpy scalars
    except AttributeError:
        return str(o)


def format_junit(reports, unchecked=None) -> str:
    """JUnit XML: one ``testsuite`` per asset, one ``testcase`` per rule that ran or was skipped.
    Error findings are ``<failure>``; a crashed rule (COL002) or an unreadable asset is an
    ``<error>``; warnings and info go to ``<system-out>``; a rule that could not run is
    ``<skipped>``.  An interrupted run has ``incomplete="true"`` on ``<testsuites>`` and a
    ``not checked (interrupted)`` suite with a skipped case per path not checked."""
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
    if unchecked is not None:
        suite = ET.SubElement(suites, "testsuite", name="not checked (interrupted)", tests=str(len(unchecked)),
                              failures="0", errors="0", skipped=str(len(unchecked)), time="0")
        for p in unchecked:
            case = ET.SubElement(suite, "testcase", classname=p, name="not checked", time="0")
            ET.SubElement(case, "skipped", message="the run was interrupted before this asset was checked")
        t_tests, t_skip = t_tests + len(unchecked), t_skip + len(unchecked)
    suites.set("tests", str(t_tests))
    suites.set("failures", str(t_fail))
    suites.set("errors", str(t_err))
    suites.set("skipped", str(t_skip))
    if unchecked is not None:
        suites.set("incomplete", "true")
    ET.indent(suites)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(suites, encoding="unicode") + "\n"


#: The text formats.  The HTML report draws pictures, so it lives a floor up
#: (:func:`colossus.render.html.format_html`, chosen by the command line).
FORMATS = {"text": format_text, "json": format_json, "junit": format_junit}


def write_atomic(path: str, text: str) -> None:
    """Write the report ``text`` to ``path`` atomically (:func:`colossus.pipeline.tempfiles.write_atomic`)."""
    from colossus.pipeline.tempfiles import write_atomic as _write

    _write(path, text)
