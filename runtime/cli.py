"""``colossus play ASSET [--clip NAME] [--script FILE.json] -o run.gif``: a player sphere on the
animated collider, driven by the character controller (runtime.controller) through a script of
intents (runtime.script; the default drops it on the model and waits), rendered offscreen with
pyvista and recorded step by step in a CSV."""

from __future__ import annotations

import os

import click
import numpy as np

from pipeline.cli import maps_errors

#: Largest number of GIF frames; longer clips are subsampled.
MAX_FRAMES = 60
#: The player's colour in the GIF, by controller state.
STATE_COLOURS = {"standing": "#3a9e4f", "sliding": "#e08a1e", "holding": "#2f6fd0",
                 "hanging": "#8e3fc0", "falling": "#d0312d"}


def render_gif(col, run, path, size=(480, 360), max_frames=MAX_FRAMES):
    """Write the run as an animated GIF (offscreen; starts a virtual X server only if needed)."""
    import pyvista as pv

    pv.OFF_SCREEN = True
    try:
        import vtk

        vtk.vtkObject.GlobalWarningDisplayOff()
    except Exception:  # pragma: no cover
        pass
    idx = np.unique(np.linspace(0, len(run.times) - 1, min(max_frames, len(run.times))).round().astype(int))
    tris = col.triangles
    faces = np.c_[np.full(len(tris), 3), tris].ravel()
    pose = col.pose(run.clip, run.times[0])
    mesh = pv.PolyData(pose.points.astype(np.float64), faces)
    ball = pv.Sphere(radius=run.radius, center=(0, 0, 0), theta_resolution=24, phi_resolution=16)
    ball_pts = ball.points.copy()
    try:
        pl = pv.Plotter(off_screen=True, window_size=list(size))
    except Exception:  # pragma: no cover - no offscreen GL: try a virtual framebuffer
        pv.start_xvfb()
        pl = pv.Plotter(off_screen=True, window_size=list(size))
    pl.set_background("white")
    pl.add_mesh(mesh, color="#c9b79c", smooth_shading=False, show_edges=False)
    ball_actor = pl.add_mesh(ball, color=STATE_COLOURS["standing"])
    # frame the whole run: union of every shown pose and the player's path
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for i in idx:
        pose = col.pose(run.clip, run.times[i], out=pose)
        lo = np.minimum(lo, pose.points.min(0))
        hi = np.maximum(hi, pose.points.max(0))
    lo = np.minimum(lo, run.positions.min(0) - run.radius)
    hi = np.maximum(hi, run.positions.max(0) + run.radius)
    centre, extent = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    up = col.up
    if getattr(run, "floor", None) is not None:  # the script's terrain plane
        at = centre + (run.floor - centre @ up) * up
        pl.add_mesh(pv.Plane(center=tuple(at), direction=tuple(up), i_size=extent, j_size=extent),
                    color="#9aa38f", opacity=0.5)
    side = np.array([1.0, 0.0, 0.0]) if up[0] == 0 else np.array([0.0, 1.0, 0.0])
    eye = centre + extent * (0.9 * side + 0.5 * up + 0.9 * np.cross(up, side))
    pl.camera_position = [tuple(eye), tuple(centre), tuple(up)]
    label = pl.add_text(" ", font_size=9, color="black")
    fps = col.data.time_codes_per_second * len(idx) / max(len(run.times), 1)
    pl.open_gif(os.fspath(path), fps=max(1, int(round(fps))))
    for i in idx:
        pose = col.pose(run.clip, run.times[i], out=pose)
        mesh.points = pose.points.astype(np.float64)
        ball.points = ball_pts + run.positions[i]
        state = str(run.states[i])
        ball_actor.prop.color = STATE_COLOURS.get(state, "#3a9e4f")
        text = f"{run.clip}  t={run.times[i]:.4g}  {state}"
        if state in ("holding", "hanging"):
            text += f"  energy {run.energy[i]:.0%}"
        if hasattr(label, "set_text"):  # a CornerAnnotation (pyvista >= 0.43)
            label.set_text("upper_left", text)
        elif hasattr(label, "SetInput"):
            label.SetInput(text)
        pl.write_frame()
    pl.close()
    return len(idx)


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
    from validators import require_passing

    from .collider import load_collider
    from .errors import ColliderError
    from .player import simulate
    from .script import load_script, run_script, write_csv

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
        n = render_gif(col, run, output)
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
