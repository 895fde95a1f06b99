"""RegistrationSettings: every distance derived from one resolution."""

from __future__ import annotations

import pytest
from helpers import object_pairs

from o3d_rpointhop import (
    FPFHTransformer,
    RANSACGlobal,
    RegistrationSettings,
    register,
)
from o3d_rpointhop.datasets import make_object


def test_settings_set_every_derived_distance():
    X, _ = object_pairs(1)
    source, target = X[0]
    fpfh = FPFHTransformer()
    plain = register(source, target, fpfh)
    voxel = plain.voxel_size
    assert plain.steps[0].info["max_correspondence_distance"] == pytest.approx(1.5 * voxel)
    assert plain.steps[1].info["max_correspondence_distance"] == pytest.approx(
        [2.0 * voxel, 0.5 * voxel]
    )
    settings = RegistrationSettings(ransac_factor=3.0, icp_factors=(4.0, 1.0, 0.25))
    custom = register(source, target, fpfh, settings=settings)
    assert custom.voxel_size == voxel
    assert custom.steps[0].info["max_correspondence_distance"] == pytest.approx(3.0 * voxel)
    assert custom.steps[1].info["max_correspondence_distance"] == pytest.approx(
        [4.0 * voxel, voxel, 0.25 * voxel]
    )
    assert custom.distance == pytest.approx(0.25 * voxel)
    # A step's own value still wins over the settings.
    ransac = RANSACGlobal(max_correspondence_distance=0.05)
    own = register(source, target, fpfh, global_method=ransac)
    assert own.steps[0].info["max_correspondence_distance"] == 0.05


def test_settings_are_checked():
    with pytest.raises(ValueError, match="ransac_factor must be a positive number"):
        RegistrationSettings(ransac_factor=0.0)
    with pytest.raises(ValueError, match="icp_factors must be a non-empty tuple"):
        RegistrationSettings(icp_factors=())
    with pytest.raises(ValueError, match="no resolution yet"):
        _ = RegistrationSettings().ransac_distance
    with pytest.raises(ValueError, match="'settings' parameter"):
        register(make_object(300), make_object(300), settings={"ransac_factor": 2.0})
    bound = RegistrationSettings(normal_radius_factor=3.0).at(0.5)
    assert bound.normal_radius == 1.5 and bound.feature_radius == 2.5
