"""Correspondences, rigid fits, global steps, ICP chains and register() on known motions."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from conftest import random_motion
from sklearn.base import clone

from o3d_rpointhop import (
    FGRGlobal,
    FPFHTransformer,
    GeneralizedICP,
    MultiScaleICP,
    PointToPlaneICP,
    PointToPointICP,
    RANSACGlobal,
    RegistrationPipeline,
    RPointHopTransformer,
    SVDGlobal,
    find_correspondences,
    register,
    rigid_transform,
    to_open3d_feature,
)
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration.steps.fgr import tuple_test
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg, translation_error


def motion_matrix(rot, shift):
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = shift
    return t


def moved_copy(points, seed, translation_scale=0.5, permute=True):
    """Source = the target's points moved (and shuffled); truth maps source to target."""
    rot, shift = random_motion(seed, translation_scale)
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(points)) if permute else np.arange(len(points))
    source = points[order] @ rot.T + shift
    truth = np.linalg.inv(motion_matrix(rot, shift))
    return source, truth


@pytest.fixture(scope="module")
def model():
    return RPointHopTransformer(random_state=0).fit(
        [make_object(600, shape_seed=s) for s in range(8)]
    )


@pytest.fixture(scope="module")
def target():
    return make_object(800, shape_seed=321)


def assert_close_pose(estimate, truth, rot_deg, trans):
    assert rotation_error_deg(estimate, truth) < rot_deg
    assert translation_error(estimate, truth) < trans


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


# ----------------------------------------------------------------------------- correspondences
def test_nearest_and_mutual_matches():
    rng = np.random.default_rng(0)
    feats = rng.normal(size=(100, 16))
    perm = rng.permutation(100)
    corr = find_correspondences(feats[perm], feats)
    np.testing.assert_array_equal(corr.pairs[:, 1], perm)  # exact descriptors: exact matches
    np.testing.assert_array_equal(corr.pairs[:, 0], np.arange(100))
    np.testing.assert_allclose(corr.distances, 0.0, atol=1e-5)

    # A target with one extra near-duplicate: only one of the two can be mutual.
    tgt = np.r_[feats, feats[:1] + 1e-3]
    src = np.r_[feats, feats[:1] + 2e-3]
    mutual = find_correspondences(src, tgt, mutual_filter=True)
    assert len(mutual) == 100 and len(find_correspondences(src, tgt)) == 101


@pytest.mark.parametrize("n_refs, k", [(300, 1), (300, 2), (300, 3), (4, 2), (2, 2)])
def test_nearest_descriptors_are_the_exact_neighbours(n_refs, k):
    from scipy.spatial.distance import cdist

    from o3d_rpointhop.registration.correspondences import nearest_descriptors

    rng = np.random.default_rng(n_refs + k)
    refs = rng.normal(size=(n_refs, 24)).astype(np.float32)
    queries = np.r_[rng.normal(size=(150, 24)), refs[:5]].astype(np.float32)
    indices, distances = nearest_descriptors(queries, refs, k=k)
    exact = cdist(queries.astype(np.float64), refs.astype(np.float64))
    expected = np.sort(exact, axis=1)[:, :k]
    assert indices.shape == (len(queries), min(k, n_refs))
    np.testing.assert_allclose(distances, expected[:, : indices.shape[1]], atol=1e-5)
    np.testing.assert_allclose(
        np.take_along_axis(exact, indices, axis=1), distances, atol=1e-5
    )  # each index is at its distance


def test_ratio_and_top_k_filters_follow_the_paper():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(200, 8))
    tgt = src + rng.normal(scale=0.3, size=src.shape)
    full = find_correspondences(src, tgt)
    best = find_correspondences(src, tgt, top_k=50)
    assert len(best) == 50
    assert best.distances.max() <= np.sort(full.distances)[49] + 1e-12
    both = find_correspondences(src, tgt, top_k=50, top_k_ratio=20)
    assert len(both) == 20
    assert set(map(tuple, both.pairs)) <= set(map(tuple, best.pairs))
    assert both.ratios.max() <= np.sort(best.ratios)[19] + 1e-12
    thresholded = find_correspondences(src, tgt, max_distance=1.0, max_ratio=0.8)
    assert np.all(thresholded.distances <= 1.0) and np.all(thresholded.ratios <= 0.8)
    assert np.array_equal(np.asarray(full), full.pairs)
    assert len(full.to_open3d()) == 200


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(source_features=np.zeros((3, 4)), target_features=np.zeros((3, 5))), "differ"),
        (dict(source_features=np.full((3, 4), np.nan), target_features=np.zeros((3, 4))), "NaN"),
        (dict(source_features=np.zeros((0, 4)), target_features=np.zeros((3, 4))), "non-empty"),
        (dict(source_features=np.eye(3), target_features=np.eye(3), top_k=0), "top_k"),
        (dict(source_features=np.eye(3), target_features=np.eye(3), max_ratio=-1), "max_ratio"),
    ],
)
def test_correspondence_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        find_correspondences(**kwargs)


