"""What a file may make us read: the files it references, checked before anything is opened.

A collider asset or a source is read in CI from untrusted pull requests, so a reference is a
hostile input like any other: a glTF ``buffers[].uri`` or a USD sublayer, reference, payload or
value clip that names ``/etc/passwd``, climbs out with ``..``, follows a symlink out of the folder,
or names a FIFO (a read that never ends), a device or a directory.  The rules:

* a reference is a path relative to the referencing file's folder, and must stay inside that
  folder once symlinks are resolved; no URI scheme (``data:`` URIs are the reader's business);
* it must name a regular file, checked with ``stat`` before it is opened, and opened so that a
  file swapped for a FIFO in between cannot block (:func:`open_regular`);
* ``allow_outside`` (``--allow-outside-references``) lifts the first rule only, never the second.

USD layers are inspected with ``Sdf`` alone (:func:`layer_references`): nothing is composed, so
nothing the layer names is opened before it is checked.
"""

from __future__ import annotations

import os
import stat
from urllib.parse import unquote, urlsplit

from .errors import ColossusError


class OutsideReference(ColossusError):
    """A reference a file may not make (the message names the reference and why)."""


#: ``--allow-outside-references`` for the reads of this process (:func:`allowing_outside`).
_ALLOW_OUTSIDE = [False]


class allowing_outside:
    """``with allowing_outside(flag):`` the readers called inside may follow references out of
    their file's folder when ``flag`` (regular files only, still)."""

    def __init__(self, flag: bool):
        self.flag = bool(flag)

    def __enter__(self):
        self.saved = _ALLOW_OUTSIDE[0]
        _ALLOW_OUTSIDE[0] = self.flag

    def __exit__(self, *exc):
        _ALLOW_OUTSIDE[0] = self.saved


def resolve(base_file, ref: str, what: str = "reference", allow_outside: bool | None = None) -> str:
    """The path of the file ``ref`` names, relative to the folder of ``base_file``; raises
    :class:`OutsideReference` (one line naming ``what`` and ``ref``) when the rules above refuse it."""
    allow_outside = _ALLOW_OUTSIDE[0] if allow_outside is None else allow_outside
    ref = str(ref)
    scheme = urlsplit(ref).scheme
    if scheme and not (len(scheme) == 1 and os.name == "nt"):
        raise OutsideReference(f"{what} {ref!r}: a URI ({scheme}:) is not read; only files beside it are")
    rel = unquote(ref)
    folder = os.path.dirname(os.path.abspath(os.fspath(base_file)))
    if os.path.isabs(rel) and not allow_outside:
        raise OutsideReference(f"{what} {ref!r}: an absolute path (outside the file's folder; "
                              "--allow-outside-references reads it)")
    full = os.path.normpath(os.path.join(folder, rel))
    if not allow_outside:
        real_folder = os.path.realpath(folder)
        real = os.path.realpath(full)
        if os.path.commonpath([real_folder, real]) != real_folder:
            raise OutsideReference(f"{what} {ref!r}: leaves the file's folder (through '..' or a symlink; "
                                  "--allow-outside-references reads it)")
    try:
        st = os.stat(full)
    except OSError as e:
        raise OutsideReference(f"{what} {ref!r}: {e.strerror or 'cannot be read'}") from None
    if not stat.S_ISREG(st.st_mode):
        kind = ("a directory" if stat.S_ISDIR(st.st_mode) else "a FIFO" if stat.S_ISFIFO(st.st_mode)
                else "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "not a regular file")
        raise OutsideReference(f"{what} {ref!r}: is {kind}, not a regular file")
    return full


def open_regular(path, max_bytes: int | None = None) -> bytes:
    """The bytes of the regular file ``path``: opened without blocking (a FIFO put in its place
    after the check cannot hang us) and checked again on the open descriptor."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise OutsideReference(f"{path}: not a regular file")
        if max_bytes is not None and st.st_size > max_bytes:
            raise OutsideReference(f"{path}: {st.st_size} bytes, more than {max_bytes} a file of its kind may have")
        with os.fdopen(fd, "rb", closefd=True) as fh:
            fd = -1
            return fh.read()
    finally:
        if fd >= 0:
            os.close(fd)


def layer_references(path, composition_only: bool = False) -> list:
    """The asset paths the USD layer ``path`` names, read from that layer alone (``Sdf``; nothing
    is composed or opened besides it): sublayers, references, payloads and value clips, and,
    unless ``composition_only``, asset-valued attributes too.  Raises what usd-core raises on a
    layer it cannot parse."""
    from pxr import Sdf, UsdUtils

    if composition_only:
        layer = Sdf.Layer.FindOrOpen(os.fspath(path))
        if layer is None:
            return []
        out = list(layer.GetCompositionAssetDependencies())

        def clips(spec_path):
            spec = layer.GetPrimAtPath(spec_path) if spec_path.IsPrimPath() else None
            if spec is None or not spec.HasInfo("clips"):
                return
            for sets in spec.GetInfo("clips").values():
                if not hasattr(sets, "get"):
                    continue
                for key in ("assetPaths", "manifestAssetPath"):
                    v = sets.get(key)
                    items = [] if not v else [v] if isinstance(v, str) or hasattr(v, "path") else list(v)
                    # extend, not +=: out is the enclosing function's (an UnboundLocalError made every
                    # USD source with value clips an internal error; fuzz campaign 13, case 32)
                    out.extend(getattr(a, "path", str(a)) for a in items)

        layer.Traverse(Sdf.Path.absoluteRootPath, clips)
        return sorted(set(p for p in out if p))
    subs, refs, payloads = UsdUtils.ExtractExternalReferences(os.fspath(path))
    return sorted(set(subs) | set(refs) | set(payloads))
