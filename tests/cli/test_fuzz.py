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


def test_reference_mutator_points_outside():
    """Issue 26 item 7: the reference mutator rewrites what a file refers to (glTF buffer/image
    URIs, USD arcs) with the placeholders the oracle makes real, for every target kind."""
    seen = set()
    for ext, name, fn in ((".glb", "limb.glb", mutators.glb_refs), (".usda", "limb.usda", mutators.usda_refs)):
        data = (SAMPLES / name).read_bytes()
        for k in range(40):
            out, what = fn(data, np.random.default_rng(k))
            assert out != data, what
            seen.add(what.split(" -> ")[0].split(": ", 1)[-1].split()[0])
    assert {"buffer", "image", "USD"} <= seen or {"buffer", "image"} <= seen, seen
    assert "gltf_refs" in mutators.FORMAT_MUTATORS[".gltf"] and "usda_refs" in mutators.FORMAT_MUTATORS[".usda"]


def test_reference_oracle_sees_a_read_outside(tmp_path):
    """The oracle's watch sees a file outside the case's folder opened by the contained reader
    (a forked child): an import allowed outside (--allow-outside-references) reads the canary,
    and the case is bad; the same case without the flag is refused and good."""
    import json as _json

    from fuzz import oracle
    data = (SAMPLES / "limb.glb").read_bytes()
    doc, chunks = mutators.glb_split(data)
    # the BIN chunk as a file outside, the buffer pointing at it by absolute path
    doc["buffers"][0]["uri"] = mutators.OUT + "/canary.bin"
    chunks = [(chunks[0][0], mutators._json_bytes(doc))]
    case = {"index": 0, "campaign": 0, "kind": "import", "seed": str(SAMPLES / "limb.glb"), "ext": ".glb",
            "subprocess": False}
    rec = oracle.run_case(case, data=mutators.glb_join(chunks))
    assert rec["outcome"] == "rejected" and not rec["problems"], rec
    case_dir, outside = oracle.layout(str(tmp_path))
    src = tmp_path / "case" / "case.glb"
    src.write_bytes(oracle.materialise(mutators.glb_join(chunks), ".glb", outside, "case.glb"))
    watch = oracle.OpenWatch([case_dir, outside])
    try:
        oracle._invoke(["import", str(src), "-o", str(tmp_path / "o.usda"), "--allow-outside-references"])
        problems = []
        oracle._judge_references(problems, watch, case_dir, "import")
    finally:
        watch.close()
    assert problems and "outside the case's folder" in problems[0], problems
    assert _json.dumps(problems)


def test_usd_lines_are_recognised():
    from fuzz import oracle
    text = ("Warning: in _ReportErrors at line 3177 of /src/pxr/usd/usd/stage.cpp -- In </root>: x\n"
            "error: a.usda: reference 'x': is a FIFO, not a regular file\n")
    assert len(oracle.usd_lines(text)) == 1
