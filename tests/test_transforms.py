"""Rigid transforms: the SVD fit and applying it."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_motion

from o3d_rpointhop import (
    rigid_transform,
)
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.transforms import apply_transform, random_rigid_motion


def motion_matrix(rot, shift):
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = shift
    return t


@pytest.fixture(scope="module")
def target():
    return make_object(800, shape_seed=321)


# ----------------------------------------------------------------------------- rigid fit
def test_rigid_transform_is_exact_on_clean_pairs():
    pts = make_object(50, shape_seed=1)
    rot, shift = random_motion(4, 10.0)
    est = rigid_transform(pts, pts @ rot.T + shift)
    np.testing.assert_allclose(est, motion_matrix(rot, shift), atol=1e-10)


def test_rigid_transform_never_returns_a_reflection():
    rng = np.random.default_rng(2)
    src = rng.normal(size=(30, 3))
    mirrored = src * np.array([1.0, 1.0, -1.0])  # the best orthogonal fit is a reflection
    est = rigid_transform(src, mirrored)
    assert np.linalg.det(est[:3, :3]) == pytest.approx(1.0)


def test_rigid_transform_weights_ignore_zero_weight_outliers():
    pts = make_object(40, shape_seed=2)
    rot, shift = random_motion(5)
    tgt = pts @ rot.T + shift
    tgt[:5] += 3.0  # outliers
    weights = np.r_[np.zeros(5), np.ones(35)]
    np.testing.assert_allclose(
        rigid_transform(pts, tgt, weights), motion_matrix(rot, shift), atol=1e-10
    )


@pytest.mark.parametrize(
    "src, tgt, message",
    [
        (np.zeros((2, 3)), np.zeros((2, 3)), "at least 3"),
        (np.zeros((5, 3)), np.zeros((4, 3)), "matching"),
        (
            np.c_[np.arange(5.0), np.zeros((5, 2))],
            np.c_[np.arange(5.0), np.zeros((5, 2))],
            "collinear",
        ),
    ],
)
def test_rigid_transform_bad_input(src, tgt, message):
    with pytest.raises(ValueError, match=message):
        rigid_transform(src, tgt)


def test_unmoved_input_is_applied_by_apply_transform(target):
    t = motion_matrix(*random_motion(1))
    np.testing.assert_allclose(apply_transform(target, t), target @ t[:3, :3].T + t[:3, 3])


def test_batched_fits_agree_with_the_single_fit():
    from scipy.spatial.transform import Rotation

    from o3d_rpointhop.transforms import rigid_transform, rigid_transforms

    rng = np.random.default_rng(4)
    source = rng.normal(size=(5, 12, 3))
    rot = Rotation.random(5, random_state=5).as_matrix()
    target = np.einsum("bij,bkj->bki", rot, source) + rng.normal(size=(5, 1, 3))
    target += rng.normal(scale=0.01, size=target.shape)
    weights = rng.uniform(0.1, 1.0, size=(5, 12))
    for w in (None, weights):
        rots, shifts = rigid_transforms(source, target, w)
        for b in range(5):
            single = rigid_transform(source[b], target[b], None if w is None else w[b])
            np.testing.assert_allclose(rots[b], single[:3, :3], atol=1e-12)
            np.testing.assert_allclose(shifts[b], single[:3, 3], atol=1e-12)


def test_translation_error_about_a_point_and_rms_displacement_by_hand():
    """A quarter turn about z through (10, 0, 0) against the identity: the translations
    differ by |(10, -10, 0)|, the pivot does not move, and the points (10, 1, 0) and
    (10, -1, 0) each move by sqrt(2)."""
    from o3d_rpointhop.transforms import rms_displacement, translation_error

    turn = np.eye(4)
    turn[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    turn[:3, 3] = [10.0, -10.0, 0.0]  # x -> R (x - p) + p with p = (10, 0, 0)
    assert translation_error(turn, np.eye(4)) == pytest.approx(np.sqrt(200.0))
    assert translation_error(turn, np.eye(4), about=[10.0, 0.0, 0.0]) == pytest.approx(0.0)
    points = np.array([[10.0, 1.0, 0.0], [10.0, -1.0, 0.0]])
    assert rms_displacement(turn, np.eye(4), points) == pytest.approx(np.sqrt(2.0))
    assert rms_displacement(np.eye(4), np.eye(4), points) == 0.0


def test_from_centred_takes_a_stack_matrix_by_matrix():
    from scipy.spatial.transform import Rotation

    from o3d_rpointhop.transforms import from_centred

    stack = np.tile(np.eye(4), (3, 1, 1))
    stack[:, :3, :3] = Rotation.random(3, random_state=0).as_matrix()
    stack[:, :3, 3] = [[1.0, 2, 3], [0, -1, 0], [5, 5, 5]]
    centre = np.array([10.0, -20.0, 3.0])
    expected = np.stack([from_centred(t, centre) for t in stack])
    np.testing.assert_array_equal(from_centred(stack, centre), expected)
    assert from_centred(np.empty((0, 4, 4)), centre).shape == (0, 4, 4)


def test_random_rigid_motion_seed_is_the_former_name_of_random_state():
    """``seed=`` still gives the motion ``random_state=`` gives, with a FutureWarning."""
    with pytest.warns(FutureWarning, match="random_rigid_motion"):
        old = random_rigid_motion(seed=5)
    np.testing.assert_array_equal(old, random_rigid_motion(random_state=5))
    assert not np.array_equal(old, random_rigid_motion(random_state=6))
