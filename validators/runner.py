"""Running the rules on one asset (:func:`check_asset`); many assets: :mod:`validators.parallel`."""

from __future__ import annotations

import os
import time
import traceback
from pathlib import Path

from pxr import Tf, Usd

from colossus.pipeline.errors import one_line

from . import tolerances as tol
from .asset import LoadedAsset, open_layer, open_stage
from .findings import SEVERITIES, AssetReport, Finding
from .registry import RuleSelector, get_rule

#: COL001 messages of an asset usd-core cannot open, and of one whose prims cannot be read.
OPEN_FAILED = "usd-core cannot open the asset: {}"
READ_FAILED = "the asset could not be read: {}"

DEFAULT_OPTIONS = {
    "max_influences": tol.MAX_INFLUENCES,
    "subframes": 0,
    "continuous": True,
    "slack_ratio": tol.SLACK_RATIO,
    "chunk_frames": None,
    "clip_proofs": None,
    "max_deviation": None,
    "source": None,
}


class Context:
    """Options shared by the rules of one asset, and the cached frame proof.

    Attributes: ``max_influences`` (int), ``subframes`` (int), ``slack_ratio`` (float),
    ``max_deviation`` (``(length, relative)`` or None: COL701's limit),
    ``chunk_frames`` (int or None: automatic), ``source`` (the export the asset was made from, for
    the COL6xx rules; None: they do not run), ``clip_proofs`` (proofs of the asset's clips
    already run elsewhere, e.g. one per clip on other workers, merged instead of proving again;
    see :mod:`validators.parallel`).
    """

    def __init__(self, asset, **options):
        unknown = set(options) - set(DEFAULT_OPTIONS)
        if unknown:
            raise TypeError(f"unknown option(s): {', '.join(sorted(unknown))}")
        opts = {**DEFAULT_OPTIONS, **options}
        if int(opts["subframes"]) < 0:
            raise ValueError(f"subframes: expected >= 0, got {opts['subframes']}")
        if int(opts["max_influences"]) < 1:
            raise ValueError(f"max_influences: expected >= 1, got {opts['max_influences']}")
        self.asset = asset
        self.max_influences = int(opts["max_influences"])
        self.subframes = int(opts["subframes"])
        self.continuous = bool(opts["continuous"])
        self.slack_ratio = float(opts["slack_ratio"])
        self.chunk_frames = opts["chunk_frames"]
        self.clip_proofs = opts["clip_proofs"]
        from colossus.pipeline.options import parse_max_deviation
        #: ``(length, relative)`` or None: the COL701 limit (``--max-deviation``)
        self.max_deviation = parse_max_deviation(opts["max_deviation"])
        self.source = opts["source"]
        self._proof = None
        self._source_check = None

    def source_check(self):
        """The comparison with the ``source`` export (:func:`validators.source.compare_source`), once."""
        if self._source_check is None:
            from .source import compare_source
            self._source_check = compare_source(self.asset, self.source)
        return self._source_check

    def proof(self):
        if self._proof is None:
            from .frameproof import merge_proofs, prove
            if self.clip_proofs is not None:
                self._proof = merge_proofs(self.asset, self.clip_proofs, subframes=self.subframes)
            else:
                self._proof = prove(self.asset, subframes=self.subframes, chunk_frames=self.chunk_frames,
                                    continuous=self.continuous)
        return self._proof


def _finding(code, message, severities=None, **location):
    r = get_rule(code)
    sev = (severities or {}).get(code, r.severity)
    return Finding(code, sev, message, r.name, location)


def _check_severities(severities):
    for code, sev in (severities or {}).items():
        if sev not in SEVERITIES:
            raise ValueError(f"severity for {code}: expected one of {SEVERITIES}, got {sev!r}")
        get_rule(code)


