"""The refit loop both global estimators finish with."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.registration.steps._refit import refit_while_growing


def _scripted(counts, failing=()):
    """Transformations 0, 1, 2, ... (as a 4x4 scaled identity) whose inlier counts are
    ``counts[k]``; a refit of transformation ``k`` gives ``k + 1`` (ValueError for the
    ones in ``failing``)."""

    def within(t):
        k = int(round(t[3, 3])) - 1
        mask = np.zeros(20, dtype=bool)
        mask[: counts[k]] = True
        return mask

    def fit(t, inliers):
        k = int(round(t[3, 3])) - 1
        if k + 1 in failing:
            raise ValueError("collinear")
        assert inliers.sum() == counts[k]  # refits on the current inliers
        return np.eye(4) * (k + 2)

    return within, fit


@pytest.mark.parametrize(
    ("counts", "rounds", "failing", "ends_at"),
    [
        ([5, 7, 9, 9, 12], 10, (), 4),  # grows, then an equal count is taken and stops
        ([5, 7, 6, 12], 10, (), 2),  # a refit that loses inliers is not taken
        ([5, 7, 9, 11, 13], 2, (), 3),  # at most `rounds` refits
        ([2, 9], 10, (), 1),  # fewer than 3 inliers: nothing to refit on
        ([5, 7, 9], 10, (2,), 2),  # a failing fit keeps what there is
    ],
)
def test_refits_while_inliers_grow(counts, rounds, failing, ends_at):
    within, fit = _scripted(counts, failing)
    found, inliers = refit_while_growing(np.eye(4), within, fit, rounds)
    assert int(round(found[3, 3])) == ends_at
    assert inliers.sum() == counts[ends_at - 1]


@pytest.mark.parametrize(
    ("counts", "ends_at"), [([5, 7, 6, 12], 3), ([5, 4, 9], 2), ([5, 7, 9, 9], 4)]
)
def test_keep_losing_takes_a_losing_refit_and_stops(counts, ends_at):
    """RANSAC's refit on the clouds keeps the last refit, even one that lost inliers,
    and stops there."""
    within, fit = _scripted(counts)
    found, inliers = refit_while_growing(np.eye(4), within, fit, 10, keep_losing=True)
    assert int(round(found[3, 3])) == ends_at
    assert inliers.sum() == counts[ends_at - 1]


def test_ransac_refit_on_clouds_keeps_open3d_rule():
    """RANSAC's refit on the clouds, through the shared loop, takes the least-squares
    refit on the sample's inliers even when it loses a pair at the threshold's edge."""
    from o3d_rpointhop._utils.cells import CellGrid
    from o3d_rpointhop.registration.steps._ransac import _refit_on_clouds

    rng = np.random.default_rng(0)
    target = rng.uniform(-1, 1, size=(400, 3))
    source = target + rng.normal(scale=0.02, size=target.shape)
    start = np.eye(4)
    start[:3, 3] = [0.03, 0.0, 0.0]  # a sample's fit: slightly off
    grid = CellGrid(target, 0.05)
    found = _refit_on_clouds(start, (source, target), grid)
    # Whatever the counts did, the result is a least-squares refit: much closer than the start.
    assert np.abs(found[:3, 3]).max() < 0.01
