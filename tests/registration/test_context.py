"""The registration context: the clouds the global step sees."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from helpers import CodesBySize

from o3d_rpointhop import register
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration import RegistrationContext
from o3d_rpointhop.registration.prepared import estimate_normals


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


def test_prepared_clouds_and_features_register_like_computed_ones(pretrained32):
    from o3d_rpointhop import PointToPlaneICP, RANSACGlobal, RegistrationPipeline
    from o3d_rpointhop.registration import RegistrationContext
    from o3d_rpointhop.registration.prepared import PreparedCloud

    target = make_object(3000, shape_seed=8, sample_seed=1)
    source = make_object(3000, shape_seed=8, sample_seed=2)[::-1] @ np.diag([1, -1, -1.0]) + 0.2
    pipeline = RegistrationPipeline(
        [("global", RANSACGlobal()), ("icp", PointToPlaneICP())], descriptor=pretrained32
    )
    plain = pipeline.register(source, target)
    computed = RegistrationContext(source, target, descriptor=pretrained32)
    assert computed.downsampled
    prepared = [
        PreparedCloud(
            np.asarray(computed.global_cloud(w).points) + computed.origin,
            computed.features(pretrained32, w),
        )
        for w in ("source", "target")
    ]
    # No descriptor at all: the prepared descriptors are the context's own, and nothing
    # is described again (the default model is never loaded).
    context = RegistrationContext(source, target, voxel_size=computed.voxel_size, prepared=prepared)
    result = RegistrationPipeline([("global", RANSACGlobal()), ("icp", PointToPlaneICP())]).run(
        context
    )
    assert context.descriptor is None
    np.testing.assert_allclose(result.transformation, plain.transformation, atol=1e-9)
    assert result.voxel_size == plain.voxel_size
    with pytest.raises(ValueError, match="one row per point"):
        PreparedCloud(prepared[0].points, prepared[0].features[:5])
    with pytest.raises(ValueError, match=r"prepared points must be \(n, 3\), got \(5, 2\)"):
        PreparedCloud(np.zeros((5, 2)))
    with pytest.raises(ValueError, match=r"normals must be one per point: \(4, 3\) for 5"):
        PreparedCloud(np.zeros((5, 3)), normals=np.zeros((4, 3)))
    with pytest.raises(TypeError, match="PreparedCloud"):
        RegistrationContext(source, target, prepared=(prepared[0].points, prepared[1]))


def test_prepared_clouds_without_features_are_described_by_the_context(pretrained32):
    from o3d_rpointhop.registration import RegistrationContext
    from o3d_rpointhop.registration.prepared import prepare_cloud

    cloud = make_object(3000, shape_seed=8)
    prepared = prepare_cloud(cloud, 0.05)
    assert prepared.features is None and len(prepared.points) < len(cloud)
    context = RegistrationContext(
        cloud, cloud, descriptor=pretrained32, prepared=(prepared, prepared)
    )
    np.testing.assert_allclose(
        context.features(None, "source"), pretrained32.transform(prepared.points), atol=1e-6
    )
    # "auto": the prepared clouds' own spacing, about the voxel they were prepared at.
    assert 0.5 * 0.05 < context.voxel_size < 1.5 * 0.05


def test_a_prepared_scan_is_described_as_a_pair_describes_it():
    """prepare_cloud (scan sets) and the context (pairs) describe by one route: FPFH's
    radii are the registration's multiples of the resolution in both, so a scan
    prepared once carries the features a pair's context computes for the same cloud."""
    from o3d_rpointhop import FPFHTransformer
    from o3d_rpointhop.registration import RegistrationSettings
    from o3d_rpointhop.registration.context import RegistrationContext
    from o3d_rpointhop.registration.prepared import PreparedCloud, prepare_cloud

    cloud = make_object(4000, shape_seed=2)
    voxel = 0.08  # coarser than the samples' spacing: FPFH's own "auto" would differ
    settings = RegistrationSettings().at(voxel)
    prepared = prepare_cloud(cloud, voxel, FPFHTransformer(), settings=settings)
    bare = PreparedCloud(prepared.points)
    context = RegistrationContext(
        cloud, cloud, voxel_size=voxel, prepared=(bare, bare), settings=RegistrationSettings()
    )
    # The context centres the clouds, which moves Open3D's normals by rounding and a
    # few histogram counts with them: the same up to that (median difference 0).
    paired = np.abs(prepared.features - context.features(FPFHTransformer(), "source"))
    assert np.median(paired) == 0.0 and paired.mean() < 0.1
    # FPFH's own "auto" radii (from the prepared cloud's spacing) describe otherwise.
    own = np.abs(prepared.features - FPFHTransformer().transform(prepared.points))
    assert np.median(own) > 1.0 and own.mean() > 1.0


