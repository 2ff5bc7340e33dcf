"""The project's one exception root and its one-line message helper (floor 1: every package may
import this module; it imports nothing of the project).

Library code raises :class:`ColossusError` subclasses and never prints or exits; the command
line maps them to exit statuses in one place (``pipeline.cli.maps_errors``).
"""

from __future__ import annotations

import re

#: usd-core's ``Error in 'func' at line N in file F : 'why'`` reduced to ``why``.
_TF_REASON = re.compile(r"file \S+ : '(.+?)'(?: Error in|$)")


def one_line(e: BaseException | str, limit: int = 300) -> str:
    """An exception's message (or a text) on one readable line.

    Whitespace is collapsed, usd-core's ``Error in 'func' at line ... : 'why'`` becomes ``why``,
    and the text is cut to ``limit`` characters with ``...`` (a parser that quotes the file it
    choked on must not print hundreds of characters of it).  An empty message gives the
    exception's type name.
    """
    text = " ".join(str(e).split())
    m = _TF_REASON.search(text)
    if m:
        text = m.group(1)
    if len(text) > limit:
        text = text[: max(0, limit - 3)].rstrip() + "..."
    if not text and isinstance(e, BaseException):
        text = type(e).__name__
    return text


class ColossusError(Exception):
    """Base class of every error colossus raises on purpose (``str()`` is one line)."""


class ColliderError(ColossusError):
    """A collider asset cannot be read or fails verification (one-line message)."""
