"""Matches between salient points: a repeated region's matches are dropped."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import CodesBySize, consensus_matcher, global_step_only
from scipy.spatial.transform import Rotation

from o3d_rpointhop import ConsensusGlobal
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration.correspondences import (
    distinctiveness,
    k_best_correspondences,
    salient,
)
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg


def test_salient_keeps_the_distinct_rows_and_the_share_asked_for():
    rng = np.random.default_rng(0)
    repeated = np.tile([1.0, 0.0, 0.0, 0.0], (60, 1)) + rng.normal(0, 1e-3, (60, 4))
    distinct = rng.normal(0, 1, (40, 4))
    features = np.r_[repeated, distinct]
    score = distinctiveness(features)
    assert score[:60].max() < score[60:].min()
    keep = salient(features, 0.4)
    assert keep.sum() == 40 and keep[60:].all()
    assert salient(features, 0.333).sum() == 34  # ceil(0.333 * 100)
    assert salient(features, 1.0).all()
    with pytest.raises(ValueError, match="share"):
        salient(features, 0.0)


def _pair_with_a_floor():
    """An object standing on a floor, seen twice. The object's points carry codes
    shared with their true partners; the floor's points all carry nearly one code, so
    each of their nearest descriptors is an arbitrary floor point of the other cloud."""
    rng = np.random.default_rng(1)
    thing = make_object(300, shape_seed=4, sample_seed=0) * 0.3 + [0.0, 0.0, 0.5]
    floor = np.c_[rng.uniform(-2, 2, (700, 2)), np.zeros(700)]
    target = np.r_[thing, floor]
    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_euler("zyx", [40, 10, -5], degrees=True).as_matrix()
    truth[:3, 3] = [0.3, -0.2, 0.1]
    keep = rng.permutation(len(target))[:900]  # the source: 900 of the same points
    source = apply_transform(target[keep], np.linalg.inv(truth))
    dim = 8
    tgt_codes = np.r_[rng.normal(0, 1, (300, dim)), np.ones((700, dim)) * 5.0]
    tgt_codes[300:] += rng.normal(0, 1e-3, (700, dim))
    src_codes = tgt_codes[keep] + rng.normal(0, 1e-6, (900, dim))
    src_codes[keep >= 300] = 5.0 + rng.normal(0, 1e-3, ((keep >= 300).sum(), dim))
    return source, target, truth, CodesBySize({900: src_codes, 1000: tgt_codes})


def test_the_floors_matches_are_dropped_and_the_pose_found():
    source, target, truth, descriptor = _pair_with_a_floor()
    every = global_step_only(ConsensusGlobal(), source, target, descriptor).steps[0]
    only = global_step_only(
        ConsensusGlobal(matcher=consensus_matcher(salient_share=0.3)), source, target, descriptor
    )
    step = only.steps[0]
    assert step.info["candidate_matches"] < every.info["candidate_matches"]
    # What is left is the object's matches, right under the truth.
    moved = apply_transform(step.matches[:, 0], truth)
    right = np.linalg.norm(moved - step.matches[:, 1], axis=1) < 1e-6
    assert right.mean() > 0.9
    every_right = (
        np.linalg.norm(apply_transform(every.matches[:, 0], truth) - every.matches[:, 1], axis=1)
        < 1e-6
    )
    assert right.mean() > every_right.mean() + 0.3
    assert rotation_error_deg(only.transformation, truth) < 1.0


def test_too_few_salient_matches_is_a_clear_error():
    source, target, _, descriptor = _pair_with_a_floor()
    with pytest.raises(ValueError, match="salient"):
        global_step_only(
            ConsensusGlobal(matcher=consensus_matcher(salient_share=0.001)),
            source,
            target,
            descriptor,
        )


def _pair_with_decoys():
    """An object seen twice, the target with a decoy point for 95 % of the source's
    points: a point elsewhere whose code is nearer to that source point's than its true
    partner's, so the right match is only second nearest."""
    rng = np.random.default_rng(2)
    shape = make_object(400, shape_seed=5, sample_seed=0)
    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_euler("zyx", [70, -20, 15], degrees=True).as_matrix()
    truth[:3, 3] = [0.2, 0.1, -0.3]
    source = apply_transform(shape, np.linalg.inv(truth))
    decoyed = rng.permutation(400)[:380]
    target = np.r_[shape, rng.uniform(shape.min(axis=0), shape.max(axis=0), (380, 3))]
    dim = 8
    src_codes = rng.normal(0, 1, (400, dim))
    tgt_codes = np.r_[
        src_codes + rng.normal(0, 1e-2, (400, dim)),
        src_codes[decoyed] + rng.normal(0, 1e-3, (380, dim)),
    ]
    return source, target, truth, CodesBySize({400: src_codes, 780: tgt_codes})


def test_two_nearest_matches_hold_the_partners_that_are_second_nearest():
    source, target, truth, descriptor = _pair_with_decoys()
    found = {
        k: global_step_only(
            ConsensusGlobal(matcher=consensus_matcher(n_nearest=k, both_directions=False)),
            source,
            target,
            descriptor,
        )
        for k in (1, 2)
    }
    right = {}
    for k, result in found.items():
        matches = result.steps[0].matches
        moved = apply_transform(matches[:, 0], truth)
        right[k] = int((np.linalg.norm(moved - matches[:, 1], axis=1) < 1e-6).sum())
    assert right[1] == 20 and right[2] == 400
    assert rotation_error_deg(found[2].transformation, truth) < 1.0


def test_two_nearest_both_ways_add_each_target_point_s_two_nearest():
    source, target, truth, descriptor = _pair_with_decoys()
    result = global_step_only(
        ConsensusGlobal(matcher=consensus_matcher(n_nearest=2)), source, target, descriptor
    )
    src, tgt = descriptor.codes[400], descriptor.codes[780]
    forward = k_best_correspondences(src, tgt, 2).pairs
    back = k_best_correspondences(tgt, src, 2).pairs[:, ::-1]
    expected = np.unique(np.r_[forward, back], axis=0)  # a pair found both ways once
    assert len(expected) < len(forward) + len(back)
    assert result.steps[0].info["candidate_matches"] == len(expected)
    assert rotation_error_deg(result.transformation, truth) < 1.0


def test_two_nearest_refuses_the_filters_defined_on_the_nearest_alone():
    for step in (
        ConsensusGlobal(matcher=consensus_matcher(n_nearest=2, mutual_filter=True)),
        ConsensusGlobal(matcher=consensus_matcher(n_nearest=2, max_ratio=0.9)),
    ):
        with pytest.raises(ValueError, match="n_nearest"):
            step.validate()
    ConsensusGlobal(matcher=consensus_matcher(n_nearest=2)).validate()
