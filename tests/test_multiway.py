"""Multiway registration: poses of unposed scans through a pose graph."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_motion

from o3d_rpointhop import register_multiway
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.evaluation.protocols import crop_nearest
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg


def _motion(seed: int) -> np.ndarray:
    rot, shift = random_motion(seed, 0.5)
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, shift
    return out


def _scans(n_scans: int, seed: int = 0, n_points: int = 2400):
    """Overlapping partial views of one object, each moved by its own rigid motion;
    returns the moved scans and each scan's true pose in scan 0's frame."""
    rng = np.random.default_rng(seed)
    scans, poses = [], []
    for k in range(n_scans):
        whole = make_object(n_points, shape_seed=21, sample_seed=100 + k)
        view = whole[crop_nearest(whole, 0.7, rng)]
        motion = np.eye(4) if k == 0 else _motion(seed * 100 + k)
        scans.append(apply_transform(view, motion))
        poses.append(np.linalg.inv(motion))  # back into the object's (= scan 0's) frame
    return scans, poses


def test_poses_of_a_synthetic_multiscan_object_are_recovered():
    scans, truth = _scans(4)
    result = register_multiway(scans, seed=0)
    assert result.unconnected == [] and len(result.poses) == 4
    np.testing.assert_array_equal(result.poses[0], np.eye(4))
    for k in range(1, 4):
        assert rotation_error_deg(result.poses[k], truth[k]) < 2.0
        gap = apply_transform(scans[k], result.poses[k]) - apply_transform(scans[k], truth[k])
        assert np.linalg.norm(gap, axis=1).mean() < 0.02
    assert len(result.pose_graph.nodes) == 4 and len(result.edges) >= 3
    assert set(result.pairs) == {(i, j) for i in range(4) for j in range(i + 1, 4)}


def test_a_scan_of_something_else_is_reported_unconnected():
    scans, truth = _scans(3, seed=1)
    stranger = make_object(1700, shape_seed=77) * 0.8 + 0.3  # another object entirely
    result = register_multiway([*scans, stranger], seed=0)
    assert result.unconnected == [3] and result.poses[3] is None
    assert all((3 not in edge) for edge in result.edges)
    for k in range(1, 3):
        assert rotation_error_deg(result.poses[k], truth[k]) < 2.0


def test_scans_of_different_sizes_and_resolutions():
    scans, truth = _scans(3, seed=2, n_points=6000)
    scans[1] = scans[1][::3]  # a third of the points: coarser spacing
    scans[2] = np.concatenate([scans[2], scans[2] + 1e-4])  # every point twice
    result = register_multiway(scans, seed=0)
    assert result.unconnected == []
    for k in (1, 2):
        assert rotation_error_deg(result.poses[k], truth[k]) < 3.0


@pytest.mark.parametrize(
    ("clouds", "message"),
    [
        ([], "at least two clouds"),
        ([make_object(500)], "at least two clouds"),
        (make_object(500), "at least two clouds"),
        ([make_object(500), np.full((50, 3), np.nan)], r"clouds\[1\]"),
    ],
)
def test_bad_input(clouds, message):
    with pytest.raises(ValueError, match=message):
        register_multiway(clouds)


def test_reconstruct_command(tmp_path, capsys):
    import json

    from o3d_rpointhop.cli import EXIT_OK, EXIT_UNRELIABLE, main

    scans, _ = _scans(3, seed=1)
    names = []
    for k, scan in enumerate(scans):
        np.save(tmp_path / f"s{k}.npy", scan)
        names.append(str(tmp_path / f"s{k}.npy"))
    out, poses = tmp_path / "merged.ply", tmp_path / "poses.json"
    assert main(["reconstruct", *names, "-o", str(out), "--poses", str(poses)]) == EXIT_OK
    summary = json.loads(poses.read_text())
    assert summary["unconnected"] == [] and len(summary["poses"]) == 3
    import open3d as o3d

    merged = o3d.io.read_point_cloud(str(out))
    assert len(merged.points) > 1000 and merged.has_colors()
    # Each scan's colour is there (voxels shared by two scans blend theirs).
    colours = {tuple(c) for c in np.asarray(merged.colors).round(2)}
    assert {(0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.17, 0.63, 0.17)} <= colours
    np.save(tmp_path / "other.npy", make_object(1700, shape_seed=77) * 0.8 + 0.3)
    status = main(["reconstruct", *names, str(tmp_path / "other.npy"), "-o", str(out)])
    assert status == EXIT_UNRELIABLE
    assert "unconnected (left out)" in capsys.readouterr().err
