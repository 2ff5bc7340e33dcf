"""``colossus validate``: the CI gate (a thin click layer over :mod:`validators.runner`).

Exit status (the contract): 0 every asset passes; 1 any error-severity finding; 2 a path does
not exist or cannot be read, or a usage error.
"""

from __future__ import annotations

import sys

import click

from colossus.cli._errors import CommandError, interrupted_status, maps_errors


def _codes(values):
    out = []
    for v in values:
        out += [c.strip() for c in v.split(",") if c.strip()]
    return out or None


def _list_rules(ctx, param, value):
    if not value or ctx.resilient_parsing:
        return
    from colossus.validators.registry import all_rules
    for r in all_rules():
        click.echo(f"{r.code}  {r.severity:<7}  {r.name:<26} {r.summary}")
    ctx.exit(0)


@click.command("validate")
@click.argument("paths", nargs=-1, type=click.Path())
@click.option("--format", "fmt", type=click.Choice(["text", "json", "junit", "html", "sarif", "github"]), default="text", show_default=True,
              help="Report format.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, writable=True),
              help="Write the report to FILE (atomically) instead of stdout.")
@click.option("--select", multiple=True, help="Codes or prefixes to check (comma-separated; default all).")
@click.option("--ignore", multiple=True, help="Codes or prefixes to skip (longest prefix wins).")
@click.option("--severity", "severity", multiple=True, metavar="CODE=LEVEL",
              help="Override a rule's severity, e.g. COL206=error.")
@click.option("--max-influences", type=click.IntRange(min=1), default=4, show_default=True,
              help="Most influences a vertex may have.")
@click.option("--subframes", type=click.IntRange(min=0), default=0, show_default=True,
              help="Also check K evenly spaced in-between times per frame interval.")
@click.option("--slack-ratio", type=click.FloatRange(min=1.0), default=1.5, show_default=True,
              help="Warn when a sphere is this many times the tightest radius.")
@click.option("--max-deviation", default=None, metavar="D",
              help="A simplified proxy must stay within D of the full skinned mesh (stage units, or D% of "
                   "the model size; COL701).")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=1, show_default=True,
              help="Check assets in N parallel processes.")
@click.option("--scheduler", metavar="ADDRESS",
              help="Run on a Dask cluster instead (tcp://host:8786, or local:N for N local workers; "
                   "needs colossus[dask]).")
@click.option("--split-above", "split_above", metavar="SIZE", default="64M", show_default=True,
              help="With --jobs > 1 or --scheduler, prove assets at least this large one clip per task "
                   "(bytes, or K/M/G; 'never').")
@click.option("--source", "source", type=click.Path(), default=None, metavar="FILE",
              help="Also check the asset against the export it was made from (COL6xx): motion within "
                   "1e-4 x model size on every frame, same clips and vertices; a different sha256 warns.")
@click.option("--progress/--no-progress", default=None,
              help="Progress bar on stderr (default: when stderr is a terminal).")
@click.option("-v", "--verbose", is_flag=True, help="Text format: list every finding, not only the worst.")
@click.option("--strict", is_flag=True, default=False,
              help="Warnings fail too (exit 1 when any finding is an error or a warning).")
@click.option("--config", "config", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Take the rule settings of this project file's [validate] table (default: colossus.toml, "
                   "or pyproject.toml with [tool.colossus], found walking up from the working directory); "
                   "options given on the command line win.")
@click.option("--no-config", is_flag=True, help="Ignore any project file.")
@click.option("--list-rules", is_flag=True, expose_value=False, is_eager=True, callback=_list_rules,
              help="Print the rule catalog and exit.")