class _Counting:
    """A descriptor that counts the clouds it describes."""

    def __init__(self, inner):
        self.inner, self.calls = inner, 0

    def transform(self, X):
        self.calls += 1
        return self.inner.transform(X)


def test_preparation_is_the_pipelines_first_stage(pretrained32):
    """Both clouds are prepared and described once, before the first step, for every
    global step that shares the descriptor; a chain without a global step prepares
    nothing. The result says what the preparation cost."""
    from o3d_rpointhop import PointToPlaneICP, RANSACGlobal, RegistrationPipeline, SVDGlobal
    from o3d_rpointhop.registration import RegistrationContext

    target = make_object(3000, shape_seed=8, sample_seed=1)
    source = make_object(3000, shape_seed=8, sample_seed=2) + 0.1
    counting = _Counting(pretrained32)
    seen = {}

    class Looking(SVDGlobal):
        def _run(self, context, transformation):
            seen["features"] = sorted(context._features)  # what was ready before it ran
            seen["calls"] = counting.calls
            return super()._run(context, transformation)

    pipeline = RegistrationPipeline(
        [("global", RANSACGlobal()), ("second", Looking()), ("icp", PointToPlaneICP())],
        descriptor=counting,
    )
    context = RegistrationContext(source, target, descriptor=counting)
    result = pipeline.run(context)
    assert counting.calls == 2 and seen["calls"] == 2
    assert seen["features"] == [("own", "source", 1), ("own", "target", 1)]
    assert 0.0 < result.preparation_seconds < result.seconds
    assert result.as_dict()["preparation_seconds"] == result.preparation_seconds

    alone = _Counting(pretrained32)
    icp_only = RegistrationPipeline([("icp", PointToPlaneICP())], descriptor=alone)
    assert icp_only.register(source, target).preparation_seconds == 0.0
    assert alone.calls == 0


def test_prepare_cloud_keeps_normals_and_places_its_grid():
    """prepare_cloud: an Open3D cloud's normals kept (averaged per voxel), the caller's
    cloud untouched, the grid's centre changing nothing but rounding, and a cloud kept
    as it is without downsampling."""
    import open3d as o3d

    from o3d_rpointhop.registration.prepared import prepare_cloud

    points = make_object(3000, shape_seed=4) + [5000.0, -300.0, 20.0]
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.normals = o3d.utility.Vector3dVector(np.tile([0.0, 0.0, 1.0], (len(points), 1)))
    before = np.asarray(cloud.points).copy()
    own = prepare_cloud(cloud, 0.05)
    np.testing.assert_array_equal(np.asarray(cloud.points), before)
    assert own.normals is not None and np.allclose(own.normals, [0.0, 0.0, 1.0])
    assert len(own.points) < len(points)
    elsewhere = prepare_cloud(points, 0.05, centre=points[0])
    assert elsewhere.normals is None
    np.testing.assert_allclose(
        np.sort(elsewhere.points, axis=0), np.sort(own.points, axis=0), atol=1e-6
    )
    kept = prepare_cloud(points, 0.05, downsample=False)
    np.testing.assert_array_equal(kept.points, points)


def test_the_coarse_context_shares_the_frame():
    """The trial refinements' coarse context holds the global clouds in this context's
    frame, without centring them again."""
    from o3d_rpointhop.registration import RegistrationContext

    cloud = make_object(20000, shape_seed=5) + 100.0
    context = RegistrationContext(cloud + 0.01, cloud)
    coarse = context.coarse()
    assert coarse is not context and not coarse.origin.any()
    np.testing.assert_array_equal(
        np.asarray(coarse.source.points), np.asarray(context.global_cloud("source").points)
    )


@pytest.mark.parametrize("origin", [[0.0, 1.0], [np.nan, 0.0, 0.0], "here"])
def test_a_bad_origin_is_refused(origin):
    cloud = make_object(500, shape_seed=1)
    from o3d_rpointhop.registration import RegistrationContext

    with pytest.raises(ValueError, match="origin"):
        RegistrationContext(cloud, cloud, origin=origin)


def test_viewpoints_for_a_descriptor_that_takes_none_are_a_clear_error():
    cloud = make_object(500)
    codes = CodesBySize({500: np.random.default_rng(0).normal(size=(500, 8))})
    with pytest.raises(TypeError, match="CodesBySize.transform takes none"):
        register(cloud, cloud + 0.1, codes, viewpoints="origin", global_method="consensus")
    # Without viewpoints the same descriptor registers.
    assert register(cloud, cloud + 0.1, codes, global_method="consensus").steps


