import json
import os
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"


@pytest.fixture(scope="session")
def samples_meta():
    return json.loads((SAMPLES / "samples.json").read_text())


@pytest.fixture(scope="session")
def imported(tmp_path_factory):
    """Import each (sample, format) once per session: returns a function giving (result, out_path)."""
    from pipeline.run import import_asset

    cache = {}
    base = tmp_path_factory.mktemp("imported")

    def get(name, ext):
        key = (name, ext)
        if key not in cache:
            out = base / f"{name}-{ext}.usda"
            cache[key] = (import_asset(SAMPLES / f"{name}.{ext}", out), out)
        return cache[key]

    return get
