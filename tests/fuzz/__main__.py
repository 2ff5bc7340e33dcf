"""``python -m tests.fuzz``: run a fuzz campaign (see :mod:`tests.fuzz`); exit 1 on any bad outcome."""

from __future__ import annotations

import argparse
import json
import os
import sys

from .campaign import campaign


def _replay(path):
    """Run saved cases again (a case folder, or a folder of them): print each outcome."""
    from .oracle import run_case
    dirs = [path] if os.path.exists(os.path.join(path, "recipe.json")) else sorted(
        os.path.join(path, d) for d in os.listdir(path) if os.path.exists(os.path.join(path, d, "recipe.json")))
    bad = 0
    assets = {}  # validate cases: the good assets of the campaign's work folder are gone, make them again
    work = None
    for d in dirs:
        with open(os.path.join(d, "recipe.json")) as fh:
            rec = json.load(fh)
        name = next(f for f in os.listdir(d) if f != "recipe.json")
        with open(os.path.join(d, name), "rb") as fh:
            data = fh.read()
        if rec["kind"] == "validate" and not os.path.exists(rec["seed"]):
            if work is None:
                import tempfile
                from .seeds import derived_seeds
                work = tempfile.mkdtemp(prefix="colossus-fuzz-replay-")
                assets = {s.ext: s.path for s in derived_seeds(work)[1]}
            rec["seed"] = assets[rec["ext"]]
        out = run_case({k: rec[k] for k in ("index", "campaign", "kind", "seed", "ext", "steps", "subprocess")}, data=data)
        bad += bool(out["problems"])
        print(f"{d}: {out['outcome']} (exit {out['exit']}) {'BAD: ' + out['class'] if out['problems'] else 'ok'}")
        if out["stderr"]:
            print(f"    stderr: {out['stderr'][-300:]}")
    if work is not None:
        import shutil
        shutil.rmtree(work, ignore_errors=True)
    return 1 if bad else 0


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m tests.fuzz", description=__doc__)
    ap.add_argument("-n", "--cases", type=int, default=300, help="number of cases [300]")
    ap.add_argument("--seed", type=int, default=12, help="campaign seed [12]; case i is fixed by (seed, i)")
    ap.add_argument("--start", type=int, default=0, help="first case index [0] (--start 123 -n 1: one case again)")
    ap.add_argument("-j", "--jobs", type=int, default=min(2, os.cpu_count() or 1), help="worker processes [2]")
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds per case before it counts as a hang [60]")
    ap.add_argument("--out", help="save every bad case (file + recipe.json) under this folder")
    ap.add_argument("--max-seed-bytes", type=float, default=1e6,
                    help="skip seed files larger than this [1e6]; 0: no limit")
    ap.add_argument("--formats", help="comma-separated extensions to fuzz (default: every seed format)")
    ap.add_argument("--subprocess-every", type=int, default=50,
                    help="run every K-th import case as a real subprocess [50]; 0: never")
    ap.add_argument("--replay", metavar="PATH", help="run saved case(s) again instead of a campaign")
    a = ap.parse_args(argv)
    if a.replay:
        return _replay(a.replay)
    formats = [f if f.startswith(".") else "." + f for f in a.formats.split(",")] if a.formats else None
    s = campaign(n=a.cases, seed=a.seed, jobs=a.jobs, timeout=a.timeout, keep=a.out,
                 max_seed_bytes=int(a.max_seed_bytes) or None, formats=formats,
                 subprocess_every=a.subprocess_every, start=a.start, echo=print)
    print(s.render())
    if a.out and s.bad_count:
        print(f"bad cases saved under {a.out}/ (python -m tests.fuzz --replay {a.out})")
    return 1 if s.bad_count else 0


if __name__ == "__main__":
    sys.exit(main())
