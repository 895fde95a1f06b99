"""Benchmark pair protocols."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.evaluation.protocols import PROTOCOLS, crop_nearest, make_pairs
from o3d_rpointhop.transforms import apply_transform


@pytest.mark.parametrize("protocol", sorted(PROTOCOLS))
def test_protocol_truth_maps_source_onto_its_clean_points(shapes, protocol):
    pairs = make_pairs(shapes, protocol, seed=0)
    assert len(pairs) == 3
    for pair, shape in zip(pairs, shapes, strict=True):
        back = apply_transform(pair.source, pair.truth)
        tol = 0.05 * np.sqrt(3) + 1e-9 if protocol.endswith("noise") else 1e-9
        assert np.abs(back - pair.source_clean).max() <= tol
        # the clean source points are points of the shape
        assert np.isin(
            pair.source_clean.view([("", float)] * 3), shape.view([("", float)] * 3)
        ).all()
        frac = {"paper-partial": 0.75, "resampled-partial": 0.70}.get(protocol, 1.0)
        assert len(pair.source) == round(frac * 1024) and len(pair.target) == round(frac * 1024)
        angles = np.degrees(np.arccos(np.clip((np.trace(pair.truth[:3, :3]) - 1) / 2, -1, 1)))
        if protocol.startswith("paper"):
            assert angles <= 45 * np.sqrt(3) + 1e-6
        if protocol.startswith("resampled"):
            overlap = set(map(tuple, pair.source_clean)) & set(map(tuple, pair.target))
            assert not overlap  # different samples: no shared points


def test_pairs_are_seeded(shapes):
    a = make_pairs(shapes, "resampled-noise", seed=4)
    b = make_pairs(shapes, "resampled-noise", seed=4)
    c = make_pairs(shapes, "resampled-noise", seed=5)
    np.testing.assert_array_equal(a[1].source, b[1].source)
    assert not np.array_equal(a[1].source, c[1].source)
    with pytest.raises(ValueError, match="unknown protocol"):
        make_pairs(shapes, "upside-down")


def test_crop_keeps_the_points_nearest_to_one_point():
    pts = np.random.default_rng(0).normal(size=(200, 3))
    keep = crop_nearest(pts, 0.25, np.random.default_rng(1))
    assert len(keep) == 50
    centre = pts[np.random.default_rng(1).integers(200)]  # the crop's random centre
    rest = np.setdiff1d(np.arange(200), keep)
    kept_far = np.linalg.norm(pts[keep] - centre, axis=1).max()
    assert kept_far <= np.linalg.norm(pts[rest] - centre, axis=1).min()