def test_evaluations_are_open3ds_to_the_bit_whatever_the_order():
    """The context measures each transformation once, at the widest distance asked (or
    the spread distance), and reads nearer ones from it: every evaluation equals
    Open3D's own at that distance, fitness, RMSE and inlier pairs, in any order of
    distances and transformations, on both cloud sets."""
    import open3d as o3d
    from scipy.spatial.transform import Rotation

    from o3d_rpointhop._utils.threads import repeatable_open3d
    from o3d_rpointhop.registration.context import RegistrationContext

    rng = np.random.default_rng(3)
    target = make_object(6000, shape_seed=9, sample_seed=1) * 2.0
    source = make_object(5500, shape_seed=9, sample_seed=2) * 2.0 + [0.01, -0.02, 0.0]
    context = RegistrationContext(source, target, n_global_points=800)
    spread = context.settings.spread_distance
    motions = [np.eye(4)]
    for _ in range(3):
        motion = np.eye(4)
        motion[:3, :3] = Rotation.from_rotvec(rng.normal(0, 0.2, 3)).as_matrix()
        motion[:3, 3] = rng.normal(0, 0.1, 3)
        motions.append(motion)
    asked = [
        (k % 4, which, d)
        for k, (which, d) in enumerate(
            [
                ("full", 0.3 * spread),
                ("full", spread),
                ("global", 0.5 * spread),
                ("full", 0.05 * spread),
                ("global", 2.5 * spread),
                ("full", 4.0 * spread),
                ("full", 0.7 * spread),
                ("global", 0.2 * spread),
            ]
        )
    ] + [(0, "full", 0.3 * spread), (0, "full", 3.0 * spread), (1, "full", 0.6 * spread)]
    seen_partial = 0
    for m, which, distance in asked:
        got = context.evaluate(motions[m], distance, which)
        source_cloud, target_cloud = context.clouds(which)
        with repeatable_open3d():  # Open3D's sums in one order, as the context runs it
            want = o3d.pipelines.registration.evaluate_registration(
                source_cloud, target_cloud, distance, motions[m]
            )
        assert got.fitness == want.fitness and got.inlier_rmse == want.inlier_rmse
        np.testing.assert_array_equal(got.correspondence_set, np.asarray(want.correspondence_set))
        seen_partial += 0.0 < got.fitness < 1.0
    assert seen_partial >= 5  # the distances cut through the clouds, not around them
    assert len(context.fitness._nearest) <= 8 and len(context.fitness._grids) <= 8


def test_clouds_with_normals_are_cached_by_typed_keys_and_shared():
    """Every step that asks for the same cloud at the same level gets the same object
    (estimated once); levels and scales are kept apart, and the radius follows the scale."""
    cloud = make_object(3000, shape_seed=2)
    context = RegistrationContext(cloud, cloud + 0.05, voxel_size=0.02)
    full = context.with_normals("target")
    assert context.with_normals("target", "full", 1.0) is full and full.has_normals()
    assert len(full.points) == 3000 and not context.target.has_normals()  # a copy
    coarse = context.with_normals("target", "full", 3.0)
    assert coarse is context.with_normals("target", "full", 3)
    assert len(coarse.points) == len(context.cloud_at("target", "full", 3.0).points) < 3000
    assert context.cloud_at("target", "full", 3.0) is context.cloud_at("target", "full", 3.0)
    expected = o3d.geometry.PointCloud(context.cloud_at("target", "full", 3.0))
    estimate_normals(expected, 3 * context.settings.normal_radius)
    np.testing.assert_array_equal(np.asarray(coarse.normals), np.asarray(expected.normals))
    assert context.with_normals("source", "global") is not context.with_normals("target", "global")


@pytest.mark.parametrize("radius", ["auto", 0.05])
def test_fpfh_takes_the_contexts_normals_only_when_they_are_its_own(monkeypatch, radius):
    """FPFH at the registration's normal radius describes the global cloud with the
    normals the context estimated for it (one estimate per cloud, not two), to the
    same bits as estimating its own; at another radius it estimates its own."""
    from o3d_rpointhop import FPFHTransformer
    from o3d_rpointhop.registration.prepared import describe_global

    cloud = make_object(3000, shape_seed=4)
    context = RegistrationContext(cloud, cloud + 0.05, n_global_points=800)
    fpfh = FPFHTransformer(normal_radius=radius)
    alone = describe_global(
        fpfh, context.global_cloud("source"), context.voxel_size, context.settings
    )
    calls = []
    estimate = o3d.geometry.PointCloud.estimate_normals

    def counted(self, *args, **kwargs):
        calls.append(len(self.points))
        return estimate(self, *args, **kwargs)

    monkeypatch.setattr(o3d.geometry.PointCloud, "estimate_normals", counted)
    context.with_normals("source", "global")  # as the verification asks for them
    shared = context.features(fpfh, "source")
    np.testing.assert_array_equal(shared, alone)
    assert len(calls) == (1 if radius == "auto" else 2)
