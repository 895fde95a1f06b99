"""RPointHopTransformer under scikit-learn's estimator contract."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import NOT_APPLICABLE, assert_passes_check_estimator
from sklearn.base import clone
from sklearn.decomposition import PCA
from sklearn.exceptions import NotFittedError
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import StandardScaler

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_blob

SMALL = dict(n_neighbors=(4, 3), hop_sizes=(1.0, 0.5), lrf_neighbors=5)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.SkipTestWarning")
def test_sklearn_check_estimator():
    assert_passes_check_estimator(RPointHopTransformer(**SMALL), NOT_APPLICABLE)


# The properties the inapplicable checks would have covered, tested on real clouds.
def test_init_only_stores_parameters():
    params = dict(n_neighbors=[8, 8], hop_sizes=[1.0, 0.5], lrf_neighbors=9, scale="bad")
    est = RPointHopTransformer(**params)  # no validation, no conversion in __init__
    for name, value in params.items():
        assert getattr(est, name) is value
    assert not [k for k in vars(est) if k.endswith("_")]


def test_fit_returns_self_does_not_touch_params_and_is_idempotent(train_clouds):
    est = RPointHopTransformer(random_state=0)
    before = est.get_params()
    assert est.fit(train_clouds) is est
    assert est.get_params() == before
    first = [k.copy() for k in est.kernels_]
    est.fit(train_clouds)
    for a, b in zip(first, est.kernels_, strict=True):
        np.testing.assert_array_equal(a, b)
    assert est.n_features_in_ == 3
    assert est.n_training_clouds_ == len(train_clouds)


def test_not_fitted_raises():
    with pytest.raises(NotFittedError):
        RPointHopTransformer().transform(make_blob(200))


def test_clone_and_set_params(fitted):
    copy = clone(fitted)
    assert copy.get_params() == fitted.get_params()
    assert not hasattr(copy, "kernels_")
    copy.set_params(energy_threshold=0.01, n_neighbors=(32, 32, 32, 32))
    assert copy.energy_threshold == 0.01 and copy.n_neighbors == (32, 32, 32, 32)


def test_readonly_input(fitted, cloud):
    ro = cloud.copy()
    ro.setflags(write=False)
    np.testing.assert_array_equal(fitted.transform(ro), fitted.transform(cloud))
    RPointHopTransformer().fit([ro, ro])


def test_pipeline_with_pca(train_clouds, cloud):
    pipe = Pipeline(
        [
            ("rph", RPointHopTransformer(random_state=0)),
            ("scale", StandardScaler()),
            ("pca", PCA(16, random_state=0)),
        ]
    )
    pipe.fit(cloud)  # one cloud: its points are the PCA's samples
    out = pipe.transform(cloud)
    assert out.shape == (len(cloud), 16)
    # The pipeline clones cleanly and pickles like any estimator.
    assert clone(pipe).get_params()["rph__random_state"] == 0

    # A fitted descriptor followed by a PCA fitted on its outputs.
    rph = RPointHopTransformer().fit(train_clouds)
    pca = PCA(8).fit(rph.transform(train_clouds[0]))
    reduced = make_pipeline(rph, pca).transform(cloud)
    np.testing.assert_allclose(reduced, pca.transform(rph.transform(cloud)), rtol=1e-5)


def test_feature_names_out(fitted):
    names = fitted.get_feature_names_out()
    assert len(names) == fitted.n_features_out_
    assert names[0] == "rpointhoptransformer0"
    assert len(set(names)) == len(names)


def test_fit_transform_equals_fit_then_transform(train_clouds, cloud):
    a = RPointHopTransformer().fit_transform(cloud)
    b = RPointHopTransformer().fit(cloud).transform(cloud)
    np.testing.assert_array_equal(a, b)
