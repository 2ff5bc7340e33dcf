"""Values of the import's and the validator's options that both the library and the command line
take: ``--max-deviation`` (:func:`parse_max_deviation`, :func:`resolve_max_deviation`).

They live on this floor, not in the command line's: :class:`~colossus.pipeline.run.ImportSettings`
and the ``simplify`` stage take ``max_deviation`` as text (``import_asset(..., max_deviation="1%")``),
and so does :func:`colossus.validators.check_asset` (the COL701 limit), below ``colossus.cli``."""

from __future__ import annotations

import numpy as np

from .errors import UsageError


def parse_max_deviation(value):
    """``--max-deviation``: ``(length, relative)`` from ``"0.01"`` (stage units) or ``"0.5%"``
    (percent of the model size); None for None.  Raises :class:`UsageError`."""
    if value is None or value == "":
        return None
    if isinstance(value, tuple):
        return value
    text = str(value).strip()
    rel = text.endswith("%")
    try:
        v = float(text[:-1] if rel else text)
    except ValueError:
        raise UsageError(f"--max-deviation {value!r}: expected a length in stage units or a percentage "
                         "of the model size, e.g. 0.01 or 0.5%") from None
    if not (np.isfinite(v) and v > 0):
        raise UsageError(f"--max-deviation {value!r}: expected a positive length")
    return v, rel


def resolve_max_deviation(spec, size: float) -> float | None:
    """The limit in stage units: ``spec`` from :func:`parse_max_deviation`, ``size`` the model size."""
    if spec is None:
        return None
    v, rel = spec
    return v * size / 100.0 if rel else v
