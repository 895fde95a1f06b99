"""Sampling for the hops: farthest points, Poisson disks, neighbour search."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import CONTRACT, random_motion, relative_difference
from hypothesis import given, settings
from hypothesis import strategies as st

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_blob, make_object
from o3d_rpointhop.descriptors.pointhop._neighbors import drop_self, knn, spatial_order
from o3d_rpointhop.descriptors.pointhop._sampling import (
    fps_subsets,
    hop_subsets,
    poisson_disk_subset,
)


@pytest.fixture(scope="module")
def poisson_model(train_clouds):
    return RPointHopTransformer(sampling="poisson", random_state=0).fit(train_clouds)


# ----------------------------------------------------------------------------- sampling
def _reference_fps(points, m, start):
    chosen = [start]
    dist = np.linalg.norm(points - points[start], axis=1)
    for _ in range(m - 1):
        j = int(np.argmax(dist))
        chosen.append(j)
        dist = np.minimum(dist, np.linalg.norm(points - points[j], axis=1))
    return np.sort(chosen)


# ----------------------------------------------------------------------------- sampling
@settings(max_examples=10, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.05, 1.0))
def test_poisson_disk_moves_with_the_cloud(seed, share):
    points = make_object(1500, shape_seed=seed % 50, sample_seed=seed)
    m = max(1, int(share * len(points)))
    base = poisson_disk_subset(points, m)
    rot, shift = random_motion(seed, 1000.0)
    perm = np.random.default_rng(seed).permutation(len(points))
    assert len(base) == m and np.all(np.diff(base) > 0)
    np.testing.assert_array_equal(poisson_disk_subset(points @ rot.T + shift, m), base)
    np.testing.assert_array_equal(np.sort(perm[poisson_disk_subset(points[perm], m)]), base)


def test_poisson_disk_spreads_the_sample():
    points = make_blob(4000, shape_seed=2)
    kept = points[poisson_disk_subset(points, 1000)]
    chance = points[np.random.default_rng(0).choice(4000, 1000, replace=False)]

    def closest(sample):
        d = np.linalg.norm(sample[:, None] - sample[None], axis=2)
        np.fill_diagonal(d, np.inf)
        return d.min(axis=1)

    # A hard-core sample: its closest pairs are far apart compared with a random one's.
    assert np.percentile(closest(kept), 1) > 4 * np.percentile(closest(chance), 1)


def test_hop_subsets_are_nested_and_auto_switches_at_the_threshold(monkeypatch):
    points = make_blob(3000, shape_seed=4)
    for method in ("fps", "poisson"):
        big, small = hop_subsets(points, [2000, 900], method)
        assert len(big) == 2000 and len(small) == 900 and np.isin(small, big).all()
    import o3d_rpointhop.descriptors.pointhop._sampling as sampling

    monkeypatch.setattr(sampling, "FPS_MAX_POINTS", 2999)
    np.testing.assert_array_equal(
        hop_subsets(points, [1500], "auto")[0], hop_subsets(points, [1500], "poisson")[0]
    )
    monkeypatch.setattr(sampling, "FPS_MAX_POINTS", 3000)
    np.testing.assert_array_equal(
        hop_subsets(points, [1500], "auto")[0], hop_subsets(points, [1500], "fps")[0]
    )


@pytest.mark.parametrize("seed", [0, 1])
def test_poisson_descriptors_are_rigid_invariant_and_permutation_equivariant(poisson_model, seed):
    cloud = make_blob(700, shape_seed=40 + seed)
    base = poisson_model.transform(cloud)
    rot, shift = random_motion(seed, 100.0)
    assert relative_difference(base, poisson_model.transform(cloud @ rot.T + shift)) < CONTRACT
    perm = np.random.default_rng(seed).permutation(len(cloud))
    assert relative_difference(poisson_model.transform(cloud[perm]), base[perm]) < CONTRACT
    np.testing.assert_array_equal(poisson_model.transform(cloud), base)  # deterministic


def test_fps_matches_reference_and_is_nested():
    pts = make_blob(400, shape_seed=8)
    start = int(np.argmax(np.linalg.norm(pts - pts.mean(0), axis=1)))
    big, small = fps_subsets(pts, [300, 120])
    np.testing.assert_array_equal(big, _reference_fps(pts, 300, start))
    np.testing.assert_array_equal(small, _reference_fps(pts, 120, start))
    assert np.isin(small, big).all()


def test_fps_is_rigid_and_permutation_invariant():
    pts = make_blob(400, shape_seed=9)
    rot, shift = random_motion(1, 50.0)
    perm = np.random.default_rng(2).permutation(400)
    (base,) = fps_subsets(pts, [150])
    (moved,) = fps_subsets(pts @ rot.T + shift, [150])
    (permuted,) = fps_subsets(pts[perm], [150])
    np.testing.assert_array_equal(base, moved)
    np.testing.assert_array_equal(np.sort(perm[permuted]), base)


def test_knn_and_drop_self():
    pts = make_blob(100, shape_seed=10)
    idx, sq = knn(pts, pts, 5)
    np.testing.assert_array_equal(idx[:, 0], np.arange(100))
    brute = np.argsort(((pts[:, None] - pts[None]) ** 2).sum(-1), axis=1)[:, :5]
    np.testing.assert_array_equal(idx, brute)
    assert np.all(np.diff(sq, axis=1) >= 0)
    kept = drop_self(idx, sq, 4)
    np.testing.assert_array_equal(kept, idx[:, 1:])
    # A query that is not one of the points keeps its k nearest.
    far_idx, far_sq = knn(pts, pts[:3] + 10.0, 5)
    np.testing.assert_array_equal(drop_self(far_idx, far_sq, 4), far_idx[:, :4])
    with pytest.raises(ValueError, match="cannot take"):
        knn(pts[:3], pts, 5)


def test_spatial_order_is_a_permutation_that_keeps_neighbours_together():
    pts = make_blob(3000, shape_seed=13)
    order = spatial_order(pts)
    np.testing.assert_array_equal(np.sort(order), np.arange(3000))
    step = np.linalg.norm(np.diff(pts[order], axis=0), axis=1).mean()
    scattered = np.linalg.norm(np.diff(pts, axis=0), axis=1).mean()
    assert step < scattered / 5  # consecutive points are near each other
    # Points in one Morton cell stay in input order; a cloud without extent is kept.
    np.testing.assert_array_equal(spatial_order(np.zeros((4, 3))), np.arange(4))
