"""``colossus build``, ``colossus check`` and ``colossus config``: the data-driven pipeline over the
project file (:mod:`colossus.cli.project`).

* ``build [ASSET...]`` imports the entries whose build key changed (source bytes and the files it
  pulls in, resolved settings, importer version), skipping and counting the others; ``--jobs`` /
  ``--scheduler`` like ``import``; one failed entry never stops the others.  Exit 0 all built or
  up to date, 1 any failed, 2 a bad project file or usage.
* ``check``: the CI gate.  Every output exists and is up to date (else ``stale: source changed``
  and/or ``settings changed`` / ``importer version changed``), and passes ``validate`` with the
  project's rules (``--deep``: also against its source, ``validate --source``).  Exit 0 all up to
  date and passing, 1 any missing, stale or failing, 2 a bad project file or usage.
* ``config``: the resolved settings of every entry.
"""

from __future__ import annotations

import json
import os
import sys
import time

import click

from colossus.cli._errors import CommandError, interrupted_status, maps_errors

config_option = click.option("--config", "config", type=click.Path(dir_okay=False), default=None, metavar="FILE",
                             help="The project file (default: colossus.toml, or pyproject.toml with "
                                  "[tool.colossus], found walking up from the working directory).")


set_option = click.option("--set", "sets", multiple=True, metavar="KEY=VALUE",
                          help="Override the project file for this run (wins over [import], [validate] and the "
                               "entries): an import option (max-influences=2) or validate.NAME (validate.subframes=2).")


def _load(config, sets=()):
    from colossus.cli.project import ProjectError, load_project, parse_overrides

    overrides = parse_overrides(sets)  # a malformed --set: UsageError, exit 2
    try:
        return load_project(config, overrides=overrides)
    except ProjectError as e:
        raise CommandError(str(e), 2) from None


def _rel(path, root):
    r = os.path.relpath(path, root)
    return path if r.startswith("..") else r


def _build_unit(src, out, settings, strict, stamp):
    """Worker side of one build entry: never raises for a bad input."""
    from colossus.pipeline.errors import ColossusError, one_line
    from colossus.pipeline.run import import_asset
    from colossus.runtime import usdlog

    from .import_ import error_rules

    usdlog.silence()
    usdlog.take()
    t0 = time.perf_counter()
    try:
        os.makedirs(os.path.dirname(out) or ".", exist_ok=True)
        # the error rules on the written file before its rename, as `colossus import` runs them
        import_asset(src, out, settings, strict=strict, build=stamp, check=error_rules)
    except ColossusError as e:
        return {"ok": False, "error": one_line(e)}
    except OSError as e:
        return {"ok": False, "error": f"cannot write {out}: {e.strerror or e}"}
    except MemoryError:
        return {"ok": False, "error": "out of memory"}
    except Exception as e:
        return {"ok": False, "error": f"internal error ({type(e).__name__}: {one_line(e)})"}
    return {"ok": True, "seconds": time.perf_counter() - t0}


@click.command("build")
@click.argument("assets", nargs=-1)
@config_option
@set_option
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=1, show_default=True,
              help="Import in N parallel processes.")
@click.option("--scheduler", metavar="ADDRESS",
              help="Run on a Dask cluster (tcp://host:8786, or local:N; needs colossus[dask]).")
@click.option("--force", is_flag=True, help="Rebuild every selected entry, changed or not.")
@click.option("--dry-run", "-n", "dry_run", is_flag=True, help="Say what would be built; build nothing.")
@click.option("--progress/--no-progress", default=None,
              help="Progress bar on stderr (default: when stderr is a terminal).")
