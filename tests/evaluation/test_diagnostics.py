"""Descriptor diagnostics: true correspondences, frame repeatability and correct matches,
on pairs whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import motion_matrix, random_motion
from scipy.spatial.transform import Rotation

from o3d_rpointhop import FPFHTransformer
from o3d_rpointhop.datasets import make_object, make_room
from o3d_rpointhop.evaluation.diagnostics import (
    frame_repeatability,
    match_inliers,
    pair_diagnostics,
    true_correspondences,
)
from o3d_rpointhop.registration.context import RegistrationContext
from o3d_rpointhop.transforms import apply_transform


def test_true_correspondences_pair_points_within_the_radius():
    target = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    truth = motion_matrix(np.eye(3), [0.0, 0.0, 0.05])
    source = np.array([[0.0, 0, -0.05], [1, 0, -0.2], [0, 1, -0.04]])  # 0.0, 0.15, 0.01 away
    np.testing.assert_array_equal(
        true_correspondences(source, target, truth, 0.1), [[0, 0], [2, 2]]
    )


def test_frame_repeatability_counts_whole_frames_normals_and_lines():
    frames = Rotation.random(8, random_state=1).as_matrix()
    rotation = Rotation.random(random_state=2).as_matrix()
    target = rotation @ frames  # every frame turned exactly
    target[1] = target[1] @ Rotation.from_euler("z", 40, degrees=True).as_matrix()  # in-plane
    target[2] = target[2] @ np.diag([1.0, -1.0, -1.0])  # normal flipped (a half turn about x)
    target[3] = target[3] @ Rotation.from_euler("x", 10, degrees=True).as_matrix()  # within 25
    pairs = np.c_[np.arange(8), np.arange(8)]
    out = frame_repeatability(frames, target, pairs, rotation)
    assert out["correspondences"] == 8
    assert out["frames"] == pytest.approx(6 / 8)  # 1 (40 deg) and 2 (180 deg) disagree
    assert out["normals"] == pytest.approx(7 / 8)  # only 2's normal points the other way
    assert out["normal_lines"] == pytest.approx(1.0)
    empty = frame_repeatability(frames, target, np.zeros((0, 2), np.int64), rotation)
    assert empty["frames"] is None and empty["correspondences"] == 0


def test_match_inliers_on_a_known_pair():
    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    truth[:3, 3] = [0.5, 0.1, -0.2]
    shifted = truth @ motion_matrix(np.eye(3), [0.3, 0.0, 0.0])
    target = make_object(800, shape_seed=3)
    source = apply_transform(target, np.linalg.inv(truth))  # truth maps source to target
    context = RegistrationContext(source, target)
    ratio, count = match_inliers(context, FPFHTransformer(), truth)
    assert ratio > 0.5 and count > 10
    assert match_inliers(context, FPFHTransformer(), shifted, radius=0.1) == (0.0, 0)


def test_pair_diagnostics_see_frames_repeat_with_viewpoints(fitted):
    """A scan and the same scan moved, with its sensor: every frame repeats exactly with
    viewpoints; FPFH reports matches only."""
    target = make_room(1500, random_state=4) + [1.0, 1.3, 2.5]
    rot, shift = random_motion(3, 2.0)
    source = apply_transform(target, motion_matrix(rot, shift))
    truth = np.linalg.inv(motion_matrix(rot, shift))  # source back onto target
    seen = RegistrationContext(source, target, viewpoints=(shift, np.zeros(3)))
    row = pair_diagnostics(seen, fitted, truth)
    assert row["frames"] == pytest.approx(1.0) and row["normals"] == pytest.approx(1.0)
    assert row["correspondences"] >= 1400
    assert row["correct_matches"] >= row["inlier_count"] > 100
    # Sensors not where they were: the normal axes keep their lines, not their signs.
    wrong = RegistrationContext(source, target, viewpoints=(np.zeros(3), np.zeros(3)))
    off = pair_diagnostics(wrong, fitted, truth)
    assert off["normal_lines"] == pytest.approx(1.0) and off["normals"] < 0.9
    fpfh = pair_diagnostics(seen, FPFHTransformer(), truth)
    assert fpfh["frames"] is None and fpfh["correct_matches"] > 0


def test_choice_diagnostics_say_whether_the_matches_or_the_choice_failed(pretrained32):
    """The global step's matches, the shares the truth and the estimate explain, and its
    verified hypotheses; a wrong truth explains none of them; no global step, no diagnostics."""
    from o3d_rpointhop import RANSACGlobal, register
    from o3d_rpointhop.datasets import make_object
    from o3d_rpointhop.evaluation.diagnostics import choice_diagnostics

    target = make_object(1500, shape_seed=4, sample_seed=1)
    truth = np.eye(4)
    truth[:3, 3] = [0.1, -0.2, 0.05]
    source = make_object(1500, shape_seed=4, sample_seed=2) - truth[:3, 3]
    result = register(
        source, target, pretrained32, global_method=RANSACGlobal(n_hypotheses=3), refine=None
    )
    found = choice_diagnostics(result, truth)
    assert found["matches"] == len(result.steps[0].matches)
    assert 0.05 < found["match_inlier_ratio"] <= 1.0
    assert found["support"] == result.support == result.steps[0].match_inliers.mean()
    assert len(found["hypothesis_scores"]) >= 1 and "margin" in found
    far = truth.copy()
    far[:3, 3] += 10.0
    assert choice_diagnostics(result, far)["match_inlier_ratio"] == 0.0
    alone = register(source, target, pretrained32, global_method=None)
    assert choice_diagnostics(alone, truth) is None


def test_records_carry_the_diagnostics_of_register_methods(pretrained32):
    from o3d_rpointhop.datasets import make_object
    from o3d_rpointhop.evaluation._common import Progress, evaluate_methods, fixed_resolution
    from o3d_rpointhop.evaluation.protocols import make_pairs

    shapes = np.stack([make_object(2048, shape_seed=s) for s in range(2)])
    pairs = make_pairs(shapes, "resampled", 0)
    _, records = evaluate_methods(
        pairs,
        ["rpointhop-ransac-icp", "icp"],
        pretrained32,
        fixed_resolution(0.05),
        0,
        Progress(len(pairs), "test", False),
    )
    ours = records["rpointhop-ransac-icp"][0].as_dict()
    assert ours["diagnostics"]["matches"] > 0
    assert "diagnostics" not in records["icp"][0].as_dict()  # not through register()
