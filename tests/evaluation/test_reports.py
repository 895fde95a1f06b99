"""Benchmark reports, with the timings kept apart."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from o3d_rpointhop.evaluation.metrics import (
    pair_errors,
    summarize,
)
from o3d_rpointhop.evaluation.records import PairRecord


def _fake_results(seconds: float) -> dict:
    records = [
        PairRecord(**pair_errors(np.eye(4), np.eye(4)), seconds=seconds, pair="a"),
        PairRecord(**pair_errors(np.eye(4), np.eye(4)), seconds=2 * seconds, pair="b"),
    ]
    return {
        "dataset": "bunny",
        "settings": {
            "seed": 0,
            "machine": f"box {seconds}",
            "python": "3.11",
            "open3d": "0.20",
            "numpy": "2",
        },
        "protocols": {
            "scans": {
                "description": "two pairs",
                "summary": {"icp": summarize(records)},
                "records": {"icp": [r.as_dict() for r in records]},
                "fit_seconds": 10 * seconds,
            }
        },
    }


def test_reports_keep_timings_apart(tmp_path):
    from o3d_rpointhop.evaluation.report import split_timings, write_report

    kept, timed = split_timings(_fake_results(1.0))
    assert "seconds" not in json.dumps(kept) and "box" not in json.dumps(kept)
    assert timed["protocols"]["scans"]["records"]["icp"] == [{"seconds": 1.0}, {"seconds": 2.0}]
    assert timed["protocols"]["scans"]["summary"]["icp"] == {"seconds_per_pair": 1.5}
    first = write_report(_fake_results(1.0), tmp_path / "one")
    second = write_report(_fake_results(3.0), tmp_path / "two")
    names = [Path(p).name for p in first]
    assert names[:4] == ["bunny.json", "bunny.md", "bunny_timings.json", "bunny_timings.md"]
    for name in ("bunny.json", "bunny.md"):  # a rerun leaves the result files unchanged
        assert (tmp_path / "one" / name).read_text() == (tmp_path / "two" / name).read_text()
    assert "s per pair" not in (tmp_path / "one" / "bunny.md").read_text()
    assert (
        "| scans | point-to-point ICP alone" in (tmp_path / "two" / "bunny_timings.md").read_text()
    )
    assert "4.500" in (tmp_path / "two" / "bunny_timings.md").read_text()
    timings = json.loads((tmp_path / "two" / "bunny_timings.json").read_text())
    assert timings["settings"] == {"machine": "box 3.0"}
    assert [Path(p).name for p in second] == names
