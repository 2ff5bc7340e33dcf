"""Native-fault containment: run a function on an untrusted file in a forked child process.

assimp and usd-core parse hostile bytes in C++, in our process.  A segfault or an abort there
would kill ``colossus`` with no message.  :func:`contained` runs ``fn(*args)`` in a child made by
``os.fork()`` and hands its result (or its exception) back pickled, so a native crash, a runaway
allocation or a hang becomes one :class:`ChildFailed` in the parent, which the callers turn into
their usual one-line error naming the file (:func:`read_isolated` for ``colossus import``,
``validators.parallel`` for ``colossus validate --jobs 1``).

Why ``fork`` and not a spawned worker: the child starts with everything the parent has loaded
(usd-core, assimp, numpy) already imported, so the cost per file is the fork and one pickle of
the result (measured by ``colossus bench --only import``), not seconds of imports.

What the child does differently from an in-process call:

* its stderr and stdout (fds 2 and 1, where native libraries print) go to an anonymous file:
  native chatter never reaches the user (nor ``--json`` output); its last line is quoted when
  the child dies;
* Python warnings are recorded and re-issued in the parent (same category, message and
  location), so warning filters and tests see exactly what an in-process call would show;
* its private writable memory is capped (``RLIMIT_DATA``: heap and anonymous maps, not the
  address space that thread arenas merely reserve) at what it has plus ``memory`` bytes, so an
  allocation that escapes the readers' own budget (a native one inside assimp, say) fails there
  as a ``MemoryError`` instead of eating the machine;
* it has ``timeout`` seconds; then it is killed.

Forking a multi-threaded process is delicate: only the forking thread exists in the child.  The
child only runs the readers (numpy, assimp, usd-core: no numba kernel, no thread of ours), the
command line reads before any parallel kernel runs, and the parent's timeout bounds a child that
would hang on a lock some other thread held at fork time.  Such a child sleeps and uses no CPU
(usd-core's worker threads free stages in the background: forking while one holds a lock
usd-core's reader then needs leaves the child waiting forever).  So on Linux the parent watches
its child: one that has slept without using any CPU for :data:`STALL_SECONDS` is killed and
forked again, once (the lock's holder, in the parent, has long finished by then); a second
stall waits for the timeout as before.

A caller that can do better serialises instead of watching (issue 26 item 6): ``guards`` are
locks the forking thread takes before the fork and releases after it (in the parent and in the
child), so no other thread holds them at that moment; and :func:`usd_serial` keeps usd-core's
own work (parallel loops, the detached tasks that free stages) on the calling thread, so at a
fork from that thread no usd-core thread is in the middle of anything.  ``validate --jobs 1``
probes crate assets that way, with the watch off (``watch=False``).  The watch stays on by
default because :func:`read_isolated` (``colossus import``) forks from a process that may have
usd-core, numba or Dask threads at work (a multi-file import writes stages between reads, and
keeping usd-core serial there would cost its writer its threads): there a stall is still
possible, and the watch is what turns it into a re-fork instead of a false timeout.  Python's "this process is
multi-threaded, use of fork() may lead to deadlocks" ``DeprecationWarning`` is silenced for that
reason.  Where ``os.fork`` does not exist, or ``COLOSSUS_ISOLATE=0``, the call runs in-process.

Tests inject faults by patching the function the child runs (``tests/faults.py``; a fork
inherits the patch): no test switch is read here.
"""

from __future__ import annotations

import gc
import mmap
import os
import pickle
import select
import signal
import struct
import sys
import tempfile
import time
import traceback
import warnings
from contextlib import ExitStack, contextmanager

from .errors import ColossusError, InputError, one_line

#: Seconds a contained read may take before its child is killed (``COLOSSUS_READ_TIMEOUT``
#: overrides); generous: the 200,000-triangle benchmark file reads in about a second.
READ_TIMEOUT = 600.0

#: Seconds a contained child may sleep without using any CPU before it is taken as deadlocked
#: at the fork (a lock some other thread of the parent held) and forked again, once.
STALL_SECONDS = 20.0