def test_open3d_feature_interop(model, target):
    feature = to_open3d_feature(model.transform(target))
    assert isinstance(feature, o3d.pipelines.registration.Feature)
    assert feature.data.shape == (model.n_features_out_, len(target))
    corr = find_correspondences(feature, feature)  # Features are accepted directly
    # every point finds a descriptor identical to its own (itself, or a point so close
    # that it pools the same neighbours in the same octants)
    np.testing.assert_array_equal(corr.distances, 0.0)
    with pytest.raises(ValueError, match="2-D"):
        to_open3d_feature(np.zeros(5))


# ----------------------------------------------------------------------------- global steps
def test_svd_is_exact_on_a_moved_copy(model, target):
    """The paper's protocol: same points, moved: the one-shot SVD is exact."""
    source, truth = moved_copy(target, 1)
    result = register(source, target, model, global_method="svd", refine=None)
    np.testing.assert_allclose(result.transformation, truth, atol=1e-8)
    assert result.steps[0].info["matches_used"] == round(0.125 * len(target))


@pytest.mark.parametrize("seed", [2, 3])
def test_ransac_recovers_any_rotation_exactly(model, target, seed):
    source, truth = moved_copy(target, seed, translation_scale=5.0)
    result = register(source, target, model, refine=None, seed=seed)
    np.testing.assert_allclose(result.transformation, truth, atol=1e-8)
    assert result.fitness == pytest.approx(1.0)


def test_ransac_through_open3d_feature_matching_agrees(model, target):
    """The descriptors drop into Open3D's own RANSAC pipeline."""
    reg = o3d.pipelines.registration
    source, truth = moved_copy(target, 4)
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target))
    o3d.utility.random.seed(0)
    result = reg.registration_ransac_based_on_feature_matching(
        src,
        tgt,
        to_open3d_feature(model.transform(source)),
        to_open3d_feature(model.transform(target)),
        True,
        0.05,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [],
        reg.RANSACConvergenceCriteria(100000, 0.999),
    )
    assert_close_pose(np.asarray(result.transformation), truth, 1e-4, 1e-6)


def test_fgr_recovers_a_moved_copy(model, target):
    source, truth = moved_copy(target, 5)
    result = register(source, target, model, global_method="fgr", refine=None)
    assert_close_pose(result.transformation, truth, 1.0, 0.01)
    assert result.steps[0].info["after_tuple_test"] <= result.steps[0].info["candidate_matches"]


def test_tuple_test_drops_inconsistent_matches():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(60, 3))
    pairs = np.c_[np.arange(60), np.arange(60)]
    pairs[:20, 1] = rng.permutation(20) + 40  # 20 wrong matches (to scrambled points)
    kept = tuple_test(pts, pts, pairs, seed=0)
    good = kept[:, 0] == kept[:, 1]
    # every right match survives; a wrong one survives only if a random triple happens
    # to be length-consistent, which is rarer: FGR's test thins outliers, it is no oracle
    assert good.sum() == 40 and (~good).sum() <= 12


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
def test_icp_steps_converge_from_a_nearby_start(target, step):
    source, truth = moved_copy(target, 6, permute=False)
    nudge = np.eye(4)
    nudge[:3, :3] = random_motion(7)[0]  # any rotation...
    angle = np.radians(4.0)  # ... shrunk to 4 degrees
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    from scipy.spatial.transform import Rotation

    nudge[:3, :3] = Rotation.from_rotvec(axis * angle).as_matrix()
    nudge[:3, 3] = [0.01, -0.02, 0.015]
    result = register(source, target, global_method=None, refine=step, init=nudge @ truth)
    assert_close_pose(result.transformation, truth, 0.05, 1e-3)


def test_multiscale_pulls_in_a_poor_start(target):
    source, truth = moved_copy(target, 8, permute=False)
    from scipy.spatial.transform import Rotation

    start = np.eye(4)
    start[:3, :3] = Rotation.from_rotvec([0.0, 0.0, np.radians(45)]).as_matrix()
    start = start @ truth
    plain = register(source, target, global_method=None, refine="point_to_point", init=start)
    multi = register(
        source, target, global_method=None, refine=MultiScaleICP(scales=(8, 4, 1)), init=start
    )
    assert rotation_error_deg(multi.transformation, truth) < 0.1
    assert rotation_error_deg(plain.transformation, truth) > 10  # one scale gets stuck