@click.option("-v", "--verbose", is_flag=True, help="Also list the entries skipped as up to date.")
@maps_errors(input_status=1)
def build_cmd(assets, config, sets, jobs, scheduler, force, dry_run, progress, verbose):
    """Import the project's [[asset]] entries whose source, settings or importer version changed.

    \b
    ASSET...: entry names, sources or outputs (default: every entry).
    Exit 0 every entry built or up to date; 1 any failed; 2 a bad project file or usage;
    130 interrupted.
    """
    from colossus.cli.project import StampCache, build_stamp, select_entries
    from colossus.pipeline.engine import Engine, Progress, Task, make_backend
    from colossus.pipeline.errors import one_line

    t0 = time.perf_counter()
    project = _load(config, sets)
    entries = select_entries(project, assets)
    cache = StampCache(project.root)
    todo, skipped, rows = [], [], {}
    for e in entries:
        try:
            want = build_stamp(e)
        except OSError as exc:
            rows[id(e)] = {"ok": False, "error": f"cannot read the source: {exc.strerror or exc}"}
            continue
        have = None if force else cache.key(e.output)
        if have is not None and have == want["key"]:
            skipped.append(e)
        else:
            todo.append((e, want))
    t_plan = time.perf_counter() - t0
    root = project.root
    if dry_run:
        cache.save()
        for e, _ in todo:
            click.echo(f"would build  {_rel(e.source, root)} -> {_rel(e.output, root)}")
        click.echo(f"{len(todo)} to build, {len(skipped)} up to date")
        return
    show = sys.stderr.isatty() if progress is None else progress
    backend = make_backend(jobs, scheduler)
    bar = Progress(len(todo), "building", show)

    def task(e, stamp):
        def ok(value):
            rows[id(e)] = value
            bar.advance(not value["ok"])

        def err(exc):
            rows[id(e)] = {"ok": False, "error": f"import crashed: {one_line(exc)}"}
            bar.advance(True)

        def lost(exc):
            rows[id(e)] = {"ok": False, "error": f"import crashed: {exc}"}
            bar.advance(True)
        return Task(_build_unit, (e.source, e.output, e.settings, e.strict, stamp), ok, err, lost)

    skipped_ids = {id(e) for e in skipped}
    engine = Engine(backend)
    try:
        engine.run([task(e, s) for e, s in sorted(todo, key=lambda es: -_size(es[0].source))])
    finally:
        bar.close()
    stamps = {id(e): s for e, s in todo}
    for e in entries:  # what was written now is known without reading it back
        r = rows.get(id(e))
        if r is not None and r["ok"]:
            cache.remember(e.output, stamps[id(e)]["key"])
    cache.save()
    built = failed = 0
    for e in entries:
        r = rows.get(id(e))
        if id(e) in skipped_ids:
            if verbose:
                click.echo(f"skip   {_rel(e.source, root)} -> {_rel(e.output, root)} (up to date)")
            continue
        if r is None:
            click.echo(f"skip   {_rel(e.source, root)}: not built (interrupted)")
        elif r["ok"]:
            built += 1
            click.echo(f"built  {_rel(e.source, root)} -> {_rel(e.output, root)} ({r['seconds']:.2f} s)")
        else:
            failed += 1
            click.echo(f"FAIL   {_rel(e.source, root)}: {r['error']}")
            click.echo(f"error: {_rel(e.source, root)}: {r['error']}", err=True)
    total = time.perf_counter() - t0
    click.echo(f"{built} built, {len(skipped)} skipped (up to date), {failed} failed "
               f"({total:.2f} s; checking keys {t_plan:.2f} s)")
    status = interrupted_status() if engine.interrupted else 1 if failed else 0
    click.get_current_context().exit(status)


def _size(path) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


@click.command("check")
@config_option
@set_option
@click.option("--format", "fmt", type=click.Choice(["text", "json", "junit", "sarif", "github"]), default="text",
              show_default=True, help="Format of the validation report.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), help="Write the validation report to FILE.")
@click.option("--deep", is_flag=True, help="Also compare each output with its source (validate --source).")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=1, show_default=True,
              help="Validate in N parallel processes.")
@click.option("--scheduler", metavar="ADDRESS",
              help="Validate on a Dask cluster (tcp://host:8786, or local:N; needs colossus[dask]).")
@click.option("--progress/--no-progress", default=None,
              help="Progress bar on stderr (default: when stderr is a terminal).")
@maps_errors(input_status=2)
def check_cmd(config, sets, fmt, output, deep, jobs, scheduler, progress):
    """CI gate: every [[asset]] output exists, is up to date with its source, settings and importer
    version, and passes validate with the project's rules.

    \b
    Exit 0 all up to date and passing; 1 any missing, stale or failing; 2 a bad project file or usage.
    A missing or stale output is one line on stderr: 'error: OUT: stale: source changed'.
    """
    from colossus.cli.project import build_stamp, read_stamp, staleness
    from colossus.validators.parallel import check_many
    from colossus.validators.report import render as render_report, write_atomic

    project = _load(config, sets)
    root = project.root
    problems, present = [], []
    for e in project.entries:
        if not os.path.isfile(e.output):
            problems.append((e, "missing: not built (run colossus build)"))
            continue
        try:
            want = build_stamp(e)
        except OSError as exc:
            problems.append((e, f"cannot read the source {e.source}: {exc.strerror or exc}"))
            continue
        changed = staleness(read_stamp(e.output), want)
        if changed:
            problems.append((e, "stale: " + ", ".join(changed)))
        present.append(e)
    show = sys.stderr.isatty() if progress is None else progress
    # one validation run per distinct rule configuration (a waiver changes an entry's ignore list)
    groups = {}
    for e in present:
        kw = dict(e.validate)
        kw.setdefault("max_influences", e.settings.max_influences)
        if deep:
            kw["source"] = e.source
        key = json.dumps(kw, sort_keys=True, default=str)
        groups.setdefault(key, (kw, []))[1].append(e)
    reports, interrupted = {}, False
    for kw, es in groups.values():
        res = check_many([e.output for e in es], jobs=jobs, scheduler=scheduler, progress=show, **kw)
        by_path = {os.path.abspath(r.path): r for r in res.reports}
        for e in es:
            if os.path.abspath(e.output) in by_path:
                reports[id(e)] = by_path[os.path.abspath(e.output)]
        interrupted = interrupted or res.interrupted
    ordered = [reports[id(e)] for e in present if id(e) in reports]
    for r in ordered:
        r.path = _rel(r.path, os.getcwd())
    cwd = os.getcwd()
    outputs = [{"output": _rel(e.output, cwd), "source": _rel(e.source, cwd),
                "status": next((why for p, why in problems if p is e), "up to date")} for e in project.entries]
    text = with_outputs(fmt, render_report(fmt, ordered), outputs)
    if output:
        write_atomic(output, text)
    else:
        click.echo(text, nl=False)
    for e, why in problems:
        click.echo(f"error: {_rel(e.output, os.getcwd())}: {why}", err=True)
    strict = project.validate_strict
    failing = [r for r in ordered if not r.passed or (strict and any(f.severity == "warning" for f in r.findings))]
    n = len(project.entries)
    click.echo(f"check: {n} entries, {n - len(problems)} up to date, {len(problems)} missing or stale, "
               f"{len(failing)} failing validation", err=True)
    status = interrupted_status() if interrupted else 1 if problems or failing else 0
    click.get_current_context().exit(status)


