"""The compiled k-d tree: the k nearest points of scipy's tree, for gathered and heap
searches alike, in any order of the queries and on any number of threads."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from o3d_rpointhop._utils.kdtree import KDTree
from o3d_rpointhop.datasets import make_object


@pytest.mark.parametrize("k", [1, 7, 65])
def test_the_nearest_points_are_scipy_s(k):
    pts = make_object(3000, shape_seed=4, sample_seed=1)
    rng = np.random.default_rng(0)
    queries = np.concatenate([pts[::3], rng.uniform(-2, 2, (200, 3))])  # on and off it
    index, sq = KDTree(pts).query(queries, k)
    distance, expected = cKDTree(pts).query(queries, k)
    np.testing.assert_allclose(np.sqrt(sq), distance.reshape(len(queries), k), rtol=1e-12)
    np.testing.assert_array_equal(index, expected.reshape(len(queries), k))
    assert np.all(np.diff(sq, axis=1) >= 0)  # nearest first


def test_unsorted_results_are_the_same_sets_and_the_same_bytes_on_any_thread_count():
    pts = make_object(5000, shape_seed=5, sample_seed=2)
    tree = KDTree(pts)
    sorted_index, _ = tree.query(pts, 20)
    loose, loose_sq = tree.query(pts, 20, sort=False, n_threads=1)
    np.testing.assert_array_equal(np.sort(loose, axis=1), np.sort(sorted_index, axis=1))
    again, again_sq = tree.query(pts, 20, sort=False, n_threads=2)
    np.testing.assert_array_equal(again, loose)
    np.testing.assert_array_equal(again_sq, loose_sq)


def test_queries_in_a_scattered_order_and_far_away_get_the_same_answers():
    pts = make_object(2000, shape_seed=6, sample_seed=3)
    tree = KDTree(pts)
    perm = np.random.default_rng(1).permutation(2000)  # each guess from a far-off query
    a, _ = tree.query(pts, 30)
    b, _ = tree.query(pts[perm], 30)
    np.testing.assert_array_equal(b, a[perm])
    far, _ = tree.query(pts[:5] + 1e6, 30)
    np.testing.assert_array_equal(far, cKDTree(pts).query(pts[:5] + 1e6, 30)[1])


def test_ties_are_decided_by_the_lower_index():
    grid = np.stack(np.meshgrid(*[np.arange(6.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    index, sq = KDTree(grid).query(grid[:50], 9)
    for row, d in zip(index, sq, strict=True):
        # within each distance the indices increase
        for value in np.unique(d):
            group = row[d == value]
            assert np.all(np.diff(group) > 0)


def test_duplicates_and_a_cloud_of_one_point_repeated():
    pts = np.zeros((100, 3))
    index, sq = KDTree(pts).query(pts[:3], 10)
    np.testing.assert_array_equal(index, np.tile(np.arange(10), (3, 1)))
    assert not sq.any()


@settings(max_examples=25, deadline=None)
@given(st.integers(5, 400), st.integers(1, 12), st.integers(0, 10_000), st.floats(1e-6, 1e6))
def test_any_cloud_any_scale(n, k, seed, scale):
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(n, 3)) * scale + rng.uniform(-1e3, 1e3, 3)
    k = min(k, n)
    index, sq = KDTree(pts, leaf_size=4).query(pts, k)
    distance, expected = cKDTree(pts).query(pts, k)
    np.testing.assert_allclose(np.sqrt(sq), distance.reshape(n, k), rtol=1e-9)
    # the same sets (scipy may order exact ties otherwise)
    np.testing.assert_array_equal(np.sort(index, 1), np.sort(expected.reshape(n, k), 1))


def test_bad_arguments():
    with pytest.raises(ValueError, match="shape"):
        KDTree(np.zeros((10, 2)))
    with pytest.raises(ValueError, match="cannot take 11 neighbours among 10"):
        KDTree(np.zeros((10, 3))).query(np.zeros((1, 3)), 11)
