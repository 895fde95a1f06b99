"""Registration as scikit-learn composition: nested parameters, model selection, settings."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_motion
from sklearn.base import clone
from sklearn.frozen import FrozenEstimator
from sklearn.model_selection import GridSearchCV

from o3d_rpointhop import (
    FPFHTransformer,
    PointToPlaneICP,
    RANSACGlobal,
    RegistrationPipeline,
    RegistrationSettings,
    RPointHopTransformer,
    register,
    registration_scorer,
)
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.transforms import apply_transform


def _pairs(n: int, seed: int = 0):
    """Pairs of different samples of one object, moved apart over SO(3), with the truth."""
    X, y = [], []
    for k in range(n):
        target = make_object(700, shape_seed=40 + k, sample_seed=1)
        rot, shift = random_motion(seed * 10 + k, 0.3)
        truth = np.eye(4)
        truth[:3, :3], truth[:3, 3] = rot.T, -rot.T @ shift
        X.append((make_object(700, shape_seed=40 + k, sample_seed=2) @ rot.T + shift, target))
        y.append(truth)
    return X, np.array(y)


def _pipeline(descriptor=None) -> RegistrationPipeline:
    return RegistrationPipeline(
        [("global", RANSACGlobal()), ("icp", PointToPlaneICP())], descriptor=descriptor
    )


def test_descriptor_parameters_are_reachable_through_the_pipeline():
    pipe = _pipeline(RPointHopTransformer(lrf_neighbors=48))
    params = pipe.get_params(deep=True)
    assert params["descriptor__lrf_neighbors"] == 48
    assert params["global__max_iteration"] == 1_000_000 and params["icp__max_iteration"] == 50
    pipe.set_params(descriptor__lrf_neighbors=32, global__mutual_filter=True)
    assert pipe.descriptor.lrf_neighbors == 32 and pipe.named_steps["global"].mutual_filter
    copy = clone(pipe)
    assert copy.get_params()["descriptor__lrf_neighbors"] == 32
    assert copy.descriptor is not pipe.descriptor
    assert set(pipe.get_params(deep=False)) == {
        "steps",
        "descriptor",
        "voxel_size",
        "n_global_points",
        "seed",
        "settings",
    }


def test_grid_search_over_descriptor_and_step_parameters():
    X, y = _pairs(4)
    search = GridSearchCV(
        _pipeline(FPFHTransformer(normal_radius="auto")),
        # A histogram radius far below the point spacing leaves FPFH empty: no pair can
        # register with it, so the search must pick "auto".
        {"descriptor__radius": ["auto", 1e-4], "icp__max_iteration": [30]},
        scoring=registration_scorer(),
        cv=2,
    )
    search.fit(X, y)
    assert search.best_params_ == {"descriptor__radius": "auto", "icp__max_iteration": 30}
    scores = dict(
        zip(
            map(str, search.cv_results_["param_descriptor__radius"]),
            search.cv_results_["mean_test_score"],
            strict=True,
        )
    )
    assert scores["auto"] == 1.0 and scores["0.0001"] == 0.0
    assert search.best_estimator_.descriptor_.radius == "auto"
    assert search.score(X, y) == 1.0


def test_fit_predict_score():
    X, y = _pairs(2, seed=1)
    pipe = _pipeline(FPFHTransformer(radius="auto", normal_radius="auto"))
    with pytest.raises(Exception, match="not fitted"):
        pipe.predict(X)
    assert pipe.fit(X) is pipe
    predicted = pipe.predict(X)
    assert predicted.shape == (2, 4, 4)
    for (source, _), estimate, truth in zip(X, predicted, y, strict=True):
        gap = apply_transform(source, estimate) - apply_transform(source, truth)
        assert np.linalg.norm(gap, axis=1).mean() < 0.02
    assert pipe.score(X, y) == 1.0
    wrong = np.array([np.eye(4)] * 2)
    assert pipe.score(X, wrong) == 0.0
    with pytest.raises(ValueError, match="one 4x4 transformation per pair"):
        pipe.score(X, y[:1])
    with pytest.raises(ValueError, match="pairs"):
        pipe.fit([X[0][0]])


def test_frozen_pretrained_descriptor_is_kept_by_fit():
    model = RPointHopTransformer.pretrained(n_components=32)
    X, _ = _pairs(1)
    pipe = _pipeline(FrozenEstimator(model)).fit(X)
    cloud = X[0][1]
    np.testing.assert_array_equal(pipe.descriptor_.transform(cloud), model.transform(cloud))


def test_settings_set_every_derived_distance():
    X, _ = _pairs(1)
    source, target = X[0]
    fpfh = FPFHTransformer(radius="auto", normal_radius="auto")
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
