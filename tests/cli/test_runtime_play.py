"""``colossus play``: the player sphere lands on the animated creature and is carried along."""

from __future__ import annotations

import numpy as np
from click.testing import CliRunner

from colossus.runtime import load_collider
from colossus.cli.play import play_cmd
from colossus.runtime.player import simulate


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


# -- play --script ------------------------------------------------------------------------------

import csv  # noqa: E402
import json  # noqa: E402

import pytest  # noqa: E402

from colossus.runtime.controller import STATES  # noqa: E402
from colossus.runtime.script import CSV_COLUMNS, ScriptError, load_script, parse_script, run_script  # noqa: E402

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "docs" / "play-climb.json"


def test_readme_example_script_shows_every_state(imported, tmp_path):
    """The README's ``colossus play ... --script docs/play-climb.json``: all five states, a GIF
    and a CSV with one row per step."""
    src = imported("creature", "glb")[1]
    out, table = tmp_path / "climb.gif", tmp_path / "climb.csv"
    res = CliRunner().invoke(play_cmd, [str(src), "--script", str(EXAMPLE), "-o", str(out)])
    assert res.exit_code == 0, res.output
    script = load_script(EXAMPLE)
    rows = list(csv.DictReader(table.open()))
    assert tuple(rows[0]) == CSV_COLUMNS and len(rows) == len(script.intents)
    states = [r["state"] for r in rows]
    assert set(states) == set(STATES)
    assert f"{len(rows)} rows" in res.output
    assert all(float(r["penetration"]) < 0.01 * float(res.output.split("radius ")[1].split(",")[0]) for r in rows)
    for r in rows:  # contact triangle given whenever it stands on, holds or hangs from the body
        if r["state"] in ("holding", "hanging"):
            assert int(r["triangle"]) >= 0
    import imageio.v3 as iio

    assert iio.imread(out, index=None).shape[0] <= 60


def test_script_runs_match_the_controller_states(imported):
    """A scripted wait on the back is the default play: it lands and stands; a jump leaves."""
    col = load_collider(imported("creature", "glb")[1])
    s = parse_script({"steps": [{"wait": 1.0}, {"jump": True}, {"wait": 0.2}]}, "inline")
    run = run_script(col, s, "walk")
    assert len(run.times) == 60 + 1 + 12
    assert run.states[59] == "standing" and run.states[60] == "falling"
    assert run.positions[72] @ col.up > run.positions[59] @ col.up + 0.1  # in the air


BAD_SCRIPTS = [
    ("not json", "[1, 2", "not JSON"),
    ("not an object", "[1, 2]", "JSON object"),
    ("no steps", '{"clip": "walk"}', "no \"steps\""),
    ("empty steps", '{"steps": []}', "non-empty"),
    ("unknown top key", '{"steps": [{"wait": 1}], "speed": 3}', "unknown key 'speed'"),
    ("unknown step key", '{"steps": [{"jmup": true}]}', "steps[0]: unknown key 'jmup'"),
    ("two actions", '{"steps": [{"wait": 1, "grab": 2}]}', "one of wait, jump, grab"),
    ("bad vector", '{"steps": [{"walk": [1, 0], "for": 1}]}', "walk must be [x, y, z]"),
    ("too long a move", '{"steps": [{"walk": [2, 0, 0], "for": 1}]}', "length <= 1"),
    ("negative time", '{"steps": [{"wait": -1}]}', "between 0"),
    ("walk without for", '{"steps": [{"walk": [1, 0, 0]}]}', "needs a duration"),
    ("jump for", '{"steps": [{"jump": true, "for": 1}]}', "one step"),
    ("bad controller key", '{"controller": {"speed": 2}, "steps": [{"wait": 1}]}', "unknown parameter 'speed'"),
    ("bad controller value", '{"controller": {"max_slope": "steep"}, "steps": [{"wait": 1}]}', "must be a number"),
    ("too long", '{"steps": [{"wait": 100000}]}', "between 0"),
]


@pytest.mark.parametrize("name,text,msg", BAD_SCRIPTS, ids=[b[0] for b in BAD_SCRIPTS])
def test_bad_scripts_one_line_naming_the_file(tmp_path, name, text, msg):
    p = tmp_path / "bad.json"
    p.write_text(text)
    with pytest.raises(ScriptError) as e:
        load_script(p)
    m = str(e.value)
    assert msg in m and str(p) in m and "\n" not in m


def test_play_cli_bad_script(imported, tmp_path):
    src = imported("limb", "glb")[1]
    out = tmp_path / "x.gif"
    cases = {"missing.json": None, "bad.json": "{ nope", "range.json": json.dumps(
        {"controller": {"max_slope": 120}, "steps": [{"wait": 0.1}]}), "clip.json": json.dumps(
        {"clip": "dance", "steps": [{"wait": 0.1}]})}
    for name, text in cases.items():
        p = tmp_path / name
        if text is not None:
            p.write_text(text)
        res = CliRunner().invoke(play_cmd, [str(src), "--script", str(p), "-o", str(out)])
        assert res.exit_code == 2, (name, res.output)
        lines = res.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error:") and "Traceback" not in res.output, (name, res.output)
        assert name in lines[0] or "dance" in lines[0]
        assert not out.exists() and not out.with_suffix(".csv").exists()


def test_readme_controller_example_runs(imported):
    """The README's controller snippet runs as written (on the imported sample) and its script
    example is docs/play-climb.json."""
    section = (ROOT / "README.md").read_text().split("### The character controller")[1]
    code = section.split("```python\n")[1].split("```")[0]
    code = code.replace('"out/creature.usda"', repr(str(imported("creature", "glb")[1])))
    ns = {}
    exec(compile(code, "README.md", "exec"), ns)
    s = ns["s"]
    assert s.state in STATES and s.penetration < 0.01 * 0.13
    example = section.split("```json\n")[1].split("```")[0]
    assert json.loads(example) == json.loads(EXAMPLE.read_text())
