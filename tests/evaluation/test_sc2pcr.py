"""SC2-PCR, the benchmark peer of the consensus: it finds a planted motion among outlier
matches, repeats itself, and as a step runs on the consensus's own matches."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from helpers import CodesBySize
from scipy.spatial.transform import Rotation
from sklearn.base import clone

from o3d_rpointhop import ConsensusGlobal, RegistrationPipeline, RegistrationWarning
from o3d_rpointhop.datasets import make_room
from o3d_rpointhop.evaluation.sc2pcr import SC2PCRGlobal, _seeds, sc2pcr
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg


def _truth(seed: int = 0) -> np.ndarray:
    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_euler("zyx", [35, -15, 60], degrees=True).as_matrix()
    truth[:3, 3] = [0.8, -0.4, 1.5]
    return truth


def _planted_matches(n_in: int, n_out: int, seed: int = 0):
    """Matches in a 4 m room: ``n_in`` follow the motion (with 1 cm noise), ``n_out``
    join random points."""
    rng = np.random.default_rng(seed)
    truth = _truth()
    source = rng.uniform(0, 4, (n_in + n_out, 3))
    target = apply_transform(source, truth)
    target[:n_in] += rng.normal(0, 0.01, (n_in, 3))
    target[n_in:] = rng.uniform(0, 4, (n_out, 3))
    order = rng.permutation(n_in + n_out)  # the inliers are not the first rows
    return source[order], target[order], truth


@pytest.mark.parametrize("n_in, n_out", [(80, 320), (30, 570)])
def test_the_planted_motion_is_found_among_outliers(n_in, n_out):
    source, target, truth = _planted_matches(n_in, n_out)
    found, seeds = sc2pcr(source, target)
    assert rotation_error_deg(found, truth) < 1.0
    assert np.linalg.norm(found[:3, 3] - truth[:3, 3]) < 0.02
    assert 1 <= seeds <= int(0.2 * (n_in + n_out))  # at most the seed ratio's share


def test_it_repeats_itself_on_any_thread_count():
    source, target, _ = _planted_matches(60, 440, seed=3)
    one = sc2pcr(source, target, n_threads=1)
    again = sc2pcr(source, target, n_threads=1)
    two = sc2pcr(source, target, n_threads=2)
    np.testing.assert_array_equal(one[0], again[0])
    np.testing.assert_array_equal(one[0], two[0])
    assert one[1] == two[1]


def test_seeds_are_local_maxima_first():
    # Two matches 5 cm apart (one suppressed by the other) and one far away.
    source = np.array([[0.0, 0, 0], [0.05, 0, 0], [2.0, 0, 0]])
    confidence = np.array([0.9, 0.5, 0.7])
    seeds = _seeds(source, confidence, radius=0.1, ratio=1.0)
    assert seeds.tolist() == [0, 2, 1]  # the suppressed match ranks after both maxima
    assert _seeds(source, confidence, radius=0.1, ratio=0.5).tolist() == [0]


def test_as_a_step_it_runs_on_the_consensus_matches():
    rng = np.random.default_rng(2)
    room = make_room(1500, random_state=2)
    truth = _truth()
    keep = rng.permutation(1500)[:1400]
    source = apply_transform(room[keep], np.linalg.inv(truth))
    target_codes = rng.normal(size=(1500, 6))
    source_codes = target_codes[keep] + rng.normal(0, 1e-3, (1400, 6))
    descriptor = CodesBySize({1400: source_codes, 1500: target_codes})

    step = SC2PCRGlobal()
    assert clone(step).get_params() == step.get_params()
    assert {"threshold", "seed_ratio", "matcher"} <= set(step.get_params())
    assert step.default_matcher().get_params() == ConsensusGlobal.default_matcher().get_params()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RegistrationWarning)
        found = RegistrationPipeline([("global", step)], descriptor=descriptor)
        result = found.register(source, room)
        peer = RegistrationPipeline([("global", ConsensusGlobal())], descriptor=descriptor)
        reference = peer.register(source, room)
    assert rotation_error_deg(result.transformation, truth) < 0.5
    # The same matches as the consensus builds with the same matching parameters.
    np.testing.assert_array_equal(result.steps[0].matches, reference.steps[0].matches)
