"""``colossus validate``: the CI gate (a thin click layer over :mod:`validators.runner`).

Exit status (the contract): 0 every asset passes; 1 any error-severity finding; 2 a path does
not exist or cannot be read, or a usage error.
"""

from __future__ import annotations

import sys

import click


def _codes(values):
    out = []
    for v in values:
        out += [c.strip() for c in v.split(",") if c.strip()]
    return out or None


def _list_rules(ctx, param, value):
    if not value or ctx.resilient_parsing:
        return
    from .registry import all_rules
    for r in all_rules():
        click.echo(f"{r.code}  {r.severity:<7}  {r.name:<26} {r.summary}")
    ctx.exit(0)


@click.command("validate")
@click.argument("paths", nargs=-1, type=click.Path())
@click.option("--format", "fmt", type=click.Choice(["text", "json", "junit"]), default="text", show_default=True,
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
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=1, show_default=True,
              help="Check assets in N parallel processes.")
@click.option("--progress/--no-progress", default=None,
              help="Progress bar on stderr (default: when stderr is a terminal).")
@click.option("-v", "--verbose", is_flag=True, help="Text format: list every finding, not only the worst.")
@click.option("--list-rules", is_flag=True, expose_value=False, is_eager=True, callback=_list_rules,
              help="Print the rule catalog and exit.")
def validate_cmd(paths, fmt, output, select, ignore, severity, max_influences, subframes, slack_ratio, jobs,
                 progress, verbose):
    """Check collider assets: PATHS are files or directories (searched for *.usd, *.usda,
    *.usdc, *.usdz).  Exit 0 all pass, 1 any error finding, 2 a path unreadable or usage."""
    from .registry import RuleSelector
    from .report import FORMATS, format_text, write_atomic
    from .runner import check_paths

    if not paths:
        raise click.UsageError("give at least one asset file or directory")
    sel, ign = _codes(select), _codes(ignore)
    try:
        RuleSelector(sel, ign)
    except ValueError as e:
        raise click.UsageError(str(e))
    sev = {}
    for s in severity:
        code, _, level = s.partition("=")
        if level not in ("error", "warning", "info"):
            raise click.UsageError(f"--severity {s!r}: expected CODE=error|warning|info")
        sev[code.strip().upper()] = level
    try:
        from .registry import get_rule
        for code in sev:
            get_rule(code)
    except KeyError as e:
        raise click.UsageError(f"--severity: unknown rule code {e}")

    show = sys.stderr.isatty() if progress is None else progress
    bar = None
    cb = None
    if show:
        bar = click.progressbar(length=1, label="validating", file=sys.stderr)
        bar.__enter__()

        def cb(done, total, path):
            bar.length = total
            bar.update(1)

    try:
        reports, missing = check_paths(paths, jobs=jobs, progress=cb, select=sel, ignore=ign, severities=sev,
                                       max_influences=max_influences, subframes=subframes,
                                       slack_ratio=slack_ratio)
    finally:
        if bar is not None:
            bar.__exit__(None, None, None)
    for m in missing:
        click.echo(f"colossus validate: {m}: no such file or directory", err=True)
    render = FORMATS[fmt]
    text = format_text(reports, verbose=verbose) if fmt == "text" else render(reports)
    if output:
        write_atomic(output, text)
    else:
        click.echo(text, nl=False)
    unreadable = bool(missing) or any(f.code == "COL003" for r in reports for f in r.findings)
    if unreadable:
        sys.exit(2)
    sys.exit(0 if all(r.passed for r in reports) else 1)
