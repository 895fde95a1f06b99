"""Matches by cosine distance (``metric="cosine"``): descriptors compared by direction,
planted where partners differ only in length."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import (
    CodesBySize,
    TurnedCodesBySize,
    consensus_matcher,
    global_step_only,
    moved_part,
    moved_samples,
)

from o3d_rpointhop import ConsensusGlobal, Matcher, RANSACGlobal, register
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration.correspondences import find_correspondences, unit_rows
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg


def test_unit_rows_scale_every_descriptor_to_unit_length():
    rng = np.random.default_rng(0)
    features = rng.normal(size=(3, 40, 6)).astype(np.float32)
    features[1, 7] = 0.0
    unit = unit_rows(features)
    assert unit.shape == features.shape and unit.dtype == np.float32
    norms = np.linalg.norm(unit, axis=-1)
    norms[1, 7] = 1.0
    np.testing.assert_allclose(norms, 1.0, rtol=1e-6)
    np.testing.assert_array_equal(unit[1, 7], 0.0)  # a zero descriptor stays zero
    # The same directions: each row is its input times a positive number.
    cosine = np.sum(unit * features, axis=-1) / np.linalg.norm(features, axis=-1).clip(1e-30)
    np.testing.assert_allclose(np.delete(cosine.ravel(), 47), 1.0, rtol=1e-5)
    np.testing.assert_array_equal(unit_rows(features[0]), unit[0])  # (n, d) alike


def _moved_part():
    """An object of 600 points, 500 of them moved: the source, the target, the motion
    and which target point each source point is."""
    return moved_part(np.random.default_rng(4), 3, [-70, 30, 15], [0.3, -0.1, 0.2])


def _lengths(rng, n):
    """Partners' length factors: a tenth to ten times, none near one."""
    return np.exp(rng.uniform(np.log(2.0), np.log(10.0), n) * rng.choice([-1, 1], n))


def _right(step, truth):
    moved = apply_transform(step.matches[:, 0], truth)
    return np.linalg.norm(moved - step.matches[:, 1], axis=1) < 1e-6


def _pair_whose_partners_differ_in_length():
    """Planted codes: each source point's partner has its code times a factor between
    a tenth and ten (away from one), plus noise far below the codes' spread."""
    rng = np.random.default_rng(5)
    source, target, truth, keep = _moved_part()
    src = rng.normal(size=(500, 8))
    tgt = rng.normal(size=(600, 8))
    tgt[keep] = src * _lengths(rng, 500)[:, None] + rng.normal(0, 1e-4, (500, 8))
    return source, target, truth, CodesBySize({500: src, 600: tgt})


@pytest.mark.parametrize("make_step", [ConsensusGlobal, RANSACGlobal])
def test_only_the_cosine_distance_finds_partners_that_differ_in_length(make_step):
    source, target, truth, descriptor = _pair_whose_partners_differ_in_length()
    plain = global_step_only(make_step(), source, target, descriptor).steps[0]
    cosine = global_step_only(
        make_step(matcher=make_step.default_matcher().set_params(metric="cosine")),
        source,
        target,
        descriptor,
    )
    right = _right(cosine.steps[0], truth)
    assert right.sum() == 500  # every partner, and by RANSAC one match per source point
    assert _right(plain, truth).mean() < 0.2
    assert rotation_error_deg(cosine.transformation, truth) < 0.5


def test_cosine_matches_are_those_of_the_unit_descriptors():
    source, target, _, descriptor = _pair_whose_partners_differ_in_length()
    step = global_step_only(
        RANSACGlobal(matcher=Matcher(metric="cosine")), source, target, descriptor
    )
    codes = descriptor.codes
    expected = find_correspondences(unit_rows(codes[500]), unit_rows(codes[600]))
    matched = step.steps[0].matches[:, 1]  # back in the target's frame: to rounding
    np.testing.assert_allclose(matched, target[expected.pairs[:, 1]], rtol=0, atol=1e-12)


def test_cosine_distance_over_frame_turns():
    """Partners that agree only after a quarter turn of the target's frames and differ
    in length: found over turns by cosine distance, neither alone finds them."""
    rng = np.random.default_rng(6)
    source, target, truth, keep = _moved_part()
    src = rng.normal(size=(4, 500, 8))
    tgt = rng.normal(size=(4, 600, 8))
    tgt[1, keep] = src[0] * _lengths(rng, 500)[:, None] + rng.normal(0, 1e-4, (500, 8))
    descriptor = TurnedCodesBySize({500: src, 600: tgt})
    both = ConsensusGlobal(
        matcher=consensus_matcher(metric="cosine", frame_turns=4, both_directions=False)
    )
    found = global_step_only(both, source, target, descriptor)
    assert _right(found.steps[0], truth).sum() == 500
    assert rotation_error_deg(found.transformation, truth) < 0.5
    for alone in (
        ConsensusGlobal(matcher=consensus_matcher(frame_turns=4)),
        ConsensusGlobal(matcher=consensus_matcher(metric="cosine")),
    ):
        step = global_step_only(alone, source, target, descriptor).steps[0]
        assert _right(step, truth).mean() < 0.2


def test_a_real_model_registers_with_cosine_matches(object_model):
    source, target, truth = moved_samples()
    for step in (
        ConsensusGlobal(matcher=consensus_matcher(metric="cosine")),
        RANSACGlobal(matcher=Matcher(metric="cosine")),
    ):
        result = register(source, target, object_model, global_method=step)
        assert rotation_error_deg(result.transformation, truth) < 2.0


def test_an_unknown_metric_is_refused():
    with pytest.raises(ValueError, match="metric"):
        ConsensusGlobal(matcher=consensus_matcher(metric="manhattan")).run(None, np.eye(4))
    with pytest.raises(ValueError, match="metric"):
        RANSACGlobal(matcher=Matcher(metric="cityblock")).run(None, np.eye(4))


def test_the_context_scales_descriptors_once(object_model):
    from o3d_rpointhop.registration import RegistrationContext

    cloud = make_object(1200, shape_seed=5)
    context = RegistrationContext(cloud, cloud + 0.05, descriptor=object_model)
    unit = context.features(None, "source", unit=True)
    assert context.features(None, "source", unit=True) is unit  # not scaled again
    np.testing.assert_array_equal(unit, unit_rows(context.features(None, "source")))
    turned = context.features(None, "target", 4, unit=True)
    np.testing.assert_array_equal(turned, unit_rows(context.features(None, "target", 4)))
