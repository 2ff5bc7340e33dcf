"""Where the tests find the project's files (imported by conftest.py and the tests; never a test module)."""

import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"
CORPUS = ROOT.parent / "shared" / "corpus"


def fbx_road() -> str:
    """Which reader ``.fbx`` goes through in this environment: ``"ufbx"`` (the ``pipeline`` extra's
    binding) or ``"assimp"`` (without it, or with ``COLOSSUS_FBX_READER=assimp``)."""
    import os

    from colossus.pipeline.readers import ufbx_reader
    if os.environ.get("COLOSSUS_FBX_READER", "ufbx") == "assimp" or not ufbx_reader.available():
        return "assimp"
    return "ufbx"
