"""benchmarks/rooms_order.py: one scene's fragments in five orders, scored on gt.log."""

from __future__ import annotations

import pytest
from helpers import benchmark_script, synthetic_scene

from o3d_rpointhop.registration.defaults import default_descriptor


@pytest.fixture(scope="module")
def rooms_order():
    return benchmark_script("rooms_order")


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
    synthetic_scene(tmp_path, "room", ids=(0, 4, 10), seed=5)
    found = rooms_order.run_scene(tmp_path, "room", default_descriptor(), None, None, 0)
    assert found["fragments"] == 3 and found["gt_pairs"] == 2
    assert found["min"] == found["max"] == 2 and found["spread"] == 0
    assert all(run["placed"] == 3 for run in found["orders"].values())
    assert found["largest_pose_difference_deg"] < 1e-6
    assert found["largest_pose_difference_m"] < 1e-6
