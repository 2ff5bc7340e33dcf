"""Reporters (after flake8's ``BaseFormatter``): every format renders the same list of
:class:`~validators.findings.AssetReport`."""

from __future__ import annotations

import json
import os
from xml.etree import ElementTree as ET

from .findings import SEVERITY_RANK, summary_line
from .registry import all_rules

__all__ = ["FORMATS", "render", "summary_line", "summary_counts", "format_text", "format_json", "format_junit",
           "format_sarif", "format_github", "github_escape_data", "github_escape_property", "write_atomic",
           "JSON_REPORT_VERSION"]

#: Version of the JSON report's shape (``"version"``; its JSON Schema: ``docs/report-schema.json``).
#: Adding a field keeps it; removing or renaming one raises it.
JSON_REPORT_VERSION = 1


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
            prim = worst.prim_path
            if where or prim != "/":
                out.append(f"        at {where + ' ' if where else ''}(prim {prim})")
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


def summary_counts(reports, unchecked=None) -> dict:
    """Counts over a run: assets (checked), passed, failed, not checked, and findings by severity."""
    sev = {s: 0 for s in ("error", "warning", "info")}
    for r in reports:
        for f in r.findings:
            sev[f.severity] = sev.get(f.severity, 0) + 1
    passed = sum(r.passed for r in reports)
    return {"assets": len(reports), "passed": passed, "failed": len(reports) - passed,
            "not_checked": len(unchecked or ()), "errors": sev["error"], "warnings": sev["warning"],
            "info": sev["info"]}


