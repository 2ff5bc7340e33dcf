"""One fuzz case: make the mutated file, run the command on it, judge the outcome.

The rules (issue 12; the contract's "one line, exit 1, nothing written"):

``import``
    exit 0, the asset written, and ``colossus validate`` on it exits 0 or 1 with findings (never
    ``COL001``/``COL002``/``COL003``: an asset we wrote must be readable and checkable); or exit 1
    with exactly one line on stderr, ``error: ...``, no ``internal error``, no traceback, no
    ``out of memory`` (an allocation that escaped the readers' budget), of readable length,
    and no output file (nor a temporary one) left.  Always: no Python warning, nothing printed
    natively on stderr, no exception escaping click.
``validate``
    a mutated asset checked together with a good one (``validate BAD GOOD --format json``):
    exit 0, 1 or 2 with the JSON report of both; the good asset passes; the bad one gets
    findings (``COL001`` when it cannot be read), never ``COL002`` (a rule crashed) nor an
    internal error; no Python warning.  usd-core's own C++ diagnostics on stderr (a corrupt crate
    makes it print ``failed call to posix_madvise``) are counted, not judged: the report on
    stdout is the interface.

References (issue 26 item 7)
    every case runs in its own folder, beside a folder *outside* it holding canary files and
    FIFOs; the case's folder holds a directory, FIFOs, symlinks out and a symlink loop (see
    :data:`tests.fuzz.mutators.REF_TARGETS`: the reference mutator points a file's references at
    them).  Both folders are watched (Linux inotify, every process: the contained child and the
    subprocess cases too): any of those files opened is a bad outcome, whatever the exit status;
    so is any line of usd-core's on stderr (``validate`` included: its native stderr is judged).

Cases run in-process through click's ``CliRunner`` (fast: no interpreter start per case) with
warnings recorded and file descriptor 2 redirected to a file, so native output is seen too; a
sample runs as a real ``python -m colossus`` subprocess, the path users take.
"""

from __future__ import annotations

import ctypes
import json
import os
import re
import struct
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from contextlib import contextmanager

import numpy as np

from .mutators import OUT, SELF, glb_join, glb_split, mutate, NotApplicable

#: Longest acceptable error line (characters, not counting the input's path).
MAX_MESSAGE = 300

#: Codes of the validator that mean "the check itself failed", never acceptable on our own asset.
CHECK_FAILURES = ("COL001", "COL002", "COL003")

_SEED_CACHE: dict = {}


def case_rng(campaign: int, index: int):
    return np.random.default_rng([int(campaign), int(index)])


def build_case(case: dict):
    """The mutated bytes of ``case`` and the mutation steps (deterministic)."""
    path = case["seed"]
    if path not in _SEED_CACHE:
        with open(path, "rb") as fh:
            _SEED_CACHE[path] = fh.read()
    return mutate(_SEED_CACHE[path], case["ext"], case_rng(case["campaign"], case["index"]))


@contextmanager
def captured_fd2():
    """Redirect file descriptor 2 (native stderr) to a temporary file; yields a getter."""
    sys.stderr.flush()
    saved = os.dup(2)
    tmp = tempfile.TemporaryFile()
    os.dup2(tmp.fileno(), 2)
    box = {"text": ""}
    try:
        yield box
    finally:
        sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)
        tmp.seek(0)
        box["text"] = tmp.read().decode("utf-8", "replace")
        tmp.close()


# ------------------------------------------------------------------------------ references
#: Files in the case's folder a reference may name but nothing may open (see mutators.REF_TARGETS).
FORBIDDEN_INSIDE = ("fifo", "fifo.usda", "link.bin", "link.usda", "loop")


def layout(workdir: str):
    """The case's folder and the folder outside it, with the targets of the reference mutator:
    returns ``(case_dir, outside_dir)``."""
    case_dir, outside = os.path.join(workdir, "case"), os.path.join(workdir, "outside")
    os.makedirs(os.path.join(case_dir, "sub"))
    os.makedirs(outside)
    with open(os.path.join(outside, "canary.bin"), "wb") as fh:
        fh.write(b"\0" * 4096)
    with open(os.path.join(outside, "canary.usda"), "w") as fh:
        fh.write('#usda 1.0\n\ndef Xform "root"\n{\n}\n')
    for d in (outside, case_dir):
        for name in ("fifo", "fifo.usda"):
            os.mkfifo(os.path.join(d, name))
    os.symlink(os.path.join(outside, "canary.bin"), os.path.join(case_dir, "link.bin"))
    os.symlink(os.path.join(outside, "canary.usda"), os.path.join(case_dir, "link.usda"))
    os.symlink("loop", os.path.join(case_dir, "loop"))
    return case_dir, outside


