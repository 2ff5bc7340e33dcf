"""``colossus play ASSET [--clip NAME] [--script FILE.json] -o run.gif``: a player sphere on the
animated collider, driven by the character controller (runtime.controller) through a script of
intents (runtime.script; the default drops it on the model and waits), rendered offscreen with
pyvista and recorded step by step in a CSV."""

from __future__ import annotations

import os

import click

from colossus.cli._errors import maps_errors


@click.command("play")
@click.argument("asset", type=click.Path(dir_okay=False))
@click.option("--clip", default=None, help="Clip name (default: the first).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="GIF to write.")
@click.option("--radius", default=0.035, show_default=True, type=click.FloatRange(0.001, 0.5),
              help="Player radius as a fraction of the model size (bounding-box diagonal).")
@click.option("--substeps", default=4, show_default=True, type=click.IntRange(1, 64),
              help="Simulation steps per clip frame.")
@click.option("--verify/--no-verify", default=False, show_default=True,
              help="Run the validators' error rules on the asset first.")
@click.option("--script", "script_path", default=None, type=click.Path(dir_okay=False),
              help="JSON script of intents (walk, jump, grab, wait); see the README. Default: drop and wait.")
@click.option("--csv", "csv_path", default=None, type=click.Path(dir_okay=False),
              help="Per-step CSV to write (default: the GIF's name with .csv).")
@maps_errors(input_status=2)
def play_cmd(asset, clip, output, radius, substeps, verify, script_path, csv_path):
    """Drop a player sphere on ASSET's animated collider, play a script of intents, and record
    it as a GIF (the player coloured by state) and a per-step CSV.

    Prints the largest penetration and the largest slip relative to the surface."""
    from colossus.validators import require_passing

    from colossus.runtime.collider import load_collider
    from colossus.runtime.errors import ColliderError
    from colossus.render.run import render_run_gif
    from colossus.runtime.player import simulate
    from colossus.runtime.script import load_script, run_script, write_csv

    script = load_script(script_path) if script_path is not None else None  # a bad script: exit 2
    col = load_collider(asset, verify=require_passing if verify else None)
    if not col.clips:
        raise ColliderError(f"{asset}: has no animation clips")
    if script is None:
        clip = clip or col.clips[0]
    if clip is not None and clip not in col.clips:  # a script's own clip is checked with the script
        raise click.UsageError(f"no clip {clip!r} in {asset}; clips: {', '.join(col.clips)}")
    if not str(output).lower().endswith(".gif"):
        raise click.UsageError("-o must name a .gif file")
    csv_path = csv_path or os.path.splitext(output)[0] + ".csv"
    try:
        if script is None:
            run = simulate(col, clip, radius_fraction=radius, substeps=substeps)
        else:
            run = run_script(col, script, clip, radius_fraction=radius)
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    try:
        n = render_run_gif(col, run, output)
        rows = write_csv(run, csv_path)
    except OSError as e:
        raise click.ClickException(f"cannot write {e.filename or output}: {e.strerror or e}") from None
    r = run.radius
    landed = f"landed at t={run.landed_at:g}" if run.landed_at is not None else "never landed"
    states = ", ".join(f"{k} {v}" for k, v in run.state_counts().items())
    click.echo(f"play {os.path.basename(asset)} clip {run.clip!r}: {len(run.times)} steps at {run.rate:g}/s, "
               f"radius {r:.4g}, {landed}; {states}")
    click.echo(f"largest penetration {run.max_penetration:.4g} ({run.max_penetration / r:.1%} of radius)")
    click.echo(f"largest slip relative to the surface {run.max_slip:.4g} per step "
               f"({run.max_slip / r:.1%} of radius)")
    click.echo(f"wrote {output} ({n} frames), {csv_path} ({rows} rows)")
