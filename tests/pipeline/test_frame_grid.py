"""The default frame grid is the source's own (issue 20 item 4): any regular rate its keys sit
on, 37 fps included, not only the rates of a list; a source off every regular grid is resampled
at 30 fps with its bound stated."""

from __future__ import annotations

import numpy as np
import pytest

from colossus.bench.synth import write_glb
from colossus.pipeline.readers.scene.timeline import choose_fps
from colossus.pipeline.run import ImportSettings, import_asset


@pytest.mark.parametrize("fps", [37.0, 24.0, 17.5])
def test_glb_keyed_at_its_own_rate_keeps_it(tmp_path, fps):
    src = tmp_path / f"tube{fps:g}.glb"
    write_glb(src, triangles=800, bones=4, clips=1, frames=15, fps=fps)
    res = import_asset(src, tmp_path / "o.usda", ImportSettings())
    assert res.mesh.time_codes_per_second == fps
    info = res.mesh.source["clip_info"][0]
    assert info["keys_on_grid"] and not info.get("error_bound_relative")
    assert len(res.mesh.clips[0].times) == 15


def test_own_rate_is_read_off_float32_keys_and_refused_off_grid():
    keys = (np.arange(40) / 37).astype(np.float32).astype(np.float64)
    assert choose_fps([keys]) == 37.0
    assert choose_fps([keys], hint=24.0) == 37.0             # the declared rate does not hold them
    assert choose_fps([np.array([0.0, 0.013, 0.9])]) == 30.0  # no regular grid: the default
    assert choose_fps([np.arange(0, 40, 2) / 37]) == 18.5     # every other frame: still its grid
