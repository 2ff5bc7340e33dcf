"""Many inputs at once: ``--jobs N`` local processes, or ``--scheduler ADDRESS`` on a Dask cluster.

This is the distribution layer of ``colossus import`` and ``colossus validate`` when they are
given several inputs (paths, directories, globs).  The work unit is one asset; the validator
also splits a very large asset into one frame-proof task per clip (see
:mod:`validators.parallel`).  Everything here is command-agnostic:

* :func:`expand_inputs` -- paths, directories (recursed, sorted) and globs into files;
* backends, all with the same ``submit(fn, *args) -> future`` shape:
  :class:`InlineBackend` (``--jobs 1``: in this process, no pickling),
  :class:`ProcessBackend` (``--jobs N``: a spawn process pool, rebuilt when a worker dies),
  :class:`DaskBackend` (``--scheduler tcp://host:8786``, or ``local:N`` for a private
  ``LocalCluster``; needs the optional extra ``pip install 'colossus[dask]'``);
* :class:`Engine`: runs :class:`Task` s on a backend, streams results back as they finish,
  retries a task whose worker died **once, alone on the cluster** (so an innocent task that
  shared the dying worker is not blamed twice), then hands the loss to the task's ``on_lost``;
  Ctrl-C cancels what is running and returns what finished (``engine.interrupted``);
* :class:`Progress`: the stderr bar (assets done/total, failures so far);
* :func:`import_many`: ``colossus import A B C -o DIR`` (output names: :func:`output_names`);
* :func:`run_bench`: the ``colossus bench --only scale`` benchmark.

Results are merged in input order, never in completion order, so a report is identical
whichever backend made it (timing fields aside).
"""

from __future__ import annotations

import glob
import logging
import os
import queue
import signal
import sys
import time
import uuid
from collections import deque
from concurrent.futures import Future

from .errors import one_line

#: A glob is an input that does not exist as written and contains one of these.
GLOB_CHARS = "*?["

#: Scheduler-side setting used for clusters colossus starts itself (``--scheduler local:N``):
#: the scheduler does not retry a task whose worker died; the engine's own single, isolated
#: retry does (a remote scheduler keeps its own ``distributed.scheduler.allowed-failures``).
ALLOWED_FAILURES = 0

#: Seconds to wait for a ``--scheduler`` to answer.
CONNECT_TIMEOUT = 15.0


# ------------------------------------------------------------------------------ inputs
def is_glob(item: str) -> bool:
    return not os.path.exists(item) and any(c in item for c in GLOB_CHARS)


def expand_inputs(items, suffixes, exclude=()):
    """Expand command-line inputs into files.

    A directory recurses for files ending in one of ``suffixes`` (case-insensitive), sorted by
    path; a glob (``assets/**/*.usda``, recursive) expands to its sorted matches (directories
    among them recurse); an existing file is taken as given.  Paths under one of ``exclude``
    (directories) are skipped.  Returns ``(files, missing)``, both in input order.
    """
    suffixes = tuple(s.lower() for s in suffixes)
    excl = [os.path.abspath(e) + os.sep for e in exclude]

    def keep(p):
        a = os.path.abspath(p)
        return not any(a.startswith(e) for e in excl)

    def walk(d):
        found = []
        for root, dirs, files in os.walk(d):
            dirs.sort()
            found += [os.path.join(root, f) for f in files if f.lower().endswith(suffixes)]
        return sorted(p for p in found if keep(p))

    files, missing = [], []
    for item in items:
        item = os.fspath(item)
        if os.path.isdir(item):
            files += walk(item)
        elif os.path.exists(item):
            files.append(item)
        elif is_glob(item):
            matches = sorted(glob.glob(item, recursive=True))
            if not matches:
                missing.append(item)
            for m in matches:
                if os.path.isdir(m):
                    files += walk(m)
                elif m.lower().endswith(suffixes) and keep(m):
                    files.append(m)
        else:
            missing.append(item)
    return files, missing


# ------------------------------------------------------------------------------ backends
class WorkerLost(RuntimeError):
    """The process running a task died (or was killed) before returning."""