def with_outputs(fmt: str, text: str, outputs: list) -> str:
    """The validation report ``text`` with what ``check`` found of each entry's output (``outputs``:
    ``{"output", "source", "status"}``, status ``up to date``, ``missing: ...`` or ``stale: ...``), in
    that format's own terms: a line per bad output (text), an annotation (github), a
    ``colossus check`` suite with a case per output (junit), ``"outputs"`` (json), a tool
    notification (sarif)."""
    bad = [o for o in outputs if o["status"] != "up to date"]
    if fmt == "text":
        return text + "".join(f"{o['output']}: {o['status']}\n" for o in bad)
    if fmt == "github":
        from colossus.validators.report import github_escape_data, github_escape_property
        return "".join(f"::error file={github_escape_property(o['output'])},title={github_escape_property('colossus check')}::"
                       f"{github_escape_data(o['status'] + ' (source ' + o['source'] + ')')}\n" for o in bad) + text
    if fmt == "json":
        doc = json.loads(text)
        doc["outputs"] = outputs
        return json.dumps(doc, indent=2) + "\n"
    if fmt == "sarif":
        doc = json.loads(text)
        inv = doc["runs"][0]["invocations"][0]
        inv.setdefault("toolExecutionNotifications", []).extend(
            {"level": "error", "message": {"text": f"{o['output']}: {o['status']}"},
             "locations": [{"physicalLocation": {"artifactLocation": {"uri": o["output"]}}}]} for o in bad)
        return json.dumps(doc, indent=2) + "\n"
    if fmt == "junit":
        from xml.etree import ElementTree as ET
        root = ET.fromstring(text)
        suite = ET.Element("testsuite", name="colossus check: outputs up to date", tests=str(len(outputs)),
                           failures=str(len(bad)), errors="0", skipped="0", time="0.000")
        for o in outputs:
            case = ET.SubElement(suite, "testcase", classname=o["output"], name="up to date", time="0")
            if o in bad:
                ET.SubElement(case, "failure", message=o["status"], type="stale" if o["status"].startswith("stale")
                              else "missing").text = f"{o['output']} (from {o['source']}): {o['status']}"
        root.insert(0, suite)
        for k in ("tests", "failures"):
            root.set(k, str(int(root.get(k, "0")) + int(suite.get(k))))
        ET.indent(root)
        return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
    return text


@click.command("config")
@config_option
@set_option
@click.option("--json", "as_json", is_flag=True, help="Print the resolved settings as JSON.")
@maps_errors(input_status=2)
def config_cmd(config, sets, as_json):
    """Print the project file found and the resolved settings of every [[asset]] entry.
    Exit 0; 2 a bad project file."""
    from colossus.cli.project import describe

    project = _load(config, sets)
    doc = {"project": project.path, "root": project.root,
           "validate": {**{k.replace("_", "-"): v for k, v in project.validate.items()},
                        "strict": project.validate_strict},
           "assets": [describe(e, project.root) for e in project.entries]}
    if as_json:
        click.echo(json.dumps(doc, indent=2, default=str))
        return
    click.echo(f"project: {project.path}")
    click.echo("validate: " + (" ".join(f"{k}={_show(v)}" for k, v in doc["validate"].items()) or "(defaults)"))
    for a in doc["assets"]:
        click.echo(f"asset {a['entry']} {a['name']!r}: {a['source']} -> {a['output']}")
        click.echo("  import: " + " ".join(f"{k}={_show(v)}" for k, v in a["import"].items()))
        click.echo("  validate: " + " ".join(f"{k}={_show(v)}" for k, v in a["validate"].items()))
        if a.get("waiver"):
            click.echo(f"  waiver: ignore {','.join(a['waiver']['ignore'])} ({a['waiver']['reason']})")


def _show(v):
    if v is None:
        return "-"
    if isinstance(v, (list, tuple)):
        return ",".join(map(str, v)) or "[]"
    if isinstance(v, dict):
        return ",".join(f"{k}:{x}" for k, x in v.items()) or "{}"
    return str(v)
