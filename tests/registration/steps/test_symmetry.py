"""SymmetryCheck: an estimate's 180-degree twins."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from sklearn.base import clone

from o3d_rpointhop import (
    PointToPointICP,
    RANSACGlobal,
    RegistrationPipeline,
    SymmetryCheck,
    register,
)
from o3d_rpointhop.registration.context import RegistrationContext
from o3d_rpointhop.registration.flags import twin_transformations
from o3d_rpointhop.registration.result import StepResult
from o3d_rpointhop.registration.steps.symmetry import fits_better, truncated_cost
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg


def box_surface(n: int, seed: int, knob: bool) -> np.ndarray:
    """Points on a 2 x 1 x 0.5 box (symmetric under half-turns about its axes), with an
    optional small cube on one end of the top face that breaks the symmetry."""
    rng = np.random.default_rng(seed)
    half = np.array([1.0, 0.5, 0.25])
    pts = rng.uniform(-half, half, size=(n, 3))
    face = rng.integers(0, 3, n)
    pts[np.arange(n), face] = half[face] * rng.choice([-1.0, 1.0], n)
    if knob:
        k = n // 6
        cube = rng.uniform(-0.15, 0.15, size=(k, 3))
        side = rng.integers(0, 3, k)
        cube[np.arange(k), side] = 0.15 * rng.choice([-1.0, 1.0], k)
        pts[:k] = cube + [0.75, 0.2, 0.25 + 0.15]
    return pts


def half_turn(axis: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = Rotation.from_rotvec(np.pi * axis / np.linalg.norm(axis)).as_matrix()
    return t


def test_twins_are_half_turns_that_keep_a_symmetric_shape_in_place():
    base = box_surface(500, 0, knob=False)
    # Close the sample under the box's half-turns, so it is exactly symmetric.
    points = np.concatenate([base, base * [1, -1, -1], base * [-1, 1, -1], base * [-1, -1, 1]])
    pose = np.eye(4)
    pose[:3, :3] = Rotation.random(random_state=1).as_matrix()
    pose[:3, 3] = [0.3, -0.2, 1.0]
    twins = twin_transformations(points, pose)
    assert twins.shape == (3, 4, 4)
    moved = apply_transform(points, pose)
    tree = cKDTree(moved)
    axes = []
    for twin in twins:
        rot = twin[:3, :3]
        np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)
        assert np.linalg.det(rot) == pytest.approx(1.0)
        flip = twin @ np.linalg.inv(pose)
        assert rotation_error_deg(flip, np.eye(4)) == pytest.approx(180.0)
        np.testing.assert_allclose(flip @ flip, np.eye(4), atol=1e-9)  # a half-turn
        # The twin lays the symmetric box exactly onto itself.
        distance, _ = tree.query(apply_transform(points, twin))
        assert distance.max() < 1e-9
        axes.append(Rotation.from_matrix(flip[:3, :3]).as_rotvec() / np.pi)
    # ... turning about the box's three axes, one twin per axis.
    box_axes = pose[:3, :3].T
    np.testing.assert_allclose(np.abs(np.array(axes) @ box_axes.T).max(axis=1), 1.0, atol=1e-9)


def test_truncated_cost_rewards_overlap_and_accuracy():
    assert truncated_cost(1.0, 0.0, 0.1) == 0.0
    assert truncated_cost(0.0, 0.0, 0.1) == pytest.approx(0.01)
    assert truncated_cost(1.0, 0.01, 0.1) < truncated_cost(0.9, 0.01, 0.1)
    assert truncated_cost(1.0, 0.01, 0.1) < truncated_cost(1.0, 0.02, 0.1)


def test_a_twin_must_fit_better_on_every_count():
    def fit(fitness, rmse):
        return StepResult("x", np.eye(4), fitness, rmse, np.zeros((0, 2), dtype=np.int64))

    # Measured on ModelNet40 (threshold 0.12): a noisy keyboard, truth against its twin ...
    assert fits_better(fit(1.0, 0.0167), fit(0.999, 0.0233), 0.12, 0.1)
    # ... and a cropped dresser: the twin covers more of the other crop, loosely.
    assert not fits_better(fit(0.859, 0.0365), fit(0.701, 0.0072), 0.12, 0.1)
    assert not fits_better(fit(1.0, 0.0230), fit(1.0, 0.0233), 0.12, 0.1)  # within margin
    assert not fits_better(fit(0.9, 0.001), fit(1.0, 0.0233), 0.12, 0.1)  # less coverage


@pytest.mark.parametrize("axis", [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
def test_a_near_symmetric_shape_registered_turned_over_is_put_right(axis):
    target = box_surface(2000, 1, knob=True)
    source = box_surface(2000, 2, knob=True)  # another sample of the same shape
    context = RegistrationContext(source, target)
    centre = np.eye(4)
    centre[:3, 3] = source.mean(0)
    wrong = centre @ half_turn(np.array(axis)) @ np.linalg.inv(centre)  # the "twin" answer
    # Steps work in the context's centred frame.
    result = SymmetryCheck().run(context, context.to_local(wrong))
    found = context.to_world(result.transformation)
    assert result.info["chosen_twin"] >= 0
    assert rotation_error_deg(found, np.eye(4)) < 2.0
    assert np.linalg.norm(found[:3, 3]) < 0.05
    assert len(result.info["costs"]) == 4
    assert min(result.info["costs"][1:]) < 0.9 * result.info["costs"][0]


def test_an_exactly_symmetric_shape_keeps_the_estimate():
    target = box_surface(2000, 1, knob=False)
    context = RegistrationContext(target.copy(), target)
    result = SymmetryCheck().run(context, np.eye(4))
    assert result.info["chosen_twin"] == -1
    np.testing.assert_array_equal(result.transformation, np.eye(4))
    assert result.fitness == pytest.approx(1.0)


def test_a_correct_estimate_is_kept_on_downsampled_clouds():
    # Large clouds: the twins are tried on the global step's clouds, the result is full.
    target = box_surface(6000, 3, knob=True)
    source = box_surface(6000, 4, knob=True)
    pipeline = RegistrationPipeline(
        [("refine", PointToPointICP()), ("symmetry", SymmetryCheck())], n_global_points=800
    )
    result = pipeline.register(source, target)
    assert result.steps[1].info["chosen_twin"] == -1
    np.testing.assert_array_equal(result.transformation, result.steps[0].transformation)
    turned = pipeline.register(source, target, init=half_turn(np.array([0, 0, 1.0])))
    assert turned.steps[1].info["chosen_twin"] >= 0
    assert rotation_error_deg(turned.transformation, np.eye(4)) < 2.0


def test_parameters_and_bad_values():
    step = SymmetryCheck(refine=PointToPointICP(max_iteration=5), margin=0.2)
    assert clone(step).get_params()["refine__max_iteration"] == 5
    step.set_params(refine__max_iteration=7, max_correspondence_distance=0.1)
    assert step.refine.max_iteration == 7 and step.max_correspondence_distance == 0.1
    context = RegistrationContext(box_surface(300, 0, False), box_surface(300, 1, False))
    for bad, match in [
        (dict(margin=1.5), "margin"),
        (dict(max_correspondence_distance=-1.0), "max_correspondence_distance"),
        (dict(refine=RANSACGlobal()), "refine"),
        (dict(refine=SymmetryCheck()), "refine"),
    ]:
        with pytest.raises(ValueError, match=match):
            SymmetryCheck(**bad).run(context, np.eye(4))


def test_register_chains_the_check_after_the_icp_it_copies():
    target = box_surface(2000, 1, knob=True)
    source = box_surface(2000, 2, knob=True)
    turned = half_turn(np.array([1.0, 0, 0]))
    plain = register(source, target, global_method=None, refine="point_to_plane", init=turned)
    assert rotation_error_deg(plain.transformation, np.eye(4)) > 170  # ICP alone stays turned
    checked = register(
        source,
        target,
        global_method=None,
        refine=["point_to_plane", "symmetry_check"],
        init=turned,
    )
    assert [s.name for s in checked.steps] == ["refine", "symmetry_check"]
    assert rotation_error_deg(checked.transformation, np.eye(4)) < 2.0
    assert checked.fitness > plain.fitness
