"""usd-core's diagnostics kept off the user's terminal.

usd-core prints its warnings and status messages (``Warning: in _ReportErrors at line 3326 of
stage.cpp -- ...``) straight to stderr, several lines per problem.  A command speaks in one line
per problem, its own, so the command line and the worker processes register a
``UsdUtils.CoalescingDiagnosticDelegate`` once: while one is registered usd-core collects its
diagnostics there instead of printing them.  Errors still reach us as ``Tf.ErrorException``
(and become our one line or a finding); the collected warnings are dropped after each unit of
work (:func:`take`), or shown with ``COLOSSUS_DEBUG=1``.  Game code is not affected: the runtime
never installs it by itself.
"""

from __future__ import annotations

import os
import sys

_DELEGATE = []


def silence() -> None:
    """Collect usd-core's warnings and status messages in this process instead of printing them
    (idempotent; a forked child keeps the registration)."""
    if _DELEGATE:
        return
    from pxr import UsdUtils

    _DELEGATE.append(UsdUtils.CoalescingDiagnosticDelegate())


def take() -> list:
    """The diagnostics collected since the last call, as one-line strings (emptied); printed to
    stderr as well under ``COLOSSUS_DEBUG=1``."""
    if not _DELEGATE:
        return []
    out = [" ".join(str(d.commentary).split()) for d in _DELEGATE[0].TakeUncoalescedDiagnostics()]
    if out and os.environ.get("COLOSSUS_DEBUG"):
        for line in out:
            print(f"usd-core: {line}", file=sys.stderr)
    return out


class quiet_stderr:
    """``with quiet_stderr():`` what is written to file descriptor 2 inside (usd-core's C++ and
    boost.python print there directly: a corrupt crate value's "TypeError: No to_python
    converter ..." once per failed read) goes to a scratch file instead, dropped on exit, or
    copied to the real stderr under ``COLOSSUS_DEBUG=1``.  For a unit of work in a command's
    process, whose messages are printed after it; nesting is harmless."""

    def __enter__(self):
        import tempfile

        try:
            sys.stderr.flush()
        except Exception:
            pass
        self._scratch = tempfile.TemporaryFile()
        self._saved = os.dup(2)
        os.dup2(self._scratch.fileno(), 2)
        # boost.python prints through Python's sys.stderr (PyErr_Print), which is fd 2 in a real
        # process but a replaced object under click's CliRunner (or any embedding): the same file
        self._py = sys.stderr
        self._text = open(os.dup(self._scratch.fileno()), "w", encoding="utf-8", errors="replace")
        sys.stderr = self._text
        return self

    def __exit__(self, *exc):
        try:
            sys.stderr.flush()
        except Exception:
            pass
        if sys.stderr is self._text:
            sys.stderr = self._py
        self._text.close()
        os.dup2(self._saved, 2)
        os.close(self._saved)
        if os.environ.get("COLOSSUS_DEBUG"):
            self._scratch.seek(0)
            text = self._scratch.read().decode("utf-8", "replace")
            if text:
                print(text, end="", file=sys.stderr)
        self._scratch.close()
        return False
