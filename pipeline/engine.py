"""The distribution engine under ``colossus import`` and ``colossus validate`` with several
inputs: ``--jobs N`` local processes, or ``--scheduler ADDRESS`` on a Dask cluster.

Command-agnostic and below both of its users (:mod:`pipeline.batch`, :mod:`validators.parallel`):

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

Results are merged by the callers in input order, never in completion order, so a report is
identical whichever backend made it (timing fields aside).
"""

from __future__ import annotations

import glob
import logging
import os
import queue
import signal
import sys
import uuid
from collections import deque
from concurrent.futures import Future

from .errors import UsageError, one_line
from .tempfiles import is_temp

#: A glob is an input that does not exist as written and contains one of these.
GLOB_CHARS = "*?["
#: Directory levels a directory input or a glob's directory is walked down at most.
MAX_WALK_DEPTH = 64

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
        # a symlinked directory is not entered (os.walk's default), a directory reached twice
        # (bind mounts, hard-linked trees) is walked once, and the depth is bounded: no loop hangs
        found, seen = [], set()
        base = os.path.abspath(d).rstrip(os.sep).count(os.sep)
        for root, dirs, files in os.walk(d):
            try:
                st = os.stat(root)
            except OSError:
                dirs[:] = []
                continue
            if (st.st_dev, st.st_ino) in seen or os.path.abspath(root).count(os.sep) - base >= MAX_WALK_DEPTH:
                dirs[:] = []
                continue
            seen.add((st.st_dev, st.st_ino))
            dirs.sort()
            found += [os.path.join(root, f) for f in files if f.lower().endswith(suffixes) and not is_temp(f)]
        return sorted(p for p in found if keep(p))

    files, missing = [], []
    for item in items:
        item = os.fspath(item)
        if os.path.isdir(item):
            files += walk(item)
        elif os.path.exists(item):
            files.append(item)
        elif is_glob(item):
            matches = _glob(item)
            if not matches:
                missing.append(item)
            for m in matches:
                if os.path.isdir(m):
                    files += walk(m)
                elif m.lower().endswith(suffixes) and keep(m) and not is_temp(m):
                    files.append(m)
        else:
            missing.append(item)
    return files, missing


def _glob(pattern: str) -> list:
    """Sorted matches of ``pattern`` (``**`` spans directories, as ``glob.glob(recursive=True)``;
    names starting with a dot match only a pattern component that does too).  A ``**`` pattern is
    matched by walking its fixed prefix folder without entering symlinked directories, each
    directory once and at most :data:`MAX_WALK_DEPTH` deep: glob's own recursion follows symlinks
    and a symlink loop makes it run for ever."""
    if "**" not in pattern:
        return sorted(glob.glob(pattern))
    import re

    def component(part):  # one path component: * and ? stay inside it
        out, i = "", 0
        while i < len(part):
            c = part[i]
            if c == "*":
                out += "[^/]*"
            elif c == "?":
                out += "[^/]"
            elif c == "[" and "]" in part[i + 2:] or part[i + 1:i + 2] == "]" and "]" in part[i + 2:]:
                j = part.index("]", i + 2) if part[i + 1:i + 2] in ("!", "]") else part.index("]", i + 1)
                inner = part[i + 1:j]
                inner = "^" + inner[1:] if inner.startswith("!") else inner
                out += "[" + inner.replace("\\", "\\\\") + "]"
                i = j
            else:
                out += re.escape(c)
            i += 1
        return out

    parts = pattern.split(os.sep)
    k = next(i for i, part in enumerate(parts) if any(c in part for c in GLOB_CHARS))
    base = os.sep.join(parts[:k]) or ("." if not pattern.startswith(os.sep) else os.sep)
    rx = ""
    for i, part in enumerate(parts[k:]):
        last = i == len(parts) - k - 1
        if part == "**":
            rx += "(?:[^/.][^/]*(?:/|$))*"
        else:
            body = component(part)
            if not part.startswith("."):
                body = "(?![.])" + body
            rx += body + ("" if last else "/")
    want = re.compile(rx + r"\Z", re.S)
    out, seen = [], set()
    start = os.path.abspath(base).rstrip(os.sep).count(os.sep)
    for root, dirs, files in os.walk(base):
        try:
            st = os.stat(root)
        except OSError:
            dirs[:] = []
            continue
        if (st.st_dev, st.st_ino) in seen or os.path.abspath(root).count(os.sep) - start >= MAX_WALK_DEPTH:
            dirs[:] = []
            continue
        seen.add((st.st_dev, st.st_ino))
        rel = os.path.relpath(root, base)
        rel = "" if rel == "." else rel.replace(os.sep, "/") + "/"
        for name in dirs + files:
            if want.match(rel + name):
                out.append(os.path.join(rel, name) if base == "." else os.path.join(root, name))
    if len(parts) - k == 1 and parts[-1] == "**" and base != ".":
        out.append(os.path.join(base, ""))  # glob's "dir/**" names the folder itself too
    return sorted(set(out))


# ------------------------------------------------------------------------------ backends
class WorkerLost(RuntimeError):
    """The process running a task died (or was killed) before returning."""


def _worker_init(numba_threads, parent=0):
    """Pool workers: Ctrl-C is the coordinator's to handle, they die with the coordinator (a
    killed command leaves no worker behind), and the compiled kernels share the cores with the
    other workers instead of each taking all of them."""
    if parent:
        from .isolation import die_with_parent
        die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.setdefault("NUMBA_NUM_THREADS", str(numba_threads))
    from colossus.runtime import usdlog

    usdlog.silence()


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
                                       initializer=_worker_init, initargs=(_share(self.workers), os.getpid()))
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
            raise UsageError("--scheduler needs Dask: pip install 'colossus[dask]' "
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
            raise UsageError(f"cannot reach the Dask scheduler at {address}: {one_line(e)}") from None
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


