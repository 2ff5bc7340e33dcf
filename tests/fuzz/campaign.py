"""A fuzz campaign: cases spread over worker processes, each bounded in memory and time.

* Case ``i`` of campaign ``seed`` is fully determined by ``(seed, i)``: its seed file (round
  robin over the seeds, so every format gets its share; every ``VALIDATE_EVERY``-th case mutates
  a collider asset for ``validate`` instead), its mutations (:func:`tests.fuzz.mutators.mutate`
  with ``numpy.random.default_rng([seed, i])``), and whether it runs as a real subprocess.
* Workers are spawned processes (a clean interpreter each, ``NUMBA_NUM_THREADS=1``, usd-core's
  ``Work`` concurrency 1) that run cases
  in-process (:func:`tests.fuzz.oracle.run_case`).  Each caps its address space
  (``RLIMIT_AS``: what it maps after start-up plus ``memory`` bytes), so a runaway allocation
  fails in the case instead of taking the machine; the campaign kills a worker whose case
  exceeds ``timeout`` seconds (a hang) and records a worker that dies (a native crash that got
  past the containment) as bad outcomes of that case, then starts a fresh worker.
* Bad cases are saved (file + ``recipe.json``) to ``out`` when given; the summary groups them
  by class.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import shutil
import tempfile
import time
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from multiprocessing.connection import wait

#: Every this-many-th case fuzzes ``colossus validate`` (a mutated collider asset).
VALIDATE_EVERY = 6

#: Address space a worker may map beyond what it has after start-up (bytes).
WORKER_MEMORY = 8 * 2**30


def plan(n: int, seed: int, sources, assets, subprocess_every: int = 0, start: int = 0) -> list:
    """The cases ``start .. start + n - 1`` of campaign ``seed`` (dicts, see :mod:`.oracle`)."""
    cases = []
    k_src = k_val = 0
    for i in range(start, start + n):
        if assets and (i % VALIDATE_EVERY == VALIDATE_EVERY - 1 or not sources):
            s = assets[(i // VALIDATE_EVERY) % len(assets)]
            k_val += 1
        else:
            s = sources[(i - i // VALIDATE_EVERY) % len(sources)]
            k_src += 1
        cases.append({"index": i, "campaign": seed, "kind": s.kind, "seed": s.path, "ext": s.ext,
                      "subprocess": bool(subprocess_every) and s.kind == "import" and i % subprocess_every == 0})
    return cases


def _worker(conn, timeout, keep, memory):
    os.environ["NUMBA_NUM_THREADS"] = "1"
    # usd-core single-threaded too: a worker runs hundreds of cases, and the contained reads fork
    # it; a usd-core worker thread holding a lock at that moment (a previous case's stage torn
    # down in the background) can leave the child waiting out its timeout.  Seen once in four
    # CI campaigns (case 35 of seed 12, a validate that replays clean in 1.1 s).
    # (set through the API: the PXR_WORK_THREAD_LIMIT variable would print a banner on stderr)
    from pxr import Work

    Work.SetConcurrencyLimit(1)
    import resource

    from . import oracle
    from colossus.cli import main  # noqa: F401  (load everything before measuring the address space)
    import colossus.cli.import_  # noqa: F401
    import colossus.cli.validate  # noqa: F401

    with open("/proc/self/statm") as fh:
        mapped = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    resource.setrlimit(resource.RLIMIT_AS, (mapped + memory, resource.RLIM_INFINITY))
    conn.send(("ready", os.getpid()))
    while True:
        case = conn.recv()
        if case is None:
            return
        try:
            rec = oracle.run_case(case, timeout=timeout, keep=keep)
        except BaseException as e:  # the harness itself failed on this case: a bad outcome too
            rec = {**case, "steps": [], "outcome": "harness error", "exit": None, "stderr": "",
                   "problems": [f"harness: {type(e).__name__}: {e}"], "seconds": 0.0}
            rec["class"] = rec["problems"][0]
        conn.send(("done", rec))


@dataclass
class Summary:
    cases: int = 0
    seconds: float = 0.0
    outcomes: Counter = field(default_factory=Counter)
    by_format: Counter = field(default_factory=Counter)
    by_mutator: Counter = field(default_factory=Counter)
    bad: dict = field(default_factory=lambda: defaultdict(list))  # class -> [records]
    slowest: list = field(default_factory=list)
    subprocess_cases: int = 0
    noise: int = 0

    @property
    def bad_count(self) -> int:
        return sum(len(v) for v in self.bad.values())

    def add(self, rec):
        self.cases += 1
        self.outcomes[f"{rec['kind']}: {rec['outcome']}"] += 1
        self.by_format[f"{rec['kind']} {rec['ext']}"] += 1
        self.subprocess_cases += bool(rec.get("subprocess"))
        self.noise += bool(rec.get("noise"))
        for name, _ in rec.get("steps", []):
            self.by_mutator[name] += 1
        if rec.get("problems"):
            self.bad[rec["class"]].append(rec)
        self.slowest = sorted(self.slowest + [(rec["seconds"], rec["index"], os.path.basename(rec["seed"]))],
                              reverse=True)[:5]

    def render(self) -> str:
        lines = [f"fuzz: {self.cases} cases in {self.seconds:.1f} s ({self.subprocess_cases} as subprocesses), "
                 f"{self.bad_count} bad outcome(s) in {len(self.bad)} class(es)"]
        lines.append("  cases per format: " + ", ".join(f"{k} {v}" for k, v in sorted(self.by_format.items())))
        lines.append("  outcomes: " + ", ".join(f"{k} {v}" for k, v in sorted(self.outcomes.items())))
        lines.append("  mutators: " + ", ".join(f"{k} {v}" for k, v in sorted(self.by_mutator.items())))
        lines.append(f"  validate cases with native stderr output (judged: each is a bad outcome too): {self.noise}")
        lines.append("  slowest: " + ", ".join(f"#{i} {n} {s:.1f} s" for s, i, n in self.slowest))
        for cls, recs in sorted(self.bad.items(), key=lambda kv: -len(kv[1])):
            r = recs[0]
            lines.append(f"  BAD x{len(recs)}: {cls}")
            lines.append(f"      e.g. case {r['index']} seed {os.path.basename(r['seed'])}: "
                         f"{'; '.join(w for _, w in r.get('steps', []))[:200]}")
            if r.get("stderr"):
                lines.append(f"      stderr: {r['stderr'].splitlines()[-1][:200]}")
        return "\n".join(lines)


class _Slot:
    def __init__(self, ctx, timeout, keep, memory):
        self.parent, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker, args=(child, timeout, keep, memory), daemon=True)
        self.proc.start()
        child.close()
        self.case = None
        self.deadline = None
        self.ready = False

    def kill(self):
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join(5)
        self.parent.close()


def run_campaign(cases, jobs: int = 2, timeout: float = 60.0, keep: str | None = None,
                 memory: int = WORKER_MEMORY, echo=None) -> Summary:
    """Run ``cases`` (from :func:`plan`) on ``jobs`` workers; returns the :class:`Summary`."""
    from . import oracle

    ctx = mp.get_context("spawn")
    t0 = time.perf_counter()
    summary = Summary()
    todo = list(reversed(cases))
    startup = 300.0  # a cold worker compiles the numba kernels once

    def fresh():
        slot = _Slot(ctx, timeout, keep, memory)
        slot.deadline = time.monotonic() + startup
        return slot

    slots = [fresh() for _ in range(max(1, min(jobs, len(cases))))]

    def lost(slot, why):
        rec = {**slot.case, "steps": [], "outcome": why, "exit": None, "stderr": "", "problems": [why], "seconds": timeout}
        try:
            data, rec["steps"] = oracle.build_case(slot.case)
            if keep:
                rec["class"] = why
                oracle.save_case(keep, rec, data)
        except Exception:
            pass
        rec["class"] = why
        return rec

    try:
        while slots:
            for s in list(slots):
                if s.ready and s.case is None:
                    if todo:
                        s.case = todo.pop()
                        s.deadline = time.monotonic() + timeout
                        s.parent.send(s.case)
                    else:
                        s.parent.send(None)
                        s.proc.join(10)
                        slots.remove(s)
            if not slots:
                break
            now = time.monotonic()
            ready = wait([s.parent for s in slots], timeout=max(0.05, min(s.deadline for s in slots) - now))
            for s in list(slots):
                if s.parent in ready:
                    try:
                        kind, payload = s.parent.recv()
                    except (EOFError, OSError):
                        code = s.proc.exitcode if s.proc.join(5) is None else None
                        if s.case is not None:
                            rec = lost(s, f"worker died (exit {s.proc.exitcode}) running the case")
                            summary.add(rec)
                        elif not s.ready:
                            raise RuntimeError(f"a fuzz worker failed to start (exit {code})")
                        s.kill()
                        slots[slots.index(s)] = fresh()
                        continue
                    if kind == "ready":
                        s.ready = True
                    else:
                        s.case = None
                        summary.add(payload)
                        if echo and summary.cases % 100 == 0:
                            echo(f"  ... {summary.cases}/{len(cases)} cases, {summary.bad_count} bad, "
                                 f"{time.perf_counter() - t0:.0f} s")
                elif time.monotonic() > s.deadline:
                    if s.case is None:
                        raise RuntimeError("a fuzz worker did not start in time")
                    summary.add(lost(s, f"timeout: the case ran over {timeout:g} s"))
                    s.kill()
                    slots[slots.index(s)] = fresh()
    finally:
        for s in slots:
            s.kill()
    summary.seconds = time.perf_counter() - t0
    return summary


def campaign(n: int = 300, seed: int = 12, jobs: int = 2, timeout: float = 60.0, keep: str | None = None,
             max_seed_bytes: int | None = 1_000_000, formats=None, subprocess_every: int = 0, start: int = 0,
             echo=None) -> Summary:
    """Seeds, plan and run: the whole campaign (what ``python -m tests.fuzz`` and CI run)."""
    from .seeds import derived_seeds, source_seeds

    work = tempfile.mkdtemp(prefix="colossus-fuzz-seeds-")
    try:
        sources = source_seeds(max_seed_bytes, formats)
        extra, assets = derived_seeds(work, formats)
        sources = sorted(sources + extra, key=lambda s: (s.ext, s.path))
        if formats and not any(f in (".usda", ".usdc") for f in formats):
            assets = []
        if echo:
            echo(f"fuzz: {len(sources)} source seeds ({', '.join(sorted({s.ext for s in sources}))}), "
                 f"{len(assets)} collider assets; campaign {seed}, cases {start}..{start + n - 1}, {jobs} workers")
        cases = plan(n, seed, sources, assets, subprocess_every, start)
        return run_campaign(cases, jobs=jobs, timeout=timeout, keep=keep, echo=echo)
    finally:
        shutil.rmtree(work, ignore_errors=True)
