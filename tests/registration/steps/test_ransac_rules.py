"""RANSAC's own rules on matches with a known answer: the number of draws its stopping
rule asks for, the cap, and which hypothesis wins with and without whole-cloud
verification."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import motion_matrix, random_motion

from o3d_rpointhop.registration.steps._ransac import _needed, ransac
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg


def test_the_draws_needed_follow_the_textbook_formula():
    # log(1 - p) / log(1 - w^n), by hand: log(0.01) / log(0.875) = 34.4875...
    assert _needed(0.5, 0.99, 3) == pytest.approx(34.4875, abs=1e-3)
    assert _needed(0.2, 0.999, 3) == pytest.approx(860.01, abs=0.01)
    assert _needed(1.0, 0.99, 3) == 0.0
    assert _needed(0.0, 0.99, 3) == np.inf
    assert _needed(0.5, 0.99, 4) > _needed(0.5, 0.99, 3)  # bigger samples, more draws


def _planted(n: int, share: float, seed: int, motion: np.ndarray):
    """Exact matches under ``motion`` for a ``share`` of ``n``; the rest pair random
    points of a 10 m box (never within the threshold of any one motion's prediction)."""
    rng = np.random.default_rng(seed)
    source = rng.uniform(-1, 1, (n, 3))
    target = apply_transform(source, motion)
    wrong = rng.choice(n, n - int(round(share * n)), replace=False)
    target[wrong] = rng.uniform(-5, 5, (len(wrong), 3))
    return source, target


def test_drawing_stops_at_the_first_batch_boundary_past_the_rule():
    truth = motion_matrix(*random_motion(3, 0.5))
    source, target = _planted(1000, 0.2, seed=1, motion=truth)
    found = ransac(
        source, target, 0.01, max_iteration=100_000, confidence=0.999, edge_length=0.9, seed=0
    )
    assert rotation_error_deg(found.transformation, truth) < 1e-4
    ratio = found.inliers.sum() / len(source)
    assert ratio == pytest.approx(0.2, abs=0.002)
    # Batches of 256, 512, 1024, ...: 768 draws are short of the 860 the rule asks
    # for at w = 0.2, so a third batch runs, and no fourth.
    assert found.iterations == 256 + 512 + 1024
    capped = ransac(
        source, target, 0.01, max_iteration=300, confidence=0.999, edge_length=0.9, seed=0
    )
    assert capped.iterations == 300  # the cap, to the draw
    easy_source, easy_target = _planted(500, 1.0, seed=2, motion=truth)
    easy = ransac(
        easy_source,
        easy_target,
        0.01,
        max_iteration=100_000,
        confidence=0.999,
        edge_length=0.9,
        seed=0,
    )
    assert easy.iterations == 256  # every match an inlier: one batch is enough


def test_verification_prefers_the_whole_clouds_fit_over_the_match_count():
    """Two consistent groups of matches: the larger one is a wrong motion, the smaller
    the true one. Without the clouds RANSAC keeps the hypothesis with the most inlier
    matches; with them, the one whose clouds fit."""
    rng = np.random.default_rng(5)
    truth = motion_matrix(*random_motion(4, 0.3))
    decoy = motion_matrix(*random_motion(9, 0.3))
    cloud = rng.uniform(-1, 1, (3000, 3))
    moved = apply_transform(cloud, truth)
    true_src = cloud[:150]
    decoy_src = cloud[150:350]
    source = np.concatenate([true_src, decoy_src, cloud[350:1000]])
    target = np.concatenate(
        [
            apply_transform(true_src, truth),
            apply_transform(decoy_src, decoy),
            rng.uniform(-5, 5, (650, 3)),
        ]
    )
    kwargs = dict(max_iteration=20_000, confidence=0.9999, edge_length=0.9, seed=0)
    by_matches = ransac(source, target, 0.01, **kwargs)
    assert rotation_error_deg(by_matches.transformation, decoy) < 1e-4
    by_clouds = ransac(source, target, 0.01, clouds=(cloud, moved), **kwargs)
    assert rotation_error_deg(by_clouds.transformation, truth) < 1e-4


def test_the_refits_are_least_squares_fits_on_the_inliers():
    """From a slightly wrong hypothesis, the refit on the matches is the least-squares
    fit on the true matches (the only ones within the threshold), and the refit on the
    clouds the least-squares fit on their nearest-neighbour pairs."""
    from o3d_rpointhop._utils.cells import CellGrid
    from o3d_rpointhop.registration.steps._ransac import _refit_on_clouds, _refit_on_matches
    from o3d_rpointhop.transforms import rigid_transform

    rng = np.random.default_rng(8)
    truth = motion_matrix(*random_motion(5, 0.4))
    source = rng.uniform(-1, 1, (400, 3))
    target = apply_transform(source, truth) + rng.normal(scale=0.002, size=(400, 3))
    target[300:] = rng.uniform(-5, 5, (100, 3))  # outliers
    start = truth.copy()
    start[:3, 3] += [0.003, -0.002, 0.0]
    planes = np.ascontiguousarray(source.T), np.ascontiguousarray(target.T)
    found = _refit_on_matches(start, planes, 0.02**2, source, target)
    expected = rigid_transform(source[:300], target[:300])
    np.testing.assert_allclose(found, expected, atol=1e-12)

    cloud = rng.uniform(-1, 1, (300, 3))  # sparse: every nearest neighbour is the partner
    moved = apply_transform(cloud, truth) + rng.normal(scale=0.001, size=cloud.shape)
    fitted = _refit_on_clouds(start, (cloud, moved), CellGrid(moved, 0.01))
    np.testing.assert_allclose(fitted, rigid_transform(cloud, moved), atol=1e-9)


def test_verification_ranks_by_fitness_then_rmse_then_order():
    from o3d_rpointhop._utils.cells import CellGrid
    from o3d_rpointhop.registration.steps._ransac import _verify

    rng = np.random.default_rng(2)
    cloud = rng.uniform(-1, 1, (1500, 3))
    truth = motion_matrix(*random_motion(6, 0.3))
    moved = apply_transform(cloud, truth)
    grid = CellGrid(moved, 0.01)

    def hypothesis(shift):
        t = truth.copy()
        t[:3, 3] += shift
        return t

    candidates = [
        hypothesis([0.5, 0, 0]),  # far off: no fitness
        hypothesis([0.004, 0, 0]),  # every point within 0.01, RMSE 0.004
        hypothesis([0.001, 0, 0]),  # every point within 0.01, RMSE 0.001: the best
        hypothesis([0.001, 0, 0]),  # a tie with the one before: the first wins
        hypothesis([0.009, 0.009, 0]),  # fewer points within 0.01
    ]
    rot = np.array([c[:3, :3] for c in candidates])
    shift = np.array([c[:3, 3] for c in candidates])
    # The whole ranking: fitness, then RMSE, then the order drawn.
    np.testing.assert_array_equal(_verify(rot, shift, (cloud, moved), grid), [2, 3, 1, 4, 0])
    np.testing.assert_array_equal(
        _verify(rot[[0, 4, 1]], shift[[0, 4, 1]], (cloud, moved), grid), [2, 1, 0]
    )
