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


def test_weights_resampling_bound_holds_and_is_exact_for_one_linear_shape():
    """The blend-shape part of a clip's resampling bound (``timeline._weights_resampling_bound``):
    at source keys between frames it is never below the true displacement gap (shapes with
    in-betweens, several shapes on a vertex, a skinning that scales by 2), and for one shape
    without in-betweens it is that gap exactly (1% less would fail)."""
    from colossus.pipeline.model import BlendShape, kernel_shapes
    from colossus.pipeline.readers.scene.timeline import _weights_resampling_bound
    from colossus.runtime.kernels import skin as SK

    rng = np.random.default_rng(3)
    n = 6
    shapes = [BlendShape("a", np.arange(n), rng.normal(size=(n, 3)).astype(np.float32),
                         ((0.4, rng.normal(size=(n, 3)).astype(np.float32)),)),
              BlendShape("b", np.array([1, 3, 4]), rng.normal(size=(3, 3)).astype(np.float32))]
    frames = np.arange(5.0)
    W = rng.uniform(-0.5, 1.5, size=(5, 2))
    key_frames = np.array([0.5, 1.25, 2.9, 3.6])
    W_keys = rng.uniform(-0.5, 1.5, size=(4, 2))
    local = np.tile(np.diag([2.0, 2.0, 2.0, 1.0]), (4, 1, 1, 1))  # (K, 1 joint, 4, 4): scale 2
    parents, bind = np.array([-1]), np.eye(4)[None]
    b = _weights_resampling_bound(frames, W, key_frames, W_keys, shapes, n, local, parents, bind)
    ks = kernel_shapes(shapes, n)
    grid = np.stack([np.interp(key_frames, frames, W[:, s]) for s in range(2)], 1)
    zero = np.zeros((n, 3), np.float32)
    gap = 2.0 * np.linalg.norm(SK.shape_points(zero, ks, W_keys) - SK.shape_points(zero, ks, grid), axis=2).max()
    assert gap <= b * (1 + 1e-9) and gap > 0
    one = [BlendShape("c", np.arange(n), rng.normal(size=(n, 3)).astype(np.float32))]
    b1 = _weights_resampling_bound(frames, W[:, :1], key_frames, W_keys[:, :1], one, n, local, parents, bind)
    ks1 = kernel_shapes(one, n)
    gap1 = 2.0 * np.linalg.norm(SK.shape_points(zero, ks1, W_keys[:, :1])
                                - SK.shape_points(zero, ks1, grid[:, :1]), axis=2).max()
    assert gap1 <= b1 * (1 + 1e-9) and 0.99 * b1 < gap1
