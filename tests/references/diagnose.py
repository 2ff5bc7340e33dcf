"""Diagnose today's importer against the independent references, over the third-party corpus.

Run from the repository root::

    .venv/bin/python -m tests.references.diagnose                 # every corpus character
    .venv/bin/python -m tests.references.diagnose realworld/godot_mannequiny.glb --clips
    .venv/bin/python -m tests.references.diagnose --all-instants   # every key and mid-key

Each file is imported with the contract's command line (``colossus import SRC -o OUT.usda``, the
``colossus`` next to this Python), into a temporary folder; the written asset is then skinned by
plain usd-core and compared with the file's reference (:mod:`.compare`).  Nothing of the project
is imported here.  Files with no independent reference (Collada, DirectX, MD5, FBX without Maya
truth) are imported only, and listed with their import status.

Columns: clips; whether every source key sits on the asset's frame grid (``mixed`` when some
clips do); the largest error at the source's key times and halfway between keys, in units of
the model size; reference vertices with no asset vertex at their rest position, by source
mesh; the import's own one-line failure, or the comparison's problems.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

from . import compare

#: every corpus character that has an independent reference, relative to the corpus folder
CHARACTERS = (
    "khronos/RiggedSimple.gltf",
    "khronos/RiggedFigure.gltf",
    "khronos/SimpleSkin.gltf",
    "khronos/Fox.glb",
    "realworld/godot_mannequiny.glb",
    "realworld/godot_platformer_player.glb",
    "realworld/playcanvas_lumberjack.glb",
    "realworld/threejs_r121_RobotExpressive.glb",
    "realworld/threejs_r121_CesiumMan.glb",
    "assimp/quad_skin.glb",
    "realworld/openusd_lbs.usda",
    "realworld/usdwg_CesiumMan.usdz",
    "realworld/usdwg_SoC-ElephantWithMonochord.usdc",
    "assimp/simple-skin-animation-test.usda",
    "realworld/ufbx_maya_kenney_character_7700_binary.fbx",
    "realworld/ufbx_maya_game_sausage_7500_binary_combined.fbx",
)
#: corpus characters without an independent reference here (imported, not compared)
UNREFERENCED = (
    "assimp/library_animation_clips.dae",
    "assimp/box_nested_animation.dae",
    "realworld/threejs_r121_stormtrooper.dae",
    "assimp/anim_test.x",
    "assimp/Testwuson.X",
    "assimp/Bob.md5mesh",
    "assimp/animation_with_skeleton.fbx",
    "assimp/huesitos.fbx",
    "realworld/ufbx_blender_293_barbarian_7400_binary.fbx",
)


def corpus_dir() -> str:
    """``../shared/corpus`` relative to the repository root."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    return os.path.join(os.path.dirname(root), "shared", "corpus")


def colossus_command() -> list:
    exe = os.path.join(os.path.dirname(sys.executable), "colossus")
    return [exe] if os.path.exists(exe) else ["colossus"]


def import_with_cli(src, out, extra=()) -> str | None:
    """Run ``colossus import src -o out``; return None on success, else its stderr's last line."""
    proc = subprocess.run(colossus_command() + ["import", os.fspath(src), "-o", os.fspath(out), *extra],
                          capture_output=True, text=True)
    if proc.returncode == 0 and os.path.exists(out):
        return None
    lines = [ln for ln in (proc.stderr or proc.stdout).strip().splitlines() if ln.strip()]
    return f"exit {proc.returncode}: {lines[-1] if lines else '(no message)'}"


def diagnose_file(src, workdir, max_instants=compare.MAX_INSTANTS) -> compare.FileReport:
    """Import ``src`` with the CLI and compare the asset with the reference."""
    base = os.path.basename(src)
    try:
        ref = compare.reference_for(src)
    except compare.NoReference:
        ref = None
    fmt = ref.format if ref else os.path.splitext(base)[1].lstrip(".").upper()
    out = os.path.join(workdir, base + ".usda")
    failure = import_with_cli(src, out)
    if failure:
        return compare.FileReport(base, fmt, failure=failure)
    if ref is None:
        return compare.FileReport(base, fmt, asset=out, notes=["imported; no independent reference"])
    try:
        return compare.compare(src, out, max_instants=max_instants, reference=ref)
    except Exception as exc:  # an asset usd-core cannot read is a finding, not a crash of this tool
        msg = " ".join(str(exc).split())
        quoted = re.search(r" : '(.+?)(?: in </>)?'\s*(?:Error in|$)", msg)  # pxr errors: the first message
        msg = quoted.group(1) if quoted else msg
        return compare.FileReport(base, fmt, asset=out, failure=f"asset unreadable: {type(exc).__name__}: {msg[:160]}")


def summary_table(reports) -> str:
    """One row per file: the table of the issue's item 2."""
    head = ("file", "fmt", "clips", "keys on grid", "err@keys", "err@mid", "missing", "failure / problems")
    rows = []

    def fe(e):
        return "-" if e is None else f"{e:.1e}"

    for r in reports:
        grids = {c.on_grid for c in r.clips if c.on_grid is not None}
        grid = "-" if not grids else ("yes" if grids == {True} else "no" if grids == {False} else "mixed")
        meshes = list(r.missing_meshes.items())
        miss = "-" if r.failure or r.reference_vertices == 0 else (
            f"{r.missing}" + (f" ({', '.join(f'{k}: {v}' for k, v in meshes[:4])}{', ...' if len(meshes) > 4 else ''})" if meshes else ""))
        note = r.brief() if (r.failure or r.reference_vertices) else "; ".join(r.notes)
        rows.append((r.source, r.format, str(len(r.clips)) if not r.failure else "-", grid,
                     fe(r.err_keys), fe(r.err_mid), miss, note))
    widths = [max(len(str(x)) for x in col) for col in zip(head, *rows)]
    widths[-1] = 0

    def line(r):
        return "  ".join(str(x).ljust(w) for x, w in zip(r, widths)).rstrip()

    return "\n".join([line(head), line(tuple("-" * w for w in widths[:-1]) + ("-" * 18,))] + [line(r) for r in rows])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.references.diagnose", description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="*", help="corpus files (relative to the corpus folder, or paths); default: all")
    ap.add_argument("--clips", action="store_true", help="also print one row per clip")
    ap.add_argument("--all-instants", action="store_true", help="compare at every key and mid-key (default: at most 40 per clip)")
    ap.add_argument("--corpus", default=corpus_dir(), help="corpus folder (default ../shared/corpus)")
    args = ap.parse_args(argv)
    if not os.path.isdir(args.corpus):
        print(f"no corpus folder at {args.corpus}", file=sys.stderr)
        return 2
    files = args.files or list(CHARACTERS + UNREFERENCED)
    paths = [f if os.path.exists(f) else os.path.join(args.corpus, f) for f in files]
    reports = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="colossus-diagnose-") as tmp:
        for p in paths:
            reports.append(diagnose_file(p, tmp, 0 if args.all_instants else compare.MAX_INSTANTS))
            print(f"  {os.path.basename(p)}: done", file=sys.stderr)
    print(summary_table(reports))
    if args.clips:
        print()
        print(compare.format_table([r for r in reports if r.clips]))
    notes = [(r.source, n) for r in reports for n in r.notes if r.clips or r.reference_vertices]
    if notes:
        print("\nnotes:")
        for s, n in notes:
            print(f"  {s}: {n}")
    print(f"\n{len(reports)} files in {time.perf_counter() - t0:.0f} s; errors are x model size; "
          f"tolerance {compare.TOL:g} where keys sit on the asset's grid, {compare.OFF_GRID_TOL:g} elsewhere", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
