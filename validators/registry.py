"""The one table of rules (after ruff's ``codes.rs`` and OpenUSD's ``usdValidation`` registry).

Every rule is a small function registered with :func:`rule`::

    @rule("COL201", "triangles-only", "error", "The runtime ray-casts triangles only.",
          needs=("mesh_raw",))
    def triangles_only(asset, ctx):
        '''What: ... Why: ... Example: ...'''
        for face in bad_faces:
            yield hit("face 3 has 4 vertices", face=3)

A rule yields :func:`hit` records; the runner stamps them with the code and severity.  A rule
that raises becomes a ``COL002`` checker error naming the rule, kept apart from failed checks.
``needs`` names what the rule reads (see :meth:`validators.asset.LoadedAsset.ready`); when that is
broken the rule is skipped, with the reason, and the broken thing has its own finding.

Codes are stable and never reused: a retired rule stays in the table with ``removed=True``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Callable

from .findings import SEVERITIES

#: Families in code order: (prefix, module, title).
FAMILIES = (
    ("COL0", "colossus.validators.rules.general", "General: reading the asset, checker errors"),
    ("COL1", "colossus.validators.rules.structure", "Structure: prims, metadata, parts attributes"),
    ("COL2", "colossus.validators.rules.mesh", "Mesh: the triangle geometry"),
    ("COL3", "colossus.validators.rules.skin", "Skin: joint influences and bind pose"),
    ("COL4", "colossus.validators.rules.parts", "Parts: spheres that must hold on every frame"),
    ("COL5", "colossus.validators.rules.animation", "Animation: the clips"),
    ("COL6", "colossus.validators.rules.source", "Source: the asset against the export it was made from (`--source`)"),
    ("COL7", "colossus.validators.rules.proxy", "Proxy: a simplified collision mesh and its deviation"),
)


@dataclass(frozen=True)
class Rule:
    """Metadata and check function of one rule."""

    code: str
    name: str
    severity: str
    summary: str
    func: Callable | None = None
    needs: tuple = ()
    removed: bool = False
    doc: str = field(default="", compare=False)

    @property
    def family(self) -> str:
        return self.code[:4]


_RULES: dict[str, Rule] = {}


def rule(code: str, name: str, severity: str, summary: str, needs=(), removed=False, doc=None):
    """Register the decorated function as rule ``code`` (``None``: a finding the runner makes)."""
    if severity not in SEVERITIES:
        raise ValueError(f"rule {code}: severity must be one of {SEVERITIES}, got {severity!r}")

    def deco(func):
        if code in _RULES:
            raise ValueError(f"rule code {code} registered twice ({_RULES[code].name}, {name})")
        text = doc if doc is not None else (func.__doc__ or "") if func else ""
        _RULES[code] = Rule(code, name, severity, summary, func, tuple(needs), removed, text.strip())
        return func

    return deco


def hit(message: str, sort_key: float = 0.0, **location) -> dict:
    """A finding without code and severity (the runner adds them)."""
    return {"message": message, "sort_key": float(sort_key), "location": location}


def _load() -> None:
    for _, mod, _ in FAMILIES:
        importlib.import_module(mod)


def all_rules(include_removed: bool = False) -> list[Rule]:
    """Every registered rule, sorted by code."""
    _load()
    return [r for _, r in sorted(_RULES.items()) if include_removed or not r.removed]


def get_rule(code: str) -> Rule:
    _load()
    return _RULES[code]


class RuleSelector:
    """Decides which codes are on (flake8's ``DecisionEngine``): the longest matching prefix
    among ``select`` and ``ignore`` wins; on a tie ``ignore`` wins.  ``select=None`` means
    ``["COL"]`` (everything)."""

    def __init__(self, select=None, ignore=None):
        self.select = tuple(s.strip().upper() for s in (select if select else ["COL"]) if s.strip())
        self.ignore = tuple(s.strip().upper() for s in (ignore or ()) if s.strip())
        known = [r.code for r in all_rules(include_removed=True)]
        for p in self.select + self.ignore:
            if not any(c.startswith(p) for c in known):
                raise ValueError(f"unknown rule code or prefix {p!r}")

    def enabled(self, code: str) -> bool:
        s = max((len(p) for p in self.select if code.startswith(p)), default=-1)
        i = max((len(p) for p in self.ignore if code.startswith(p)), default=-1)
        return s > i

    def rules(self) -> list[Rule]:
        return [r for r in all_rules() if self.enabled(r.code)]
