"""A player sphere on an animated collider (thesis 5.5): falls under gravity, lands, stands and
is carried along by the skin.

* Discrete collision resolution (5.5.2): the contacts' resolve vectors ``normal * depth`` are
  averaged and the player moved by the average (a few passes per step).
* Momentum inheritance (5.5.3): while standing, the contacts are kept as barycentric points on
  their triangles; at the next step the player moves by the mean displacement of those points.

Library code only (no printing); :mod:`runtime.cli` drives it and renders.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .collider import Collider, SurfacePoints

GRAVITY = 9.81  # m/s^2
MAX_SLOPE_COS = np.cos(np.radians(55.0))  # steeper contacts do not count as standing
SKIN = 0.05  # standing test radius = radius * (1 + SKIN)


@dataclass
class PlayerRun:
    """Trajectory of one run, one row per clip frame (after the frame's substeps).

    times (N,) time codes, positions (N, 3), grounded (N,) bool, penetration (N,) largest
    remaining depth at the end of the frame, slip (N,) largest move of the player relative to
    the surface points it stood on during the frame (stage units)."""

    clip: str
    radius: float
    times: np.ndarray
    positions: np.ndarray
    grounded: np.ndarray
    penetration: np.ndarray
    slip: np.ndarray
    landed_at: float | None = None
    notes: list = field(default_factory=list)

    @property
    def max_penetration(self) -> float:
        return float(self.penetration.max()) if len(self.penetration) else 0.0

    @property
    def max_slip(self) -> float:
        return float(self.slip.max()) if len(self.slip) else 0.0


def start_position(col: Collider, clip: str, radius: float, drop: float) -> np.ndarray:
    """Above the most upward-facing spot near the middle of the model on the clip's first frame."""
    t0 = col.frame_times(clip)[0] if clip is not None else 0.0
    pose = col.pose(clip, t0)
    up = col.up
    pts = pose.points.astype(np.float64)
    lo, hi = pts.min(0), pts.max(0)
    # a grid of downward rays over the footprint
    axes = [i for i in range(3) if up[i] == 0]
    g = np.linspace(0.15, 0.85, 15)
    u, v = np.meshgrid(g, g)
    o = np.zeros((u.size, 3))
    o[:, axes[0]] = lo[axes[0]] + u.ravel() * (hi - lo)[axes[0]]
    o[:, axes[1]] = lo[axes[1]] + v.ravel() * (hi - lo)[axes[1]]
    top = float((pts @ up).max())
    o += up * (top + 1.0)
    hits = pose.raycast(o, np.repeat(-up[None], len(o), 0))
    ok = hits.hit
    if not ok.any():
        return pts.mean(0) + up * (top - pts.mean(0) @ up + drop + radius)
    n = np.abs(hits.normal[ok] @ up)
    centre = (lo + hi) / 2
    off = np.linalg.norm((hits.point[ok] - centre) - np.outer(hits.point[ok] @ up - centre @ up, up), axis=1)
    score = n - 0.5 * off / max(np.linalg.norm(hi - lo), 1e-12)
    best = hits.point[ok][np.argmax(score)]
    return best + up * (radius + drop)


def simulate(col: Collider, clip: str, radius_fraction: float = 0.035, substeps: int = 4,
             drop_fraction: float = 0.15, resolve_passes: int = 3) -> PlayerRun:
    """Drop a player sphere (radius = ``radius_fraction`` x model size) on ``clip``."""
    times = col.frame_times(clip)
    if len(times) < 2:
        raise ValueError(f"clip {clip!r} has {len(times)} frames; need at least 2")
    size = col.size()
    r = radius_fraction * size
    up = col.up
    g = -up * GRAVITY / col.data.meters_per_unit  # stage units / s^2
    tcps = col.data.time_codes_per_second
    pos = start_position(col, clip, r, drop_fraction * size)
    vel = np.zeros(3)
    pa, pb = col.pose(clip, times[0]), col.pose(clip, times[0])
    anchors: SurfacePoints | None = None
    anchor_pts = None
    out_pos, out_ground, out_pen, out_slip = [], [], [], []
    landed = None
    grounded = False
    for i, t_frame in enumerate(times):
        frame_slip = 0.0
        steps = [t_frame] if i == 0 else list(np.linspace(times[i - 1], t_frame, substeps + 1)[1:])
        for t in steps:
            dt = (t - pa.time) / tcps
            pb = col.pose(clip, t, out=pb)
            carried = pos.copy()
            if anchors is not None:  # momentum inheritance: ride the surface points
                carried = pos + (anchors.at(pb) - anchor_pts).mean(0)
            pos = carried
            if not grounded:
                vel = vel + g * dt
                pos = pos + vel * dt
            for _ in range(resolve_passes):  # discrete resolution: average the resolve vectors
                cs = pb.sphere_contacts(pos, r)
                if len(cs) == 0:
                    break
                pos = pos + cs.resolve_vector()
                n = cs.normal.mean(0)
                if vel @ n < 0:
                    vel = vel - (vel @ n) * n
            if anchors is not None and grounded:
                frame_slip = max(frame_slip, float(np.linalg.norm(pos - carried)))
            stand = pb.sphere_contacts(pos, r * (1 + SKIN))
            feet = stand.normal @ up > MAX_SLOPE_COS if len(stand) else np.zeros(0, bool)
            if feet.any():
                if not grounded and landed is None:
                    landed = float(t)
                grounded = True
                anchors = SurfacePoints(stand.triangle[feet], stand.barycentric[feet])
                anchor_pts = anchors.at(pb)
                vel = np.zeros(3)
            else:
                if grounded and anchors is not None and dt > 0:  # leave with the surface's velocity
                    vel = (anchors.at(pb) - anchor_pts).mean(0) / dt
                grounded = False
                anchors = None
            pa, pb = pb, pa
        cs = pa.sphere_contacts(pos, r)
        out_pos.append(pos.copy())
        out_ground.append(grounded)
        out_pen.append(float(cs.depth.max()) if len(cs) else 0.0)
        out_slip.append(frame_slip)
    return PlayerRun(clip=clip, radius=r, times=times.copy(), positions=np.array(out_pos),
                     grounded=np.array(out_ground), penetration=np.array(out_pen),
                     slip=np.array(out_slip), landed_at=landed)