#: How often the parent looks at its child's CPU time (seconds).
_STALL_TICK = 1.0

#: Extra address space the reading child may map, as a multiple of the readers' own allocation
#: budget (:class:`pipeline.readers.common.AllocationBudget`): that budget counts the arrays the
#: readers make; assimp's and usd-core's own copies come on top.
READ_MEMORY_FACTOR = 3


class ChildFailed(ColossusError):
    """The contained child died (a signal, an unexpected exit) or ran out of time.

    ``reason`` is one line (``"SIGSEGV"``, ``"exit status 3"``, ``"timed out after 60 s"``),
    ``native`` the last line the child printed on its stderr (maybe empty), ``timed_out`` a bool.
    """

    def __init__(self, reason: str, native: str = "", timed_out: bool = False):
        self.reason, self.native, self.timed_out = reason, native, timed_out
        super().__init__(reason + (f" ({native})" if native else ""))

    def __reduce__(self):
        return type(self), (self.reason, self.native, self.timed_out)


def available() -> bool:
    """Whether :func:`contained` forks (POSIX ``os.fork`` present, ``COLOSSUS_ISOLATE`` not ``0``)."""
    return hasattr(os, "fork") and os.environ.get("COLOSSUS_ISOLATE", "1").strip() not in ("0", "no", "off", "false")


def _signal_name(sig: int) -> str:
    try:
        return signal.Signals(sig).name
    except ValueError:
        return f"signal {sig}"


def _data_size() -> int:
    """Bytes of private writable memory (``VmData``: heap, anonymous maps, stacks) this process
    maps now (Linux ``/proc``; 0 when unknown)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmData:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def _progress(pid: int):
    """(state, CPU ticks used) of process ``pid`` from Linux ``/proc`` (all its threads), or None
    when unknown."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            text = fh.read()
        fields = text[text.rindex(b")") + 2:].split()  # after "pid (comm) ": state is field 3
        return fields[0].decode(), int(fields[11]) + int(fields[12])  # utime + stime
    except (OSError, ValueError, IndexError):
        return None


def _exception_payload(e: BaseException):
    """What the parent needs to raise the same exception: (class, args, attributes, traceback text)."""
    tb = "".join(traceback.format_exception(type(e), e, e.__traceback__))
    state = {k: v for k, v in getattr(e, "__dict__", {}).items() if k != "__notes__"}
    try:
        pickle.dumps((type(e), e.args, state))
        return ("raise", type(e), e.args, state, tb)
    except Exception:  # an exception class or argument that does not pickle: keep its text
        return ("raise", RuntimeError, (f"{type(e).__name__}: {e}",), {}, tb)


def _rebuild(cls, args, state, tb):
    try:
        exc = cls.__new__(cls)
        BaseException.__init__(exc, *args)
        exc.__dict__.update(state)
    except Exception:
        exc = RuntimeError(f"{cls.__name__}: {' '.join(map(str, args))}")
    exc.add_note("raised in the contained child process:\n" + tb.rstrip())
    return exc


def _scratch(name: str):
    """An anonymous read-write file: in memory (``memfd``) where Linux has it, else a temporary file."""
    if hasattr(os, "memfd_create"):
        try:
            return os.fdopen(os.memfd_create(name, getattr(os, "MFD_CLOEXEC", 0)), "w+b")
        except OSError:
            pass
    return tempfile.TemporaryFile()


_ALIGN = 64


def _pad(n: int) -> bytes:
    return b"\x00" * (-n % _ALIGN)


def _dump(obj) -> list:
    """``obj`` as the pieces of one file: a header, the pickle (protocol 5), then every large
    buffer (numpy arrays) raw and 64-byte aligned, out of band, so neither side copies them."""
    bufs = []
    main = pickle.dumps(obj, protocol=5, buffer_callback=bufs.append)
    raws = [b.raw() for b in bufs]
    head = struct.pack(f"<QQ{len(raws)}Q", len(main), len(raws), *(r.nbytes for r in raws))
    parts = [head, main, _pad(len(head) + len(main))]
    for r in raws:
        parts += [r, _pad(r.nbytes)]
    return parts


