"""The temporary files of atomic writes (an asset, a report, a picture): written beside their
target, then renamed over it.

They are named ``.colossus-<pid>-<random><ext>`` (the extension kept: usd-core picks a layer's
format by it), so

* no input expansion ever takes one for an input (:func:`is_temp`: ``validate DIR/`` after a
  killed write checks only real assets), and
* a file left by a process that was killed mid-write is recognised by its dead writer and
  removed by the next write to the same folder (:func:`clean_stale`).
"""

from __future__ import annotations

import os
import re
import time

PREFIX = ".colossus-"
#: When this process started using this module (about when the command started): a temporary file
#: older than that whose writer is dead is a killed write's, never one in progress.
_STARTED = time.time()
_NAME = re.compile(r"^\.colossus-(\d+)-[0-9a-f]+")


def temp_path(folder: str, ext: str = "") -> str:
    """A fresh temporary path in ``folder`` ending in ``ext`` (nothing is created)."""
    return os.path.join(folder, f"{PREFIX}{os.getpid()}-{os.urandom(6).hex()}{ext}")


def is_temp(name: str) -> bool:
    """True for a name (or path) one of our atomic writes uses as its temporary file."""
    return os.path.basename(os.fspath(name)).startswith(PREFIX)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def clean_stale(folder: str, older_than: float | None = None) -> int:
    """Remove the temporary files in ``folder`` whose writer is no longer running and that are
    older than ``older_than`` (a ``time.time()``; default: when this command started).  Never
    raises; returns how many were removed."""
    limit = _STARTED if older_than is None else older_than
    removed = 0
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return 0
    for e in entries:
        m = _NAME.match(e.name)
        if not m or int(m.group(1)) == os.getpid():
            continue
        try:
            if not e.is_file(follow_symlinks=False) or e.stat(follow_symlinks=False).st_mtime > limit:
                continue
            if not _alive(int(m.group(1))):
                os.unlink(e.path)
                removed += 1
        except (OSError, ValueError):
            continue
    return removed


def write_atomic(path, data) -> None:
    """Write ``data`` (``str``: UTF-8 text, or ``bytes``) to ``path`` through a temporary file in
    the same folder and a rename: a reader sees the old file or the whole new one, never a part.
    The file gets the usual permissions for a new file (``0666`` less the umask: readable by
    others under a normal umask), not the private ``0600`` of a temporary file."""
    folder = os.path.dirname(os.path.abspath(path))
    clean_stale(folder)
    tmp = temp_path(folder, ".tmp")
    payload = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # the umask applies
        with os.fdopen(fd, "wb") as fh:
            fh.write(payload)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