def materialise(data: bytes, ext: str, outside: str, name: str) -> bytes:
    """The case's bytes with the reference mutator's placeholders made real paths."""
    if OUT.encode() not in data and SELF.encode() not in data:
        return data

    def sub(b):
        return b.replace(OUT.encode(), outside.encode()).replace(SELF.encode(), name.encode())
    if ext == ".glb":
        try:
            _, chunks = glb_split(data)
            chunks[0] = (chunks[0][0], sub(chunks[0][1]).rstrip(b" "))
            return glb_join(chunks)
        except NotApplicable:
            pass
    return sub(data)


_IN_ACCESS, _IN_OPEN, _IN_ISDIR = 0x1, 0x20, 0x40000000


class OpenWatch:
    """Files of ``folders`` that any process opens while the watch lasts (Linux inotify; on other
    systems, or without inotify, :meth:`opened` is always empty)."""

    def __init__(self, folders):
        self.fd, self.wd = -1, {}
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            fd = libc.inotify_init1(os.O_NONBLOCK | os.O_CLOEXEC)
        except (OSError, AttributeError):
            return
        if fd < 0:
            return
        self.fd, self._libc = fd, libc
        for d in folders:
            wd = libc.inotify_add_watch(fd, os.fsencode(d), _IN_OPEN | _IN_ACCESS)
            if wd >= 0:
                self.wd[wd] = d

    def opened(self) -> list:
        """``[(folder, name)]`` of the files opened or read so far (the folders themselves not)."""
        out = []
        if self.fd < 0:
            return out
        while True:
            try:
                buf = os.read(self.fd, 65536)
            except BlockingIOError:
                break
            if not buf:
                break
            pos = 0
            while pos + 16 <= len(buf):
                wd, mask, _cookie, n = struct.unpack_from("iIII", buf, pos)
                name = buf[pos + 16:pos + 16 + n].rstrip(b"\0").decode("utf-8", "replace")
                pos += 16 + n
                if name and not mask & _IN_ISDIR and (self.wd.get(wd), name) not in out:
                    out.append((self.wd.get(wd), name))
        return out

    def close(self):
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


#: usd-core's diagnostics as they reach stderr (TF_WARN / TF_RUNTIME_ERROR / TF_CODING_ERROR text).
_USD_LINE = re.compile(r"Warning: in \w+ at line|Error in '|_ReportErrors|pxrInternal|Coding Error|"
                       r"Runtime Error|failed call to posix_madvise|^\s*(?:Warning|Error): in ")


def usd_lines(text: str) -> list:
    """The lines of ``text`` that are usd-core's own diagnostics."""
    return [ln for ln in text.splitlines() if _USD_LINE.search(ln) and not ln.startswith("error: ")]


def _judge_references(problems, watch, case_dir, where):
    for folder, name in watch.opened():
        if folder != case_dir:
            problems.append(f"{where}: opened {name!r} outside the case's folder")
        elif name in FORBIDDEN_INSIDE:
            problems.append(f"{where}: opened {name!r} (a FIFO or a symlink out) in the case's folder")


def _norm(text: str) -> str:
    """A message reduced to its kind: paths, numbers and quoted values removed."""
    text = re.sub(r"(/[^\s:'\"]+)+", "<path>", text)
    text = re.sub(r"'[^']*'|\"[^\"]*\"", "<v>", text)
    text = re.sub(r"0x[0-9a-fA-F]+|\d+(\.\d+)?(e[-+]?\d+)?", "N", text)
    return " ".join(text.split())[:90]


def _invoke(args):
    """``colossus ARGS`` in-process: (exit code, stdout, stderr, escaped exception, warnings, native)."""
    from click.testing import CliRunner

    from colossus.cli import main

    with captured_fd2() as native, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = CliRunner().invoke(main, args, catch_exceptions=True)
    exc = res.exception if res.exception is not None and not isinstance(res.exception, SystemExit) else None
    shown = [f"{w.category.__name__}: {w.message} [in {os.path.basename(w.filename)}]" for w in caught]
    return res.exit_code, res.stdout, res.stderr, exc, shown, native["text"]


