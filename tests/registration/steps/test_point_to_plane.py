"""The compiled point-to-plane ICP takes Open3D's steps: trial poses, and one pose on every core."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial.transform import Rotation

from o3d_rpointhop._utils import cells
from o3d_rpointhop._utils.cells import CellGrid
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration.steps import _point_to_plane
from o3d_rpointhop.registration.steps._point_to_plane import (
    point_to_plane_icp,
    refine_point_to_plane,
)

reg = o3d.pipelines.registration


def _pair(seed=0):
    rng = np.random.default_rng(seed)
    points = make_object(1500, shape_seed=seed, sample_seed=seed)
    source = points[rng.permutation(len(points))[:900]]
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.15, max_nn=30))
    return source, target


def _starts(truth, n, seed):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        step = np.eye(4)
        step[:3, :3] = Rotation.from_rotvec(rng.normal(scale=0.08, size=3)).as_matrix()
        step[:3, 3] = rng.normal(scale=0.02, size=3)
        out.append(step @ truth)
    return np.array(out)


def _open3d_icp(source, target, distance, start, iterations):
    """Open3D's point-to-plane ICP of ``source`` (an array) onto ``target`` from ``start``."""
    return reg.registration_icp(
        o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source)),
        target,
        distance,
        start,
        reg.TransformationEstimationPointToPlane(),
        reg.ICPConvergenceCriteria(max_iteration=iterations),
    )


@pytest.mark.parametrize("iterations", [1, 4, 15])
def test_same_poses_as_open3d_point_to_plane(iterations):
    source, target = _pair()
    starts = _starts(np.eye(4), 4, seed=iterations)
    distance = 0.08
    expected = np.array(
        [
            _open3d_icp(source, target, distance, start, iterations).transformation
            for start in starts
        ]
    )
    grid = CellGrid(np.asarray(target.points), distance)
    refined = refine_point_to_plane(source, grid, np.asarray(target.normals), starts, iterations)
    np.testing.assert_allclose(refined, expected, atol=1e-9)
    # and it moved: the starts were off
    assert np.abs(refined - starts).max() > 1e-3


def test_refines_towards_the_truth_and_keeps_input_order():
    source, target = _pair(1)
    starts = _starts(np.eye(4), 3, seed=5)
    grid = CellGrid(np.asarray(target.points), 0.1)
    refined = refine_point_to_plane(source, grid, np.asarray(target.normals), starts, 30)
    before = np.linalg.norm(starts[:, :3, 3], axis=1)
    after = np.linalg.norm(refined[:, :3, 3], axis=1)
    assert np.all(after < before)
    assert np.all(after < 5e-3)
    one = refine_point_to_plane(source, grid, np.asarray(target.normals), starts[1:2], 30)
    np.testing.assert_array_equal(one[0], refined[1])


def test_a_pose_without_correspondences_stays():
    source, target = _pair(2)
    far = np.eye(4)[None].copy()
    far[0, :3, 3] = 50.0  # no target point within the distance of any moved point
    grid = CellGrid(np.asarray(target.points), 0.05)
    refined = refine_point_to_plane(source, grid, np.asarray(target.normals), far, 10)
    np.testing.assert_array_equal(refined, far)


def test_a_grid_searched_by_a_tree_has_no_kernel_arguments(monkeypatch):
    monkeypatch.setattr(cells, "MAX_CELLS", 8)
    grid = CellGrid(np.random.default_rng(0).uniform(0, 10, (100, 3)), 0.1)
    assert not grid.on_cells
    with pytest.raises(ValueError, match="k-d tree"):
        grid.kernel_arguments()
    with pytest.raises(ValueError, match="k-d tree"):
        _ = grid.order


def test_threads_share_the_poses_and_change_no_byte():
    source, target = _pair(2)
    starts = _starts(np.eye(4), 7, seed=3)
    grid = CellGrid(np.asarray(target.points), 0.1)
    normals = np.asarray(target.normals)
    one = refine_point_to_plane(source, grid, normals, starts, 15, n_threads=1)
    for threads in (2, 3, 8):
        many = refine_point_to_plane(source, grid, normals, starts, 15, n_threads=threads)
        assert many.tobytes() == one.tobytes()


def _big_pair(seed=0, n=12000):
    """A source of ``n`` points (several blocks of the one-pose ICP) and its target."""
    rng = np.random.default_rng(seed)
    points = make_object(n + 3000, shape_seed=seed, sample_seed=seed)
    source = points[rng.permutation(len(points))[:n]]
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.1, max_nn=30))
    return source, target


