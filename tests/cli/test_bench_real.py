"""Smoke test of the real-character benchmark rows (``colossus bench --only validate|runtime``,
:mod:`bench.real`): the quick run's one small corpus character imports, proves and poses, and
its rows print the tier split beside the ratio.  Skipped without the corpus."""

import pytest


def test_real_character_rows_run():
    from colossus.bench import real as R

    if R.corpus_dir() is None:
        pytest.skip("no corpus (../shared/corpus or $COLOSSUS_CORPUS)")
    chars = R.Characters(quick=True, echo=lambda *a: None)
    try:
        items = chars.load()
        assert len(items) == 1 and not items[0].error, items
        assert "spheres stage" in R.format_import_rows(items)
        v = R.run_validate(chars)
        assert not v[0].get("error"), v
        assert v[0]["passed"] and sum(v[0]["tiers"].values()) == v[0]["frames"] * v[0]["parts"]
        text = R.format_validate_rows(v)
        assert "SkinPointsLBS" in text and "K " in text and "per-vertex" in text
        rt = R.run_runtime(chars)
        assert not rt[0].get("error"), rt
        assert rt[0]["pose_vs_lbs"] > 0 and "game frame" in R.format_runtime_rows(rt)
    finally:
        chars.close()
