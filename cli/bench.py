"""``colossus bench``: every benchmark, printed as ratios against baselines run in the same
process (a CLI module: it reaches every floor).  Absolute times are this machine's; the ratios are
what to compare across machines.

``import``, ``validate`` and ``runtime`` each add rows on real corpus characters with the spheres
the importer writes (:mod:`bench.real`), imported once per run (their import rows are printed
the first time one of the three needs them); without the corpus they print one line and skip.
"""

from __future__ import annotations

import os

import click

from colossus.bench.import_ import bench_import, bench_scaling, bench_simplify

from colossus.bench.validate import coldstart, format_bench, format_scale_bench, run_bench, run_scale_bench


@click.command("bench")
@click.option("--quick", is_flag=True, help="Smaller sizes (a smoke run; one small real character).")
@click.option("--only", type=click.Choice(["import", "scaling", "validate", "runtime", "scale", "coldstart", "simplify"]), multiple=True,
              help="Run only these benchmarks (repeatable).")
def bench_cmd(quick, only):
    """Run the benchmarks; absolute times are this machine's, ratios are against in-process baselines."""
    from colossus.bench.real import Characters

    want = set(only) or {"import", "scaling", "validate", "runtime", "scale", "coldstart", "simplify"}
    click.echo(f"colossus bench on {os.cpu_count()} cores (absolute times are this machine's)\n")
    chars = Characters(quick=quick, echo=click.echo)  # corpus characters, imported once for this run
    try:
        _run(want, quick, chars)
    finally:
        chars.close()


def _real(chars) -> list:
    """The imported real characters (importing them, and printing the import rows, on first use)."""
    from colossus.bench.real import format_import_rows

    if not chars.loaded:
        items = chars.load()
        if items:
            click.echo(format_import_rows(items))
        click.echo()
    return [c for c in chars.items if not c.error]


def _run(want, quick, chars):
    from colossus.bench.real import format_runtime_rows, format_validate_rows, run_runtime, run_validate

    if "import" in want:
        bench_import(*((20_000, 20, 2, 30) if quick else ()), echo=click.echo)
        click.echo()
        _real(chars)
    if "scaling" in want:
        bench_scaling((10_000, 40_000, 160_000) if quick else (50_000, 200_000, 800_000), echo=click.echo)
        click.echo()
    if "simplify" in want:
        bench_simplify(*((20_000, 1_000, 20, 2, 30) if quick else ()), echo=click.echo)
        click.echo()
    if "validate" in want:
        click.echo(format_bench(run_bench()))
        click.echo()
        if _real(chars):
            click.echo(format_validate_rows(run_validate(chars)))
            click.echo()
    if "runtime" in want:
        from colossus.bench.runtime import format_rows as rt_format, run_bench as rt_run
        click.echo(rt_format(rt_run()))
        click.echo()
        if _real(chars):
            click.echo(format_runtime_rows(run_runtime(chars)))
    if "coldstart" in want:
        click.echo("\ncold start (NUMBA_CACHE_DIR pointed at an empty folder; goal < 5 s cold) and warm:")
        coldstart(echo=click.echo, repeat=1 if quick else 2)
    if "scale" in want:
        click.echo()
        click.echo(format_scale_bench(run_scale_bench(**({"count": 40} if quick else {}))))
