"""register() and RegistrationPipeline: chains, repeatability, results, arguments."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from helpers import assert_close_pose, motion_matrix, moved_copy, random_motion
from sklearn.base import clone

from o3d_rpointhop import (
    FGRGlobal,
    FPFHTransformer,
    PointToPlaneICP,
    PointToPointICP,
    RANSACGlobal,
    RegistrationPipeline,
    SVDGlobal,
    register,
)
from o3d_rpointhop.datasets import make_object


# ----------------------------------------------------------------------------- register()
def test_realistic_pair_global_then_icp(object_model):
    """Two different samples of one object, rotated apart over SO(3)."""
    target = make_object(1024, shape_seed=700, sample_seed=1)
    truth_points = make_object(1024, shape_seed=700, sample_seed=2)
    rot, shift = random_motion(11)
    source = truth_points @ rot.T + shift
    truth = np.linalg.inv(motion_matrix(rot, shift))
    result = register(source, target, object_model)
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


def test_register_is_repeatable_and_leaves_inputs_alone(object_model):
    target = make_object(900, shape_seed=701, sample_seed=1)
    source = make_object(900, shape_seed=701, sample_seed=2) @ random_motion(12)[0].T
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source))
    before = np.asarray(pcd.points).copy()
    a = register(pcd, target, object_model, random_state=3)
    b = register(
        source,
        o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target)),
        object_model,
        random_state=3,
    )
    np.testing.assert_array_equal(a.transformation, b.transformation)
    np.testing.assert_array_equal(np.asarray(pcd.points), before)
    assert not pcd.has_normals()


def test_metric_scale_and_downsampling(object_model):
    """The same registration in millimetres, with 10x the points: the global step
    downsamples, the thresholds follow the resolution."""
    dense = make_object(10000, shape_seed=702, sample_seed=1) * 1000.0
    source_true = make_object(10000, shape_seed=702, sample_seed=2) * 1000.0
    rot, shift = random_motion(13, translation_scale=500.0)
    truth = np.linalg.inv(motion_matrix(rot, shift))
    result = register(source_true @ rot.T + shift, dense, object_model, n_global_points=1024)
    assert_close_pose(result.transformation, truth, 2.0, 5.0)
    assert 10.0 < result.voxel_size < 100.0  # millimetres, well above the spacing


def test_fpfh_descriptor_goes_through_the_same_pipeline(object_target):
    source, truth = moved_copy(object_target, 9)
    result = register(source, object_target, FPFHTransformer())
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
def test_register_bad_arguments(object_model, object_target, kwargs, message):
    with pytest.raises(ValueError, match=message):
        register(object_target, object_target, object_model, **kwargs)


def test_register_bad_clouds(object_model, object_target):
    with pytest.raises(ValueError, match="source has 1 point"):
        register(np.r_[object_target[:1] * np.nan], object_target, object_model)
    with pytest.raises(ValueError, match="cannot describe the source cloud, 50 points.*too few"):
        register(object_target[:50], object_target[:50], object_model)


def test_pipeline_params_clone_and_validation(object_model):
    pipe = RegistrationPipeline(
        [("global", RANSACGlobal(max_iteration=1000)), ("icp", PointToPlaneICP())], random_state=4
    )
    params = pipe.get_params()
    assert params["global__max_iteration"] == 1000 and params["random_state"] == 4
    pipe.set_params(global__max_iteration=5000, icp__kernel="huber", random_state=5)
    assert pipe.named_steps["global"].max_iteration == 5000
    assert pipe.named_steps["icp"].kernel == "huber" and pipe.random_state == 5
    pipe.set_params(icp=PointToPointICP())
    assert isinstance(pipe.named_steps["icp"], PointToPointICP)
    copy = clone(pipe)
    assert copy.get_params()["global__max_iteration"] == 5000
    assert copy.named_steps["global"] is not pipe.named_steps["global"]
    with pytest.raises(ValueError, match="no step named"):
        pipe.set_params(nope__x=1)
    with pytest.raises(ValueError, match="RegistrationStep"):
        RegistrationPipeline([("a", "ransac")]).register(np.eye(3), np.eye(3))
    with pytest.raises(ValueError, match="non-empty list of"):
        RegistrationPipeline([]).register(np.eye(3), np.eye(3))
    with pytest.raises(ValueError, match=r"each step must be a \(name, step\) pair"):
        RegistrationPipeline([("a", SVDGlobal(), 3)]).register(np.eye(3), np.eye(3))
    with pytest.raises(ValueError, match="unique"):
        RegistrationPipeline([("a", SVDGlobal()), ("a", SVDGlobal())]).register(
            np.eye(3), np.eye(3)
        )
    source, truth = moved_copy(make_object(700, shape_seed=5), 10)
    result = RegistrationPipeline(
        [("global", SVDGlobal()), ("icp", PointToPlaneICP()), ("fine", FGRGlobal())],
        descriptor=object_model,
    ).register(source, make_object(700, shape_seed=5))
    assert [s.name for s in result.steps] == ["global", "icp", "fine"]
    assert_close_pose(result.transformation, truth, 1.0, 0.01)


def test_result_becomes_an_open3d_result(object_model, object_target):
    source, truth = moved_copy(object_target, 6)
    result = register(source, object_target, object_model)
    o3d_result = result.to_open3d()
    assert isinstance(o3d_result, o3d.pipelines.registration.RegistrationResult)
    np.testing.assert_array_equal(np.asarray(o3d_result.transformation), result.transformation)
    assert o3d_result.fitness == pytest.approx(result.fitness)
    assert o3d_result.inlier_rmse == pytest.approx(result.inlier_rmse)
    np.testing.assert_array_equal(
        np.asarray(o3d_result.correspondence_set), result.correspondence_set
    )
    assert len(result.correspondence_set) > 0


def test_build_chain_is_the_one_way_names_become_steps():
    """Names, params by name, the twins' copy of the refinement before them, steps
    given as objects used as given, and the errors."""
    from o3d_rpointhop.registration import PointToPlaneICP, RANSACGlobal, SymmetryCheck
    from o3d_rpointhop.registration.pipeline import build_chain

    chain = build_chain(
        "ransac",
        ["point_to_point", "point_to_plane", "symmetry_check"],
        params={"ransac": {"max_iteration": 500}, "point_to_plane": {"max_iteration": 7}},
    )
    assert [name for name, _ in chain] == ["global", "refine", "refine1", "symmetry_check"]
    assert isinstance(chain[0][1], RANSACGlobal) and chain[0][1].max_iteration == 500
    twin = chain[3][1]
    assert isinstance(twin, SymmetryCheck) and twin.refine.max_iteration == 7
    assert twin.refine is not chain[2][1]  # a copy
    given = PointToPlaneICP()
    assert build_chain(None, [given]) == [("refine", given)]
    with pytest.raises(ValueError, match="nothing to do"):
        build_chain(None, None)
    with pytest.raises(ValueError, match="global_method 'magic'"):
        build_chain("magic")


def test_the_scene_models_consensus_asks_fpfh_as_a_fallback():
    """``"auto"`` for a model that states the consensus is the consensus with FPFH as a
    fallback (``FPFH_FALLBACK``), with the consensus's own matcher first; the consensus
    named, or multiway's screening (``fpfh_fallback=False``), is the model alone."""
    from o3d_rpointhop import ConsensusGlobal, PooledMatcher, RPointHopTransformer
    from o3d_rpointhop.registration.pipeline import build_chain

    scene = RPointHopTransformer.pretrained("scene")
    step = build_chain("auto", None, scene)[0][1]
    assert isinstance(step, ConsensusGlobal) and isinstance(step.matcher, PooledMatcher)
    assert step.matcher.combine == "fallback"
    assert [name for name, _, _ in step.matcher.parts] == ["model", "fpfh"]
    assert step.matcher.parts[0][2].get_params() == ConsensusGlobal.default_matcher().get_params()
    assert build_chain("consensus", None, scene)[0][1].matcher is None
    assert build_chain("auto", None, scene, fpfh_fallback=False)[0][1].matcher is None
    assert (
        build_chain("auto", None, RPointHopTransformer.pretrained("object"))[0][1].name == "ransac"
    )