def _subprocess(args, timeout):
    env = {**os.environ, "PYTHONWARNINGS": "default"}
    p = subprocess.run([sys.executable, "-m", "colossus", *args], capture_output=True, text=True,
                       timeout=timeout, env=env)
    return p.returncode, p.stdout, p.stderr, None, [], ""


def _common(problems, exc, warns, native, where, stderr=""):
    if exc is not None:
        problems.append(f"{where}: exception escaped click: {type(exc).__name__}: {_norm(str(exc))}")
    for w in warns:
        problems.append(f"{where}: Python warning {_norm(w)}")
    if native.strip():
        problems.append(f"{where}: native stderr output: {_norm(native.strip().splitlines()[-1])}")
    for ln in usd_lines(stderr)[:1] if stderr else ():
        problems.append(f"{where}: a usd-core line on stderr: {_norm(ln)}")


def _judge_error_line(problems, code, stderr, where, src=""):
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    if len(lines) != 1:
        problems.append(f"{where}: exit {code} with {len(lines)} stderr lines: {_norm(lines[-1]) if lines else ''}")
        return
    line = lines[0]
    if "Traceback" in stderr:
        problems.append(f"{where}: traceback on stderr")
    if not line.startswith("error: "):
        problems.append(f"{where}: stderr line is not 'error: ...': {_norm(line)}")
    m = re.search(r"internal error \((\w+)", line)
    if m:
        problems.append(f"{where}: internal error {m.group(1)}: {_norm(line.split(m.group(1), 1)[1])}")
    if "out of memory" in line:  # our MemoryError mapping: an allocation escaped the readers' budget
        problems.append(f"{where}: out of memory (an allocation escaped the budget)")
    if "Error in 'pxrInternal" in line or "Error in 'pxr" in line or "pxrInternal_" in line:
        problems.append(f"{where}: usd-core's raw error text (function, source line) not reduced to its reason")
    if len(line) - line.count(src) * len(src) > MAX_MESSAGE:
        problems.append(f"{where}: message of {len(line)} characters")


def _validate_written(out, problems):
    code, stdout, stderr, exc, warns, native = _invoke(["validate", out, "--format", "json"])
    _common(problems, exc, warns, native, "validate (written asset)")
    if code not in (0, 1):
        problems.append(f"validate (written asset): exit {code}: {_norm(stderr)}")
        return "validate-crash"
    try:
        doc = json.loads(stdout)
        codes = sorted({f["code"] for f in doc["assets"][0]["findings"] if f["severity"] == "error"})
    except (ValueError, KeyError, IndexError) as e:
        problems.append(f"validate (written asset): unreadable JSON report ({type(e).__name__})")
        return "validate-crash"
    for c in codes:
        if c in CHECK_FAILURES:
            msg = next(f["message"] for f in doc["assets"][0]["findings"] if f["code"] == c)
            problems.append(f"validate (written asset): {c} {_norm(msg)}")
    return "written, passes" if code == 0 else "written, findings"


def _run_import(case, src, workdir, timeout):
    out_dir = os.path.join(workdir, "out")
    os.makedirs(out_dir)
    out = os.path.join(out_dir, "asset.usda")
    args = ["import", src, "-o", out]
    problems = []
    if case.get("subprocess"):
        code, stdout, stderr, exc, warns, native = _subprocess(args, timeout)
        where = "import (subprocess)"
    else:
        code, stdout, stderr, exc, warns, native = _invoke(args)
        where = "import"
    _common(problems, exc, warns, native, where, stderr)
    if code == 0:
        if stderr.strip():
            problems.append(f"{where}: exit 0 with stderr output: {_norm(stderr.strip().splitlines()[-1])}")
        if not os.path.exists(out):
            problems.append(f"{where}: exit 0 but no asset written")
            outcome = "exit 0, nothing written"
        else:
            outcome = _validate_written(out, problems)
    elif code == 1:
        outcome = "rejected"
        _judge_error_line(problems, code, stderr, where, src)
        left = os.listdir(out_dir)
        if left:
            problems.append(f"{where}: exit 1 but left {'the output' if 'asset.usda' in left else 'a temporary file'} behind")
    else:
        outcome = f"exit {code}"
        problems.append(f"{where}: exit status {code}: {_norm(stderr.strip()[-200:])}")
    return outcome, code, stderr.strip(), problems


