"""The plain ``colossus play`` run (thesis 5.5): a player sphere dropped above the top of the
animated model, left to fall, land and ride the surface for one pass of the clip.

It is the default script of :mod:`runtime.script` played by :mod:`runtime.controller` (discrete
collision resolution, momentum inheritance through the contacts' barycentric positions); this
module only keeps the original entry point.  Library code only (no printing).
"""

from __future__ import annotations

from .collider import Collider
from .script import Run, default_script, run_script, start_position

__all__ = ["simulate", "start_position", "Run"]


def simulate(col: Collider, clip: str, radius_fraction: float = 0.035, substeps: int = 4,
             drop_fraction: float = 0.15, resolve_passes: int = 4) -> Run:
    """Drop a player sphere (radius = ``radius_fraction`` x model size) ``drop_fraction`` x model
    size above the top of the model and play ``clip`` once at ``substeps`` controller steps per
    frame, at most ``resolve_passes`` resolution queries per sub-step."""
    times = col.frame_times(clip)
    if len(times) < 2:
        raise ValueError(f"clip {clip!r} has {len(times)} frames; need at least 2")
    script = default_script(col, clip, substeps=substeps, drop=drop_fraction)
    script.controller = {"max_iterations": resolve_passes}
    return run_script(col, script, clip, radius_fraction=radius_fraction)
