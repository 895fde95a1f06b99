"""What a registration uses when not told: the global cloud size and the global step a
model states."""

from __future__ import annotations

import pytest

from o3d_rpointhop import (
    FPFHTransformer,
    PointToPlaneICP,
    RANSACGlobal,
    RegistrationPipeline,
    register,
)
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration.context import RegistrationContext
from o3d_rpointhop.registration.defaults import (
    DEFAULT_GLOBAL_METHOD,
    DEFAULT_GLOBAL_POINTS,
    resolve_global_method,
    resolve_global_points,
)


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


class _Consensus:
    """A stand-in descriptor that states its global step."""

    registration_global_method_ = "consensus"


def test_resolve_global_method():
    assert resolve_global_method("auto") == DEFAULT_GLOBAL_METHOD == "ransac"
    assert resolve_global_method("auto", FPFHTransformer()) == "ransac"
    assert resolve_global_method("auto", _Consensus()) == "consensus"
    assert resolve_global_method("fgr", _Consensus()) == "fgr"  # the call wins
    assert resolve_global_method(None, _Consensus()) is None
    step = RANSACGlobal()
    assert resolve_global_method(step, _Consensus()) is step


def test_register_runs_the_step_the_model_states(object_model):
    cloud = make_object(1200, shape_seed=5)
    moved = cloud + [0.05, 0.0, 0.0]
    stated = object_model.__class__(**object_model.get_params())
    stated.__dict__.update(object_model.__dict__)
    stated.registration_global_method_ = "consensus"
    auto = register(moved, cloud, stated)
    assert "hypotheses" in auto.steps[0].info  # the consensus ran
    plain = register(moved, cloud, object_model)
    assert "hypotheses" not in plain.steps[0].info  # RANSAC ran
    stated.registration_global_method_ = "magic"
    with pytest.raises(ValueError, match="registration_global_method_ 'magic'"):
        register(moved, cloud, stated)


def test_register_describes_with_the_object_model_when_given_none():
    """No descriptor means the shipped one-hop object model: the same result, to the
    bit, as naming it."""
    from o3d_rpointhop import RPointHopTransformer

    target = make_object(900, shape_seed=12, sample_seed=1)
    source = make_object(900, shape_seed=12, sample_seed=2) + [0.2, -0.1, 0.3]
    default = register(source, target, random_state=3)
    named = register(source, target, RPointHopTransformer.pretrained("object"), random_state=3)
    assert default.transformation.tobytes() == named.transformation.tobytes()
    assert default.fitness == named.fitness and default.inlier_rmse == named.inlier_rmse
    context = RegistrationContext(source, target)
    context.features(None, "source")
    assert context.descriptor.n_features_out_ == 24
    assert context.descriptor.get_params() == RPointHopTransformer.pretrained("object").get_params()
