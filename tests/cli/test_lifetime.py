"""Every process a command starts dies with it, and SIGTERM is handled like Ctrl-C (exit 143).

A reader that hangs (before the references check, a glTF buffer that was a FIFO did; here the
reader child is patched to hang, ``tests/faults.py``) keeps the contained reader child alive for as
long as the command waits; a ``validate --jobs 2`` has a pool of worker processes.  Killing the
command (SIGKILL, SIGTERM) must leave none of them running 5 s later."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

from paths import SAMPLES

from paths import ROOT

COLOSSUS = [sys.executable, "-m", "colossus"]
#: ``colossus`` with the contained reader patched to hang (a fork inherits the patch)
HANGING_READER = [sys.executable, "-c",
                  "import sys, faults\n"
                  "from colossus.pipeline import isolation\n"
                  "isolation._read_in_child = faults.dying(isolation._read_in_child, 'hang')\n"
                  "from colossus.cli import main\n"
                  "main(sys.argv[1:], prog_name='colossus')\n"]


def _children(pid: int) -> set:
    """Every descendant process of ``pid`` (read from /proc)."""
    kids = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat", "rb") as fh:
                text = fh.read()
        except OSError:
            continue
        ppid = int(text[text.rindex(b")") + 2:].split()[1])
        kids.setdefault(ppid, set()).add(int(d))
    out, todo = set(), [pid]
    while todo:
        for k in kids.get(todo.pop(), ()):
            if k not in out:
                out.add(k)
                todo.append(k)
    return out


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            text = fh.read()
    except OSError:
        return False
    return text[text.rindex(b")") + 2:].split()[0] != b"Z"


def _wait_for(cond, seconds=60.0):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        got = cond()
        if got:
            return got
        time.sleep(0.1)
    return None


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killed_import_leaves_no_reader(tmp_path, sig):
    out = tmp_path / "o.usda"
    proc = subprocess.Popen(HANGING_READER + ["import", str(SAMPLES / "limb.glb"), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT / "tests")})
    try:
        kids = _wait_for(lambda: _children(proc.pid))
        assert kids, "the contained reader never started"
        time.sleep(0.5)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
        left = _wait_for(lambda: not any(_alive(k) for k in kids), 5.0)
        assert left, f"still running 5 s after the command died: {[k for k in kids if _alive(k)]}"
        assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".colossus-")]
        if sig == signal.SIGTERM:
            assert proc.returncode == 143 and err.splitlines() == ["error: terminated"], (proc.returncode, err)
    finally:
        if proc.poll() is None:
            proc.kill()


@pytest.fixture(scope="module")
def assets(imported, tmp_path_factory):
    d = tmp_path_factory.mktemp("many")
    _, creature = imported("creature", "glb")
    for i in range(12):
        shutil.copy(creature, d / f"c{i:02d}.usda")
    return d


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killed_parallel_validate_leaves_no_worker(assets, sig):
    proc = subprocess.Popen(COLOSSUS + ["validate", str(assets), "--jobs", "2", "--format", "json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        kids = _wait_for(lambda: (k := _children(proc.pid)) and len(k) >= 2 and k)
        assert kids, "no worker started"
        time.sleep(1.0)
        kids |= _children(proc.pid)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
        left = _wait_for(lambda: not any(_alive(k) for k in kids), 5.0)
        assert left, f"still running 5 s after the command died: {[k for k in kids if _alive(k)]}"
        if sig == signal.SIGTERM:
            assert proc.returncode == 143, (proc.returncode, err)
            assert "INCOMPLETE" in out or json.loads(out)["assets"] is not None
    finally:
        if proc.poll() is None:
            proc.kill()


def test_killed_write_leaves_nothing_validate_takes(imported, tmp_path):
    """SIGKILL while the asset is being written leaves a temporary file; ``validate DIR/`` checks
    only the real asset beside it, and the next write to the folder removes it."""
    folder = tmp_path / "out"
    folder.mkdir()
    _, good = imported("limb", "glb")
    shutil.copy(good, folder / "limb.usda")
    out = folder / "creature.usda"
    left = None
    for _ in range(5):  # the write stage lasts a fraction of a second: try until caught in it
        proc = subprocess.Popen(COLOSSUS + ["import", str(SAMPLES / "creature.glb"), "-o", str(out)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        left = _wait_for(lambda: [p for p in folder.iterdir() if p.name.startswith(".colossus-")
                                  and p.suffix == ".usda"], 120)
        proc.kill()
        proc.wait()
        if left and not out.exists():
            break
        if out.exists():
            out.unlink()
    assert left and not out.exists(), "never caught the write in progress"
    time.sleep(1.1)  # older than the next command's start
    r = subprocess.run(COLOSSUS + ["validate", str(folder), "--format", "json"], capture_output=True, text=True,
                       timeout=300)
    assert [os.path.basename(a["path"]) for a in json.loads(r.stdout)["assets"]] == ["limb.usda"], r.stdout
    r = subprocess.run(COLOSSUS + ["import", str(SAMPLES / "limb.glb"), "-o", str(folder / "again.usda")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert not [p for p in folder.iterdir() if p.name.startswith(".colossus-")]
