"""A player run on an animated collider as a GIF (``colossus play``): the body, the player sphere
coloured by its controller state, a label per frame."""

from __future__ import annotations

import os

import numpy as np

from .draw import offscreen_pyvista

#: Largest number of GIF frames; longer clips are subsampled.
MAX_FRAMES = 60
#: The player's colour in the GIF, by controller state.
STATE_COLOURS = {"standing": "#3a9e4f", "sliding": "#e08a1e", "holding": "#2f6fd0",
                 "hanging": "#8e3fc0", "falling": "#d0312d"}
#: The player's colour on a frame where the moving body pushed it (since the previous frame shown).
PUSHED_COLOUR = "#f2c200"


def frame_colour(run, prev, i):
    """(pushed, colour) of the player on the frame of step ``i`` when the previous frame shown was
    step ``prev``: :data:`PUSHED_COLOUR` when the moving body pushed it on a step in between, else
    its state's colour."""
    pushed = getattr(run, "pushed", None)
    hit = pushed is not None and bool(np.any(pushed[prev + 1:i + 1]))
    return hit, PUSHED_COLOUR if hit else STATE_COLOURS.get(str(run.states[i]), "#3a9e4f")


def render_run_gif(col, run, path, size=(480, 360), max_frames=MAX_FRAMES):
    """Write the run as an animated GIF (offscreen; starts a virtual X server only if needed)."""
    pv = offscreen_pyvista()
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
    prev = -1
    for i in idx:
        pose = col.pose(run.clip, run.times[i], out=pose)
        mesh.points = pose.points.astype(np.float64)
        ball.points = ball_pts + run.positions[i]
        state = str(run.states[i])
        hit, colour = frame_colour(run, prev, i)
        prev = i
        ball_actor.prop.color = colour
        text = f"{run.clip}  t={run.times[i]:.4g}  {state}" + ("  pushed" if hit else "")
        if state in ("holding", "hanging"):
            text += f"  energy {run.energy[i]:.0%}"
        if hasattr(label, "set_text"):  # a CornerAnnotation (pyvista >= 0.43)
            label.set_text("upper_left", text)
        elif hasattr(label, "SetInput"):
            label.SetInput(text)
        pl.write_frame()
    pl.close()
    return len(idx)