def _run_validate(case, bad, workdir):
    good = os.path.join(os.path.dirname(bad), "good" + case["ext"])
    shutil.copyfile(case["seed"], good)
    code, stdout, stderr, exc, warns, native = _invoke(["validate", bad, good, "--format", "json"])
    problems = []
    # usd-core's own diagnostics (TF_WARN, "failed call to posix_madvise") on a corrupt asset
    # went to fd 2 from C++; since issue 26 item 4 nothing of usd-core's reaches stderr: judged
    case["noise"] = bool(native.strip())
    _common(problems, exc, warns, native, "validate", stderr)
    outcome = f"exit {code}"
    if code not in (0, 1, 2):
        problems.append(f"validate: exit status {code}: {_norm(stderr.strip()[-200:])}")
        return outcome, code, stderr.strip(), problems
    if "internal error" in stderr:
        problems.append(f"validate: {_norm(stderr.strip())}")
    try:
        doc = json.loads(stdout)
        rb, rg = doc["assets"]
    except (ValueError, KeyError, TypeError) as e:
        problems.append(f"validate: no JSON report of both assets ({type(e).__name__})")
        return outcome, code, stderr.strip(), problems
    if not rg.get("passed"):
        problems.append("validate: the good asset checked with a corrupt one did not pass")
    codes = sorted({f["code"] for f in rb["findings"]})
    for f in rb["findings"]:
        if f["code"] == "COL002":
            problems.append(f"validate: COL002 {_norm(f['message'])}")
            break
    outcome = "COL001" if "COL001" in codes else ("findings" if not rb.get("passed") else "passes")
    return outcome, code, stderr.strip(), problems


def run_case(case: dict, timeout: float = 60.0, keep: str | None = None, data: bytes | None = None) -> dict:
    """Run one case; returns its record (``problems`` empty when the outcome is good).

    ``keep``: a folder to copy the case into when it is bad (the worker does it; a case whose
    worker died is saved by the campaign).  ``data``: the file's bytes (a saved case replayed)
    instead of the mutation the case's recipe makes.
    """
    t0 = time.perf_counter()
    if data is None:
        data, steps = build_case(case)
    else:
        steps = case.get("steps", [])
    workdir = tempfile.mkdtemp(prefix=f"fuzz{case['index']}-")
    watch = None
    try:
        name = ("case" if case["kind"] == "import" else "bad") + case["ext"]
        case_dir, outside = layout(workdir)
        src = os.path.join(case_dir, name)
        with open(src, "wb") as fh:
            fh.write(materialise(data, case["ext"], outside, name))
        watch = OpenWatch([case_dir, outside])
        if case["kind"] == "import":
            outcome, code, stderr, problems = _run_import(case, src, workdir, timeout)
        else:
            outcome, code, stderr, problems = _run_validate(case, src, workdir)
        _judge_references(problems, watch, case_dir, case["kind"])
    finally:
        if watch is not None:
            watch.close()
        shutil.rmtree(workdir, ignore_errors=True)
    rec = {**case, "steps": steps, "outcome": outcome, "exit": code, "stderr": stderr[-1000:],
           "problems": problems, "seconds": round(time.perf_counter() - t0, 3)}
    rec["class"] = classify(problems)
    if problems and keep:
        save_case(keep, rec, data)
    return rec


def classify(problems) -> str | None:
    """The bad-outcome class of a case: its first problem, reduced to its kind."""
    return problems[0] if problems else None


def save_case(folder: str, rec: dict, data: bytes) -> str:
    """Write a bad case as ``FOLDER/<index>-<class slug>/case<ext>`` plus ``recipe.json``."""
    slug = re.sub(r"[^a-z0-9]+", "-", (rec["class"] or "bad").lower()).strip("-")[:60]
    d = os.path.join(folder, f"{rec['index']:06d}-{slug}")
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, ("case" if rec["kind"] == "import" else "bad") + rec["ext"]), "wb") as fh:
        fh.write(data)
    with open(os.path.join(d, "recipe.json"), "w") as fh:
        json.dump({k: v for k, v in rec.items()}, fh, indent=1, default=str)
    return d
