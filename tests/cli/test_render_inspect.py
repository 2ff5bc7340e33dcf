"""``colossus render``, ``colossus inspect`` and ``validate --format html`` on real imported samples.

A "broken" asset is the imported creature with one part's radius shrunk (``leg_FL_lower``, x0.85):
the frame proof fails for that part on every frame, so its renders must show red where the
good asset's show none.
"""

from __future__ import annotations

import base64
import hashlib
import io
import json
from html.parser import HTMLParser

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from paths import SAMPLES
from references.usd_fixture import open_copy
from colossus.cli.validate import validate_cmd
from colossus.cli.inspect import inspect_cmd
from colossus.cli.render import render_cmd

BROKEN_JOINT = "leg_FL_lower"


@pytest.fixture(scope="session")
def assets(imported, tmp_path_factory):
    """``{"creature", "limb", "broken", "junk"}`` -> path."""
    d = tmp_path_factory.mktemp("render")
    creature = imported("creature", "glb")[1]
    limb = imported("limb", "glb")[1]
    stage = open_copy(creature)  # never edit the layer other readers of the file share
    mesh = stage.GetDefaultPrim().GetChild("Collider")
    joints = [str(j) for j in mesh.GetAttribute("colossus:parts:joints").Get()]
    p = [j.rsplit("/", 1)[-1] for j in joints].index(BROKEN_JOINT)
    radii = mesh.GetAttribute("colossus:parts:radii")
    r = list(radii.Get())
    r[p] *= 0.85
    radii.Set(r)
    broken = d / "broken.usda"
    stage.GetRootLayer().Export(str(broken))
    junk = d / "junk.usda"
    junk.write_text("this is not a USD layer\n")
    return {"creature": creature, "limb": limb, "broken": broken, "junk": junk, "part": p, "dir": d}


def run(cmd, *args):
    return CliRunner().invoke(cmd, [str(a) for a in args])


def red_pixels(img) -> int:
    """Strongly red pixels (the failing colour; no part colour is near red)."""
    a = np.asarray(img.convert("RGB"), dtype=np.int32)
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    return int(np.sum((r > 110) & (r > 2.5 * g) & (r > 2.5 * b)))


def assert_not_blank(img):
    a = np.asarray(img.convert("RGB"), dtype=np.int32)
    background = a[0, -1]  # the top-right corner: no caption there
    differs = np.any(np.abs(a - background) > 24, axis=-1).mean()
    assert 0.05 < differs < 0.95, differs
    assert a.std() > 10


# ----------------------------------------------------------------------------------- inspect
def test_inspect_text(assets):
    r = run(inspect_cmd, assets["creature"])
    assert r.exit_code == 0, r.output
    out = r.stdout
    assert "upAxis Y, metersPerUnit 1, timeCodesPerSecond 24" in out
    assert "5056 vertices, 10080 triangles, 16 joints, 16 parts, 2 clips (86 frames)" in out
    assert "elementSize 4" in out
    sha = hashlib.sha256((SAMPLES / "creature.glb").read_bytes()).hexdigest()
    assert f"sourceSha256  {sha}" in out and "source        creature.glb" in out
    assert "importer      colossus" in out and "max_influences=4" in out
    lines = out.splitlines()
    # the joint tree: head sits deeper than neck, neck deeper than the root spine_0
    tree = lines[lines.index("joints (16)") + 1:lines.index("joints (16)") + 17]
    indent = {ln.split()[1]: ln.rindex(ln.split()[1]) for ln in tree}
    assert indent["spine_0"] < indent["neck"] < indent["head"]
    roar = next(ln for ln in lines if ln.strip().startswith("roar"))
    assert "37 frames" in roar and "1.500 s" in roar
    walk = next(ln for ln in lines if ln.strip().startswith("walk"))
    assert "49 frames" in walk and "2.000 s" in walk


def test_inspect_json(assets):
    r = run(inspect_cmd, "--json", assets["limb"])
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["stage"] == {"upAxis": "Y", "metersPerUnit": 1.0, "timeCodesPerSecond": 24.0, "defaultPrim": "/limb"}
    assert s["counts"]["joints"] == 3 and s["counts"]["parts"] == 3 and s["counts"]["clips"] == 1
    assert [j["depth"] for j in s["joints"]] == [0, 1, 2]
    assert [j["parent"] for j in s["joints"]] == [-1, 0, 1]
    assert sum(p["faces"] for p in s["parts"]) >= s["counts"]["triangles"]
    assert all(p["radius"] > 0 for p in s["parts"])
    assert s["provenance"]["source"] == "limb.glb" and len(s["provenance"]["sourceSha256"]) == 64
    assert s["clips"][0]["frames"] >= 2 and s["clips"][0]["seconds"] > 0


