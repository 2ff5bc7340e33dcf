"""``colossus validate`` on many assets: ``--jobs N`` processes or ``--scheduler`` (Dask), with
very large assets split into one frame-proof task per clip.

The distribution machinery (backends, retries, Ctrl-C, progress) is :mod:`pipeline.engine`;
this module holds the validator's work units and the merge:

================= ===========================================================================
unit              does (in a worker)
================= ===========================================================================
``unit_check``    every rule on one asset (``check_asset``): the usual unit
``unit_plan``     for an asset of at least ``split_bytes``: the clip names to split by (or
                  None: the asset is not provable, or has fewer than two clips)
``unit_clip``     the frame proof of one clip of that asset
``unit_finish``   every rule on that asset, the frame proof merged from the clip proofs
                  (:func:`validators.frameproof.merge_proofs`: identical to proving it whole)
================= ===========================================================================

Reports come back in any order and are put in input order (directories expanded sorted), so
every format (text, JSON, JUnit) is the same as a ``--jobs 1`` run, timing fields aside
(:func:`comparable`).  A unit whose worker dies is retried once, alone; if it dies again the
asset gets a ``COL001`` finding ("checking the asset crashed") and every other asset keeps its
result.  Ctrl-C returns what finished; :func:`validators.report.render` marks such a report incomplete.
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import dataclass, field

from colossus.pipeline.engine import Engine, InlineBackend, Progress, Task, expand_inputs, make_backend
from colossus.pipeline.isolation import ChildFailed, contained, usd_is_serial, usd_serial
from colossus.pipeline.readers import USD_EXTENSIONS

from .runner import OPEN_FAILED, READ_FAILED, _crash_report, check_asset, unreadable_report

#: Assets at least this large (bytes on disk) are split by clip across workers.
SPLIT_BYTES = 64 * 2**20

#: Rules that read the frame proof: splitting only pays when one of them is selected.
PROOF_RULES = ("COL403", "COL404", "COL407")


# ------------------------------------------------------------------------------ work units
def _quiet():
    """A unit's context, in whatever process runs it (the command's, a pool or Dask worker):
    usd-core's warnings collected, not printed, the last unit's dropped, and what usd-core and
    boost.python write to file descriptor 2 kept off the terminal (:mod:`runtime.usdlog`): what
    usd-core has to say about an asset becomes a finding, never extra lines."""
    from colossus.runtime import usdlog
    usdlog.silence()
    usdlog.take()
    return usdlog.quiet_stderr()


def unit_check(path, kw):
    with _quiet():
        return check_asset(path, **kw)


#: Seconds the contained read of one crate asset may take (``--jobs 1``; see :func:`unit_check_contained`).
PROBE_TIMEOUT = 600.0


def is_crate(path) -> bool:
    """Whether ``path`` holds binary crate data (``.usdc``, ``.usdz``, or a ``.usd`` in crate form)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError:
        return False
    return head == b"PXR-USDC" or head[:4] == b"PK\x03\x04"


def _probe(path):
    with _quiet():  # COLOSSUS_ISOLATE=0 runs it in this process: usd-core's chatter stays off stderr
        return _probe_read(path)


def _probe_read(path):
    """Read everything of the asset that usd-core decodes natively: the stage, the arrays
    :class:`validators.asset.LoadedAsset` reads, and every time sample of every clip (crate
    values are decoded lazily, on first read).  Returns None, or the ``COL001`` message of
    :func:`check_asset` when the asset cannot be opened or read (so it is not read twice)."""
    from colossus.pipeline.errors import one_line

    from .asset import CLIP_ATTRS, LoadedAsset, open_layer, open_stage
    from .runner import external_references
    try:  # parsed once: held while its references are listed and the stage is opened on it
        layer = open_layer(path)
        if external_references(path):
            return None  # check_asset reports COL004 without opening the stage
    except Exception as e:  # a layer Sdf cannot parse is never composed (check_asset: COL001)
        return OPEN_FAILED.format(one_line(e))
    try:
        stage = open_stage(path, layer)
    except Exception as e:
        return OPEN_FAILED.format(one_line(e))
    try:
        asset = LoadedAsset(stage, path)
    except Exception as e:
        return READ_FAILED.format(one_line(e))
    try:
        for clip in asset.clips:
            for name in CLIP_ATTRS:
                attr = clip.prim.GetAttribute(name)
                if attr:
                    for t in clip.times:
                        attr.Get(float(t))
    except Exception:
        pass  # the rules report undecodable values (COL001) along with everything else
    return None


