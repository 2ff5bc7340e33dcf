"""The project's small exception hierarchy.

Library code raises these; only the command line turns them into messages and exit codes
(:mod:`pipeline.cli`).  Every message is one line that names the file and the problem.
"""

from __future__ import annotations


def one_line(e: BaseException, limit: int = 300) -> str:
    """An exception's message on one line (whitespace collapsed, at most ``limit`` characters)."""
    text = " ".join(str(e).split())
    return text[:limit] or type(e).__name__


class ColossusError(Exception):
    """Base class of every error colossus raises on purpose."""


class InputError(ColossusError):
    """The input file is unusable (unreadable, corrupt, unsupported, semantically invalid).

    ``str(err)`` is a single line of the form ``"<file>: <problem>"``.
    """

    def __init__(self, path, problem: str):
        self.path = str(path) if path is not None else None
        self.problem = " ".join(str(problem).split())  # force one line
        super().__init__(f"{self.path}: {self.problem}" if self.path else self.problem)


class OutputError(ColossusError):
    """The output cannot be written (directory missing or not writable, bad extension)."""


class UsageError(ColossusError):
    """The settings given are invalid (maps to exit status 2 on the command line)."""