def test_point_to_point_has_no_kernel_and_bad_kernels_are_named(target):
    with pytest.raises(ValueError, match="step 'refine': The 'kernel' parameter of PointToPlane"):
        register(target, target, global_method=None, refine=PointToPlaneICP(kernel="fancy"))


# ----------------------------------------------------------------------------- register()
def test_realistic_pair_global_then_icp(model):
    """Two different samples of one object, rotated apart over SO(3)."""
    target = make_object(1024, shape_seed=700, sample_seed=1)
    truth_points = make_object(1024, shape_seed=700, sample_seed=2)
    rot, shift = random_motion(11)
    source = truth_points @ rot.T + shift
    truth = np.linalg.inv(motion_matrix(rot, shift))
    result = register(source, target, model)
    assert_close_pose(result.transformation, truth, 2.0, 0.02)
    assert [s.name for s in result.steps] == ["global", "refine"]
    # One fitness, Open3D's: the last step's, at its correspondence distance (half the
    # resolution: two different samples of a surface meet at that distance only in part).
    assert result.distance == result.steps[-1].distance == pytest.approx(0.5 * result.voxel_size)
    assert result.fitness == pytest.approx(result.steps[-1].fitness)
    assert result.fitness > 0.1 and 0 < result.inlier_rmse < result.distance
    assert result.converged and not result.ambiguous
    assert result.correspondence_set.shape[1] == 2 and len(result.correspondence_set) > 100
    summary = result.as_dict()
    assert summary["steps"][0]["name"] == "global" and len(summary["transformation"]) == 4


def test_register_is_repeatable_and_leaves_inputs_alone(model):
    target = make_object(900, shape_seed=701, sample_seed=1)
    source = make_object(900, shape_seed=701, sample_seed=2) @ random_motion(12)[0].T
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source))
    before = np.asarray(pcd.points).copy()
    a = register(pcd, target, model, seed=3)
    b = register(source, o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target)), model, seed=3)
    np.testing.assert_array_equal(a.transformation, b.transformation)
    np.testing.assert_array_equal(np.asarray(pcd.points), before)
    assert not pcd.has_normals()


def test_metric_scale_and_downsampling(model):
    """The same registration in millimetres, with 10x the points: the global step
    downsamples, the thresholds follow the resolution."""
    dense = make_object(10000, shape_seed=702, sample_seed=1) * 1000.0
    source_true = make_object(10000, shape_seed=702, sample_seed=2) * 1000.0
    rot, shift = random_motion(13, translation_scale=500.0)
    truth = np.linalg.inv(motion_matrix(rot, shift))
    result = register(source_true @ rot.T + shift, dense, model, n_global_points=1024)
    assert_close_pose(result.transformation, truth, 2.0, 5.0)
    assert 10.0 < result.voxel_size < 100.0  # millimetres, well above the spacing


def test_fpfh_descriptor_goes_through_the_same_pipeline(target):
    source, truth = moved_copy(target, 9)
    result = register(source, target, FPFHTransformer(radius="auto", normal_radius="auto"))
    assert_close_pose(result.transformation, truth, 0.5, 0.01)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(global_method="teaser"), "'global_method' parameter of register must be"),
        (dict(refine="icp"), "'refine' parameter of register must be"),
        (dict(refine=["point_to_plane", "icp"]), "refine must hold names of"),
        (dict(global_method=None, refine=None), "nothing to do"),
        (dict(voxel_size=-1.0), "'voxel_size' parameter .* range"),
        (dict(voxel_size="fine"), "'voxel_size' parameter .* among {'auto'}"),
        (dict(global_method=None, init=np.eye(3)), "4x4"),
        (dict(global_method=None, init=np.diag([1.0, 1.0, -1.0, 1.0])), "rotation"),
    ],
)
def test_register_bad_arguments(model, target, kwargs, message):
    with pytest.raises(ValueError, match=message):
        register(target, target, model, **kwargs)


def test_register_bad_clouds(model, target):
    with pytest.raises(ValueError, match="source has 1 point"):
        register(np.r_[target[:1] * np.nan], target, model)
    with pytest.raises(ValueError, match="cannot describe the source cloud, 50 points.*too few"):
        register(target[:50], target[:50], model)