def unit_check_contained(path, kw):
    """``--jobs 1``: :func:`unit_check`, after a contained read of a crate asset.

    usd-core decodes a crate file (LZ4, compressed integers, offsets) in C++ in this process; a
    hostile one can crash it natively, which would end the whole run with no report.  So a crate
    asset is first read in a forked child (:func:`pipeline.isolation.contained`): if that child
    dies, the asset gets a ``COL001`` finding and the other assets are still checked; if it
    lives, the asset is checked here as usual (one that cannot even be opened gets the report
    :func:`check_asset` would give, without being read again: a corrupt crate can make usd-core
    allocate gigabytes before it gives up).  Text assets (``.usda``) are parsed completely when
    opened, by a parser that has not been seen to crash, and are not read twice.  With
    ``--jobs > 1`` the worker processes are the containment (the engine retries, then reports).
    """
    if is_crate(path) and os.access(path, os.R_OK):
        try:
            # no stall watch when usd-core is serial (check_many's --jobs 1 run is): the child
            # cannot have inherited a usd-core lock, so a sleeping child is a real hang
            message = contained(_probe, path, path=path, timeout=PROBE_TIMEOUT, watch=not usd_is_serial())
        except ChildFailed as e:
            what = "reading it took too long" if e.timed_out else f"usd-core crashed reading it ({e})"
            return _crash_report(path, what, kw)
        if message is not None:  # cannot be opened or read: the same report check_asset gives
            return unreadable_report(path, message, **kw)
    return unit_check(path, kw)


def unit_plan(path, kw):
    with _quiet():
        return _plan(path, kw)


def _plan(path, kw):
    from .asset import LoadedAsset, open_stage
    from .runner import external_references
    try:
        if external_references(path):  # never composed: unit_check reports COL004 (or COL001)
            return None
        asset = LoadedAsset(open_stage(path), path)
        if not asset.ready("proof")[0]:
            return None
        names = [c.name for c in asset.clips]
    except Exception:
        return None  # unit_check reports it
    if len(names) < 2 or len(set(names)) != len(names):
        return None
    return names


def unit_clip(path, clip, kw):
    from .asset import LoadedAsset, open_stage
    from .frameproof import prove
    with _quiet():
        asset = LoadedAsset(open_stage(path), path)
        return prove(asset, subframes=kw.get("subframes", 0), chunk_frames=kw.get("chunk_frames"), clips=[clip],
                     continuous=kw.get("continuous", True))


def unit_finish(path, kw, proofs):
    with _quiet():
        return check_asset(path, clip_proofs=proofs, **kw)


# ------------------------------------------------------------------------------ driver
@dataclass
class BatchResult:
    """``reports``: one per checked asset, input order (missing paths last, as ``COL003``);
    ``missing``: paths that do not exist (or globs matching nothing); ``interrupted``: Ctrl-C
    stopped the run; ``unchecked``: assets not checked because of it; ``retried``: units rerun
    after their worker died; ``split``: assets whose frame proof ran one clip per task."""

    reports: list
    missing: list
    interrupted: bool = False
    unchecked: list = field(default_factory=list)
    retried: int = 0
    split: list = field(default_factory=list)


def _should_split(kw) -> bool:
    from .registry import RuleSelector
    sel = RuleSelector(kw.get("select"), kw.get("ignore"))
    return any(sel.enabled(c) for c in PROOF_RULES)


