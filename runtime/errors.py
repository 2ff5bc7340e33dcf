"""The project's one exception root and its one-line message helper (floor 1: every package may
import this module; it imports nothing of the project).

Library code raises :class:`ColossusError` subclasses and never prints or exits; the command
line maps them to exit statuses in one place (``pipeline.cli.maps_errors``).
"""

from __future__ import annotations

import re

#: usd-core's ``Error in 'func' at line N in file F : 'why'`` reduced to ``why``.
_TF_REASON = re.compile(r"file \S+ : '(.+?)'(?: Error in|$)")

#: A quoted run (``"..."`` or ``'...'``) longer than this is cut: parsers quote the bytes they
#: choked on (assimp's ``Cannot parse string "p.375 0.25 0.375 ..."``).
QUOTE_LIMIT = 60
#: usd-core's C++ namespace in the names its text parser quotes (``parse error matching
#: pxrInternal_v0_26_11__pxrReserved__::Sdf_TextFileFormatParser::TupleValueClose``): dropped.
_PXR_NAMESPACE = re.compile(r"pxrInternal_v\d+(?:_\d+)*__pxrReserved__(?:_pegtl)?::")
_LONG_QUOTE = re.compile(r"""(["'])([^"']{%d,})\1""" % (QUOTE_LIMIT + 1))


def _text(e) -> str:
    """``str(e)``, even for an exception whose ``__str__`` itself fails (usd-core's
    ``Tf.ErrorException`` raises ``UnicodeDecodeError`` when the message quotes bytes of a file
    that are not UTF-8)."""
    try:
        return str(e)
    except Exception as inner:
        parts = []
        for a in getattr(e, "args", ()):
            for attr in ("commentary", None):
                try:
                    parts.append(str(getattr(a, attr)) if attr else str(a))
                    break
                except Exception:
                    continue
        text = " ".join(parts)
        return text or f"{type(e).__name__} (its message could not be decoded: {type(inner).__name__})"


def one_line(e: BaseException | str, limit: int = 300) -> str:
    """An exception's message (or a text) on one readable line; never raises.

    Whitespace is collapsed, usd-core's ``Error in 'func' at line ... : 'why'`` becomes ``why``,
    quoted runs longer than :data:`QUOTE_LIMIT` characters are cut, and the text is cut to
    ``limit`` characters with ``...`` (a parser that quotes the file it choked on must not print
    hundreds of characters of it).  An empty message gives the exception's type name.
    """
    text = " ".join(_text(e).split())
    m = _TF_REASON.search(text)
    if m:
        text = m.group(1)
    text = _PXR_NAMESPACE.sub("", text)
    text = _LONG_QUOTE.sub(lambda q: f"{q.group(1)}{q.group(2)[:QUOTE_LIMIT - 3].rstrip()}...{q.group(1)}", text)
    if len(text) > limit:
        text = text[: max(0, limit - 3)].rstrip() + "..."
    if not text and isinstance(e, BaseException):
        text = type(e).__name__
    return text


class ColossusError(Exception):
    """Base class of every error colossus raises on purpose (``str()`` is one line)."""


class ColliderError(ColossusError):
    """A collider asset cannot be read or fails verification (one-line message)."""