def check_asset(path_or_stage, select=None, ignore=None, severities=None, **options) -> AssetReport:
    """Run every selected rule on one asset; never raises for a bad asset.

    Parameters
    ----------
    path_or_stage : str, os.PathLike or pxr.Usd.Stage
    select, ignore : list of str, optional
        Codes or prefixes (``"COL4"``, ``"COL403"``); the longest matching prefix wins, ignore
        on a tie.  Default: everything.
    severities : dict, optional
        ``code -> "error" | "warning" | "info"`` overrides.
    **options
        ``max_influences`` (4), ``subframes`` (0), ``continuous`` (True: certify every time between
        frames), ``slack_ratio`` (1.5), ``chunk_frames`` (auto), ``max_deviation`` (None; ``"0.02"``
        stage units or ``"1%"`` of the model size: COL701).

    Returns
    -------
    AssetReport
        ``.passed`` is False when any finding has severity error.
    """
    selector = RuleSelector(select, ignore)
    _check_severities(severities)
    Context(None, **options)  # validate options before touching the asset
    t0 = time.perf_counter()
    if isinstance(path_or_stage, Usd.Stage):
        path = path_or_stage.GetRootLayer().identifier
        stage = path_or_stage
    else:
        path = os.fspath(path_or_stage)
        stage = None
    report = AssetReport(path)

    def add(code, message, **loc):
        if selector.enabled(code):
            report.findings.append(_finding(code, message, severities, **loc))

    if stage is None:
        if not os.path.isfile(path) or not os.access(path, os.R_OK):
            add("COL003", f"{path} does not exist or is not a readable file")
            report.sort()
            return report
        try:  # parsed once: held while its references are listed and the stage is opened on it
            layer = open_layer(path)
            refs = external_references(path)
        except Exception as e:  # not composed: usd-core composes what it parsed of a broken layer
            add("COL001", OPEN_FAILED.format(one_line(e)))
            report.sort()
            return report
        if refs:  # read from the layer alone: nothing it names is opened
            shown = ", ".join(repr(r) for r in refs[:5]) + (f" (+{len(refs) - 5} more)" if len(refs) > 5 else "")
            add("COL004", f"names {len(refs)} other file(s), not read: {shown}")
            report.sort()
            return report
        try:
            stage = open_stage(path, layer)
        except Exception as e:  # usd-core raises Tf.ErrorException and friends
            add("COL001", OPEN_FAILED.format(one_line(e)))
            report.sort()
            return report
    try:
        asset = LoadedAsset(stage, path)
    except Exception as e:
        add("COL001", READ_FAILED.format(one_line(e)))
        report.sort()
        return report
    ctx = Context(asset, **options)
    t_load = time.perf_counter() - t0
    def undecodable(code, e):  # usd-core cannot decode what is read: a corrupt asset, not a rule bug
        if not any(f.code == "COL001" for f in report.findings):
            add("COL001", f"usd-core cannot read the asset's values (needed by {code}): {one_line(e)}")

    for rule in selector.rules():
        if rule.func is None:
            continue
        try:  # readiness reads values too (every clip sample, for the frame proof)
            blocked = next((asset.ready(n)[1] for n in rule.needs if not asset.ready(n)[0]), None)
        except Tf.ErrorException as e:
            undecodable(rule.code, e)
            report.skipped[rule.code] = "usd-core cannot read what it needs"
            continue
        if blocked is not None:
            report.skipped[rule.code] = blocked
            continue
        report.rules_run.append(rule.code)
        try:
            for h in rule.func(asset, ctx):
                sev = (severities or {}).get(rule.code, rule.severity)
                report.findings.append(Finding(rule.code, sev, h["message"], rule.name,
                                               {k: v for k, v in h["location"].items() if v is not None},
                                               h["sort_key"]))
        except Tf.ErrorException as e:
            undecodable(rule.code, e)
        except Exception as e:
            tb = traceback.extract_tb(e.__traceback__)[-1]
            add("COL002", f"rule {rule.code} ({rule.name}) crashed: {type(e).__name__}: {one_line(e)} "
                          f"[{Path(tb.filename).name}:{tb.lineno}]", validator=rule.code)
    report.stats = _stats(asset, ctx, t_load, time.perf_counter() - t0)
    locate_prims(report, asset)
    report.sort()
    return report


#: Families whose findings are about the collision mesh (its points, faces, skin, parts, proxy,
#: motion against the source) when the rule names no prim of its own.
_MESH_FAMILIES = ("COL2", "COL3", "COL4", "COL6", "COL7")


