"""The import stage's exceptions, under the project's one root :class:`ColossusError`.

Library code raises these; only the command line turns them into messages and exit codes
(:func:`pipeline.cli.maps_errors`).  Every message is one line that names the file and the problem.
"""

from __future__ import annotations

from colossus.runtime.errors import ColossusError, one_line

__all__ = ["ColossusError", "one_line", "InputError", "OutputError", "UsageError"]


#: Longest problem text of an :class:`InputError` (the command line adds "error: " and ": ").
PROBLEM_LIMIT = 300 - len("error: ") - len(": ")


class InputError(ColossusError):
    """The input file is unusable (unreadable, corrupt, unsupported, semantically invalid).

    ``str(err)`` is a single line of the form ``"<file>: <problem>"``.
    """

    def __init__(self, path, problem: str):
        self.path = str(path) if path is not None else None
        # one line, of readable length: "error: <file>: <problem>" is at most 300 characters
        # besides the file's path
        self.problem = one_line(problem, limit=PROBLEM_LIMIT)
        super().__init__(f"{self.path}: {self.problem}" if self.path else self.problem)


class OutputError(ColossusError):
    """The output cannot be written (directory missing or not writable, bad extension)."""


class UsageError(ColossusError):
    """The settings given are invalid (maps to exit status 2 on the command line)."""
