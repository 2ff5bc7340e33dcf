"""Fixtures shared by the runtime's tests: the two samples' colliders."""

import pytest

from colossus.runtime import load_collider


@pytest.fixture(scope="session")
def creature_path(imported):
    return imported("creature", "glb")[1]


@pytest.fixture(scope="session")
def limb_path(imported):
    return imported("limb", "glb")[1]


@pytest.fixture(scope="module")
def creature(creature_path):
    """The creature sample's collider, loaded once per test module (a module may pose it freely)."""
    return load_collider(creature_path)


@pytest.fixture(scope="module")
def limb(limb_path):
    return load_collider(limb_path)