@pytest.mark.parametrize("which", ["junk", "missing"])
def test_inspect_unreadable_exit_2(assets, which):
    path = assets["junk"] if which == "junk" else assets["dir"] / "nope.usda"
    r = run(inspect_cmd, path)
    assert r.exit_code == 2
    assert r.stdout == "" and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert str(path) in r.stderr


# ------------------------------------------------------------------------------------ render
def test_render_consistent_with_the_proof(assets):
    """What the renderer draws red is exactly what the frame proof fails."""
    from colossus.validators import check_asset
    from colossus.render.draw import poses
    from colossus.validators.summary import open_asset

    good = open_asset(assets["creature"])
    for c in good.clips:
        assert not any(p.failing.any() for p in poses(good, c.name, c.times))
    bad = open_asset(assets["broken"])
    f = max(check_asset(assets["broken"]).by_code("COL403"), key=lambda f: f.sort_key)
    (pose,) = poses(bad, f.clip, [f.time])
    assert np.nonzero(pose.failing)[0].tolist() == [assets["part"]] == [f.part]
    assert f.vertex in pose.outside
    assert pose.excess[f.part] == pytest.approx(f.excess, rel=1e-3, abs=1e-6)


@pytest.fixture(scope="module")
def walk_pngs(assets):
    """Good and broken creature at walk t=20, 320x240."""
    out = {}
    for name in ("creature", "broken"):
        png = assets["dir"] / f"{name}-walk20.png"
        r = run(render_cmd, assets[name], "-o", png, "--clip", "walk", "--time", "20", "--size", "320x240")
        assert r.exit_code == 0, r.output
        out[name] = (png, r.stdout)
    return out


def test_render_png_size_and_not_blank(walk_pngs):
    for png, _ in walk_pngs.values():
        img = Image.open(png)
        assert img.format == "PNG" and img.size == (320, 240)
        assert_not_blank(img)


def test_render_failing_part_in_red(walk_pngs):
    good = red_pixels(Image.open(walk_pngs["creature"][0]))
    bad = red_pixels(Image.open(walk_pngs["broken"][0]))
    assert good < 20, good
    assert bad > 150 and bad > 20 * max(good, 1), (good, bad)
    assert "1 part with a failing sphere" in walk_pngs["broken"][1]
    assert "failing" not in walk_pngs["creature"][1]


def test_render_bind_pose_default(assets):
    png = assets["dir"] / "limb-bind.png"
    r = run(render_cmd, assets["limb"], "-o", png, "--size", "200x160")
    assert r.exit_code == 0, r.output
    assert "bind pose" in r.stdout
    img = Image.open(png)
    assert img.size == (200, 160)
    assert_not_blank(img)


def test_render_gif_whole_clip(assets):
    gif = assets["dir"] / "limb.gif"
    r = run(render_cmd, assets["limb"], "-o", gif, "--max-frames", "6")
    assert r.exit_code == 0, r.output
    img = Image.open(gif)
    assert img.format == "GIF" and img.size == (480, 360)
    assert 2 <= img.n_frames <= 6
    frames = []
    for i in range(img.n_frames):
        img.seek(i)
        frames.append(np.asarray(img.convert("RGB"), dtype=np.int32))
    assert_not_blank(Image.fromarray(frames[0].astype(np.uint8)))
    assert np.abs(frames[0] - frames[-1]).mean() > 0.5  # it moves
    assert img.info.get("loop") == 0 and img.info.get("duration", 0) > 0


def test_gif_subsampling_and_size_parsing():
    from colossus.render.draw import gif_times, parse_size

    assert len(gif_times(np.arange(49), 60)) == 49
    t = gif_times(np.arange(200), 60)
    assert len(t) <= 60 and t[0] == 0
    assert parse_size("480x360") == (480, 360) and parse_size("64X48") == (64, 48)
    for bad in ("480", "x", "0x10", "10x99999", "axb"):
        with pytest.raises(ValueError):
            parse_size(bad)


