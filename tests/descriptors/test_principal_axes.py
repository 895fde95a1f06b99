"""Principal axes of the descriptors (n_components): projection, truncation, exact
equivariance, the pretrained axes."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import CONTRACT, relative_difference

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_blob


# ----------------------------------------------------------------------------- axes
@pytest.fixture(scope="module")
def axes_model(train_clouds):
    return RPointHopTransformer(n_components=12, random_state=0).fit(train_clouds)


def test_principal_axes_project_and_truncate(axes_model, tmp_path):
    cloud = make_blob(500, shape_seed=13)
    full = RPointHopTransformer(random_state=0).fit(
        [make_blob(384, shape_seed=s) for s in range(6)]
    )
    out = axes_model.transform(cloud)
    assert out.shape == (500, 12) and out.dtype == np.float32
    # The projection of the full descriptor on the stored axes.
    expected = (full.transform(cloud) - axes_model.pca_mean_) @ axes_model.components_.T
    np.testing.assert_allclose(out, expected, rtol=1e-4, atol=1e-4 * np.abs(expected).max())
    # Axes by decreasing variance; fewer axes are the leading columns.
    assert np.all(np.diff(axes_model.explained_variance_) <= 0)
    fewer = axes_model.set_params(n_components=5).transform(cloud)
    np.testing.assert_allclose(fewer, out[:, :5], rtol=1e-6, atol=1e-6 * np.abs(out).max())
    assert axes_model.n_features_out_ == 5
    with pytest.raises(ValueError, match="fitted with 12 principal axes"):
        axes_model.set_params(n_components=13).transform(cloud)
    axes_model.set_params(n_components=12)
    axes_model.save(tmp_path / "m.npz")
    np.testing.assert_array_equal(
        RPointHopTransformer.load(tmp_path / "m.npz").transform(cloud), out
    )


def test_projected_descriptors_stay_permutation_equivariant(axes_model):
    cloud = make_blob(700, shape_seed=14)
    base = axes_model.transform(cloud)
    for seed in range(3):
        perm = np.random.default_rng(seed).permutation(len(cloud))
        assert relative_difference(axes_model.transform(cloud[perm]), base[perm]) < CONTRACT
    np.testing.assert_array_equal(axes_model.transform(cloud), base)


def test_pretrained_axes():
    short = RPointHopTransformer.pretrained(n_components=32)
    assert short.n_features_out_ == 32 and short.components_.shape == (128, 1624)
    assert RPointHopTransformer.pretrained().n_features_out_ == 1624
    with pytest.raises(ValueError, match="fitted with 128 principal axes"):
        RPointHopTransformer.pretrained(n_components=129)
