"""The registration context: the clouds the global step sees."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.datasets import make_object


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