@pytest.mark.parametrize("args, needle", [
    (["-o", "{d}/x.jpg"], ".png or .gif"),
    (["-o", "{d}/x.png", "--size", "big"], "WxH"),
    (["-o", "{d}/x.gif", "--time", "3"], "--time"),
    (["-o", "{d}/x.png", "--clip", "nope"], "no clip 'nope' (clips: bend)"),
])
def test_render_usage_errors_exit_2(assets, args, needle):
    r = run(render_cmd, assets["limb"], *[a.format(d=assets["dir"]) for a in args])
    assert r.exit_code == 2, r.output
    assert needle in r.stderr and "Traceback" not in r.output + r.stderr
    assert not list(assets["dir"].glob("x.*"))


@pytest.mark.parametrize("which", ["junk", "missing"])
def test_render_unreadable_exit_2(assets, which):
    path = assets["junk"] if which == "junk" else assets["dir"] / "nope.usda"
    out = assets["dir"] / "unreadable.png"
    r = run(render_cmd, path, "-o", out)
    assert r.exit_code == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not out.exists()


# -------------------------------------------------------------------------------------- html
class _Page(HTMLParser):
    """Sections with their images (data URIs), notes and findings-table codes."""

    def __init__(self):
        super().__init__()
        self.sections = []
        self._td = 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "section" and "asset" in (a.get("class") or "").split():
            self.sections.append({"path": a.get("data-path"), "class": a["class"], "imgs": [], "codes": [],
                                  "text": []})
        elif self.sections and tag == "img":
            self.sections[-1]["imgs"].append(a["src"])
        elif self.sections and tag == "td":
            self._td += 1

    def handle_endtag(self, tag):
        if tag == "tr":
            self._td = 0

    def handle_data(self, data):
        if self.sections:
            self.sections[-1]["text"].append(data)
            if self._td == 1 and data.strip():
                self.sections[-1]["codes"].append(data.strip())


def test_validate_html_report(assets):
    paths = [assets["creature"], assets["broken"], assets["junk"]]
    out = assets["dir"] / "report.html"
    r = run(validate_cmd, *paths, "--format", "html", "-o", out)
    assert r.exit_code == 1, r.output
    page = _Page()
    page.feed(out.read_text(encoding="utf-8"))
    assert [s["path"] for s in page.sections] == [str(p) for p in paths]
    # the same finding list as the JSON reporter
    j = json.loads(run(validate_cmd, *paths, "--format", "json").stdout)
    for s, a in zip(page.sections, j["assets"]):
        assert sorted(s["codes"]) == sorted(f["code"] for f in a["findings"])
        assert ("fail" in s["class"].split()) == (not a["passed"])
    good, broken, junk = page.sections
    assert "COL403" in broken["codes"] and not junk["imgs"]
    assert "could not be read" in "".join(junk["text"])
    for s in (good, broken):
        assert len(s["imgs"]) == 2  # the frame picture and the slack plot
        for src in s["imgs"]:
            assert src.startswith("data:image/png;base64,")
            data = base64.b64decode(src.split(",", 1)[1], validate=True)
            assert data[:8] == b"\x89PNG\r\n\x1a\n"
            Image.open(io.BytesIO(data)).verify()
    pic = lambda s: Image.open(io.BytesIO(base64.b64decode(s["imgs"][0].split(",", 1)[1])))  # noqa: E731
    assert red_pixels(pic(broken)) > 300 and red_pixels(pic(good)) < 20
    assert "src=\"http" not in out.read_text() and "<script" not in out.read_text()


# ------------------------------------------------------------------------------------ README
def test_readme_inspect_example_and_picture(assets):
    from paths import ROOT

    readme = (ROOT / "README.md").read_text()
    block = readme.split("$ colossus inspect out/creature.usda\n", 1)[1].split("```", 1)[0]
    r = run(inspect_cmd, assets["creature"])
    assert r.exit_code == 0
    shown = [ln for ln in block.splitlines()[1:] if ln.strip() and ln.strip() != "..."]
    actual = r.stdout.splitlines()
    assert shown and all(ln in actual for ln in shown), [ln for ln in shown if ln not in actual]
    png = ROOT / "docs" / "creature.png"
    assert "](docs/creature.png)" in readme and png.stat().st_size < 200_000
    img = Image.open(png)
    assert img.format == "PNG"
    assert_not_blank(img)