def format_json(reports, unchecked=None) -> str:
    """The contract's shape: ``{"assets": [{"path", "passed", "findings": [...], "stats"}]}``, plus
    ``"version"`` (:data:`JSON_REPORT_VERSION`), ``"tool"``, ``"summary"`` (:func:`summary_counts`),
    and ``"incomplete": true, "not_checked": [paths]`` for an interrupted run.  Every finding has a
    ``"prim"``.  Its JSON Schema: ``docs/report-schema.json``."""
    from colossus._version import __version__

    doc = {"version": JSON_REPORT_VERSION, "tool": {"name": "colossus", "version": __version__},
           "summary": summary_counts(reports, unchecked), "assets": [r.to_dict() for r in reports]}
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
    ``<skipped>``.  An interrupted run has a ``not checked (interrupted)`` suite with the property
    ``incomplete=true`` and a skipped case per path not checked.

    The document keeps to the common JUnit schema (the ``junit-10.xsd`` that Jenkins' xUnit plugin
    validates with, which GitLab and Azure DevOps also read): only ``name``, ``tests``, ``failures``,
    ``errors`` and ``time`` on ``<testsuites>``, times as plain decimals."""
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
        suite.set("time", _seconds(rep.stats.get("seconds", 0)))
        t_tests, t_fail, t_err, t_skip = t_tests + tests, t_fail + fails, t_err + errs, t_skip + skips
    if unchecked is not None:
        suite = ET.SubElement(suites, "testsuite", name="not checked (interrupted)", tests=str(len(unchecked)),
                              failures="0", errors="0", skipped=str(len(unchecked)), time="0")
        props = ET.SubElement(suite, "properties")
        ET.SubElement(props, "property", name="incomplete", value="true")
        for p in unchecked:
            case = ET.SubElement(suite, "testcase", classname=p, name="not checked", time="0")
            ET.SubElement(case, "skipped", message="the run was interrupted before this asset was checked")
        t_tests, t_skip = t_tests + len(unchecked), t_skip + len(unchecked)
    # <testsuites> carries only what the common JUnit schema allows there (name, tests, failures,
    # errors, time): the skipped count is on each <testsuite>, and an interrupted run says so in
    # its "not checked (interrupted)" suite's <properties>.
    suites.set("tests", str(t_tests))
    suites.set("failures", str(t_fail))
    suites.set("errors", str(t_err))
    suites.set("time", _seconds(sum(float(r.stats.get("seconds", 0) or 0) for r in reports)))
    ET.indent(suites)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(suites, encoding="unicode") + "\n"


def _seconds(value) -> str:
    """A JUnit ``time``: a plain decimal (the schema's pattern has no exponent, no sign, no nan)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = 0.0
    return f"{v:.3f}" if v == v and 0 <= v < float("inf") else "0.000"


#: SARIF ``level`` of each severity.
SARIF_LEVEL = {"error": "error", "warning": "warning", "info": "note"}
SARIF_SCHEMA = "https://docs.oasis-open.org/sarif/sarif/v2.1.0/errata01/os/schemas/sarif-schema-2.1.0.json"


def _artifact_uri(path: str, base: str) -> tuple:
    """``(uri, uriBaseId or None)``: ``path`` relative to ``base`` (forward slashes, percent-encoded)
    when it lies under it, else an absolute ``file:`` URI."""
    from pathlib import Path
    from urllib.parse import quote

    p = Path(os.path.abspath(path))
    try:
        rel = p.relative_to(os.path.abspath(base))
        return quote(rel.as_posix()), "SRCROOT"
    except ValueError:
        return p.as_uri(), None


def _rule_help(rule) -> tuple:
    """(text, markdown) help of a rule from its catalog docstring (What / Why / Example)."""
    import re

    doc = re.sub(r"\n\s+", " ", rule.doc or "")
    lines = []
    for label in ("What", "Why", "Example"):
        m = re.search(rf"{label}:\s*(.*?)(?=\s+(?:What|Why|Example):|$)", doc, re.S)
        if m:
            lines.append((label, m.group(1).strip()))
    if not lines:
        return rule.summary, rule.summary
    text = "\n".join(f"{label}: {body}" for label, body in lines)
    md = "\n".join(f"- *{label}:* {body}" for label, body in lines)
    return text, md


def format_sarif(reports, unchecked=None, base: str | None = None) -> str:
    """SARIF 2.1.0 (GitHub code scanning, Azure DevOps, GitLab via converters): one run, one
    ``reportingDescriptor`` per rule code in the catalog (its summary, its What / Why / Example
    help, its default level), one result per finding with the asset as the artifact location
    (relative to ``base``, default the working directory, through the ``SRCROOT`` base id) and
    the finding's USD prim path as a logical location; the location fields (clip, frame, part
    ...) go to the result's ``properties``.  An interrupted run is an unsuccessful invocation
    with one notification per asset not checked."""
    from colossus._version import __version__

    base = os.getcwd() if base is None else base
    rules = all_rules(include_removed=True)
    index = {r.code: i for i, r in enumerate(rules)}
    descriptors = []
    for r in rules:
        text, md = _rule_help(r)
        d = {"id": r.code, "name": r.name, "shortDescription": {"text": r.summary},
             "fullDescription": {"text": text}, "help": {"text": text, "markdown": md},
             "defaultConfiguration": {"level": SARIF_LEVEL[r.severity], "enabled": not r.removed},
             "properties": {"tags": ["colossus", r.family]}}
        descriptors.append(d)
    results, artifacts, art_index = [], [], {}
    for rep in reports:
        uri, base_id = _artifact_uri(rep.path, base)
        if rep.path not in art_index:
            art_index[rep.path] = len(artifacts)
            loc = {"uri": uri, **({"uriBaseId": base_id} if base_id else {})}
            artifacts.append({"location": loc, "roles": ["analysisTarget"]})
        for f in rep.findings:
            res = {"ruleId": f.code, "level": SARIF_LEVEL.get(f.severity, "warning"),
                   "message": {"text": f.message},
                   "locations": [{
                       "physicalLocation": {"artifactLocation": {
                           "uri": uri, **({"uriBaseId": base_id} if base_id else {}),
                           "index": art_index[rep.path]}},
                       "logicalLocations": [{"fullyQualifiedName": f.prim_path,
                                             "name": f.prim_path.rsplit("/", 1)[-1] or "/",
                                             "kind": "element"}]}]}
            if f.code in index:
                res["ruleIndex"] = index[f.code]
            props = {k: v for k, v in f.to_dict().items() if k not in ("code", "severity", "message", "rule")}
            if props:
                res["properties"] = json.loads(json.dumps(props, default=_jsonable))
            results.append(res)
    invocation = {"executionSuccessful": unchecked is None}
    if unchecked:
        invocation["toolExecutionNotifications"] = [
            {"level": "error", "message": {"text": f"not checked (interrupted): {p}"}} for p in unchecked]
    run = {"tool": {"driver": {"name": "colossus", "version": __version__, "semanticVersion": __version__,
                               "rules": descriptors}},
           "originalUriBaseIds": {"SRCROOT": {"uri": _dir_uri(base)}},
           "artifacts": artifacts, "invocations": [invocation], "results": results,
           "columnKind": "unicodeCodePoints"}
    doc = {"$schema": SARIF_SCHEMA, "version": "2.1.0", "runs": [run]}
    return json.dumps(doc, indent=2, default=_jsonable) + "\n"


def _dir_uri(folder: str) -> str:
    """``folder`` as a ``file:`` URI ending in ``/`` (SARIF's rule for a base URI)."""
    from pathlib import Path

    uri = Path(os.path.abspath(folder)).as_uri()
    return uri if uri.endswith("/") else uri + "/"


def github_escape_data(text: str) -> str:
    """A workflow command's message, escaped as GitHub's toolkit does (``escapeData``)."""
    return str(text).replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")


def github_escape_property(text: str) -> str:
    """A workflow command's property value (``escapeProperty``): also ``:`` and ``,``."""
    return github_escape_data(text).replace(":", "%3A").replace(",", "%2C")


#: Workflow command of each severity.
GITHUB_COMMAND = {"error": "error", "warning": "warning", "info": "notice"}


def format_github(reports, unchecked=None, base: str | None = None) -> str:
    """GitHub Actions workflow commands: per asset and rule, one annotation
    ``::error file=<asset>,title=<CODE> <rule>::<message> (at ... prim ...)`` for its worst
    finding (``::warning`` for warnings, ``::notice`` for info; the count when there are more),
    the file relative to ``base`` (default the working directory); then the summary line.
    Messages and properties are escaped as GitHub's toolkit does (``%``, CR and LF everywhere;
    also ``:`` and ``,`` in properties)."""
    base = os.getcwd() if base is None else base
    out = []
    for r in reports:
        p = os.path.abspath(r.path)
        rel = os.path.relpath(p, os.path.abspath(base))
        shown = rel if not rel.startswith("..") else p
        groups = {}
        for f in r.findings:
            groups.setdefault(f.code, []).append(f)
        for code, fs in sorted(groups.items(), key=lambda kv: (SEVERITY_RANK[kv[1][0].severity], kv[0])):
            worst = max(fs, key=lambda f: f.sort_key) if any(f.sort_key for f in fs) else fs[0]
            where = worst.where()
            msg = worst.message + f" (at {where + ' ' if where else ''}prim {worst.prim_path})"
            if len(fs) > 1:
                msg += f" [{len(fs)} findings, worst shown]"
            cmd = GITHUB_COMMAND.get(worst.severity, "warning")
            title = f"{code} {worst.rule}".strip()
            out.append(f"::{cmd} file={github_escape_property(shown)},title={github_escape_property(title)}::{github_escape_data(msg)}")
    out.append(summary_line(reports))
    if unchecked is not None:
        out.append(f"::error title={github_escape_property('colossus validate')}::"
                   + github_escape_data(f"INCOMPLETE: interrupted; {len(unchecked)} asset(s) not checked"))
    return "\n".join(out) + "\n"


#: The text formats.  The HTML report draws pictures, so it lives a floor up
#: (:func:`colossus.render.html.format_html`, chosen by the command line).
FORMATS = {"text": format_text, "json": format_json, "junit": format_junit, "sarif": format_sarif,
           "github": format_github}


def write_atomic(path: str, text: str) -> None:
    """Write the report ``text`` to ``path`` atomically (:func:`colossus.pipeline.tempfiles.write_atomic`)."""
    from colossus.pipeline.tempfiles import write_atomic as _write

    _write(path, text)