def _worker_init(numba_threads):
    """Pool workers: Ctrl-C is the coordinator's to handle, and the compiled kernels share the
    cores with the other workers instead of each taking all of them."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.setdefault("NUMBA_NUM_THREADS", str(numba_threads))


def _share(workers: int) -> int:
    return max(1, (os.cpu_count() or 1) // max(1, workers))


class InlineBackend:
    """``--jobs 1``: run each task right here when it is submitted."""

    name = "inline"
    workers = 1
    max_inflight = 1

    def submit(self, fn, *args):
        fut = Future()
        try:
            fut.set_result(fn(*args))
        except KeyboardInterrupt:
            raise
        except BaseException as e:
            fut.set_exception(e)
        return fut

    def is_worker_death(self, exc):
        return False

    def close(self, cancel=False):
        pass


class ProcessBackend:
    """``--jobs N``: a spawn process pool.  A worker that dies breaks the whole
    ``ProcessPoolExecutor``; the pool is rebuilt and every task it held counts as lost once."""

    name = "processes"

    def __init__(self, jobs: int):
        self.workers = jobs
        self.max_inflight = 2 * jobs  # keep the pool fed; bounds what one dying worker takes down
        self._gen = 0
        self._ex = None
        self._new_pool()

    def _new_pool(self):
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor
        if self._ex is not None:
            self._ex.shutdown(wait=False, cancel_futures=True)
        self._ex = ProcessPoolExecutor(max_workers=self.workers, mp_context=mp.get_context("spawn"),
                                       initializer=_worker_init, initargs=(_share(self.workers),))
        self._gen += 1

    def submit(self, fn, *args):
        from concurrent.futures.process import BrokenProcessPool
        try:
            fut = self._ex.submit(fn, *args)
        except BrokenProcessPool:
            self._new_pool()
            fut = self._ex.submit(fn, *args)
        fut.generation = self._gen
        return fut

    def is_worker_death(self, exc):
        from concurrent.futures import CancelledError
        from concurrent.futures.process import BrokenProcessPool
        return isinstance(exc, (BrokenProcessPool, CancelledError))

    def on_death(self, fut):
        if getattr(fut, "generation", None) == self._gen:
            self._new_pool()

    def close(self, cancel=False):
        if self._ex is None:
            return
        procs = list(getattr(self._ex, "_processes", {}).values()) if cancel else []
        self._ex.shutdown(wait=not cancel, cancel_futures=cancel)
        for p in procs:  # a task already running is not cancellable: stop its process
            if p.is_alive():
                p.terminate()
        self._ex = None


def local_cluster(n_workers: int = 2, **kw):
    """A ``distributed.LocalCluster`` of ``n_workers`` single-threaded worker processes, with
    the scheduler leaving worker-death retries to the engine (:data:`ALLOWED_FAILURES`)."""
    import dask
    from distributed import LocalCluster
    kw["env"] = {"NUMBA_NUM_THREADS": str(_share(n_workers)), **kw.get("env", {})}
    with dask.config.set({"distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
                          # the statistical profiler samples the task thread every 10 ms: it costs
                          # pure-Python work (usd-core calls per frame) ~30 % here
                          "distributed.worker.profile.enabled": False}):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                            dashboard_address=None, silence_logs=logging.ERROR, **kw)


class DaskBackend:
    """``--scheduler ADDRESS``: tasks go to a Dask distributed scheduler.

    ``ADDRESS`` is what ``dask-scheduler`` prints (``tcp://host:8786``; a bare ``host:port``
    gets ``tcp://``), or ``local:N`` to start a private ``LocalCluster`` of N worker processes.
    The workers import the task functions by module path (``pipeline.batch``,
    ``validators.parallel``): they need colossus installed and the input and output paths
    reachable under the same names.
    """

    name = "dask"
    max_inflight = None  # the scheduler queues; a dying worker only takes what it was running

    def __init__(self, address: str, connect_timeout: float | None = None):
        try:
            from distributed import Client
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise RuntimeError("--scheduler needs Dask: pip install 'colossus[dask]' "
                               f"(or 'dask[distributed]'): {e}") from None
        self._cluster = None
        if address.startswith("local"):
            n = int(address.partition(":")[2] or os.cpu_count() or 1)
            self._cluster = local_cluster(n)
            address = self._cluster.scheduler_address
        elif "://" not in address:
            address = "tcp://" + address
        self.address = address
        try:
            self.client = Client(address, timeout=connect_timeout or CONNECT_TIMEOUT, set_as_default=False)
        except Exception as e:
            if self._cluster is not None:
                self._cluster.close()
            raise RuntimeError(f"cannot reach the Dask scheduler at {address}: {' '.join(str(e).split())}") from None
        self.workers = max(1, sum(self.client.nthreads().values()))
        self._futures = set()

    def submit(self, fn, *args):
        key = f"{fn.__name__}-{uuid.uuid4().hex}"  # never a cached (e.g. erred) result of an earlier try
        fut = self.client.submit(fn, *args, key=key, pure=False, retries=0)
        self._futures.add(fut)
        fut.add_done_callback(self._futures.discard)
        return fut

    def is_worker_death(self, exc):
        from concurrent.futures import CancelledError

        from distributed import KilledWorker
        return isinstance(exc, (KilledWorker, CancelledError))

    def close(self, cancel=False):
        try:
            if cancel and self._futures:
                self.client.cancel(list(self._futures), force=True)
            self.client.close()
        finally:
            if self._cluster is not None:
                self._cluster.close()


def make_backend(jobs: int = 1, scheduler: str | None = None):
    """The backend for ``--jobs`` / ``--scheduler`` (``--scheduler`` wins)."""
    if scheduler:
        return DaskBackend(scheduler)
    if jobs <= 1:
        return InlineBackend()
    return ProcessBackend(jobs)


# ------------------------------------------------------------------------------ engine
class Task:
    """One call ``fn(*args)`` in a worker.

    ``on_result(value)``: it returned; ``on_error(exc)``: the function raised; ``on_lost(exc)``:
    its worker died on both tries.  Each may return follow-up tasks (a list, or None).  ``fn``
    must be a module-level function (workers import it by name).
    """

    __slots__ = ("fn", "args", "on_result", "on_error", "on_lost", "tries")

    def __init__(self, fn, args, on_result, on_error, on_lost):
        self.fn, self.args = fn, args
        self.on_result, self.on_error, self.on_lost = on_result, on_error, on_lost
        self.tries = 0


class Engine:
    """Run tasks on a backend, streaming results back in completion order.

    A task whose worker dies is put aside; when nothing else is running it is retried once,
    alone, and if its worker dies again ``task.on_lost`` is called.  Ctrl-C (KeyboardInterrupt)
    stops: running tasks are cancelled, :attr:`interrupted` is set, and :meth:`run` returns.
    """

    def __init__(self, backend):
        self.backend = backend
        self.interrupted = False
        self.retried = 0

    def run(self, tasks):
        b = self.backend
        pending = deque(tasks)
        suspects = deque()
        inflight = {}
        done = queue.Queue()
        isolated = None
        try:
            while pending or inflight or suspects:
                if not pending and not inflight:
                    isolated = suspects.popleft()
                    pending.append(isolated)
                limit = 1 if isolated is not None else b.max_inflight
                while pending and (limit is None or len(inflight) < limit):
                    t = pending.popleft()
                    t.tries += 1
                    fut = b.submit(t.fn, *t.args)
                    inflight[fut] = t
                    fut.add_done_callback(done.put)
                while True:
                    try:
                        fut = done.get(timeout=0.25)
                        break
                    except queue.Empty:
                        continue
                t = inflight.pop(fut, None)
                if t is None:
                    continue
                if t is isolated:
                    isolated = None
                try:
                    value = fut.result()
                except KeyboardInterrupt:
                    raise
                except BaseException as e:
                    if b.is_worker_death(e):
                        if hasattr(b, "on_death"):
                            b.on_death(fut)
                        if t.tries < 2:
                            self.retried += 1
                            suspects.append(t)
                        else:
                            lost = WorkerLost(f"the worker process died twice running it ({type(e).__name__})")
                            pending.extend(t.on_lost(lost) or ())
                    else:
                        pending.extend(t.on_error(e) or ())
                    continue
                pending.extend(t.on_result(value) or ())
        except KeyboardInterrupt:
            self.interrupted = True
            b.close(cancel=True)
            return
        except BaseException:
            b.close(cancel=True)
            raise
        b.close()


# ------------------------------------------------------------------------------ progress
class Progress:
    """A progress bar on stderr: ``label [####    ] done/total  N failed``."""

    def __init__(self, total: int, label: str, enabled: bool):
        self.total, self.done, self.failed = total, 0, 0
        self._bar = None
        if enabled and total:
            import click
            self._bar = click.progressbar(length=total, label=label, file=sys.stderr, show_pos=True,
                                          show_eta=True, item_show_func=lambda s: s)
            self._bar.__enter__()
            self._bar.render_progress()

    def advance(self, failed: bool = False):
        self.done += 1
        self.failed += bool(failed)
        if self._bar is not None:
            self._bar.update(1, f"{self.failed} failed" if self.failed else "")

    def close(self):
        if self._bar is not None:
            self._bar.__exit__(None, None, None)
            self._bar = None


# ------------------------------------------------------------------------------ import
#: Inputs ``colossus import`` picks up in a directory or glob.
IMPORT_SUFFIXES = (".glb", ".gltf", ".fbx", ".dae", ".usd", ".usda", ".usdc", ".usdz")


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


def _import_unit(src, out, settings):
    """Worker side of one batch import: never raises for a bad input."""
    from .errors import ColossusError
    from .run import import_asset
    crash_hook(src)
    try:
        res = import_asset(src, out, settings)
    except ColossusError as e:
        return {"source": src, "output": out, "ok": False, "error": one_line(e)}
    except MemoryError:
        return {"source": src, "output": out, "ok": False, "error": "out of memory"}
    except Exception as e:
        return {"source": src, "output": out, "ok": False,
                "error": f"internal error ({type(e).__name__}: {one_line(e)})"}
    return {"source": src, "output": out, "ok": True, "summary": res.summary()}


def crash_hook(path):
    """Test hook, for worker processes only (never the coordinator): die (``os._exit``) on every
    unit of an asset whose path contains ``$COLOSSUS_TEST_CRASH``, and on the first unit only
    (a marker file ``PATH.crashed`` remembers it) of one containing ``$COLOSSUS_TEST_CRASH_ONCE``."""
    import multiprocessing as mp
    path = os.fspath(path)
    always, once = os.environ.get("COLOSSUS_TEST_CRASH"), os.environ.get("COLOSSUS_TEST_CRASH_ONCE")
    if not (always or once) or mp.parent_process() is None:
        return
    if always and always in path:
        os._exit(70)
    if once and once in path and not os.path.exists(path + ".crashed"):
        open(path + ".crashed", "w").close()
        os._exit(70)


def import_many(sources, out_dir, settings, jobs=1, scheduler=None, progress=False):
    """Import every file of ``sources`` (see :func:`expand_inputs`) into ``out_dir``.

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
        return Task(_import_unit, (src, out, settings), ok, err, lost)

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


# ------------------------------------------------------------------------------ benchmark
def make_library(directory, count=200, triangles=3000, bones=12, clips=3, frames=24, seed=0):
    """``count`` collider assets for benchmarks and tests: one synthetic ``.glb`` imported once,
    then its USD text copied with every part radius scaled by a random factor in [0.97, 1.3)
    (some assets fail the frame proof, most pass, as in a real library).  Returns the paths."""
    import numpy as np

    from .run import import_asset
    from .synth.glb import write_glb
    os.makedirs(directory, exist_ok=True)
    src = os.path.join(directory, "_source.glb")
    write_glb(src, triangles, bones, clips, frames)
    base = os.path.join(directory, "_base.usda")
    import_asset(src, base)
    from pxr import Sdf
    layer = Sdf.Layer.FindOrOpen(base)
    attr = next(s for s in _walk_attrs(layer) if s.name == "colossus:parts:radii")
    radii = np.array(attr.default, dtype=np.float64)
    rng = np.random.default_rng(seed)
    paths = []
    for i in range(count):
        attr.default = [float(r) for r in radii * rng.uniform(0.97, 1.3)]
        p = os.path.join(directory, f"asset{i:04d}.usda")
        layer.Export(p)
        paths.append(p)
    os.unlink(src)
    os.unlink(base)
    return paths


def _walk_attrs(layer):
    out = []

    def visit(path):
        spec = layer.GetObjectAtPath(path)
        if hasattr(spec, "attributes"):
            out.extend(spec.attributes)
    layer.Traverse("/", visit)
    return out


def run_bench(count=200, triangles=6000, frames=48, echo=print):
    """Validate ``count`` generated assets (a few thousand vertices, 3 clips each) with
    ``--jobs 1``, ``--jobs 2`` and a 2-worker ``LocalCluster``; check the three reports are the
    same; return wall times, speed-ups and the cluster path's per-asset overhead."""
    import tempfile

    from validators.parallel import check_many, comparable

    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        paths = make_library(tmp, count=count, triangles=triangles, frames=frames)
        t_gen = time.perf_counter() - t0
        check_many(paths[:1])  # warm numba's on-disk cache in this process
        cores = os.cpu_count() or 1
        runs = [("--jobs 1", dict(jobs=1)), ("--jobs 2", dict(jobs=2))]
        try:
            import distributed  # noqa: F401
            runs.append(("LocalCluster(2)", dict(scheduler="cluster")))
        except ImportError:
            echo("scale: dask[distributed] is not installed; cluster run skipped (pip install 'colossus[dask]')")
        ref = None
        for label, kw in runs:
            cluster = None
            if kw.get("scheduler") == "cluster":
                t_up = time.perf_counter()
                cluster = local_cluster(2)
                rows["cluster_start_s"] = time.perf_counter() - t_up
                kw = dict(scheduler=cluster.scheduler_address)
            try:
                t0 = time.perf_counter()
                res = check_many(paths, **kw)
                rows[label] = time.perf_counter() - t0
            finally:
                if cluster is not None:
                    cluster.close()
            same = comparable(res.reports)
            ref = ref if ref is not None else same
            rows[label + " same"] = same == ref
        # per-asset overhead of the cluster path: one tiny task per asset round-trip
        if "LocalCluster(2)" in rows:
            rows["cluster_overhead_ms"] = _task_overhead(count) * 1e3
    j1 = rows["--jobs 1"]
    out = {"assets": count, "triangles": triangles, "clips": 3, "frames": frames, "cores": cores, "generate_s": t_gen,
           "jobs1_s": j1, "jobs2_s": rows["--jobs 2"], "speedup_jobs2": j1 / rows["--jobs 2"],
           "same_reports": all(v for k, v in rows.items() if k.endswith(" same"))}
    if "LocalCluster(2)" in rows:
        c = rows["LocalCluster(2)"]
        out.update(cluster_s=c, speedup_cluster=j1 / c, cluster_start_s=rows["cluster_start_s"],
                   cluster_vs_jobs2_per_asset_ms=(c - rows["--jobs 2"]) / count * 1e3,
                   cluster_task_roundtrip_ms=rows["cluster_overhead_ms"])
    return out


def _noop(i):
    return i


def _task_overhead(n):
    """Seconds per task of submitting ``n`` no-op tasks through the engine to a 2-worker
    LocalCluster (the cluster path's fixed cost per asset, compute excluded)."""
    cluster = local_cluster(2)
    try:
        b = DaskBackend(cluster.scheduler_address)
        b.submit(_noop, 0).result()
        t0 = time.perf_counter()
        Engine(b).run([Task(_noop, (i,), lambda v: [], print, print) for i in range(n)])
        return (time.perf_counter() - t0) / n
    finally:
        cluster.close()


def format_bench(r) -> str:
    lines = [f"scale: validate {r['assets']} generated assets (~{r['triangles']} triangles, {r['clips']} clips x "
             f"{r['frames']} frames each) on {r['cores']} cores",
             f"  --jobs 1                     {r['jobs1_s']:8.2f} s   {r['jobs1_s'] / r['assets'] * 1e3:7.1f} ms/asset",
             f"  --jobs 2                     {r['jobs2_s']:8.2f} s   x{r['speedup_jobs2']:.2f} vs --jobs 1"]
    if "cluster_s" in r:
        lines += [f"  LocalCluster (2 workers)     {r['cluster_s']:8.2f} s   x{r['speedup_cluster']:.2f} vs --jobs 1 "
                  f"(+ {r['cluster_start_s']:.1f} s to start the cluster, not counted)",
                  f"  cluster path overhead        {r['cluster_vs_jobs2_per_asset_ms']:+8.1f} ms/asset vs --jobs 2; "
                  f"{r['cluster_task_roundtrip_ms']:.1f} ms per no-op task round trip"]
    lines.append(f"  reports identical across runs: {'yes' if r['same_reports'] else 'NO'}")
    return "\n".join(lines)
