"""Every process a command starts dies with it, and SIGTERM is handled like Ctrl-C (exit 143).

A reader blocked on a FIFO (a glTF buffer with no writer) keeps the contained reader child alive
for as long as the command waits; a ``validate --jobs 2`` has a pool of worker processes.  Killing
the command (SIGKILL, SIGTERM) must leave none of them running 5 s later."""

from __future__ import annotations

import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import time

import pytest

from paths import SAMPLES

COLOSSUS = [sys.executable, "-m", "colossus"]


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


@pytest.fixture()
def fifo_gltf(tmp_path):
    """The limb sample as .gltf + .bin, the .bin a FIFO nobody writes to."""
    data = (SAMPLES / "limb.glb").read_bytes()
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    doc["buffers"][0]["uri"] = "limb.bin"
    src = tmp_path / "limb.gltf"
    src.write_text(json.dumps(doc))
    os.mkfifo(tmp_path / "limb.bin")
    return src


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killed_import_leaves_no_reader(fifo_gltf, tmp_path, sig):
    out = tmp_path / "o.usda"
    proc = subprocess.Popen(COLOSSUS + ["import", str(fifo_gltf), "-o", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
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