@maps_errors(input_status=2)
def validate_cmd(paths, fmt, output, select, ignore, severity, max_influences, subframes, slack_ratio, max_deviation,
                 jobs, scheduler, split_above, source, progress, verbose, strict, config, no_config):
    """Check collider assets: PATHS are files, directories (searched for *.usd, *.usda,
    *.usdc, *.usdz) or globs ('assets/**/*.usda').  Exit 0 all pass, 1 any error finding,
    2 a path unreadable or usage, 130 interrupted (the report so far is still written, marked
    INCOMPLETE)."""
    from colossus.validators.registry import RuleSelector
    from colossus.validators.parallel import check_many
    from colossus.validators.report import render as render_report, write_atomic

    if not paths:
        raise click.UsageError("give at least one asset file or directory")
    ctx = click.get_current_context()
    given = lambda name: ctx.get_parameter_source(name) not in (click.core.ParameterSource.DEFAULT, None)  # noqa: E731
    project = {} if no_config else _project_validate(config)
    proj_sev = dict(project.get("severities") or {})
    if not given("select") and project.get("select"):
        select = tuple(project["select"])
    if not given("ignore") and project.get("ignore"):
        ignore = tuple(project["ignore"])
    if not given("subframes") and "subframes" in project:
        subframes = project["subframes"]
    if not given("max_influences") and "max_influences" in project:
        max_influences = project["max_influences"]
    if not given("slack_ratio") and "slack_ratio" in project:
        slack_ratio = project["slack_ratio"]
    if not given("max_deviation") and "max_deviation" in project:
        max_deviation = project["max_deviation"]
    if not given("strict") and project.get("strict"):
        strict = True
    sel, ign = _codes(select), _codes(ignore)
    try:
        RuleSelector(sel, ign)
    except ValueError as e:
        raise click.UsageError(str(e))
    sev = dict(proj_sev)  # the project file's overrides, then the command line's
    for s in severity:
        code, _, level = s.partition("=")
        if level not in ("error", "warning", "info"):
            raise click.UsageError(f"--severity {s!r}: expected CODE=error|warning|info")
        sev[code.strip().upper()] = level
    try:
        from colossus.validators.registry import get_rule
        for code in sev:
            get_rule(code)
    except KeyError as e:
        raise click.UsageError(f"--severity: unknown rule code {e}")

    from colossus.pipeline.options import parse_max_deviation
    parse_max_deviation(max_deviation)  # a bad value is a usage error (exit 2) before any asset is read
    if source is not None and not __import__("os").path.isfile(source):
        click.echo(f"error: --source {source}: no such file", err=True)
        click.get_current_context().exit(2)
    split_bytes = _size(split_above)
    if output:
        _check_report_path(output)  # before any asset is read: exit 2, one line
    show = sys.stderr.isatty() if progress is None else progress
    res = check_many(paths, jobs=jobs, scheduler=scheduler, progress=show, split_bytes=split_bytes,
                     select=sel, ignore=ign, severities=sev, max_influences=max_influences,
                     subframes=subframes, slack_ratio=slack_ratio, max_deviation=max_deviation,
                     **({"source": source} if source is not None else {}))
    reports, missing = res.reports, res.missing
    for m in missing:
        click.echo(f"error: {m}: no such file or directory", err=True)
    if res.interrupted:
        click.echo(f"error: interrupted; {len(res.unchecked)} asset(s) not checked, "
                   "the report is INCOMPLETE", err=True)
    unchecked = res.unchecked if res.interrupted else None
    if fmt == "html":  # pictures: the render floor
        from colossus.render.html import format_html

        text = format_html(reports, unchecked=unchecked)
    else:
        text = render_report(fmt, reports, verbose=verbose, unchecked=unchecked)
    if output:
        try:
            write_atomic(output, text)
        except OSError as e:  # a full or read-only disk: the environment, not the assets (exit 2)
            raise CommandError(f"cannot write the report {output}: {e.strerror or e}", 2) from None
    else:
        click.echo(text, nl=False)
    unreadable = bool(missing) or any(f.code == "COL003" for r in reports for f in r.findings)
    passed = all(r.passed and not (strict and any(f.severity == "warning" for f in r.findings)) for r in reports)
    status = interrupted_status() if res.interrupted else 2 if unreadable else 0 if passed else 1
    click.get_current_context().exit(status)


def _project_validate(config) -> dict:
    """The ``[validate]`` table of the project file (``--config``, else the one found walking up
    from the working directory; none: ``{}``) as option values, plus ``strict``.  A bad file is
    exit 2 naming its line."""
    from colossus.cli.project import ProjectError, find_project, load_project

    path = config or find_project()
    if path is None:
        return {}
    try:
        project = load_project(path)
    except ProjectError as e:
        raise CommandError(str(e), 2) from None
    return {**project.validate, **({"strict": True} if project.validate_strict else {})}


def _check_report_path(output) -> None:
    """Exit 2 with one line unless the report ``output`` can be written (its folder exists, is
    writable for real, and ``output`` is not a folder)."""
    import os

    from colossus.pipeline.tempfiles import temp_path

    folder = os.path.dirname(os.path.abspath(output))
    if os.path.isdir(output):
        raise CommandError(f"cannot write the report {output}: is a directory", 2)
    if not os.path.isdir(folder):
        raise CommandError(f"cannot write the report {output}: no folder {folder}", 2)
    probe = temp_path(folder, ".probe")
    try:  # access() says yes to root on a read-only filesystem: try for real
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        os.unlink(probe)
    except OSError as e:
        raise CommandError(f"cannot write the report {output}: {e.strerror or e}", 2) from None


def _size(text):
    """``--split-above``: bytes with an optional K/M/G suffix (powers of 1024), or 'never'."""
    t = text.strip().upper().removesuffix("B")
    if t in ("NEVER", "NONE", "OFF"):
        return None
    mult = {"K": 2**10, "M": 2**20, "G": 2**30}.get(t[-1:], 1)
    try:
        n = float(t[:-1] if t[-1:] in "KMG" else t)
    except ValueError:
        raise click.UsageError(f"--split-above {text!r}: expected a size such as 64M, or 'never'")
    if n < 0:
        raise click.UsageError(f"--split-above {text!r}: expected a size >= 0")
    return int(n * mult)
