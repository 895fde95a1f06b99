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


def test_the_common_voxel_keeps_every_scan_near_the_global_size():
    """The scans' common resolution is the one their largest needs: it keeps about
    n_global_points (at most 15 % more), every other scan fewer, as register() sizes a
    pair; a scan under the size needs only its spacing."""
    import open3d as o3d

    from o3d_rpointhop._utils.geometry import point_spacing
    from o3d_rpointhop.registration.settings import common_voxel, resolve_voxel_size

    def cloud(points):
        return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))

    scans = [make_object(n, shape_seed=2, sample_seed=n) * s for n, s in ((9000, 1.0), (5000, 1.4))]
    voxel = common_voxel(scans, 1000)
    kept = [len(cloud(p).voxel_down_sample(voxel).points) for p in scans]
    assert 500 <= max(kept) <= 1.15 * 1000
    # One scan alone needs the voxel register() gives a pair of it with itself.
    for p in scans:
        alone, _ = resolve_voxel_size(cloud(p), cloud(p), "auto", 1000)
        assert common_voxel([p], 1000) == pytest.approx(alone)
    assert voxel == max(common_voxel([p], 1000) for p in scans)
    small = make_object(500, shape_seed=2, sample_seed=1)
    assert common_voxel([small], 1000) == point_spacing(small)
