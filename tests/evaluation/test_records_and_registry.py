"""Typed benchmark records and the one registry of benchmark methods."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.evaluation.metrics import pair_errors
from o3d_rpointhop.evaluation.records import PairRecord, ScanRecord, ScenePairRecord, as_rows
from o3d_rpointhop.evaluation.registry import BENCHMARKS, entries


def test_records_write_their_fields_in_order_and_read_back():
    record = PairRecord(**pair_errors(np.eye(4), np.eye(4)), seconds=1.5, pair="a")
    row = record.as_dict()
    assert list(row) == [
        "rotation_error_deg",
        "translation_error",
        "euler_error_deg",
        "translation_error_xyz",
        "seconds",
        "pair",
    ]  # "symmetric" was not checked: left out
    assert PairRecord.from_dict(row) == record
    marked = PairRecord(**pair_errors(np.eye(4), np.eye(4)), symmetric=False)
    assert marked.as_dict()["symmetric"] is False  # a False is written, only None is not
    scene = ScenePairRecord("s 0-1", "s", None, 0.1, True, True, None, 2.0, 1.0, 0.01, [])
    assert scene.as_dict()["claimed"] is None and scene.as_dict()["overlap"] is None
    assert as_rows({"m": [scene]}) == {"m": [scene.as_dict()]}


def test_a_scan_is_within_tolerance_only_when_placed_close():
    assert ScanRecord("a", True, 1.0, 0.001).within((2.0, 0.002))
    assert not ScanRecord("a", True, 3.0, 0.001).within((2.0, 0.002))
    assert not ScanRecord("a", True, 1.0, 0.003).within((2.0, 0.002))
    missing = ScanRecord("b", False)
    assert not missing.within((2.0, 0.002)) and missing.as_dict() == {"scan": "b", "placed": False}


def test_one_registry_lists_every_benchmark_s_methods():
    from o3d_rpointhop.evaluation.methods import METHODS, default_methods

    for benchmark in ("modelnet40", "bunny", "3dmatch"):
        found = entries(benchmark)
        assert all(METHODS[name].description == e.description for name, e in found.items())
        assert [n for n, e in found.items() if e.default] == default_methods(benchmark)
    assert list(entries("multiway")) == ["rpointhop", "fpfh", "open3d-recipe"]
    assert "rpointhop-128" in entries("scaling") and set(BENCHMARKS) >= {"multiway", "scaling"}
    with pytest.raises(ValueError, match="unknown benchmark"):
        entries("kitti")
