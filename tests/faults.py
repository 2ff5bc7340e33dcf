"""Fault injection for the reliability tests, by patched functions (production code reads no test
switch): replacements for the functions the project runs in a contained child or in a worker,
which die the way a native crash would before calling the real one.

* :func:`dying` wraps a function run in the forked reader child (``contained``): tests patch
  ``colossus.pipeline.isolation._read_in_child`` or ``colossus.validators.parallel._probe`` with it
  (a fork inherits the patch).
* :data:`WORKER_UNITS` are the validators' work units that kill their *worker* process on assets
  named ``*crashme*`` every time and on ``*crashonce*`` the first time (a marker file
  ``PATH.crashed`` remembers it); tests patch them into ``colossus.validators.parallel``, and pool
  and Dask workers import them from this module by name (so ``tests/`` must be on their path).
"""

from __future__ import annotations

import os
import signal
import time


def die(how: str) -> None:
    """Kill this process by ``how``: ``segv``, ``abort``, ``exit`` (status 3) or ``hang``."""
    if how == "segv":
        os.kill(os.getpid(), signal.SIGSEGV)
    elif how == "abort":
        os.abort()
    elif how == "exit":
        os._exit(3)
    elif how == "hang":
        while True:
            time.sleep(1)
    raise ValueError(f"unknown way to die: {how!r}")


def dying(fn, how: str, needle: str = ""):
    """``fn`` that first dies by ``how`` when its first argument (a path) contains ``needle``."""
    def run(path, *args, **kwargs):
        if needle in os.fspath(path):
            die(how)
        return fn(path, *args, **kwargs)
    run.__name__ = run.__qualname__ = f"dying_{getattr(fn, '__name__', 'fn')}"
    return run


def _worker_dies(path) -> None:
    import multiprocessing as mp

    path = os.fspath(path)
    if mp.parent_process() is None:  # never the coordinator
        return
    if "crashme" in path:
        os._exit(70)
    if "crashonce" in path and not os.path.exists(path + ".crashed"):
        open(path + ".crashed", "w").close()
        os._exit(70)


from colossus.validators import parallel as _parallel  # noqa: E402

#: The real units, taken when this module is first imported (before any test patches them; a
#: worker imports it fresh).
_REAL = {n: getattr(_parallel, n) for n in ("unit_check", "unit_plan", "unit_clip", "unit_finish")}


def unit_check(path, kw):
    _worker_dies(path)
    return _REAL["unit_check"](path, kw)


def unit_plan(path, kw):
    _worker_dies(path)
    return _REAL["unit_plan"](path, kw)


def unit_clip(path, clip, kw):
    _worker_dies(path)
    return _REAL["unit_clip"](path, clip, kw)


def unit_finish(path, kw, proofs):
    _worker_dies(path)
    return _REAL["unit_finish"](path, kw, proofs)


#: name in ``colossus.validators.parallel`` -> its dying replacement
WORKER_UNITS = {"unit_check": unit_check, "unit_plan": unit_plan, "unit_clip": unit_clip, "unit_finish": unit_finish}
