"""colossus validators: prove collider assets correct (``colossus validate``).

Public API::

    from colossus.validators import check_asset
    report = check_asset("boss.usda", select=None, ignore=["COL404"], subframes=2)
    report.passed, report.findings   # Finding(code, severity, message, rule, location)

and the frame-proof kernels in :mod:`validators.frameproof` (``skin_frames``,
``part_farthest``, ``skinning_transforms``, ``world_spheres``, ``prove``).
"""

from .findings import AssetReport, Finding
from .registry import RuleSelector, all_rules, get_rule


def check_asset(path_or_stage, select=None, ignore=None, severities=None, **options):
    from .runner import check_asset as _check
    return _check(path_or_stage, select=select, ignore=ignore, severities=severities, **options)


check_asset.__doc__ = """Run every selected rule on one asset (see :func:`validators.runner.check_asset`)."""


def require_passing(path):
    from .runner import require_passing as _require
    return _require(path)


require_passing.__doc__ = """Raise ``runtime.ColliderError`` when ``path`` (or a ``Usd.Stage``) has an error
finding (see :func:`validators.runner.require_passing`); the verifier for
``runtime.load_collider(path, verify=...)``, which hands it the stage it read (the file is read once)."""
require_passing.accepts_stage = True

__all__ = ["check_asset", "require_passing", "AssetReport", "Finding", "RuleSelector", "all_rules", "get_rule"]
