"""Input expansion never hangs and never takes our own temporary files for inputs; atomic writes
leave readable files and clean what a killed writer left."""

from __future__ import annotations

import glob
import os
import stat
import subprocess
import sys
import time

import pytest

from colossus.pipeline.engine import _glob, expand_inputs
from colossus.pipeline.tempfiles import clean_stale, is_temp, temp_path, write_atomic

PATTERNS = ["**/*.usda", "a/**/*.usda", "*/*.usda", "a/**/[wz].*", "a/**/?.usda", "a/**/[!z]*.usda", "**",
            "a/**", "**/b/*", "*", "**/.h*"]


@pytest.fixture()
def tree(tmp_path, monkeypatch):
    for d in ("a/b/c", "d", ".hid"):
        (tmp_path / d).mkdir(parents=True)
    for f in ("x.usda", "a/y.usda", "a/b/z.usda", "a/b/w.glb", "a/b/c/v.usda", "d/.h.usda", ".hid/q.usda"):
        (tmp_path / f).write_text("#usda 1.0\n")
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.parametrize("pattern", PATTERNS)
def test_glob_matches_the_standard_glob(tree, pattern):
    assert _glob(pattern) == sorted(glob.glob(pattern, recursive=True))
    absolute = os.path.join(str(tree), pattern)
    assert _glob(absolute) == sorted(glob.glob(absolute, recursive=True))


def test_symlink_loops_end(tree):
    """Two symlink loops under a globbed folder: glob.glob(recursive=True) runs for ever on them
    (it follows symlinked directories); expansion lists each real directory once, at once."""
    os.symlink("..", tree / "a" / "up")
    os.symlink("../..", tree / "a" / "b" / "up2")
    code = ("import sys; from colossus.pipeline.engine import expand_inputs;"
            "print(expand_inputs(sys.argv[1:], ('.usda',)))")
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, "-c", code, "**/*.usda", "."], capture_output=True, text=True,
                       timeout=60, cwd=tree)
    assert p.returncode == 0 and time.monotonic() - t0 < 30, p.stderr
    files, missing = eval(p.stdout)
    assert missing == []
    assert files[:4] == ["a/b/c/v.usda", "a/b/z.usda", "a/y.usda", "x.usda"], files  # the glob
    walked = sorted(os.path.normpath(f) for f in files[4:])                            # the folder
    assert walked == sorted(os.path.normpath(f) for f in (".hid/q.usda", "a/b/c/v.usda", "a/b/z.usda",
                                                          "a/y.usda", "d/.h.usda", "x.usda")), walked


def test_temporary_files_are_never_inputs(tree):
    """A write killed mid-way leaves ``.colossus-<pid>-<hex>.usda``: a folder or a glob never
    takes it for an asset."""
    left = tree / "a" / ".colossus-999999-0a1b2c.usda"
    left.write_text("#usda 1.0\n")
    assert is_temp(left) and is_temp(temp_path(str(tree), ".usda"))
    files, _ = expand_inputs([str(tree)], (".usda",))
    assert files and not any(is_temp(f) for f in files)
    files, _ = expand_inputs(["**/*.usda", "a/.colossus-*"], (".usda",))
    assert not any(is_temp(f) for f in files), files


def test_stale_temporary_files_are_cleaned(tmp_path):
    """Only files of a writer that no longer runs, and older than the limit, are removed."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    stale = tmp_path / f".colossus-{dead}-00aa.usda"
    mine = tmp_path / f".colossus-{os.getpid()}-00bb.usda"
    alive = tmp_path / f".colossus-1-00cc.usda"  # pid 1 runs
    other = tmp_path / "asset.usda"
    for f in (stale, mine, alive, other):
        f.write_text("x")
    old = time.time() - 3600
    for f in (stale, mine, alive):
        os.utime(f, (old, old))
    assert clean_stale(str(tmp_path), older_than=time.time() - 1800) == 1
    assert not stale.exists() and mine.exists() and alive.exists() and other.exists()


def test_write_atomic_is_readable_by_others(tmp_path):
    umask = os.umask(0o022)
    try:
        write_atomic(tmp_path / "r.json", "{}")
        write_atomic(tmp_path / "p.png", b"\x89PNG")
    finally:
        os.umask(umask)
    for name, body in (("r.json", b"{}"), ("p.png", b"\x89PNG")):
        f = tmp_path / name
        assert f.read_bytes() == body
        assert stat.S_IMODE(f.stat().st_mode) == 0o644
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.png", "r.json"]
