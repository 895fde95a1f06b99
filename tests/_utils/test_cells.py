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


def _dense_sheet(n: int, seed: int) -> np.ndarray:
    """A wavy sheet sampled far more densely than the radii below."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(0, 1, (n, 2))
    return np.c_[u, 0.02 * np.sin(6 * u[:, 0])]


@pytest.mark.parametrize("radius", [0.05, 0.12])
def test_a_dense_cloud_gets_narrower_cells_and_the_same_answers(radius):
    """Hundreds of points per radius-wide cell: the grid takes cells a few times
    narrower and searches them ring by ring; the distances are the tree's to the bit,
    and so is the neighbour wherever the nearest is unique (queries on, near, above
    and beside the sheet, and outside the grid by up to the cells per radius)."""
    rng = np.random.default_rng(7)
    points = _dense_sheet(20_000, 7)
    points = np.concatenate([points, points[:300]])  # exact duplicates: ties
    grid = CellGrid(points, radius)
    assert grid.reach > 1
    picks = points[rng.integers(len(points), size=3000)]
    queries = np.concatenate(
        [
            picks + rng.normal(scale=radius / 4, size=picks.shape),
            picks + [0.0, 0.0, 0.8 * radius],  # nearest far into the radius
            picks + [0.0, 0.0, 1.1 * radius],  # near the sheet, none within
            rng.uniform(-2 * radius, 1 + 2 * radius, (3000, 3)),  # around and outside
            points[:300],  # on the duplicated points
        ]
    )
    dist, index = grid.nearest(queries)
    expected_dist, expected_index = _tree_answer(points, queries, radius)
    np.testing.assert_array_equal(dist, expected_dist)
    differ = index != expected_index
    # Only ties may pick another point, at the same distance.
    np.testing.assert_array_equal(
        np.linalg.norm(points[index[differ]] - queries[differ], axis=1), dist[differ]
    )
    assert differ.sum() <= 300
    assert 0 < np.isfinite(dist).sum() < len(queries)


def test_ties_go_to_the_first_point_in_the_grid_on_dense_grids_too():
    """Among equally near points the one first in the grid's order wins, whatever the
    order the narrow cells are read in: the same neighbour as a scan of every point in
    that order."""
    points = _dense_sheet(20_000, 8)
    points = np.concatenate([points, points[::7], points[::11]])  # duplicated twice
    grid = CellGrid(points, 0.1)
    assert grid.reach > 1
    queries = points[::5] + 1e-4
    _, index = grid.nearest(queries)
    sorted_rows = grid.order
    position = np.empty(len(points), dtype=np.int64)
    position[sorted_rows] = np.arange(len(points))
    # Every point at the nearest distance, the first of them in the grid's order.
    for q, found in zip(queries[::50], index[::50], strict=True):
        d = np.linalg.norm(points - q, axis=1)
        diff = points - q
        squared = (diff[:, 0] * diff[:, 0] + diff[:, 1] * diff[:, 1]) + diff[:, 2] * diff[:, 2]
        tied = np.flatnonzero(squared == squared.min())
        assert found == tied[np.argmin(position[tied])]
        assert d[found] == d.min()


def test_sparse_clouds_keep_cells_as_wide_as_the_radius():
    rng = np.random.default_rng(9)
    points = rng.normal(size=(2000, 3))
    assert CellGrid(points, 0.3).reach == 1
    assert CellGrid(_dense_sheet(20_000, 9), 0.01).reach == 1  # a few points a cell