def check_many(paths, jobs=1, scheduler=None, progress=False, split_bytes=SPLIT_BYTES, **kw) -> BatchResult:
    """Check every asset under ``paths`` (files, directories, globs).

    ``jobs``: local processes (1: in this process); ``scheduler``: a Dask scheduler address (or
    ``local:N``), instead of ``jobs``; ``split_bytes``: assets at least this large have their
    frame proof split by clip (``None``: never; only with ``jobs > 1`` or a scheduler);
    ``kw``: :func:`validators.runner.check_asset` arguments.
    """
    assets, missing = expand_inputs(paths, USD_EXTENSIONS)
    backend = make_backend(jobs, scheduler)
    parallel = backend.workers > 1 or scheduler is not None
    split = parallel and split_bytes is not None and _should_split(kw)
    reports = [None] * len(assets)
    split_paths = []
    bar = Progress(len(assets), "validating", progress)

    def finish(i, rep):
        reports[i] = rep
        bar.advance(not rep.passed)

    def lost(i):
        def f(e):
            finish(i, _crash_report(assets[i], e, kw))
        return f

    unit = unit_check_contained if isinstance(backend, InlineBackend) else unit_check

    def check_task(i):
        return Task(unit, (assets[i], kw), lambda rep: finish(i, rep), lost(i), lost(i))

    def split_task(i):
        path = assets[i]

        def planned(names):
            if not names:
                return [check_task(i)]
            split_paths.append(path)
            proofs = {}
            state = {"given_up": False}  # a clip failed: no unit_finish for this asset

            def got(name):
                def f(proof):
                    proofs[name] = proof
                    if len(proofs) == len(names) and not state["given_up"]:
                        return [Task(unit_finish, (path, kw, [proofs[n] for n in names]),
                                     lambda rep: finish(i, rep), lost(i), lost(i))]
                    return []
                return f

            def clip_error(e):  # the proof raised: check the asset whole, as --jobs 1 does (COL002)
                if not state["given_up"]:
                    state["given_up"] = True
                    return [check_task(i)]

            def clip_lost(e):  # its worker died twice: one COL001 for the asset
                if not state["given_up"]:
                    state["given_up"] = True
                    lost(i)(e)
            return [Task(unit_clip, (path, n, kw), got(n), clip_error, clip_lost) for n in names]
        return Task(unit_plan, (path, kw), planned, lambda e: [check_task(i)], lost(i))

    def size(i):
        try:
            return os.path.getsize(assets[i])
        except OSError:
            return 0

    sizes = [size(i) for i in range(len(assets))]
    order = sorted(range(len(assets)), key=lambda i: -sizes[i]) if parallel else range(len(assets))
    tasks = [split_task(i) if split and sizes[i] >= split_bytes else check_task(i) for i in order]
    engine = Engine(backend)
    # --jobs 1 forks a probe per crate asset from this process: usd-core serial for the run, so no
    # usd-core thread holds a lock at a fork (issue 26 item 6; a stage freed in the background
    # used to leave a probe asleep until the stall watch re-forked it 20 s later)
    serial = usd_serial() if isinstance(backend, InlineBackend) else contextlib.nullcontext()
    try:
        with serial:
            engine.run(tasks)
    finally:
        bar.close()
    done = [r for r in reports if r is not None]
    unchecked = [a for a, r in zip(assets, reports) if r is None]
    done += [check_asset(m, **kw) for m in missing]
    return BatchResult(done, missing, engine.interrupted, unchecked, engine.retried,
                       sorted(split_paths, key=assets.index))


# ------------------------------------------------------------------------------ reports
TIMING_KEYS = ("seconds", "load_seconds")


def comparable(reports) -> list:
    """Reports as JSON-able dicts without their timing fields (what makes two runs differ)."""
    out = []
    for r in reports:
        d = json.loads(json.dumps(r.to_dict(), default=lambda o: o.item() if hasattr(o, "item") else str(o)))
        for k in TIMING_KEYS:
            d["stats"].pop(k, None)
        for k in ("seconds", "continuous_seconds"):
            d["stats"].get("frameproof", {}).pop(k, None)
        out.append(d)
    return out


__all__ = ["check_many", "comparable", "BatchResult", "SPLIT_BYTES"]
