"""The import stage's exceptions, under the project's one root :class:`ColossusError`.

Library code raises these; only the command line turns them into messages and exit codes
(:func:`pipeline.cli.maps_errors`).  Every message is one line that names the file and the problem.
"""

from __future__ import annotations

from colossus.runtime.errors import ColossusError, one_line

__all__ = ["ColossusError", "one_line", "InputError", "OutputError", "UsageError"]


class InputError(ColossusError):
    """The input file is unusable (unreadable, corrupt, unsupported, semantically invalid).

    ``str(err)`` is a single line of the form ``"<file>: <problem>"``.
    """

    def __init__(self, path, problem: str):
        self.path = str(path) if path is not None else None
        self.problem = one_line(problem, limit=300)  # force one line, of readable length
        super().__init__(f"{self.path}: {self.problem}" if self.path else self.problem)


class OutputError(ColossusError):
    """The output cannot be written (directory missing or not writable, bad extension)."""


class UsageError(ColossusError):
    """The settings given are invalid (maps to exit status 2 on the command line)."""
