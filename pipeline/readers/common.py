"""Helpers shared by the readers: input checks, allocation cap, influence packing, clip names
(:func:`unique_name`, which ``stages.write`` uses for prim names too)."""

from __future__ import annotations

import os

import numpy as np

from ..errors import InputError
from ..tolerances import ALLOC_FACTOR, ALLOC_FLOOR


def check_input_file(path) -> int:
    """Raise :class:`InputError` unless ``path`` is a readable, non-empty file; return its size."""
    p = os.fspath(path)
    if not os.path.exists(p):
        raise InputError(p, "no such file")
    if os.path.isdir(p):
        raise InputError(p, "is a directory, not a file")
    try:
        size = os.path.getsize(p)
        with open(p, "rb") as fh:
            fh.read(1)
    except OSError as exc:
        raise InputError(p, f"cannot be read ({exc.strerror or exc})") from None
    if size == 0:
        raise InputError(p, "file is empty (0 bytes)")
    return size


class AllocationBudget:
    """Caps what one input file may make the importer allocate.

    The budget is ``ALLOC_FACTOR * file_size + ALLOC_FLOOR`` bytes; :meth:`claim` raises
    :class:`InputError` when a planned allocation would exceed it.
    """

    def __init__(self, path, file_size: int):
        self.path = os.fspath(path)
        self.limit = ALLOC_FACTOR * int(file_size) + ALLOC_FLOOR
        self.used = 0

    def claim(self, nbytes: float, what: str) -> None:
        self.used += int(nbytes)
        if self.used > self.limit:
            raise InputError(self.path, f"{what} would need {self.used / 2**20:.0f} MiB, more than this "
                             f"{self.limit / 2**20:.0f} MiB budget for a file of its size allows (corrupt or hostile file?)")


def pack_influences(n: int, vertex: np.ndarray, joint: np.ndarray, weight: np.ndarray):
    """Turn flat (vertex, joint, weight) triples into padded per-vertex arrays.

    Returns ``joint_indices (n, k) int32`` and ``joint_weights (n, k) float32`` where ``k`` is
    the largest number of influences of any vertex (at least 1); entries are sorted by
    decreasing weight; padding has joint 0 and weight 0.  Zero weights are dropped.
    """
    vertex = np.asarray(vertex, dtype=np.int64)
    joint = np.asarray(joint, dtype=np.int64)
    weight = np.asarray(weight, dtype=np.float64)
    keep = weight > 0
    vertex, joint, weight = vertex[keep], joint[keep], weight[keep]
    fast = _pack_sorted(n, vertex, joint, weight)
    if fast is not None:
        return fast
    # Merge duplicate (vertex, joint) entries by summing.
    if len(vertex):
        key = vertex * (int(joint.max()) + 1) + joint
        uk, inv = np.unique(key, return_inverse=True)
        w = np.bincount(inv, weights=weight)
        jmax = int(joint.max()) + 1
        vertex, joint, weight = uk // jmax, uk % jmax, w
    counts = np.bincount(vertex, minlength=n) if len(vertex) else np.zeros(n, dtype=np.int64)
    k = max(1, int(counts.max()) if n else 1)
    order = np.lexsort((-weight, vertex))
    vertex, joint, weight = vertex[order], joint[order], weight[order]
    starts = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=starts[1:])
    slot = np.arange(len(vertex)) - starts[vertex]
    ji = np.zeros((n, k), dtype=np.int32)
    jw = np.zeros((n, k), dtype=np.float32)
    ji[vertex, slot] = joint
    jw[vertex, slot] = weight
    return ji, jw


def _pack_sorted(n, vertex, joint, weight):
    """:func:`pack_influences` for the common case of entries grouped by vertex (a glTF
    ``JOINTS_0``/``WEIGHTS_0`` set, assimp's per-vertex weights): a few row sorts instead of
    sorting every entry.  None when the entries are not grouped or a vertex names a joint twice
    (the general path merges those)."""
    if not len(vertex):
        return None
    if np.any(np.diff(vertex) < 0):
        return None
    counts = np.bincount(vertex, minlength=n)
    k = max(1, int(counts.max()))
    starts = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=starts[1:])
    slot = np.arange(len(vertex)) - starts[vertex]
    ji = np.full((n, k), -1, dtype=np.int64)
    jw = np.zeros((n, k), dtype=np.float64)
    ji[vertex, slot] = joint
    jw[vertex, slot] = weight
    if k > 1:
        sj = np.sort(ji, axis=1)
        if np.any((sj[:, 1:] == sj[:, :-1]) & (sj[:, 1:] >= 0)):
            return None
        order = np.argsort(-jw, axis=1, kind="stable")
        ji = np.take_along_axis(ji, order, axis=1)
        jw = np.take_along_axis(jw, order, axis=1)
    ji[ji < 0] = 0
    return ji.astype(np.int32), jw.astype(np.float32)


def unique_name(base: str, taken: set) -> str:
    """``base``, or the first of ``base_2``, ``base_3``, ... not in ``taken``; added to ``taken``."""
    name, i = base, 1
    while name in taken:
        i += 1
        name = f"{base}_{i}"
    taken.add(name)
    return name


def clip_name(raw: str, taken: set) -> str:
    """A clip's name as shown to users: FBX ``Armature|walk`` becomes ``walk``; duplicates get a suffix."""
    return unique_name((raw or "").split("|")[-1].strip() or "clip", taken)


def check_finite(path, what: str, arr: np.ndarray) -> None:
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero((~np.isfinite(np.asarray(arr).reshape(len(arr), -1))).any(axis=1))) if len(arr) else 0
        raise InputError(path, f"{what} contain NaN or infinite values ({bad} affected)")
