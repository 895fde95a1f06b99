"""Free-space violations: points a pose puts where the other sensor saw empty space."""

import numpy as np
import pytest

from o3d_rpointhop import register_multiway
from o3d_rpointhop.datasets import make_room
from o3d_rpointhop.registration.free_space import free_space_violation, violation_share
from o3d_rpointhop.registration.result import MultiwayResult

RNG = np.random.default_rng(0)
#: A wall 3 m in front of a sensor at the origin.
WALL = np.c_[RNG.uniform(-1, 1, 4000), RNG.uniform(-1, 1, 4000), np.full(4000, 3.0)]


def _box(depth: float, n: int = 500) -> np.ndarray:
    return np.c_[RNG.uniform(-0.3, 0.3, n), RNG.uniform(-0.3, 0.3, n), np.full(n, depth)]


@pytest.mark.parametrize(
    "points, share",
    [
        (_box(1.5), 1.0),  # in front of the wall: the sensor saw through it
        (_box(3.0), 0.0),  # on the wall
        (_box(4.0), 0.0),  # behind it: hidden, not free
        (_box(2.95), 0.0),  # within the margin
        (_box(-2.0), 0.0),  # behind the sensor: rays the wall does not cover
    ],
)
def test_violation_share(points, share):
    assert violation_share(points, WALL, margin=0.05) == share


def test_a_mix_counts_the_share_in_front():
    mixed = np.vstack([_box(1.5, 100), _box(3.5, 300)])
    assert violation_share(mixed, WALL, margin=0.05) == pytest.approx(0.25)


def test_the_violation_is_the_same_whichever_scan_is_the_source():
    turn = np.eye(4)
    c, s = np.cos(0.4), np.sin(0.4)
    turn[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    turn[:3, 3] = [0.2, -0.1, 0.5]
    source, target = _box(2.0, 800), WALL
    views = np.array([0.1, 0.0, -0.2]), np.array([0.0, 0.3, 0.1])
    one = free_space_violation(source, target, turn, views[0], views[1], 0.05)
    other = free_space_violation(target, source, np.linalg.inv(turn), views[1], views[0], 0.05)
    assert one == other and one > 0.5


def _room_scans():
    sensors = [np.array([4.5, 3.5, 1.6]), np.array([4.3, 3.8, 1.5]), np.array([4.6, 3.3, 1.7])]
    return [make_room(20000, random_state=k) - s for k, s in enumerate(sensors)]


@pytest.mark.slow
def test_multiway_records_the_violations_of_fitting_pairs(tmp_path):
    scans = _room_scans()
    with_sensors = register_multiway(scans, "scene", viewpoints="origin", max_violation=None)
    assert with_sensors.free_space  # every fitting pair measured
    assert set(with_sensors.free_space) <= set(with_sensors.pairs)
    assert all(0.0 <= v <= 1.0 for v in with_sensors.free_space.values())
    with_sensors.save(tmp_path / "m.json")
    assert MultiwayResult.load(tmp_path / "m.json").free_space == with_sensors.free_space
    blind = register_multiway(scans, "scene", viewpoints=None)
    assert blind.free_space == {}  # no sensors, nothing to measure


@pytest.mark.slow
def test_multiway_keeps_only_edges_within_the_limit():
    scans = _room_scans()
    free = register_multiway(scans, "scene", viewpoints="origin", max_violation=None)
    limit = sorted(free.free_space.values())[len(free.free_space) // 2]
    strict = register_multiway(scans, "scene", viewpoints="origin", max_violation=limit)
    assert strict.free_space == free.free_space
    assert all(strict.free_space[edge] <= limit for edge in strict.edges)
    with pytest.raises(ValueError, match="max_violation"):
        register_multiway(scans, "scene", viewpoints="origin", max_violation=1.5)


@pytest.mark.slow
def test_the_consensus_verifies_more_hypotheses_when_the_sensors_are_known():
    from o3d_rpointhop import register
    from o3d_rpointhop.registration.steps.consensus import SENSOR_HYPOTHESES

    source, target = _room_scans()[:2]
    seen = register(source, target, "scene", viewpoints="origin")
    scores = seen.steps[0].info["hypothesis_scores"]
    assert 1 < len(scores) <= SENSOR_HYPOTHESES
    blind = register(source, target, "scene", viewpoints=None)
    assert "hypothesis_scores" not in blind.steps[0].info  # one hypothesis, not verified


def test_many_poses_on_threads_give_the_same_shares():
    """free_space_violations measures each pose alone: any thread count, the same
    shares, each equal to the one-pose function's."""
    from o3d_rpointhop.registration.free_space import free_space_violations
    from o3d_rpointhop.transforms import random_rigid_motion

    rng = np.random.default_rng(0)
    points = rng.uniform([-2, -2, 1], [2, 2, 4], (3000, 3))
    poses = np.stack([random_rigid_motion(k, 0.5) for k in range(5)])
    views = (np.zeros(3), np.zeros(3))
    one = free_space_violations(points, points, poses, *views, 0.02)
    two = free_space_violations(points, points, poses, *views, 0.02, n_threads=2)
    assert one.tobytes() == two.tobytes()
    singles = [free_space_violation(points, points, t, *views, 0.02) for t in poses]
    np.testing.assert_array_equal(one, singles)
    assert one.max() > 0  # the moved poses do put points in front
