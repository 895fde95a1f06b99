"""Benchmark pair protocols."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.evaluation.metrics import modified_chamfer
from o3d_rpointhop.evaluation.protocols import (
    PROTOCOLS,
    RPMNET_POINTS,
    crop_by_plane,
    crop_nearest,
    make_pairs,
)
from o3d_rpointhop.transforms import apply_transform


@pytest.mark.parametrize("protocol", sorted(PROTOCOLS))
def test_protocol_truth_maps_source_onto_its_clean_points(shapes, protocol):
    pairs = make_pairs(shapes, protocol, seed=0)
    assert len(pairs) == 3
    for pair, shape in zip(pairs, shapes, strict=True):
        back = apply_transform(pair.source, pair.truth)
        noisy = protocol.endswith("noise") or protocol.startswith("rpmnet")
        tol = 0.05 * np.sqrt(3) + 1e-9 if noisy else 1e-9
        assert np.abs(back - pair.source_clean).max() <= tol
        # the clean source points are points of the shape
        assert np.isin(
            pair.source_clean.view([("", float)] * 3), shape.view([("", float)] * 3)
        ).all()
        frac = {"paper-partial": 0.75, "resampled-partial": 0.70}.get(protocol, 1.0)
        size = RPMNET_POINTS if protocol.startswith("rpmnet") else round(frac * 1024)
        assert len(pair.source) == size and len(pair.target) == size
        assert (pair.shape is not None) == protocol.startswith("rpmnet")
        angles = np.degrees(np.arccos(np.clip((np.trace(pair.truth[:3, :3]) - 1) / 2, -1, 1)))
        if protocol.startswith("paper") or protocol == "rpmnet-partial":
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


def test_a_plane_crop_keeps_one_side_of_a_random_plane():
    """70 % of the points, all on the far side of a plane normal to the direction the
    generator draws first: every kept point is higher along it than every dropped one."""
    pts = np.random.default_rng(0).normal(size=(1000, 3))
    keep = crop_by_plane(pts, 0.7, np.random.default_rng(3))
    direction = np.random.default_rng(3).normal(size=3)
    height = pts @ direction
    rest = np.setdiff1d(np.arange(1000), keep)
    assert len(keep) == 700 and height[keep].min() > height[rest].max()


def test_rpmnet_pairs_are_two_crops_of_one_sample(shapes):
    for pair, shape in zip(make_pairs(shapes, "rpmnet-partial", seed=2), shapes, strict=True):
        np.testing.assert_array_equal(pair.shape, shape[:2048])
        # the target is a noisy crop of the same 2048 points: every point near one
        nearest = np.linalg.norm(pair.target[:, None] - shape[None], axis=2).min(axis=1)
        assert nearest.max() <= 0.05 * np.sqrt(3) + 1e-9 and nearest.mean() > 1e-4
        # each crop misses part of the shape: a cap of at least a fifth of it
        kept = np.linalg.norm(pair.source_clean[:, None] - shape[None], axis=2).min(axis=0)
        assert (kept > 0.1).mean() > 0.2
    so3 = make_pairs(shapes, "rpmnet-partial-so3", seed=2)
    assert len(so3) == 3 and all(len(p.source) == RPMNET_POINTS for p in so3)


def test_modified_chamfer_by_hand():
    """A grid of unit spacing: the truth scores 0; an estimate off by 0.1 along x puts
    every moved source point and every target point 0.1 from the shape: 0.01 + 0.01."""
    axis = np.arange(6.0)
    shape = np.stack(np.meshgrid(axis, axis, axis), axis=-1).reshape(-1, 3)
    truth = np.eye(4)
    truth[:3, 3] = [-2.0, 1.0, 0.5]  # maps the source into the target frame
    source = shape[:150] - truth[:3, 3]
    target = shape[60:]
    assert modified_chamfer(truth, truth, source, target, shape) == 0.0
    off = truth.copy()
    off[0, 3] += 0.1
    assert modified_chamfer(off, truth, source, target, shape) == pytest.approx(0.02)
