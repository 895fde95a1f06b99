"""Registration as scikit-learn composition: nested parameters, model selection."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import object_pairs
from sklearn.base import clone
from sklearn.frozen import FrozenEstimator
from sklearn.model_selection import GridSearchCV

from o3d_rpointhop import (
    FPFHTransformer,
    Matcher,
    PointToPlaneICP,
    RANSACGlobal,
    RegistrationPipeline,
    RPointHopTransformer,
    registration_scorer,
)
from o3d_rpointhop.transforms import apply_transform


def _pipeline(descriptor=None) -> RegistrationPipeline:
    return RegistrationPipeline(
        [("global", RANSACGlobal()), ("icp", PointToPlaneICP())], descriptor=descriptor
    )


def test_descriptor_parameters_are_reachable_through_the_pipeline():
    pipe = _pipeline(RPointHopTransformer(lrf_neighbors=48))
    params = pipe.get_params(deep=True)
    assert params["descriptor__lrf_neighbors"] == 48
    assert params["global__max_iteration"] == 1_000_000 and params["icp__max_iteration"] == 50
    # A matcher's parameters are nested one level deeper (scikit-learn's ``__``).
    pipe.set_params(global__matcher=Matcher())
    pipe.set_params(descriptor__lrf_neighbors=32, global__matcher__mutual_filter=True)
    assert pipe.descriptor.lrf_neighbors == 32
    assert pipe.named_steps["global"].matcher.mutual_filter
    copy = clone(pipe)
    assert copy.get_params()["descriptor__lrf_neighbors"] == 32
    assert copy.descriptor is not pipe.descriptor
    assert set(pipe.get_params(deep=False)) == {
        "steps",
        "descriptor",
        "voxel_size",
        "n_global_points",
        "random_state",
        "settings",
        "viewpoints",
        "up",
        "n_jobs",
        "seed",
    }


@pytest.mark.slow
def test_grid_search_over_descriptor_and_step_parameters():
    X, y = object_pairs(4)
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
    X, y = object_pairs(2, seed=1)
    pipe = _pipeline(FPFHTransformer())
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
    X, _ = object_pairs(1)
    pipe = _pipeline(FrozenEstimator(model)).fit(X)
    cloud = X[0][1]
    np.testing.assert_array_equal(pipe.descriptor_.transform(cloud), model.transform(cloud))
