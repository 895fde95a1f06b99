"""benchmarks/rooms_order.py: one scene's fragments in five orders, scored on gt.log."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from helpers import benchmark_script, partial_views

from o3d_rpointhop.registration.defaults import default_descriptor


@pytest.fixture(scope="module")
def rooms_order():
    return benchmark_script("rooms_order")


def _write_records(path: Path, records: dict) -> None:
    lines = []
    for (i, j), matrix in records.items():
        lines.append(f"{i} {j} 3")
        lines += [" ".join(f"{v:.12g}" for v in row) for row in matrix]
    path.write_text("\n".join(lines) + "\n")


def test_orders_are_five_and_each_a_permutation(rooms_order):
    found = rooms_order.orders(12)
    assert list(found)[:2] == ["by number", "reversed"] and len(found) == 5
    for order in found.values():
        assert sorted(order) == list(range(12))
    assert found["reversed"] == list(range(12))[::-1]


@pytest.mark.slow
def test_a_synthetic_scene_scores_the_same_in_every_order(rooms_order, tmp_path):
    """Three views of one object laid out as a 3DMatch scene (fragments numbered 0, 4,
    10, gt.log and gt.info for two pairs): every order places all three, counts both
    pairs, and gives the same relative poses."""
    scans, truth = partial_views(3, seed=5)
    ids = [0, 4, 10]
    folder = tmp_path / "fragments" / "room"
    folder.mkdir(parents=True)
    for k, scan in zip(ids, scans, strict=True):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scan))
        o3d.io.write_point_cloud(str(folder / f"cloud_bin_{k}.ply"), cloud)
    gt = tmp_path / "benchmarks" / "3DMatch" / "room"
    gt.mkdir(parents=True)
    # gt.log maps fragment j into fragment i: inv(pose_i) @ pose_j.
    log = {(0, 4): np.linalg.inv(truth[0]) @ truth[1], (4, 10): np.linalg.inv(truth[1]) @ truth[2]}
    _write_records(gt / "gt.log", log)
    _write_records(gt / "gt.info", {pair: np.eye(6) for pair in log})
    found = rooms_order.run_scene(tmp_path, "room", default_descriptor(), None, None, 0)
    assert found["fragments"] == 3 and found["gt_pairs"] == 2
    assert found["min"] == found["max"] == 2 and found["spread"] == 0
    assert all(run["placed"] == 3 for run in found["orders"].values())
    assert found["largest_pose_difference_deg"] < 1e-6
    assert found["largest_pose_difference_m"] < 1e-6
