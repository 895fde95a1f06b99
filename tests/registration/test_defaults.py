"""What a registration uses when not told: the global cloud size a model states."""

from __future__ import annotations

import pytest

from o3d_rpointhop import (
    PointToPlaneICP,
    RegistrationPipeline,
    register,
)
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration.context import RegistrationContext
from o3d_rpointhop.registration.defaults import DEFAULT_GLOBAL_POINTS, resolve_global_points


class _Stated:
    """A stand-in descriptor that states its global cloud size."""

    registration_points_ = 1000

    def transform(self, cloud):  # pragma: no cover - never called here
        raise AssertionError


def test_resolve_global_points():
    assert resolve_global_points(512) == 512
    assert resolve_global_points("auto") == DEFAULT_GLOBAL_POINTS == 2048
    assert resolve_global_points("auto", _Stated()) == 1000
    assert resolve_global_points(4096, _Stated()) == 4096  # the call wins
    cloud = make_object(200)
    for bad in (2, 0, 1.5, True, "many"):  # refused by the public entry points
        with pytest.raises(ValueError, match="n_global_points"):
            register(cloud, cloud, n_global_points=bad)
        with pytest.raises(ValueError, match="n_global_points"):
            RegistrationPipeline([("icp", PointToPlaneICP())], n_global_points=bad).register(
                cloud, cloud
            )


def test_the_global_step_takes_the_descriptors_size():
    cloud = make_object(8000, shape_seed=3)
    stated = RegistrationContext(cloud, cloud, descriptor=_Stated())
    plain = RegistrationContext(cloud, cloud)
    assert stated.n_global_points == 1000 and plain.n_global_points == 2048
    kept = len(stated.global_cloud("source").points)
    assert 700 < kept <= 1.15 * 1000
    assert stated.voxel_size > plain.voxel_size  # fewer points: a coarser resolution
