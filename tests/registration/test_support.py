"""``RegistrationResult.support``: the share of the global step's matches its estimate
explains, on planted matches of which a known share is right."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import CodesBySize, global_step_only, moved_part

from o3d_rpointhop import ConsensusGlobal, RANSACGlobal, RegistrationResult, register
from o3d_rpointhop.transforms import rotation_error_deg


def _planted(n_right: int):
    """An object of 600 points and a moved copy of 500 of them; the first ``n_right``
    source points share a code with their true partner, the others with a target point
    far from theirs (a wrong match each)."""
    rng = np.random.default_rng(8)
    source, target, truth, keep = moved_part(rng, 5, [40, -25, 60], [0.2, 0.1, -0.3])
    tgt = rng.normal(size=(600, 8))
    partner = keep.copy()
    # A wrong partner: the target point farthest from the true one among ten drawn.
    for k in range(n_right, 500):
        drawn = rng.choice(600, 10, replace=False)
        partner[k] = drawn[np.argmax(np.linalg.norm(target[drawn] - target[keep[k]], axis=1))]
    src = tgt[partner] + rng.normal(0, 1e-4, (500, 8))
    return source, target, truth, CodesBySize({500: src, 600: tgt})


@pytest.mark.parametrize("make_step", [RANSACGlobal, ConsensusGlobal])
def test_support_is_the_share_of_matches_the_estimate_explains(make_step):
    shares = []
    for n_right in (100, 300):
        source, target, truth, descriptor = _planted(n_right)
        result = global_step_only(make_step(), source, target, descriptor)
        step = result.steps[0]
        assert rotation_error_deg(result.transformation, truth) < 1.0
        assert result.support == pytest.approx(step.match_inliers.mean())
        assert step.match_inliers.sum() == step.info["inlier_matches"]
        # The right matches and hardly any wrong one (a wrong partner is far).
        right = n_right / len(step.match_inliers)
        assert right <= result.support <= right + 0.02
        shares.append(result.support)
    assert shares[1] > 2.5 * shares[0]


def test_support_is_none_without_a_global_step_and_kept_by_save(tmp_path):
    source, target, truth, descriptor = _planted(300)
    icp_only = register(source, target, global_method=None, init=truth)
    assert icp_only.support is None
    result = global_step_only(RANSACGlobal(), source, target, descriptor)
    result.save(tmp_path / "result.json")
    loaded = RegistrationResult.load(tmp_path / "result.json")
    assert loaded.support == result.support
    # The summary (the command line's --json output) names it, and the margin.
    summary = result.as_dict()
    assert summary["support"] == result.support and summary["margin"] is None
    assert icp_only.as_dict()["support"] is None