def _load(fh):
    """Read what :func:`_dump` wrote to ``fh``: the large buffers are used in place, from a
    private (copy-on-write) mapping of the file, not copied."""
    size = fh.seek(0, os.SEEK_END)
    mm = mmap.mmap(fh.fileno(), size, access=mmap.ACCESS_COPY)
    n_main, n_buf = struct.unpack_from("<QQ", mm, 0)
    lens = struct.unpack_from(f"<{n_buf}Q", mm, 16)
    pos = 16 + 8 * n_buf
    main = mm[pos:pos + n_main]
    pos += n_main
    pos += -pos % _ALIGN
    view, buffers = memoryview(mm), []
    for n in lens:
        buffers.append(view[pos:pos + n])
        pos += n + (-n % _ALIGN)
    return pickle.loads(main, buffers=buffers)


def die_with_parent(parent_pid: int) -> None:
    """Tie this process's life to its parent's: on Linux the kernel sends it SIGKILL when the
    parent dies (``prctl(PR_SET_PDEATHSIG)``), whatever kills the parent (SIGKILL included); and if
    the parent ``parent_pid`` is already gone, exit now.  Elsewhere only the second check runs."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:
        os._exit(1)


def _child(out_fd: int, err_fd: int, fn, args, kwargs, path: str, memory: int | None, parent: int = 0) -> None:
    """The child's whole life: never returns (``os._exit``).  The pickled answer goes to the file
    ``out_fd`` (one write, no pipe ping-pong with the parent: on a loaded machine each 64 KiB
    pipe round trip costs a scheduling delay); the parent learns it is done when the child's end
    of the pipe closes, at exit."""
    code = 0
    try:
        if parent:
            die_with_parent(parent)  # a killed command leaves no reader behind
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # Ctrl-C: the parent handles it, the child just dies
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        os.dup2(err_fd, 2)
        os.dup2(err_fd, 1)  # a library printing to stdout must not corrupt the command's own output (--json)
        import faulthandler
        faulthandler.disable()  # its dump may go to a copy of the parent's stderr (pytest's does): the parent reports
        if memory:
            import resource
            soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
            cap = _data_size() + int(memory)
            if hard != resource.RLIM_INFINITY:
                cap = min(cap, hard)
            if soft == resource.RLIM_INFINITY or cap < soft:
                resource.setrlimit(resource.RLIMIT_DATA, (cap, hard))
        with warnings.catch_warnings(record=True) as caught:
            try:
                payload = ("ok", fn(*args, **kwargs))
            except BaseException as e:  # everything goes back to the parent, to be raised there
                payload = _exception_payload(e)
        shown = [(str(w.message), w.category, w.filename, w.lineno) for w in caught]
        try:
            parts = _dump((payload, shown))
        except Exception as e:
            parts = _dump((_exception_payload(e), shown))
        for part in parts:
            view = memoryview(part).cast("B")
            while view:
                view = view[os.write(out_fd, view):]
    except BaseException:
        code = 1
    finally:
        os._exit(code)


def _native_tail(fh) -> str:
    try:
        fh.seek(0)
        text = fh.read()[-4096:].decode("utf-8", "replace")
    except OSError:
        return ""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return one_line(lines[-1], limit=160) if lines else ""


@contextmanager
def usd_serial():
    """usd-core runs all its work on the calling thread while this lasts (``Work`` concurrency 1:
    TBB gets no worker thread, and ``WorkRunDetachedTask``, which frees stages in the background,
    runs the task inline).  A fork from that thread then cannot copy a lock a usd-core thread
    holds.  The previous limit is restored on exit.  Costs usd-core its parallel loops (small
    assets: nothing measurable; see ``validators.parallel.check_many``)."""
    try:
        from pxr import Work
    except ImportError:  # pragma: no cover - usd-core is a dependency
        yield
        return
    before = Work.GetConcurrencyLimit()
    Work.SetConcurrencyLimit(1)
    try:
        yield
    finally:
        Work.SetConcurrencyLimit(before)


def usd_is_serial() -> bool:
    """Whether usd-core runs on the calling thread only (inside :func:`usd_serial`)."""
    try:
        from pxr import Work
    except ImportError:  # pragma: no cover
        return True
    return Work.GetConcurrencyLimit() <= 1


def contained(fn, *args, path: str = "", timeout: float | None = None, memory: int | None = None,
              guards=(), watch: bool = True, **kwargs):
    """``fn(*args, **kwargs)`` in a forked child; its return value, or its exception raised here.

    Parameters
    ----------
    fn : callable
        Its result must pickle (numpy arrays, dataclasses of them: cheap).
    path : str
        The file the call is about (for the test hook only).
    timeout : float, optional
        Seconds before the child is killed (None: no limit), a re-fork after a stall included.
    memory : int, optional
        Bytes of address space the child may add to what it has at the fork (None: no cap).
    guards : sequence of locks
        Taken (``with``) by this thread just before the fork and released just after it, in
        both processes: a thread of ours that uses one cannot hold it at the fork.
    watch : bool
        The stall watch (:data:`STALL_SECONDS`); a caller that serialises usd-core
        (:func:`usd_serial`) and passes its locks as ``guards`` turns it off.

    Raises
    ------
    ChildFailed
        The child died without an answer (``reason``: the signal or exit status) or timed out.
    whatever ``fn`` raised
        Rebuilt from its class and arguments, with the child's traceback as a note.
    """
    if not available():
        return fn(*args, **kwargs)
    deadline = None if timeout is None else time.monotonic() + timeout
    got = _attempt(fn, args, kwargs, path, memory, deadline, timeout, watch=watch, guards=guards)
    if got is _STALLED:  # deadlocked at the fork: once more (the second is not watched)
        got = _attempt(fn, args, kwargs, path, memory, deadline, timeout, watch=False, guards=guards)
    return got


_STALLED = object()


def _attempt(fn, args, kwargs, path, memory, deadline, timeout, watch, guards=()):
    """One fork of :func:`contained`: the result, or :data:`_STALLED` when ``watch`` and the
    child slept without using CPU for :data:`STALL_SECONDS` (it was killed)."""
    for stream in (sys.stdout, sys.stderr):  # buffered text must not be written twice
        try:
            stream.flush()
        except Exception:
            pass
    read_fd, write_fd = os.pipe()
    err, out = _scratch("colossus-child-stderr"), _scratch("colossus-child-result")
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=r".*use of fork\(\) may lead to deadlocks", category=DeprecationWarning)
            # the collector would write to the header of every object the parent made, each write
            # a copy-on-write page fault in the child: freeze them out of its view, and do not
            # collect in the short-lived child at all
            held = ExitStack()
            for g in guards:  # serialised: no other thread of ours holds one at the fork
                held.enter_context(g)
            gc.freeze()
            pid, parent = -1, os.getpid()
            try:
                pid = os.fork()
            except OSError:  # no process to spare (EAGAIN, ENOMEM): read here, uncontained
                pass
            finally:
                if pid != 0:
                    gc.unfreeze()
                held.close()  # the child too: the forking thread took them, the forking thread releases
        if pid < 0:
            os.close(write_fd)
            err.close()
            out.close()
            return fn(*args, **kwargs)
        if pid == 0:  # pragma: no cover - the child (coverage does not follow it)
            gc.disable()
            os.close(read_fd)
            _child(out.fileno(), err.fileno(), fn, args, kwargs, path, memory, parent)
        os.close(write_fd)
        status, reason = None, None
        still = (None, time.monotonic())  # (last CPU ticks seen, since when)
        try:
            while True:
                wait = None if deadline is None else max(0.0, deadline - time.monotonic())
                if watch:
                    wait = _STALL_TICK if wait is None else min(wait, _STALL_TICK)
                ready, _, _ = select.select([read_fd], [], [], wait)
                if ready:
                    if not os.read(read_fd, 1):  # the child never writes here: EOF is its exit
                        break
                    continue
                if deadline is not None and time.monotonic() >= deadline:
                    reason = f"timed out after {timeout:g} s"
                    os.kill(pid, signal.SIGKILL)
                    break
                if not watch:
                    continue
                seen = _progress(pid)
                asleep = seen is not None and seen[0] == "S"
                if not asleep or seen[1] != still[0]:
                    still = (seen[1] if asleep else None, time.monotonic())
                elif time.monotonic() - still[1] >= STALL_SECONDS:  # asleep, no CPU: deadlocked
                    os.kill(pid, signal.SIGKILL)
                    os.waitpid(pid, 0)
                    err.close()
                    out.close()
                    return _STALLED
        except BaseException:  # Ctrl-C (or anything) in the parent: the child goes too
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.waitpid(pid, 0)
            raise
        _, status = os.waitpid(pid, 0)
    finally:
        os.close(read_fd)
    try:
        if reason is None:
            if os.WIFSIGNALED(status):
                reason = _signal_name(os.WTERMSIG(status))
            elif os.WEXITSTATUS(status) != 0 or out.seek(0, os.SEEK_END) == 0:
                reason = f"exit status {os.WEXITSTATUS(status)}"
        if reason is not None:
            raise ChildFailed(reason, _native_tail(err), timed_out=reason.startswith("timed out"))
        payload, shown = _load(out)
    finally:
        err.close()
        out.close()
    for message, category, filename, lineno in shown:
        warnings.warn_explicit(message, category, filename, lineno)
    if payload[0] == "ok":
        return payload[1]
    raise _rebuild(*payload[1:])


# ------------------------------------------------------------------------------ readers
def _read_in_child(path, meshes, fps, limit_mib, allow_outside=False):
    from colossus.runtime.references import allowing_outside

    import numpy as np

    from .readers import read
    try:
        # a hostile file's NaN, inf and overflowing values make numpy warn inside the readers;
        # the readers and check_read refuse such values explicitly, in one line, so numpy's own
        # warnings (which would be a second, Python-level line) are not raised while reading
        with allowing_outside(allow_outside), np.errstate(all="ignore"):
            return read(path, meshes=meshes, fps=fps)
    except MemoryError:
        raise InputError(path, f"reading it needs more memory than the {limit_mib:.0f} MiB a file of its size "
                         "may use (corrupt or hostile file?)") from None


def read_isolated(path, meshes=None, fps=None, allow_outside=False):
    """:func:`pipeline.readers.read` in a contained child: the same result or the same
    :class:`~pipeline.errors.InputError`; a native crash, a runaway allocation or a hang of the
    reader becomes an ``InputError`` naming the file too.

    Memory: the child may map ``READ_MEMORY_FACTOR`` times the readers' allocation budget for
    the file's size on top of what the process has.  Time: ``COLOSSUS_READ_TIMEOUT`` seconds
    (default :data:`READ_TIMEOUT`).
    """
    from .tolerances import ALLOC_FACTOR, ALLOC_FLOOR

    p = os.fspath(path)
    try:
        size = os.path.getsize(p)
    except OSError:
        size = 0  # the reader reports it
    budget = ALLOC_FACTOR * size + ALLOC_FLOOR
    memory = READ_MEMORY_FACTOR * budget
    try:
        timeout = float(os.environ.get("COLOSSUS_READ_TIMEOUT", READ_TIMEOUT))
    except ValueError:
        timeout = READ_TIMEOUT
    try:
        return contained(_read_in_child, p, meshes, fps, memory / 2**20, allow_outside, path=p, timeout=timeout,
                         memory=memory)
    except ChildFailed as e:
        if e.timed_out:
            raise InputError(p, f"reading it took more than {timeout:g} s (corrupt or hostile file?)") from None
        raise InputError(p, f"the reader crashed on it ({e}); corrupt or hostile file?") from None
