"""``colossus play``: the player sphere lands on the animated creature and is carried along."""

from __future__ import annotations

import numpy as np
from click.testing import CliRunner

from runtime import load_collider
from runtime.cli import play_cmd
from runtime.player import simulate


def test_player_lands_stands_and_is_carried(imported):
    col = load_collider(imported("creature", "glb")[1])
    run = simulate(col, "walk")
    assert run.landed_at is not None
    first = int(np.argmax(run.grounded))
    assert run.grounded[first:].mean() > 0.9  # stands for the rest of the clip
    assert run.max_penetration < 0.05 * run.radius
    assert run.max_slip < 0.05 * run.radius
    # carried: after landing the player moves with the walking body (not frozen in place)
    assert np.linalg.norm(run.positions[-1] - run.positions[first]) > 0.01 * run.radius


def test_play_cli(imported, tmp_path):
    src = imported("limb", "glb")[1]
    out = tmp_path / "run.gif"
    res = CliRunner().invoke(play_cmd, [str(src), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "largest penetration" in res.output and "largest slip" in res.output
    assert out.stat().st_size > 1000
    import imageio.v3 as iio

    frames = iio.imread(out, index=None)
    assert frames.shape[0] <= 60 and frames.shape[1:3] == (360, 480)


def test_play_cli_errors(tmp_path, imported):
    res = CliRunner().invoke(play_cmd, [str(tmp_path / "missing.usda"), "-o", str(tmp_path / "x.gif")])
    assert res.exit_code == 2 and "error:" in res.output and "Traceback" not in res.output
    bad = tmp_path / "bad.usda"
    bad.write_text("not usd at all")
    res = CliRunner().invoke(play_cmd, [str(bad), "-o", str(tmp_path / "x.gif")])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1
    src = imported("limb", "glb")[1]
    res = CliRunner().invoke(play_cmd, [str(src), "--clip", "nope", "-o", str(tmp_path / "x.gif")])
    assert res.exit_code == 2 and "no clip" in res.output
