"""ICP refinements."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from helpers import assert_close_pose, moved_copy, random_motion
from scipy.spatial.transform import Rotation

from o3d_rpointhop import (
    GeneralizedICP,
    MultiScaleICP,
    PointToPlaneICP,
    PointToPointICP,
    register,
)
from o3d_rpointhop.datasets.synthetic import make_object
from o3d_rpointhop.transforms import rotation_error_deg


# ----------------------------------------------------------------------------- refinement
@pytest.mark.parametrize(
    "step",
    [
        PointToPointICP(),
        PointToPlaneICP(),
        PointToPlaneICP(kernel="tukey"),
        GeneralizedICP(),
        MultiScaleICP(),
    ],
    ids=["point_to_point", "point_to_plane", "point_to_plane_tukey", "generalized", "multiscale"],
)
def test_icp_steps_converge_from_a_nearby_start(object_target, step):
    source, truth = moved_copy(object_target, 6, permute=False)
    nudge = np.eye(4)
    nudge[:3, :3] = random_motion(7)[0]  # any rotation...
    angle = np.radians(4.0)  # ... shrunk to 4 degrees
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    from scipy.spatial.transform import Rotation

    nudge[:3, :3] = Rotation.from_rotvec(axis * angle).as_matrix()
    nudge[:3, 3] = [0.01, -0.02, 0.015]
    result = register(source, object_target, global_method=None, refine=step, init=nudge @ truth)
    assert_close_pose(result.transformation, truth, 0.05, 1e-3)


def test_multiscale_pulls_in_a_poor_start(object_target):
    source, truth = moved_copy(object_target, 8, permute=False)
    from scipy.spatial.transform import Rotation

    start = np.eye(4)
    start[:3, :3] = Rotation.from_rotvec([0.0, 0.0, np.radians(45)]).as_matrix()
    start = start @ truth
    plain = register(source, object_target, global_method=None, refine="point_to_point", init=start)
    multi = register(
        source,
        object_target,
        global_method=None,
        refine=MultiScaleICP(scales=(8, 4, 1)),
        init=start,
    )
    assert rotation_error_deg(multi.transformation, truth) < 0.1
    assert rotation_error_deg(plain.transformation, truth) > 10  # one scale gets stuck


def test_point_to_point_has_no_kernel_and_bad_kernels_are_named(object_target):
    from o3d_rpointhop import PointToPointICP

    assert "kernel" not in PointToPointICP().get_params()
    with pytest.raises(TypeError, match="kernel"):
        PointToPointICP(kernel="huber")
    source, truth = moved_copy(object_target, 2, permute=False)
    start = truth.copy()
    start[:3, 3] += [0.005, 0.0, 0.0]
    plain = register(
        source, object_target, global_method=None, refine=PointToPointICP(), init=start
    )
    assert np.abs(plain.transformation - truth).max() < 1e-4  # it runs, and converges
    with pytest.raises(ValueError, match="step 'refine': The 'kernel' parameter of PointToPlane"):
        register(
            object_target, object_target, global_method=None, refine=PointToPlaneICP(kernel="fancy")
        )
    bad_steps = [
        (PointToPlaneICP(max_correspondence_distance=[]), "non-empty sequence of positive"),
        (PointToPlaneICP(max_correspondence_distance=[0.1, -1]), "got \\[0.1, -1\\]"),
        (MultiScaleICP(scales=(2, 1), max_iteration=(10,)), "non-empty and as long"),
    ]
    for step, message in bad_steps:
        with pytest.raises(ValueError, match=message):
            register(object_target, object_target, global_method=None, refine=step)


# ----------------------------------------------------------------------------- coverage guard
def test_a_narrower_pass_that_loses_coverage_is_undone(object_target, monkeypatch):
    """The fine pass is replaced by one that walks away; the coarse result must stand,
    reported at the coarse distance."""
    source, truth = moved_copy(object_target, 6, permute=False)
    start = truth.copy()
    start[:3, 3] += [0.01, 0.0, 0.0]
    step = PointToPlaneICP()
    solve = PointToPlaneICP._solve
    calls = []

    def wander(self, context, which, distance, init):
        result = solve(self, context, which, distance, init)
        calls.append(distance)
        if len(calls) == 2:  # the fine pass: half a unit off
            away = np.array(result.transformation)
            away[:3, 3] += [0.5, 0.0, 0.0]
            result.transformation = away
        return result

    monkeypatch.setattr(PointToPlaneICP, "_solve", wander)
    result = register(source, object_target, global_method=None, refine=step, init=start)
    assert result.steps[0].info["passes_undone"] == [1]
    assert_close_pose(result.transformation, truth, 0.05, 1e-3)
    assert result.steps[0].distance == calls[0]  # where the kept result was found
    assert result.fitness > 0.9


@pytest.mark.filterwarnings("ignore::o3d_rpointhop.RegistrationWarning")
def test_the_coverage_guard_reads_the_global_clouds_of_downsampled_pairs(monkeypatch):
    """On clouds downsampled for the global step the guard counts coverage there (no
    search of the whole clouds but the flags'); an undone pass is still reported on the
    whole clouds, at the coarse distance."""
    from o3d_rpointhop.registration.context import RegistrationContext

    cloud = make_object(6000, shape_seed=2)
    source, truth = moved_copy(cloud, 6, permute=False)
    solve, evaluate = PointToPlaneICP._solve, RegistrationContext.evaluate
    calls, levels = [], []

    def wander(self, context, which, distance, init):
        result = solve(self, context, which, distance, init)
        calls.append(distance)
        if len(calls) == 2:  # the fine pass, on the whole clouds: half a unit off
            away = np.array(result.transformation)
            away[:3, 3] += [0.5, 0.0, 0.0]
            result.transformation = away
        return result

    def spy(self, transformation, distance, which="full"):
        levels.append(which)
        return evaluate(self, transformation, distance, which)

    monkeypatch.setattr(PointToPlaneICP, "_solve", wander)
    monkeypatch.setattr(RegistrationContext, "evaluate", spy)
    result = register(
        source, cloud, global_method=None, refine="point_to_plane", init=truth, n_global_points=1500
    )
    step = result.steps[0]
    assert step.info["passes_undone"] == [1]
    assert levels[:2] == ["global", "global"]  # the guard's before and after
    assert step.distance == calls[0]
    clouds = [o3d.geometry.PointCloud(o3d.utility.Vector3dVector(c)) for c in (source, cloud)]
    whole = o3d.pipelines.registration.evaluate_registration(
        *clouds, calls[0], result.transformation
    )
    assert step.fitness == pytest.approx(whole.fitness, abs=1e-3)


def test_passes_that_keep_coverage_are_kept(object_target):
    source, truth = moved_copy(object_target, 6, permute=False)
    result = register(
        source, object_target, global_method=None, refine="point_to_plane", init=truth
    )
    assert result.steps[0].info["passes_undone"] == []


# ----------------------------------------------------------------------------- resolution
@pytest.mark.parametrize("step_class", [PointToPointICP, PointToPlaneICP, GeneralizedICP])
def test_full_resolution_false_keeps_every_pass_on_the_global_clouds(
    object_target, step_class, monkeypatch
):
    dense = np.repeat(object_target, 3, axis=0) + np.random.default_rng(3).normal(
        scale=1e-3, size=(3 * len(object_target), 3)
    )  # dense enough to be downsampled for the global step
    source, truth = moved_copy(dense, 6, permute=False)
    solve = step_class._solve
    seen = []

    def spy(self, context, which, distance, init):
        seen.append((which, len(context.clouds(which)[0].points)))
        return solve(self, context, which, distance, init)

    monkeypatch.setattr(step_class, "_solve", spy)
    kept = register(source, dense, global_method=None, refine=step_class(), init=truth)
    assert [w for w, _ in seen] == ["global", "full"]
    assert seen[0][1] < seen[1][1] == len(source)
    seen.clear()
    coarse = register(
        source,
        dense,
        global_method=None,
        refine=step_class(full_resolution=False),
        init=truth,
        n_global_points=1024,
    )
    assert [w for w, _ in seen] == ["global", "global"] and seen[0][1] < len(source)
    assert_close_pose(coarse.transformation, truth, 0.5, 0.02)
    assert_close_pose(kept.transformation, truth, 0.05, 1e-3)
    with pytest.raises(ValueError, match="'full_resolution' parameter"):
        register(source, dense, global_method=None, refine=step_class(full_resolution="no"))


@pytest.mark.parametrize("step", [PointToPlaneICP, GeneralizedICP, MultiScaleICP])
def test_the_l1_kernel_registers_clouds_that_share_points(step):
    # Two crops of one cloud: at the truth some residuals are exactly zero, where
    # Open3D's L1Loss weighs by 1 / 0 and answers NaN.
    cloud = make_object(2000, shape_seed=1)
    source, target = cloud[:1500], cloud[500:]
    aligned = register(source, target, global_method=None, refine=step(kernel="l1"))
    np.testing.assert_allclose(aligned.transformation, np.eye(4), atol=1e-6)
    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_rotvec(np.radians(4.0) * np.array([0.0, 0.6, 0.8])).as_matrix()
    truth[:3, 3] = [0.01, -0.02, 0.015]
    moved = (source - truth[:3, 3]) @ truth[:3, :3]  # truth carries it back onto target
    result = register(moved, target, global_method=None, refine=step(kernel="l1"))
    assert_close_pose(result.transformation, truth, 0.05, 1e-3)
