"""Benchmark metrics: errors, success, symmetry, 3DMatch error and inlier ratio."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.evaluation.metrics import (
    is_symmetry,
    match_inliers,
    mcnemar,
    pair_errors,
    rmse_3dmatch,
    summarize,
)
from o3d_rpointhop.transforms import apply_transform


def test_errors_and_summary():
    truth = np.eye(4)
    est = np.eye(4)
    est[:3, :3] = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])  # 90 deg about z
    est[:3, 3] = [0.1, 0, 0]
    e = pair_errors(est, truth)
    assert e["rotation_error_deg"] == pytest.approx(90)
    assert e["translation_error"] == pytest.approx(0.1)
    assert sorted(np.abs(e["euler_error_deg"])) == pytest.approx([0, 0, 90])
    good = {**pair_errors(np.eye(4), truth), "seconds": 1.0, "symmetric": False}
    s = summarize([good, {**e, "seconds": 3.0, "symmetric": True}])
    assert s["success_rate"] == 0.5 and s["success_rate_up_to_symmetry"] == 1.0
    assert s["mae_r"] == pytest.approx(15.0) and s["seconds_per_pair"] == 2.0
    assert s["mae_r_not_symmetric"] == pytest.approx(0.0)  # the flip is left out
    assert s["rmse_r"] == pytest.approx(np.sqrt(90**2 / 6))


def test_symmetry_check():
    rng = np.random.default_rng(0)
    phi = rng.uniform(0, 2 * np.pi, 4000)
    z = rng.uniform(-1, 1, 4000)
    cylinder = np.c_[np.cos(phi), np.sin(phi), z]  # symmetric about z
    turn = np.eye(4)
    turn[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    assert is_symmetry(turn, np.eye(4), cylinder)
    tilt = np.eye(4)
    tilt[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    assert not is_symmetry(tilt, np.eye(4), cylinder)


def test_3dmatch_error_and_match_inliers():
    from scipy.spatial.transform import Rotation

    from o3d_rpointhop import FPFHTransformer
    from o3d_rpointhop.registration.context import RegistrationContext

    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    truth[:3, 3] = [0.5, 0.1, -0.2]
    info = np.diag([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])
    assert rmse_3dmatch(truth, truth, info) == pytest.approx(0.0, abs=1e-12)
    shifted = truth @ np.array([[1, 0, 0, 0.3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    assert rmse_3dmatch(shifted, truth, info) == pytest.approx(0.3)  # sqrt(2 * 0.09 / 2)

    target = make_object(800, shape_seed=3)
    source = apply_transform(target, np.linalg.inv(truth))  # truth maps source to target
    context = RegistrationContext(source, target)
    fpfh = FPFHTransformer(radius="auto", normal_radius="auto")
    ratio, count = match_inliers(context, fpfh, truth)
    assert ratio > 0.5 and count > 10
    assert match_inliers(context, fpfh, shifted, radius=0.1) == (0.0, 0)


def test_mcnemar_counts_discordant_pairs_and_gives_the_exact_p_value():
    a = np.array([True] * 10 + [False] * 2 + [True] * 5)
    b = np.array([False] * 10 + [True] * 2 + [True] * 5)
    test = mcnemar(a, b)
    assert (test["a_only"], test["b_only"]) == (10, 2)
    # Two-sided exact binomial: 2 * P(X <= 2), X ~ Bin(12, 1/2) = 2 * 79 / 4096.
    assert test["p_value"] == pytest.approx(2 * 79 / 4096)
    assert mcnemar(a, a) == {"a_only": 0, "b_only": 0, "p_value": 1.0}
