"""``colossus inspect PATH``: a readable summary of a collider asset (thin layer over
:mod:`validators.summary`).  Exit 0 printed; 2 the asset cannot be read, or usage."""

from __future__ import annotations

import json

import click

from colossus.cli._errors import maps_errors


@click.command("inspect")
@click.argument("path", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the summary as one JSON object.")
@maps_errors(input_status=2)
def inspect_cmd(path, as_json):
    """Print a readable summary of the collider asset PATH: stage metadata, counts, the joint
    tree, clips (frames, seconds), parts (joint, faces, radius) and provenance."""
    from colossus.validators.summary import format_summary, open_asset, summarize

    s = summarize(open_asset(path))
    if as_json:
        click.echo(json.dumps(s, indent=2))
    else:
        click.echo(format_summary(s), nl=False)
