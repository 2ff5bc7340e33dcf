"""``colossus inspect PATH``: a readable summary of a collider asset (thin layer over
:mod:`validators.summary`).  Exit 0 printed; 2 the asset cannot be read, or usage."""

from __future__ import annotations

import json
import sys

import click


@click.command("inspect")
@click.argument("path", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the summary as one JSON object.")
def inspect_cmd(path, as_json):
    """Print a readable summary of the collider asset PATH: stage metadata, counts, the joint
    tree, clips (frames, seconds), parts (joint, faces, radius) and provenance."""
    from .summary import AssetError, format_summary, open_asset, summarize

    try:
        s = summarize(open_asset(path))
    except AssetError as e:
        click.echo(f"colossus inspect: {e}", err=True)
        sys.exit(2)
    if as_json:
        click.echo(json.dumps(s, indent=2))
    else:
        click.echo(format_summary(s), nl=False)
