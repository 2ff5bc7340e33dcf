import json
import pathlib

import numpy as np
import pytest

from paths import ROOT, SAMPLES  # noqa: F401


@pytest.fixture(scope="session")
def samples_meta():
    return json.loads((SAMPLES / "samples.json").read_text())


@pytest.fixture(scope="session")
def imported(tmp_path_factory):
    """Import each (sample, format, parts mode) once per session: returns a function giving
    (result, out_path); ``parts="any"`` is ``colossus import --parts any`` (overlapping parts)."""
    from colossus.pipeline.run import ImportSettings, import_asset

    cache = {}
    base = tmp_path_factory.mktemp("imported")

    def get(name, ext, parts="dominant"):
        key = (name, ext, parts)
        if key not in cache:
            suffix = "" if parts == "dominant" else f"-{parts}"
            out = base / f"{name}-{ext}{suffix}.usda"
            cache[key] = (import_asset(SAMPLES / f"{name}.{ext}", out, ImportSettings(parts=parts)), out)
        return cache[key]

    return get


@pytest.fixture(scope="session")
def odd_path(tmp_path_factory):
    """An independent asset (tests/references/usd_fixture) with a geomBindTransform, a translated, rotated
    and scaled (x1.5) SkelRoot, Z up and clips at time codes 100.. ."""
    from pxr import Gf, UsdGeom
    from references.usd_fixture import build_test_stage

    p = tmp_path_factory.mktemp("odd") / "odd.usda"
    gb = np.eye(4)
    gb[:3, 3] = (0.2, -0.1, 0.3)
    stage = build_test_stage(geom_bind=gb, path=str(p))
    x = UsdGeom.Xformable(stage.GetDefaultPrim())
    x.AddTranslateOp().Set(Gf.Vec3d(1.0, 2.0, -0.5))
    x.AddRotateXYZOp().Set(Gf.Vec3f(10.0, 20.0, 30.0))
    x.AddScaleOp().Set(Gf.Vec3f(1.5, 1.5, 1.5))
    stage.GetRootLayer().Save()
    return p


@pytest.fixture(scope="session")
def odd_skel_path(tmp_path_factory):
    """The fixture with the transform on the Skeleton prim itself (its own translate, rotate and
    x0.8 scale; the SkelRoot untouched): the skeleton's world transform the contract moves
    spheres by."""
    from pxr import Gf, UsdGeom
    from references.usd_fixture import build_test_stage

    p = tmp_path_factory.mktemp("odd_skel") / "odd_skel.usda"
    stage = build_test_stage(path=str(p))
    x = UsdGeom.Xformable(stage.GetPrimAtPath("/Tube/Skeleton"))
    x.AddTranslateOp().Set(Gf.Vec3d(-0.4, 0.25, 1.5))
    x.AddRotateXYZOp().Set(Gf.Vec3f(-35.0, 5.0, 60.0))
    x.AddScaleOp().Set(Gf.Vec3f(0.8, 0.8, 0.8))
    stage.GetRootLayer().Save()
    return p
