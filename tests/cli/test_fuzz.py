"""The fuzz campaign in CI (issue 12): a fixed-seed campaign of ``CI_CASES`` mutated files through
``colossus import`` and ``colossus validate`` must end with no bad outcome (see
:mod:`tests.fuzz.oracle` for what is good).  ``make fuzz N=10000`` runs a long one.

Seeds are the samples and the third-party corpus beside the repository (skipped when absent:
the samples alone still give every format but Collada, DirectX and MD5)."""

import os

import numpy as np
import pytest

from paths import SAMPLES
from fuzz import mutators
from fuzz.campaign import campaign
from fuzz.seeds import source_seeds

#: Cases per CI run, and the campaign seed: case i is fixed by (seed, i), so a failure here
#: replays with ``python -m tests.fuzz --seed 12 --start I -n 1``.
CI_CASES = 320
CI_SEED = 12
#: Every this-many-th import case runs as a real ``python -m colossus`` subprocess.
CI_SUBPROCESS_EVERY = 40


@pytest.fixture(scope="module")
def ci_campaign():
    s = campaign(n=CI_CASES, seed=CI_SEED, jobs=min(2, os.cpu_count() or 1), timeout=120,
                 subprocess_every=CI_SUBPROCESS_EVERY, echo=print)
    print(s.render())
    return s


def test_fuzz_campaign(ci_campaign):
    s = ci_campaign
    assert s.cases == CI_CASES >= 300
    assert s.subprocess_cases >= 4
    exts = {k.split()[1] for k in s.by_format}
    assert {".glb", ".fbx", ".usda", ".usdc"} <= exts, exts
    assert s.bad_count == 0, "bad outcomes (replay one with python -m tests.fuzz --seed %d --start INDEX -n 1):\n%s" % (
        CI_SEED, s.render())


def test_mutations_are_deterministic():
    seed = SAMPLES / "limb.glb"
    data = seed.read_bytes()
    a = mutators.mutate(data, ".glb", np.random.default_rng([1, 2]))
    b = mutators.mutate(data, ".glb", np.random.default_rng([1, 2]))
    assert a == b and a[0] != data


def test_fbx_writer_round_trips():
    """The FBX node-record mutators parse and rewrite the binary tree: unchanged, it is the same bytes."""
    for p in [SAMPLES / "limb.fbx", SAMPLES / "creature.fbx"] + [s.path for s in source_seeds(formats=[".fbx"])]:
        data = open(p, "rb").read()
        assert mutators.fbx_write(*mutators.fbx_parse(data)) == data, p


def test_glb_mutators_keep_the_container():
    """GLB JSON/BIN mutations keep a well-formed container (lengths right), so the hostile value
    reaches the glTF parser instead of the chunk reader."""
    import struct
    data = (SAMPLES / "limb.glb").read_bytes()
    for k in range(20):
        out, _ = mutators.glb_json(data, np.random.default_rng(k))
        assert struct.unpack_from("<I", out, 8)[0] == len(out)
        mutators.glb_split(out)
        out, what = mutators.glb_bin(data, np.random.default_rng(k))
        assert len(out) == len(data) and out != data, what


@pytest.mark.parametrize("ext", [".glb", ".gltf", ".fbx", ".usda", ".usdc", ".usdz", ".dae"])
def test_every_format_has_structure_aware_mutators(ext):
    assert mutators.FORMAT_MUTATORS[ext]
