"""``colossus import A B C -o DIR``: many inputs imported on the engine (:mod:`pipeline.engine`:
``--jobs N`` processes or ``--scheduler`` Dask), one output per input named by
:func:`output_names`, one row per input in input order.
"""

from __future__ import annotations

import os

from .engine import Engine, Progress, Task, expand_inputs, make_backend
from .errors import one_line
from .readers import READERS


#: Inputs ``colossus import`` picks up in a directory or glob: every extension of the reader table.
IMPORT_SUFFIXES = tuple(sorted(READERS))


def output_names(sources, ext: str = ".usda") -> list:
    """Output file names for a batch import, in the order of ``sources``.

    ``<stem><ext>``; inputs sharing a stem (``boss.glb`` and ``boss.fbx``) all get
    ``<stem>.<source ext><ext>`` (``boss.glb.usda``, ``boss.fbx.usda``); inputs still sharing a
    name (``a/boss.glb`` and ``b/boss.glb``) are prefixed with their parent directories, as
    many as needed, joined by ``_`` (``a_boss.glb.usda``, ``b_boss.glb.usda``).  The names
    depend only on the set of inputs, not on their order.
    """
    srcs = [os.path.normpath(os.path.abspath(s)) for s in sources]

    def name(s, level):
        base = os.path.basename(s)
        stem, sext = os.path.splitext(base)
        if level == 0:
            return stem + ext
        if level == 1:
            return f"{stem}{sext}{ext}"
        parents = os.path.dirname(s).strip(os.sep).split(os.sep)[-(level - 1):]
        return "_".join([p for p in parents if p] + [f"{stem}{sext}{ext}"])

    level = [0] * len(srcs)
    while True:
        names = [name(s, lv) for s, lv in zip(srcs, level)]
        seen = {}
        for i, n in enumerate(names):
            seen.setdefault(n, []).append(i)
        clash = [ix for ix in seen.values() if len(ix) > 1]
        if not clash:
            return names
        progressed = False
        for ix in clash:
            for i in ix:
                if level[i] < 2 + len(os.path.dirname(srcs[i]).strip(os.sep).split(os.sep)):
                    level[i] += 1
                    progressed = True
        if not progressed:  # the very same file twice: callers de-duplicate first
            raise ValueError(f"cannot give distinct output names to {sorted(set(names))}")


def _import_unit(src, out, settings, strict=False, check=None):
    """Worker side of one batch import: never raises for a bad input (``check``: a module-level
    function, so that it pickles by name to a worker process)."""
    from colossus.runtime import usdlog

    from .errors import ColossusError
    from .run import import_asset
    usdlog.silence()
    usdlog.take()
    try:
        res = import_asset(src, out, settings, strict=strict, check=check)
    except ColossusError as e:
        return {"source": src, "output": out, "ok": False, "error": one_line(e)}
    except MemoryError:
        return {"source": src, "output": out, "ok": False, "error": "out of memory"}
    except Exception as e:
        return {"source": src, "output": out, "ok": False,
                "error": f"internal error ({type(e).__name__}: {one_line(e)})"}
    return {"source": src, "output": out, "ok": True, "summary": res.summary()}

def import_many(sources, out_dir, settings, jobs=1, scheduler=None, progress=False, strict=False, check=None):
    """Import every file of ``sources`` (see :func:`expand_inputs`) into ``out_dir``
    (``strict``: refuse each input whose reader met anything not carried exactly; ``check``: run
    on each written asset before its rename, :func:`pipeline.run.import_asset`).

    Returns ``(rows, interrupted)``: one dict per input in input order (``source``,
    ``output``, ``ok``, and ``summary`` or ``error``); inputs not imported because of Ctrl-C
    have ``ok`` None.
    """
    files, missing = expand_inputs(sources, IMPORT_SUFFIXES, exclude=[out_dir])
    seen, uniq = set(), []
    for f in files:
        k = os.path.realpath(f)
        if k not in seen:
            seen.add(k)
            uniq.append(f)
    os.makedirs(out_dir, exist_ok=True)
    names = output_names(uniq)
    rows = {}
    for m in missing:
        rows[m] = {"source": m, "output": None, "ok": False, "error": "no such file, directory or match"}
    backend = make_backend(jobs, scheduler)
    bar = Progress(len(uniq), "importing", progress)

    def task(src, out):
        def ok(value):
            rows[src] = value
            bar.advance(not value["ok"])

        def err(e):
            rows[src] = {"source": src, "output": out, "ok": False, "error": f"import crashed: {one_line(e)}"}
            bar.advance(True)

        def lost(e):
            rows[src] = {"source": src, "output": out, "ok": False, "error": f"import crashed: {e}"}
            bar.advance(True)
        extra = (strict, check) if check is not None else (True,) if strict else ()
        return Task(_import_unit, (src, out, settings) + extra, ok, err, lost)

    outs = [os.path.join(out_dir, n) for n in names]
    work = list(zip(uniq, outs))
    if backend.workers > 1 or scheduler:
        work.sort(key=lambda so: -_size(so[0]))  # biggest first: the long poles start early
    engine = Engine(backend)
    try:
        engine.run([task(s, o) for s, o in work])
    finally:
        bar.close()
    order = uniq + missing
    return [rows.get(s) or {"source": s, "output": o, "ok": None, "error": "not imported (interrupted)"}
            for s, o in zip(order, outs + [None] * len(missing))], engine.interrupted


def _size(path) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


def format_import_rows(rows, interrupted=False) -> str:
    lines = []
    for r in rows:
        if r["ok"]:
            s = r["summary"]
            lines.append(f"ok    {r['source']} -> {r['output']}  ({s['vertices_out']} vertices, {s['faces_out']} "
                         f"triangles, {s['parts']} parts, {s['clips']} clips, {s['seconds']:.2f} s)")
            lines += [f"        warning: {w}" for w in s["warnings"]]
        elif r["ok"] is None:
            lines.append(f"skip  {r['source']}: {r['error']}")
        else:
            lines.append(f"FAIL  {r['source']}: {r['error']}")
    n = len(rows)
    ok = sum(bool(r["ok"]) for r in rows)
    bad = sum(r["ok"] is False for r in rows)
    lines.append(f"{n} inputs, {ok} imported, {bad} failed" + (f", {n - ok - bad} not imported (interrupted: "
                                                             "INCOMPLETE)" if interrupted else ""))
    return "\n".join(lines)