def locate_prims(report: AssetReport, asset: LoadedAsset | None) -> None:
    """Give every finding of ``report`` a ``prim`` location (the USD prim path it is about) when
    its rule named none: the clip's ``SkelAnimation`` for a finding about one clip, the collision
    mesh for the mesh, skin, parts, source and proxy families (COL2-4, COL6, COL7), the
    ``Skeleton`` for a joint, else the ``SkelRoot`` (the asset as a whole); ``/`` (the layer's
    pseudo-root) when the asset has none of these or could not be read."""
    clips = {}
    if asset is not None:
        for c in getattr(asset, "clips", None) or []:
            try:
                clips[c.name] = str(c.prim.GetPath())
            except Exception:
                pass

    def path_of(prim):
        try:
            return str(prim.GetPath()) if prim is not None and prim.IsValid() else None
        except Exception:
            return None

    mesh = path_of(getattr(asset, "mesh", None))
    skel = path_of(getattr(asset, "skeleton", None))
    root = path_of(getattr(asset, "root", None))
    for f in report.findings:
        if f.location.get("prim"):
            continue
        where = None
        if f.location.get("clip") in clips:
            where = clips[f.location["clip"]]
        elif f.code.startswith(_MESH_FAMILIES):
            where = mesh
        elif f.location.get("joint") is not None:
            where = skel
        f.location["prim"] = where or root or mesh or "/"


def unreadable_report(path, message: str, select=None, ignore=None, severities=None, **options) -> AssetReport:
    """The report :func:`check_asset` gives an asset it cannot open or read (``message``: its
    ``COL001``, :data:`OPEN_FAILED` or :data:`READ_FAILED`), for a caller that already tried to
    read it elsewhere (``validators.parallel``'s contained read) and need not read it twice."""
    selector = RuleSelector(select, ignore)
    report = AssetReport(os.fspath(path))
    if selector.enabled("COL001"):
        report.findings.append(_finding("COL001", message, severities))
    report.sort()
    return report


def external_references(path) -> list:
    """The asset paths the layer ``path`` names (:func:`runtime.references.layer_references`).

    Raises what usd-core raises on a layer it cannot parse: the caller reports that as ``COL001``
    and never composes the layer, for ``Usd.Stage.Open`` composes what it did parse of a broken
    text layer, sublayers included, before it fails (fuzz campaign 12, case 1193: a sublayer
    naming a FIFO beside a broken asset hung ``validate``)."""
    from colossus.runtime.references import layer_references

    return layer_references(path)


def require_passing(path) -> AssetReport:
    """Run every rule on ``path`` (a path, or a ``Usd.Stage`` already read: ``load_collider``
    hands over the stage it read) and raise :class:`runtime.ColliderError` (one line listing the
    first error findings) when any has severity error; the verifier game code hands to
    ``runtime.load_collider(path, verify=require_passing)``.  Returns the report otherwise."""
    from colossus.runtime.errors import ColliderError

    report = check_asset(path)
    errs = [f for f in report.findings if f.severity == "error"]
    if errs:
        listing = "; ".join(f"{f.code} {f.message}" for f in errs[:5])
        more = f" (+{len(errs) - 5} more)" if len(errs) > 5 else ""
        raise ColliderError(one_line(f"{report.path}: fails verification: {listing}{more}", limit=1000))
    return report


require_passing.accepts_stage = True


def _stats(asset, ctx, t_load, t_total) -> dict:
    s = {
        "vertices": asset.n,
        "faces": 0 if asset.face_counts is None else len(asset.face_counts),
        "joints": len(asset.joints or []),
        "parts": len(asset.part_joints or []),
        "clips": {c.name: len(c.times) for c in asset.clips},
        "load_seconds": round(t_load, 4),
        "seconds": round(t_total, 4),
    }
    if ctx._proof is not None:
        s["frameproof"] = ctx._proof.stats()
    else:
        try:
            ok, why = asset.ready("proof")
        except Tf.ErrorException:
            ok, why = False, "usd-core cannot read the asset's values"
        s["frameproof"] = {"checked": [], "not_checked": [
            "the frame proof did not run: " + (why if not ok else "COL403/COL404/COL407 not selected")]}
    return s


# ------------------------------------------------------------------------------ many paths
# Many assets run through :func:`validators.parallel.check_many` (processes, Dask, retries).


def _crash_report(path, e, kw):
    rep = AssetReport(path)
    rep.findings.append(_finding("COL001", f"checking the asset crashed: {one_line(e)}", kw.get("severities")))
    return rep
