"""The cell grid answers what scipy's k-d tree answers for a bounded nearest query."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from o3d_rpointhop._utils import cells
from o3d_rpointhop._utils.cells import CellGrid


def _tree_answer(points, queries, radius):
    dist, index = cKDTree(points).query(queries, distance_upper_bound=radius)
    return dist, index


@pytest.mark.parametrize("radius", [0.02, 0.1, 0.7, 5.0])
def test_same_distances_and_neighbours_as_the_tree(radius):
    rng = np.random.default_rng(3)
    points = rng.normal(size=(800, 3))
    queries = np.concatenate(
        [
            points[rng.integers(800, size=500)] + rng.normal(scale=radius / 2, size=(500, 3)),
            rng.uniform(-6, 6, (500, 3)),  # many far outside the grid
        ]
    )
    dist, index = CellGrid(points, radius).nearest(queries)
    expected_dist, expected_index = _tree_answer(points, queries, radius)
    np.testing.assert_array_equal(dist, expected_dist)  # to the bit
    np.testing.assert_array_equal(index, expected_index)
    assert 0 < np.isfinite(dist).sum() < len(queries)


def test_only_points_strictly_closer_than_the_radius():
    points = np.array([[0.0, 0.0, 0.0], [5.0, 5.0, 5.0]])
    queries = np.array([[0.5, 0.0, 0.0], [0.25, 0.0, 0.0], [0.0, -0.5, 0.0]])
    dist, index = CellGrid(points, 0.5).nearest(queries)
    np.testing.assert_array_equal(dist, [np.inf, 0.25, np.inf])
    np.testing.assert_array_equal(index, [2, 0, 2])


def test_wide_clouds_fall_back_on_the_tree(monkeypatch):
    monkeypatch.setattr(cells, "MAX_CELLS", 10)
    rng = np.random.default_rng(4)
    points = rng.uniform(0, 10, (300, 3))
    queries = points + rng.normal(scale=0.3, size=points.shape)
    grid = CellGrid(points, 0.5)
    assert grid._tree is not None
    dist, index = grid.nearest(queries)
    expected_dist, expected_index = _tree_answer(points, queries, 0.5)
    np.testing.assert_array_equal(dist, expected_dist)
    np.testing.assert_array_equal(index, expected_index)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    scale=st.floats(1e-3, 1e3),
    offset=st.floats(-1e6, 1e6),
)
def test_agrees_with_the_tree_at_any_scale_and_offset(seed, scale, offset):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-1, 1, (200, 3)) * scale + offset
    queries = points[rng.integers(200, size=300)] + rng.normal(scale=0.05 * scale, size=(300, 3))
    radius = 0.1 * scale
    dist, index = CellGrid(points, radius).nearest(queries)
    expected_dist, expected_index = _tree_answer(points, queries, radius)
    np.testing.assert_array_equal(dist, expected_dist)
    np.testing.assert_array_equal(index, expected_index)


def test_a_radius_tiny_against_the_cloud_takes_the_tree():
    """1e13 cells per axis would overflow the grid's integer keys: the tree answers."""
    rng = np.random.default_rng(5)
    points = rng.uniform(-1e6, 1e6, (100, 3))
    queries = points + rng.normal(scale=1e-8, size=points.shape)
    grid = CellGrid(points, 1e-7)
    assert grid._tree is not None
    dist, index = grid.nearest(queries)
    expected_dist, expected_index = _tree_answer(points, queries, 1e-7)
    np.testing.assert_array_equal(dist, expected_dist)
    np.testing.assert_array_equal(index, expected_index)
