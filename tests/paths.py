"""Where the tests find the project's files (imported by conftest.py and the tests; never a test module)."""

import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"
CORPUS = ROOT.parent / "shared" / "corpus"