@pytest.mark.parametrize("iterations", [1, 5, 50])
def test_one_pose_matches_open3d_result(iterations):
    source, target = _big_pair()
    assert len(source) > 2 * _point_to_plane.BLOCK
    start = _starts(np.eye(4), 1, seed=iterations)[0]
    distance = 0.06
    expected = _open3d_icp(source, target, distance, start, iterations)
    grid = CellGrid(np.asarray(target.points), distance)
    got = point_to_plane_icp(
        source, grid, np.asarray(target.normals), start, iterations, 1e-6, 1e-6
    )
    np.testing.assert_allclose(got.transformation, expected.transformation, atol=1e-9)
    assert got.fitness == pytest.approx(expected.fitness, abs=1e-12)
    assert got.inlier_rmse == pytest.approx(expected.inlier_rmse, rel=1e-9)
    np.testing.assert_array_equal(got.correspondence_set, np.asarray(expected.correspondence_set))
    assert np.abs(got.transformation - start).max() > 1e-3  # it moved


def test_one_pose_gives_the_same_bytes_on_any_thread_count():
    source, target = _big_pair(1)
    start = _starts(np.eye(4), 1, seed=9)[0]
    grid = CellGrid(np.asarray(target.points), 0.06)
    normals = np.asarray(target.normals)
    one = point_to_plane_icp(source, grid, normals, start, 30, 1e-6, 1e-6, n_threads=1)
    for threads in (2, 3, 8):
        many = point_to_plane_icp(source, grid, normals, start, 30, 1e-6, 1e-6, threads)
        assert many.transformation.tobytes() == one.transformation.tobytes()
        assert many.correspondence_set.tobytes() == one.correspondence_set.tobytes()


def test_one_pose_without_correspondences_stays():
    source, target = _big_pair(2, n=5000)
    far = np.eye(4)
    far[:3, 3] = 50.0
    grid = CellGrid(np.asarray(target.points), 0.05)
    got = point_to_plane_icp(source, grid, np.asarray(target.normals), far, 10, 1e-6, 1e-6)
    np.testing.assert_array_equal(got.transformation, far)
    assert got.fitness == 0.0 and got.inlier_rmse == 0.0
    assert got.correspondence_set.shape == (0, 2)


def test_the_step_runs_compiled_and_falls_back_to_open3d_on_a_wide_target(monkeypatch):
    from o3d_rpointhop import register
    from o3d_rpointhop.registration import PointToPlaneICP

    source, target = _big_pair(3, n=6000)
    start = _starts(np.eye(4), 1, seed=4)[0]
    moved = source @ start[:3, :3].T + start[:3, 3]

    def run():
        return register(
            moved,
            np.asarray(target.points),
            None,
            global_method=None,
            refine=PointToPlaneICP(0.05),
            voxel_size=0.02,
        )

    from o3d_rpointhop.registration.steps import icp

    calls = []

    def counted(*args, **kwargs):
        calls.append(len(args[0]))
        return point_to_plane_icp(*args, **kwargs)

    monkeypatch.setattr(icp, "point_to_plane_icp", counted)
    compiled = run()
    assert calls  # the compiled pass ran
    calls.clear()
    monkeypatch.setattr(cells, "MAX_CELLS", 8)  # no grid fits: Open3D's ICP
    fallback = run()
    assert not calls  # Open3D's ICP ran
    np.testing.assert_allclose(compiled.transformation, fallback.transformation, atol=1e-9)
    assert compiled.fitness == pytest.approx(fallback.fitness, abs=1e-12)
    # both undo the start's motion
    residual = compiled.transformation @ start
    assert np.abs(residual[:3, 3]).max() < 5e-3


def test_a_dense_target_on_narrow_cells_gives_the_same_poses(monkeypatch):
    """A target far denser than the correspondence distance is searched on narrower
    cells (:data:`~o3d_rpointhop._utils.cells.DENSE_CELL`): the same poses, to the
    bit, as on cells as wide as the distance."""
    points = make_object(30_000, shape_seed=2, sample_seed=2)
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.1, max_nn=30))
    source = points[::13]
    starts = _starts(np.eye(4), 3, seed=5)
    distance = 0.2
    narrow = CellGrid(points, distance)
    monkeypatch.setattr(cells, "DENSE_CELL", 10**9)
    wide = CellGrid(points, distance)
    assert narrow.reach > 1 and wide.reach == 1
    normals = np.asarray(target.normals)
    np.testing.assert_array_equal(
        refine_point_to_plane(source, narrow, normals, starts, 10),
        refine_point_to_plane(source, wide, normals, starts, 10),
    )
