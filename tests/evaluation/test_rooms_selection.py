"""benchmarks/rooms_selection.py: a multiway setting measured on training rooms."""

from __future__ import annotations

import json

import pytest
from helpers import benchmark_script, synthetic_scene

from o3d_rpointhop.registration import multiway


@pytest.fixture(scope="module")
def rooms_selection():
    return benchmark_script("rooms_selection")


def test_held_out_scenes_are_refused(rooms_selection, tmp_path):
    synthetic_scene(tmp_path, "sun3d-home_at-home_at_scan1_2013_jan_1")
    with pytest.raises(SystemExit):
        rooms_selection.main(
            ["--setting", "screening_queries", "--scenes", "home_at", "--data", str(tmp_path)]
        )


@pytest.mark.slow
def test_each_candidate_is_measured_and_recorded(rooms_selection, tmp_path):
    """Every candidate rebuilds the scene and is scored on its gt pairs; the records
    name the setting and total each candidate; the module's setting is restored."""
    synthetic_scene(tmp_path / "data", "7-scenes-redkitchen")
    out = tmp_path / "out"
    argv = ["--setting", "screening_queries", "--candidates", "none,0.5"]
    argv += ["--scenes", "redkitchen", "--data", str(tmp_path / "data"), "--n-jobs", "1"]
    assert rooms_selection.main([*argv, "--output", str(out), "--stem", "picked"]) == 0
    found = json.loads((out / "picked.json").read_text())
    assert found["setting"] == "screening_queries"
    runs = found["scenes"]["7-scenes-redkitchen"]["runs"]
    assert set(runs) == {"none", "0.5"}
    assert all(run["placed"] == 3 and run["gt_pairs_registered"] == 2 for run in runs.values())
    assert found["totals"]["0.5"] == {"registered": 2, "gt_pairs": 2}
    assert (out / "picked_timings.md").is_file() and "| 7-scenes-redkitchen |" in (
        out / "picked.md"
    ).read_text()
    assert multiway.SCREENING_QUERIES is None


def test_a_screening_candidate_sets_the_axes_and_hypotheses(rooms_selection, monkeypatch):
    """``axes/hypotheses`` is applied to the module for the rebuild only."""
    seen = {}

    def rebuild(points, **kwargs):
        seen.update(axes=multiway.SCREENING_AXES, hypotheses=multiway.SCREENING_HYPOTHESES)
        return "rebuilt"

    monkeypatch.setattr(rooms_selection, "register_multiway", rebuild)
    before = (dict(multiway.SCREENING_AXES), multiway.SCREENING_HYPOTHESES)
    assert rooms_selection._rebuild("screening", "16/4", [], 1) == "rebuilt"
    assert seen == {"axes": {"scene": 16}, "hypotheses": 4}
    assert (multiway.SCREENING_AXES, multiway.SCREENING_HYPOTHESES) == before
