"""Matches over turns of the local frames: each point against every turned descriptor of
the other cloud's points, planted where only a turned descriptor is right."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import (
    TurnedCodesBySize,
    consensus_matcher,
    global_step_only,
    moved_part,
    moved_samples,
)

from o3d_rpointhop import (
    ConsensusGlobal,
    FPFHTransformer,
    Matcher,
    RANSACGlobal,
    register,
)
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration import RegistrationContext
from o3d_rpointhop.registration.correspondences import turned_correspondences
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg


def test_a_point_matches_the_turn_of_its_partner_that_agrees():
    rng = np.random.default_rng(0)
    source = rng.normal(size=(50, 6))
    turns = rng.normal(size=(4, 60, 6))
    partner = rng.permutation(60)[:50]
    which = rng.integers(1, 4, 50)  # the partner's right turn is never turn 0
    turns[which, partner] = source + 1e-6
    corr = turned_correspondences(source, turns)
    np.testing.assert_array_equal(corr.pairs, np.c_[np.arange(50), partner])
    np.testing.assert_allclose(
        corr.distances, np.linalg.norm(turns[which, partner] - source, axis=1)
    )
    # The ratio is against the nearest descriptor of any other point, whatever its turn.
    flat = turns.reshape(240, 6)
    for i in (0, 17, 49):
        d = np.linalg.norm(flat - source[i], axis=1)
        d[np.arange(240) % 60 == partner[i]] = np.inf
        assert corr.ratios[i] == pytest.approx(corr.distances[i] / d.min())


def test_turned_correspondences_refuse_a_flat_stack():
    with pytest.raises(ValueError, match="n_turns, m, d"):
        turned_correspondences(np.ones((3, 4)), np.ones((5, 4)))


def _pair_whose_frames_agree_after_a_turn():
    """An object and 500 of its points moved. Plain descriptors of partners are
    unrelated; the target's frames turned by a quarter turn describe a point as its
    partner's plain frame does (and the source's turned by three quarters, the other
    way round): only matches over turns find the partners."""
    rng = np.random.default_rng(3)
    source, target, truth, keep = moved_part(rng, 2, [50, -20, 10], [0.2, 0.1, -0.3])
    dim = 8
    src = rng.normal(size=(4, 500, dim))
    tgt = rng.normal(size=(4, 600, dim))
    tgt[1, keep] = src[0] + rng.normal(0, 1e-4, (500, dim))
    src[3] = tgt[0, keep] + rng.normal(0, 1e-4, (500, dim))
    return source, target, truth, TurnedCodesBySize({500: src, 600: tgt})


def test_only_matches_over_turns_find_partners_whose_frames_differ_by_a_turn():
    source, target, truth, descriptor = _pair_whose_frames_agree_after_a_turn()
    plain = global_step_only(ConsensusGlobal(), source, target, descriptor).steps[0]
    turned = global_step_only(
        ConsensusGlobal(matcher=consensus_matcher(frame_turns=4)), source, target, descriptor
    )

    def right(step):
        moved = apply_transform(step.matches[:, 0], truth)
        return np.linalg.norm(moved - step.matches[:, 1], axis=1) < 1e-6

    # Every source point's partner, found both ways (the same match once); the 100
    # target points without a partner add one wrong match each.
    assert right(turned.steps[0]).sum() == 500 and len(turned.steps[0].matches) == 600
    assert right(plain).mean() < 0.05
    assert rotation_error_deg(turned.transformation, truth) < 0.5
    # The preparation stage asked for the turns, once per cloud, and nothing else.
    assert descriptor.asked == [4, 4]


def test_ransac_matches_over_turns_too():
    source, target, truth, descriptor = _pair_whose_frames_agree_after_a_turn()
    turned = global_step_only(
        RANSACGlobal(matcher=Matcher(frame_turns=4)), source, target, descriptor
    )
    moved = apply_transform(turned.steps[0].matches[:, 0], truth)
    right = np.linalg.norm(moved - turned.steps[0].matches[:, 1], axis=1) < 1e-6
    assert right.all() and len(right) == 500  # one match per source point, each right
    assert rotation_error_deg(turned.transformation, truth) < 0.5
    with pytest.raises(ValueError, match="frame_turns=2 cannot be combined"):
        global_step_only(
            RANSACGlobal(matcher=Matcher(frame_turns=2, mutual_filter=True)),
            source,
            target,
            descriptor,
        )


def test_the_context_keeps_turn_zero_as_the_plain_descriptors(object_model):
    cloud = make_object(1200, shape_seed=5)
    context = RegistrationContext(cloud, cloud + 0.05, descriptor=object_model)
    turned = context.features(None, "source", 4)
    n_points = len(context.global_cloud("source").points)
    assert turned.shape == (4, n_points, object_model.n_features_out_)
    assert np.shares_memory(context.features(None, "source"), turned)  # not described again
    np.testing.assert_array_equal(
        turned[0], object_model.transform(np.asarray(context.global_cloud("source").points))
    )


@pytest.mark.slow
def test_a_real_model_registers_with_matches_over_turns(object_model):
    source, target, truth = moved_samples()
    for turns in (2, 4):
        step = ConsensusGlobal(matcher=consensus_matcher(frame_turns=turns))
        result = register(source, target, object_model, global_method=step)
        assert rotation_error_deg(result.transformation, truth) < 2.0


def test_turns_need_a_descriptor_with_frames_and_the_nearest_alone():
    cloud = make_object(800)
    with pytest.raises(TypeError, match="no local frames"):
        register(
            cloud,
            cloud + 0.1,
            FPFHTransformer(),
            global_method=ConsensusGlobal(matcher=consensus_matcher(frame_turns=2)),
        )
    for bad in (dict(mutual_filter=True), dict(max_ratio=0.9), dict(n_nearest=2)):
        with pytest.raises(ValueError, match="frame_turns=4 cannot be combined"):
            ConsensusGlobal(matcher=consensus_matcher(frame_turns=4, **bad)).run(None, np.eye(4))
    with pytest.raises(ValueError, match="frame_turns"):
        ConsensusGlobal(matcher=consensus_matcher(frame_turns=3)).run(None, np.eye(4))


def test_prepare_takes_descriptors_alone_or_with_their_turns(object_model):
    cloud = make_object(1200, shape_seed=5)
    context = RegistrationContext(cloud, cloud + 0.05, descriptor=object_model)
    context.prepare([None, (None, 2)])
    assert sorted(key[1:] for key in context._features) == [
        ("source", 1),
        ("source", 2),
        ("target", 1),
        ("target", 2),
    ]
