"""Seed files: every model under ``samples/`` and ``../shared/corpus/`` (read in place, never
copied into the repository; a missing corpus is skipped), plus two derived from them in the
campaign's work folder: ``limb.usdc`` (the crate form of ``samples/limb.usda``, so crate
mutators have a small seed) and the collider assets that ``validate`` cases mutate.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "samples"
CORPUS = ROOT.parent / "shared" / "corpus"

#: Source formats fuzzed through ``colossus import`` (every format a seed exists for).
SOURCE_EXTENSIONS = (".glb", ".gltf", ".fbx", ".dae", ".usda", ".usdc", ".usdz", ".x", ".md5mesh")


@dataclass(frozen=True)
class Seed:
    """One seed file: ``kind`` is ``import`` (a source) or ``validate`` (a collider asset)."""

    path: str
    ext: str
    kind: str = "import"

    @property
    def name(self) -> str:
        p = Path(self.path)
        for base in (SAMPLES, CORPUS):
            try:
                return str(p.relative_to(base.parent))
            except ValueError:
                pass
        return p.name


def _ext(path: str) -> str:
    return os.path.splitext(path)[1].lower()


def source_seeds(max_bytes: int | None = None, formats=None) -> list:
    """Every source seed (sorted, so a campaign is the same on every machine with the same files).

    ``max_bytes`` skips larger files (CI keeps to the small ones); ``formats`` keeps only those
    extensions (``[".glb", ".fbx"]``).
    """
    found = []
    for base in (SAMPLES, CORPUS):
        if not base.is_dir():
            continue
        for dirpath, dirs, files in os.walk(base):
            dirs[:] = sorted(d for d in dirs if d != "truth")  # reference results, not models
            for f in sorted(files):
                p = os.path.join(dirpath, f)
                if _ext(p) in SOURCE_EXTENSIONS:
                    found.append(p)
    out = []
    for p in sorted(found):
        if max_bytes is not None and os.path.getsize(p) > max_bytes:
            continue
        if formats and _ext(p) not in formats:
            continue
        out.append(Seed(p, _ext(p)))
    return out


def derived_seeds(work: str, formats=None) -> tuple:
    """Make the derived seeds in ``work``: ``(import seeds, validate seeds)``.

    ``limb.usdc`` is ``samples/limb.usda`` exported as a crate file by usd-core; the validate
    seeds are ``samples/limb.glb`` imported by colossus, written as ``.usda`` and ``.usdc``.
    """
    from pxr import Sdf

    from colossus.pipeline.run import import_asset

    os.makedirs(work, exist_ok=True)
    imports, assets = [], []
    usda = SAMPLES / "limb.usda"
    if usda.exists() and (not formats or ".usdc" in formats):
        crate = os.path.join(work, "limb.usdc")
        Sdf.Layer.FindOrOpen(str(usda)).Export(crate)
        imports.append(Seed(crate, ".usdc"))
    glb = SAMPLES / "limb.glb"
    if glb.exists():
        for ext in (".usda", ".usdc"):
            out = os.path.join(work, f"limb-asset{ext}")
            import_asset(str(glb), out)
            assets.append(Seed(out, ext, "validate"))
    return imports, assets
