"""``colossus play ASSET [--clip NAME] -o run.gif``: a player sphere dropped on the animated
collider, simulated (runtime.player) and rendered offscreen with pyvista."""

from __future__ import annotations

import os

import click
import numpy as np

from pipeline.cli import maps_errors

#: Largest number of GIF frames; longer clips are subsampled.
MAX_FRAMES = 60


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
    pl.add_mesh(ball, color="#3a9e4f")
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
        text = f"{run.clip}  t={run.times[i]:g}" + ("  standing" if run.grounded[i] else "")
        if hasattr(label, "SetInput"):
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
@maps_errors(input_status=2)
def play_cmd(asset, clip, output, radius, substeps, verify):
    """Drop a player sphere on ASSET's animated collider and record it as a GIF.

    Prints the largest penetration and the largest slip relative to the surface."""
    from validators import require_passing

    from .collider import load_collider
    from .errors import ColliderError
    from .player import simulate

    col = load_collider(asset, verify=require_passing if verify else None)
    if not col.clips:
        raise ColliderError(f"{asset}: has no animation clips")
    clip = clip or col.clips[0]
    if clip not in col.clips:
        raise click.UsageError(f"no clip {clip!r} in {asset}; clips: {', '.join(col.clips)}")
    if not str(output).lower().endswith(".gif"):
        raise click.UsageError("-o must name a .gif file")
    try:
        run = simulate(col, clip, radius_fraction=radius, substeps=substeps)
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    try:
        n = render_gif(col, run, output)
    except OSError as e:
        raise click.ClickException(f"cannot write {output}: {e}") from None
    r = run.radius
    landed = f"landed at t={run.landed_at:g}" if run.landed_at is not None else "never landed"
    click.echo(f"play {os.path.basename(asset)} clip {clip!r}: {len(run.times)} frames, radius {r:.4g}, "
               f"{landed}, standing {int(run.grounded.sum())}/{len(run.times)} frames")
    click.echo(f"largest penetration {run.max_penetration:.4g} ({run.max_penetration / r:.1%} of radius)")
    click.echo(f"largest slip relative to the surface {run.max_slip:.4g} per frame "
               f"({run.max_slip / r:.1%} of radius)")
    click.echo(f"wrote {output} ({n} frames)")