def test_every_step_has_one_name():
    """A step's ``name`` is its key in the pipeline's tables and its section in a config
    file; a global step run alone reports it."""
    from o3d_rpointhop.cli._config import default_config
    from o3d_rpointhop.datasets import make_object
    from o3d_rpointhop.registration import RegistrationContext
    from o3d_rpointhop.registration.pipeline import GLOBAL_METHODS, REFINE_METHODS

    sections = default_config()
    for name, step in {**GLOBAL_METHODS, **REFINE_METHODS}.items():
        assert step.name == name and name in sections
    cloud = make_object(800, shape_seed=3)
    context = RegistrationContext(cloud + [0.1, 0.0, 0.0], cloud)
    for name in ("ransac", "svd"):
        assert GLOBAL_METHODS[name]().run(context, np.eye(4)).name == name


def test_seed_is_the_former_name_of_random_state(object_model):
    """``seed`` still works, with a FutureWarning, and gives what ``random_state`` gives."""
    from o3d_rpointhop import register_multiway

    cloud = make_object(800, shape_seed=3)
    moved = cloud @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]).T + 0.2
    with pytest.warns(FutureWarning, match="random_state"):
        old = register(moved, cloud, object_model, seed=3)
    new = register(moved, cloud, object_model, random_state=3)
    np.testing.assert_array_equal(old.transformation, new.transformation)
    pipe = RegistrationPipeline([("global", RANSACGlobal())], descriptor=object_model, seed=3)
    with pytest.warns(FutureWarning, match="RegistrationPipeline"):
        piped = pipe.register(moved, cloud)
    assert piped.steps[0].transformation.shape == (4, 4)
    with pytest.warns(FutureWarning, match="register_multiway"):
        register_multiway([cloud, moved], object_model, seed=3)


def test_n_jobs_is_the_cores_of_the_whole_registration(object_model):
    """``register(n_jobs=1)`` runs the kernels and Open3D on one core, gives the same
    bytes as every core, and leaves Open3D's thread count as it found it."""
    import open3d as o3d
    from threadpoolctl import threadpool_info

    from o3d_rpointhop._utils.threads import core_budget, kernel_threads

    def blas() -> list[int]:
        return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]

    before = o3d.utility.get_max_threads()
    blas_before = blas()
    with core_budget(1):
        assert kernel_threads(None) == 1
        assert o3d.utility.get_max_threads() == 1
        assert blas() and set(blas()) == {1}  # the matches' products too
    assert o3d.utility.get_max_threads() == before
    assert blas() == blas_before
    cloud = make_object(800, shape_seed=3)
    moved = cloud @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]).T + 0.2
    one = register(moved, cloud, object_model, global_method="consensus", n_jobs=1)
    every = register(moved, cloud, object_model, global_method="consensus")
    np.testing.assert_array_equal(one.transformation, every.transformation)
    assert o3d.utility.get_max_threads() == before
    with pytest.raises(ValueError, match="n_jobs"):
        register(moved, cloud, object_model, n_jobs=1.5)
