"""Finding and report records (after glTF-Validator's ``Issue``): findings are data, never exceptions.

A :class:`Finding` is one thing wrong with one asset, with location fields where they apply.
An :class:`AssetReport` holds every finding of one asset plus statistics, including what the
frame proof did and did not check.
"""

from __future__ import annotations

from dataclasses import dataclass, field

SEVERITIES = ("error", "warning", "info")
#: Sort key: errors first.
SEVERITY_RANK = {s: i for i, s in enumerate(SEVERITIES)}

#: Location fields a finding may carry, in report order (the contract's JSON names).
LOCATION_FIELDS = ("prim", "clip", "time", "interval", "frame", "part", "joint", "vertex", "face", "excess",
                   "fraction", "ratio", "count", "validator")


@dataclass
class Finding:
    """One finding.

    Attributes
    ----------
    code : str
        Stable rule code, e.g. ``"COL403"``.
    severity : {"error", "warning", "info"}
    message : str
        One readable sentence.
    rule : str
        The rule's name (kebab-case), e.g. ``"holds-on-all-frames"``.
    location : dict
        Any of :data:`LOCATION_FIELDS`: ``clip`` (name), ``time`` (time code), ``frame`` (index in
        the clip), ``interval`` ([t0, t1] time codes of a finding between frames), ``part`` (index),
        ``joint`` (name), ``vertex`` / ``face`` (index), ``excess``
        (stage units), ``fraction`` (excess / radius), ``ratio``, ``prim`` (path) ...
    sort_key : float
        Larger is worse; findings of one rule are listed worst first.
    """

    code: str
    severity: str
    message: str
    rule: str = ""
    location: dict = field(default_factory=dict)
    sort_key: float = 0.0

    def __getattr__(self, name):  # finding.clip, finding.vertex ... (None when not set)
        if name in LOCATION_FIELDS:
            return self.__dict__.get("location", {}).get(name)
        raise AttributeError(name)

    def to_dict(self) -> dict:
        d = {"code": self.code, "severity": self.severity, "message": self.message, "rule": self.rule,
             "prim": self.prim_path}
        for k in LOCATION_FIELDS[1:]:
            if k in self.location and self.location[k] is not None:
                d[k] = self.location[k]
        return d

    @property
    def prim_path(self) -> str:
        """The USD prim path the finding is about (``/``, the layer itself, when none applies:
        an asset that could not be read)."""
        return str(self.__dict__.get("location", {}).get("prim") or "/")

    def where(self) -> str:
        """The location fields but the prim (:attr:`prim_path`) as ``key=value`` text."""
        parts = []
        for k in LOCATION_FIELDS[1:]:
            v = self.location.get(k)
            if v is None:
                continue
            if isinstance(v, float):
                v = f"{v:.4g}"
            parts.append(f"{k}={v}")
        return " ".join(parts)


@dataclass
class AssetReport:
    """Every finding of one asset.

    Attributes
    ----------
    path : str
    findings : list of Finding
        Sorted: errors first, then by code, each rule's findings worst first.
    stats : dict
        Counts (vertices, faces, joints, parts, clips, frames), timings, and ``frameproof``:
        what the frame proof checked (``checked``) and did not (``not_checked``).
    skipped : dict
        ``code -> reason`` for rules that could not run because what they read is broken
        (the broken thing has its own finding).
    """

    path: str
    findings: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)
    rules_run: list = field(default_factory=list)

    @property
    def passed(self) -> bool:
        """True when no finding has severity ``error``."""
        return not any(f.severity == "error" for f in self.findings)

    def codes(self) -> set:
        return {f.code for f in self.findings}

    def by_code(self, code: str) -> list:
        return [f for f in self.findings if f.code == code]

    def to_dict(self) -> dict:
        stats = dict(self.stats)
        if self.skipped:
            stats["skipped"] = dict(self.skipped)
        return {"path": self.path, "passed": self.passed,
                "findings": [f.to_dict() for f in self.findings], "stats": stats}

    def sort(self) -> None:
        self.findings.sort(key=lambda f: (SEVERITY_RANK.get(f.severity, 9), f.code, -f.sort_key))


def summary_line(reports) -> str:
    """``N assets, P passed, F failed`` for a list of :class:`AssetReport`."""
    n = len(reports)
    passed = sum(r.passed for r in reports)
    return f"{n} assets, {passed} passed, {n - passed} failed"
