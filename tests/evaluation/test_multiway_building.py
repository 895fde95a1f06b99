"""benchmarks/multiway_building.py: tiles of room fragments, moved, and their scoring."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from helpers import benchmark_script

from o3d_rpointhop.transforms import random_rigid_motion


@pytest.fixture(scope="module")
def building():
    return benchmark_script("multiway_building")


def test_four_tiles_cover_a_fragment_and_overlap(building):
    rng = np.random.default_rng(0)
    points = rng.uniform([-2, -1, 0], [2, 1, 0.2], (4000, 3))
    tiles = building.tiles_of(points)
    assert len(tiles) == 4 and all(len(t) > 500 for t in tiles)
    seen = np.unique(np.concatenate(tiles), axis=0)
    assert len(seen) == len(np.unique(points, axis=0))  # every point in some tile
    assert sum(len(t) for t in tiles) > 1.3 * len(points)  # neighbouring tiles overlap


def test_right_poses_score_every_pair_and_a_wrong_tile_is_caught(building):
    """Two fragments of one scene, four tiles each, moved: poses that undo the motions
    (fragment b placed by its ground truth) register the gt pair and make every tile of
    a fragment agree; one tile turned by 10 degrees disagrees with its three siblings."""
    rng = np.random.default_rng(1)
    truth_ab = random_rigid_motion(rng, 1.0)  # fragment b into fragment a
    owner = [("room", f) for f in (0, 1) for _ in range(4)]
    motions = [random_rigid_motion(rng, 2.0) for _ in owner]
    frame = {0: np.eye(4), 1: truth_ab}  # each fragment into the part's frame (a's)
    poses = [frame[f] @ np.linalg.inv(m) for (_, f), m in zip(owner, motions, strict=True)]
    truths = {"room": {(0, 1): (truth_ab, np.eye(6))}}
    result = SimpleNamespace(
        poses=poses, unconnected=[], parts=[list(range(8))], part_poses=[poses]
    )
    found = building.score(result, owner, motions, truths)
    assert found["gt_pairs_registered"] == found["gt_pairs"] == 1
    assert found["tile_pairs_of_one_fragment_agreeing"] == 6  # three per fragment
    assert found["tile_pairs_of_one_fragment_disagreeing"] == 0
    turn = np.eye(4)
    angle = np.radians(10.0)
    turn[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    wrong = list(poses)
    wrong[2] = turn @ poses[2]
    result.part_poses = [wrong]
    found = building.score(result, owner, motions, truths)
    assert found["tile_pairs_of_one_fragment_disagreeing"] == 1
    assert found["gt_pairs_registered"] == 1  # the first tiles still carry the pair
