"""Benchmark metrics: errors, success, symmetry, 3DMatch's official error (checked against
hand computations from Choi et al.'s definition) and McNemar's test."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.evaluation.metrics import (
    is_symmetry,
    mcnemar,
    overlap_share,
    pair_errors,
    rmse_3dmatch,
    summarize,
)
from o3d_rpointhop.evaluation.records import PairRecord


def _records(*rows):
    return [PairRecord(**row) for row in rows]


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
    s = summarize(_records(good, {**e, "seconds": 3.0, "symmetric": True}))
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


def _motion(rotvec=(0.0, 0.0, 0.0), shift=(0.0, 0.0, 0.0)) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    out[:3, 3] = shift
    return out


# An information matrix with every kind of entry: unequal diagonal, translation-
# translation, rotation-rotation and translation-rotation couplings (symmetric, positive
# definite), so that a mutant that drops a term or flips a sign shows.
INFO = np.array(
    [
        [4.0, 0.5, 0.0, 0.3, 0.0, 0.2],
        [0.5, 5.0, 0.1, 0.0, -0.4, 0.0],
        [0.0, 0.1, 6.0, 0.0, 0.0, 0.7],
        [0.3, 0.0, 0.0, 9.0, 0.2, 0.0],
        [0.0, -0.4, 0.0, 0.2, 8.0, 0.1],
        [0.2, 0.0, 0.7, 0.0, 0.1, 7.0],
    ]
)


def test_3dmatch_error_of_a_pure_translation_by_hand():
    t = np.array([0.1, -0.2, 0.3])
    truth = _motion([0.4, -0.1, 0.2], [1.0, 2.0, 3.0])
    estimate = truth @ _motion(shift=t)  # inv(truth) @ estimate is the pure translation
    by_hand = t @ INFO[:3, :3] @ t / INFO[0, 0]
    assert rmse_3dmatch(estimate, truth, INFO) == pytest.approx(np.sqrt(by_hand), rel=1e-12)
    assert rmse_3dmatch(truth, truth, INFO) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("angle", [0.3, 2.5, -2.5])
def test_3dmatch_error_of_a_pure_rotation_by_hand(angle):
    """About z by ``angle``: the quaternion's vector part is (0, 0, sin(angle / 2)) with
    the scalar part made non-negative (the official nibabel convention), so turning the
    other way by the same angle gives the same error."""
    truth = _motion([0.0, 0.3, 0.0], [0.5, 0.0, -1.0])
    estimate = truth @ _motion([0.0, 0.0, angle])
    q = np.array([0.0, 0.0, abs(np.sin(angle / 2))])
    by_hand = q @ INFO[3:, 3:] @ q / INFO[0, 0]
    assert rmse_3dmatch(estimate, truth, INFO) == pytest.approx(np.sqrt(by_hand), rel=1e-12)


@pytest.mark.parametrize("delta_rotvec", [(0.05, -0.08, 0.12), (0.1, -0.2, -2.4)])
def test_3dmatch_error_of_a_composed_motion_where_order_and_sign_matter(delta_rotvec):
    """The error is of ``inv(truth) @ estimate`` (in the target fragment's frame): the
    translation-rotation couplings of the information matrix see the sign of the
    quaternion's vector part (the scalar part is made non-negative; a turn of 2.4 rad
    about -z is where a matrix-to-quaternion conversion may return it negative),
    and composing the other way round moves the translation."""
    from scipy.spatial.transform import Rotation

    truth = _motion([1.2, -0.7, 0.4], [2.0, -1.0, 0.5])  # a large turn between fragments
    delta_rotvec, delta_shift = np.array(delta_rotvec), np.array([0.04, 0.09, -0.06])
    estimate = truth @ _motion(delta_rotvec, delta_shift)
    half = np.linalg.norm(delta_rotvec) / 2
    q = np.sin(half) * delta_rotvec / np.linalg.norm(delta_rotvec)  # w = cos(half) > 0
    xi = np.r_[delta_shift, q]
    by_hand = xi @ INFO @ xi / INFO[0, 0]
    assert rmse_3dmatch(estimate, truth, INFO) == pytest.approx(np.sqrt(by_hand), rel=1e-10)
    # What the mutants would compute differs by more than rounding: the other
    # composition order, and the quaternion's other sign.
    wrong_order = estimate @ np.linalg.inv(truth)
    q_wrong = Rotation.from_matrix(wrong_order[:3, :3]).as_quat()
    xi_wrong = np.r_[wrong_order[:3, 3], q_wrong[:3] * np.sign(q_wrong[3])]
    assert abs(xi_wrong @ INFO @ xi_wrong / INFO[0, 0] - by_hand) > 0.01 * by_hand
    flipped = np.r_[delta_shift, -q]
    assert abs(flipped @ INFO @ flipped / INFO[0, 0] - by_hand) > 0.01 * by_hand


def test_3dmatch_error_on_the_threshold():
    """0.2 m of translation along x under an information matrix whose first entry
    normalises it: an error of exactly 0.2."""
    info = np.diag([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
    truth = _motion([0.2, 0.1, 0.0])
    assert rmse_3dmatch(truth @ _motion(shift=[0.2, 0.0, 0.0]), truth, info) == pytest.approx(0.2)


def test_mcnemar_counts_discordant_pairs_and_gives_the_exact_p_value():
    a = np.array([True] * 10 + [False] * 2 + [True] * 5)
    b = np.array([False] * 10 + [True] * 2 + [True] * 5)
    test = mcnemar(a, b)
    assert (test["a_only"], test["b_only"]) == (10, 2)
    # Two-sided exact binomial: 2 * P(X <= 2), X ~ Bin(12, 1/2) = 2 * 79 / 4096.
    assert test["p_value"] == pytest.approx(2 * 79 / 4096)
    assert mcnemar(a, a) == {"a_only": 0, "b_only": 0, "p_value": 1.0}


def test_the_paper_s_errors_by_hand():
    """Euler-angle and per-axis translation errors keep their signs (estimate minus
    truth) and wrap into [-180, 180)."""
    from o3d_rpointhop.evaluation.metrics import _wrap

    truth = _motion((0.0, 0.0, np.deg2rad(170.0)), (1.0, 2.0, 3.0))
    estimate = _motion((0.0, 0.0, np.deg2rad(-175.0)), (1.5, 1.0, 3.25))
    e = pair_errors(estimate, truth)
    # -175 - 170 = -345 degrees, i.e. +15 after wrapping.
    assert e["euler_error_deg"] == pytest.approx([0.0, 0.0, 15.0], abs=1e-9)
    assert e["translation_error_xyz"] == pytest.approx([0.5, -1.0, 0.25])
    assert e["rotation_error_deg"] == pytest.approx(15.0)
    np.testing.assert_allclose(_wrap(np.array([359.0, 180.0, -181.0, 0.5])), [-1, -180, 179, 0.5])


def test_the_paper_s_summary_by_hand():
    """Two records with hand-computed means: MSE, RMSE and MAE over the three Euler
    angles and the three translation components, medians, success, timing, and the MAE
    that leaves out the failures that are symmetries."""
    a = {
        "euler_error_deg": [1.0, -2.0, 2.0],
        "translation_error_xyz": [0.01, 0.0, -0.02],
        "rotation_error_deg": 3.0,
        "translation_error": 0.03,
        "seconds": 1.0,
        "symmetric": False,
    }
    b = {
        "euler_error_deg": [0.0, 180.0, -90.0],
        "translation_error_xyz": [0.3, -0.4, 0.0],
        "rotation_error_deg": 120.0,
        "translation_error": 0.5,
        "seconds": 2.0,
        "symmetric": True,
    }
    c = {**b, "rotation_error_deg": 4.0, "translation_error": 0.07, "symmetric": False}
    s = summarize(_records(a, b, c))
    euler = np.array([1, -2, 2, 0, 180, -90, 0, 180, -90], float)
    trans = np.array([0.01, 0, -0.02, 0.3, -0.4, 0, 0.3, -0.4, 0])
    assert s["pairs"] == 3 and s["seconds_per_pair"] == pytest.approx(5 / 3)
    assert s["mse_r"] == pytest.approx(np.mean(euler**2))
    assert s["rmse_r"] == pytest.approx(np.sqrt(np.mean(euler**2)))
    assert s["mae_r"] == pytest.approx(np.mean(np.abs(euler)))
    assert s["mse_t"] == pytest.approx(np.mean(trans**2))
    assert s["rmse_t"] == pytest.approx(np.sqrt(np.mean(trans**2)))
    assert s["mae_t"] == pytest.approx(np.mean(np.abs(trans)))
    assert s["median_rotation_error_deg"] == 4.0 and s["median_translation_error"] == 0.07
    # a: both within 5 deg / 0.05; c: rotation within, translation not; b: neither.
    assert s["success_rate"] == pytest.approx(1 / 3)
    assert s["success_rate_up_to_symmetry"] == pytest.approx(2 / 3)
    kept = np.array([1, -2, 2, 0, 180, -90], float)  # a and c: b is a symmetric failure
    assert s["mae_r_not_symmetric"] == pytest.approx(np.mean(np.abs(kept)))
    # The thresholds are strict and can be moved.
    assert summarize(_records(a), rotation_tol=3.0)["success_rate"] == 0.0
    assert summarize(_records(a), translation_tol=0.03)["success_rate"] == 0.0
    assert summarize(_records(c), translation_tol=0.08)["success_rate"] == 1.0
    unmarked = {k: v for k, v in a.items() if k != "symmetric"}
    assert "success_rate_up_to_symmetry" not in summarize(_records(unmarked))
    only_symmetric = summarize(_records(b))
    assert only_symmetric["mae_r_not_symmetric"] == 0.0  # nothing left to average


def test_symmetry_check_boundaries():
    """The identity is a symmetry of any shape (a moved distance of 0 is not above the
    reference), and the reference is the spacing between the shape's two halves: on this
    seeded blob a 15 degree turn moves the points 0.223 on average, inside the halves'
    spacing (0.246), and a 20 degree turn 0.252, outside it (thirds would give 0.278)."""
    rng = np.random.default_rng(3)
    blob = rng.normal(size=(3000, 3)) * [3.0, 1.0, 0.5]
    assert is_symmetry(np.eye(4), np.eye(4), blob)
    assert is_symmetry(_motion((0.0, 0.0, np.deg2rad(15.0))), np.eye(4), blob)
    assert not is_symmetry(_motion((0.0, 0.0, np.deg2rad(20.0))), np.eye(4), blob)


def test_success_needs_5_degrees_and_5_centimetres_by_default():
    near = {
        "euler_error_deg": [0.0, 0.0, 5.5],
        "translation_error_xyz": [0.0, 0.0, 0.0],
        "rotation_error_deg": 5.5,
        "translation_error": 0.0,
        "seconds": 1.0,
    }
    assert summarize(_records(near))["success_rate"] == 0.0
    assert summarize(_records({**near, "rotation_error_deg": 4.9}))["success_rate"] == 1.0
    far = {**near, "rotation_error_deg": 1.0, "translation_error": 0.051}
    assert summarize(_records(far))["success_rate"] == 0.0


def test_mcnemar_takes_successes_as_0_and_1_too():
    a = np.array([1, 1, 1, 0, 0, 1])
    b = np.array([1, 0, 0, 0, 1, 1])
    as_ints, as_bools = mcnemar(a, b), mcnemar(a.astype(bool), b.astype(bool))
    assert as_ints == as_bools
    assert (as_ints["a_only"], as_ints["b_only"]) == (2, 1)


def test_summarize_gives_rpmnet_s_means_and_chamfer_by_hand():
    """With every record's Chamfer distance: the mean isotropic errors and the mean
    Chamfer distance, by hand; without one, none of the three keys."""
    from o3d_rpointhop.evaluation.metrics import summarize
    from o3d_rpointhop.evaluation.records import PairRecord

    def record(rot, trans, chamfer):
        return PairRecord(rot, trans, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], chamfer=chamfer)

    out = summarize([record(1.0, 0.01, 0.002), record(3.0, 0.03, 0.004)])
    assert out["mean_rotation_error_deg"] == pytest.approx(2.0)
    assert out["mean_translation_error"] == pytest.approx(0.02)
    assert out["chamfer"] == pytest.approx(0.003)
    plain = summarize([record(1.0, 0.01, None), record(3.0, 0.03, 0.004)])
    assert not {"mean_rotation_error_deg", "mean_translation_error", "chamfer"} & set(plain)


def test_overlap_share_counts_the_source_points_the_truth_brings_near_the_target():
    grid = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0), [0.0]), -1).reshape(-1, 3)
    target = grid[grid[:, 0] < 6]  # columns 0-5 of the plane
    source = grid[grid[:, 0] >= 2] + [0.0, 0.0, 5.0]  # columns 2-9, lifted by 5
    truth = np.eye(4)
    truth[2, 3] = -5.0  # puts the source back on the plane: columns 2-5 are shared
    assert overlap_share(source, target, truth, 0.1) == pytest.approx(4 / 8)
    assert overlap_share(source, target, np.eye(4), 0.1) == 0.0  # lifted: nothing near
    # a point exactly at the distance is not within it
    assert overlap_share(np.zeros((1, 3)), np.array([[0.1, 0.0, 0.0]]), np.eye(4), 0.1) == 0.0
