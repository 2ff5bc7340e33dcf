"""The import stages, each a plain function ``stage(mesh, ...) -> (new_mesh, StageReport)``.

They are chained in one visible place, :func:`pipeline.run.import_asset`:

    bake -> weld -> degenerate -> orient -> bind -> [simplify] -> parts -> quantize -> spheres -> write
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class StageReport:
    """What a stage did: counts for the summary table and human-readable warnings.

    ``counts`` holds plain JSON-able numbers (ints, floats, lists of them); ``details`` holds
    anything larger (e.g. per-part sphere radii) for ``--json``; ``seconds`` is filled in by
    the runner.
    """

    stage: str
    counts: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    details: dict = field(default_factory=dict)
    seconds: float = 0.0