def test_pipeline_params_clone_and_validation(model):
    pipe = RegistrationPipeline(
        [("global", RANSACGlobal(max_iteration=1000)), ("icp", PointToPlaneICP())], seed=4
    )
    params = pipe.get_params()
    assert params["global__max_iteration"] == 1000 and params["seed"] == 4
    pipe.set_params(global__max_iteration=5000, icp__kernel="huber", seed=5)
    assert pipe.named_steps["global"].max_iteration == 5000
    assert pipe.named_steps["icp"].kernel == "huber" and pipe.seed == 5
    pipe.set_params(icp=PointToPointICP())
    assert isinstance(pipe.named_steps["icp"], PointToPointICP)
    copy = clone(pipe)
    assert copy.get_params()["global__max_iteration"] == 5000
    assert copy.named_steps["global"] is not pipe.named_steps["global"]
    with pytest.raises(ValueError, match="no step named"):
        pipe.set_params(nope__x=1)
    with pytest.raises(ValueError, match="RegistrationStep"):
        RegistrationPipeline([("a", "ransac")]).register(np.eye(3), np.eye(3))
    with pytest.raises(ValueError, match="unique"):
        RegistrationPipeline([("a", SVDGlobal()), ("a", SVDGlobal())]).register(
            np.eye(3), np.eye(3)
        )
    source, truth = moved_copy(make_object(700, shape_seed=5), 10)
    result = RegistrationPipeline(
        [("global", SVDGlobal()), ("icp", PointToPlaneICP()), ("fine", FGRGlobal())],
        descriptor=model,
    ).register(source, make_object(700, shape_seed=5))
    assert [s.name for s in result.steps] == ["global", "icp", "fine"]
    assert_close_pose(result.transformation, truth, 1.0, 0.01)


def test_unmoved_input_is_applied_by_apply_transform(target):
    t = motion_matrix(*random_motion(1))
    np.testing.assert_allclose(apply_transform(target, t), target @ t[:3, :3].T + t[:3, 3])


def test_documented_open3d_recipes_run_silently_and_register(capfd):
    """The two code blocks of docs/registration.md's Open3D section, as written."""
    import re
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "registration.md").read_text()
    section = doc[doc.index("## Inside Open3D's own pipeline") : doc.index("## Command line")]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert len(blocks) == 2
    scope: dict = {}
    capfd.readouterr()
    exec(compile(blocks[0], "registration.md", "exec"), scope)
    first = np.asarray(scope["result"].transformation)
    printed = capfd.readouterr().out
    exec(compile(blocks[1], "registration.md", "exec"), scope)
    second = np.asarray(scope["result"].transformation)
    out, err = capfd.readouterr()
    assert "WARNING" not in printed + out + err and err == ""
    truth = np.eye(4)
    truth[:3, :3] = np.diag([1.0, -1.0, -1.0])
    truth[:3, 3] = [-0.3, 0.3, 0.3]
    # The first recipe ends with ICP; the second is a global estimate on 0.05-voxel
    # clouds (Open3D's RANSAC runs on several threads, so it varies from run to run).
    assert rotation_error_deg(first, truth) < 2.0
    assert np.linalg.norm(first[:3, 3] - truth[:3, 3]) < 0.02
    assert rotation_error_deg(second, truth) < 20.0
    assert np.linalg.norm(second[:3, 3] - truth[:3, 3]) < 0.15


def test_result_becomes_an_open3d_result(model, target):
    source, truth = moved_copy(target, 6)
    result = register(source, target, model)
    o3d_result = result.to_open3d()
    assert isinstance(o3d_result, o3d.pipelines.registration.RegistrationResult)
    np.testing.assert_array_equal(np.asarray(o3d_result.transformation), result.transformation)
    assert o3d_result.fitness == pytest.approx(result.fitness)
    assert o3d_result.inlier_rmse == pytest.approx(result.inlier_rmse)
    np.testing.assert_array_equal(
        np.asarray(o3d_result.correspondence_set), result.correspondence_set
    )
    assert len(result.correspondence_set) > 0


def test_import_works_under_python_OO():
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-OO", "-c", "import o3d_rpointhop; print('ok')"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


def test_global_points_are_what_register_describes():
    from o3d_rpointhop.registration.context import global_points

    small = make_object(1500, shape_seed=3) + 1000.0
    np.testing.assert_allclose(global_points(small), small, atol=1e-9)  # used as it is
    big = make_object(20000, shape_seed=3) + 1000.0
    down = global_points(big)
    assert 1500 < len(down) <= 1.15 * 2048  # about n_global_points
    # In the cloud's own coordinates: every kept point is a voxel mean, next to the cloud.
    from scipy.spatial import cKDTree

    assert cKDTree(big).query(down)[0].max() < 0.1
