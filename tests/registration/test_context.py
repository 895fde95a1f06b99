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


class _Described:
    """A descriptor whose descriptors were computed beforehand: describing again fails."""

    def transform(self, X):
        raise AssertionError("described again")


def test_prepared_global_clouds_and_features_register_like_computed_ones(pretrained32):
    from o3d_rpointhop import PointToPlaneICP, RANSACGlobal, RegistrationPipeline
    from o3d_rpointhop.registration import RegistrationContext

    target = make_object(3000, shape_seed=8, sample_seed=1)
    source = make_object(3000, shape_seed=8, sample_seed=2)[::-1] @ np.diag([1, -1, -1.0]) + 0.2
    pipeline = RegistrationPipeline(
        [("global", RANSACGlobal()), ("icp", PointToPlaneICP())], descriptor=pretrained32
    )
    plain = pipeline.register(source, target)
    computed = RegistrationContext(source, target, descriptor=pretrained32)
    assert computed.downsampled
    clouds = [
        np.asarray(computed.global_cloud(w).points) + computed.origin for w in ("source", "target")
    ]
    features = [computed.features(pretrained32, w) for w in ("source", "target")]
    stand_in = _Described()
    prepared = RegistrationContext(
        source,
        target,
        voxel_size=computed.voxel_size,
        descriptor=stand_in,
        global_clouds=clouds,
        features=features,
    )
    result = pipeline.run(prepared)
    np.testing.assert_allclose(result.transformation, plain.transformation, atol=1e-9)
    assert result.voxel_size == plain.voxel_size
    with pytest.raises(ValueError, match="features need the descriptor"):
        RegistrationContext(source, target, global_clouds=clouds, features=features)
    with pytest.raises(ValueError, match="source features have 5 rows"):
        RegistrationContext(
            source,
            target,
            descriptor=stand_in,
            global_clouds=clouds,
            features=(features[0][:5], features[1]),
        )
