"""The scalable engine: Poisson-disk hops, chunked geometry, principal axes, progress."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_motion, relative_difference
from hypothesis import given, settings
from hypothesis import strategies as st

import o3d_rpointhop.descriptors.pointhop._geometry as hops
import o3d_rpointhop.descriptors.pointhop._octants as octants
from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_blob, make_object
from o3d_rpointhop.descriptors.pointhop._sampling import hop_subsets, poisson_disk_subset


# ----------------------------------------------------------------------------- sampling
@settings(max_examples=10, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.05, 1.0))
def test_poisson_disk_moves_with_the_cloud(seed, share):
    points = make_object(1500, shape_seed=seed % 50, sample_seed=seed)
    m = max(1, int(share * len(points)))
    base = poisson_disk_subset(points, m)
    rot, shift = random_motion(seed, 1000.0)
    perm = np.random.default_rng(seed).permutation(len(points))
    assert len(base) == m and np.all(np.diff(base) > 0)
    np.testing.assert_array_equal(poisson_disk_subset(points @ rot.T + shift, m), base)
    np.testing.assert_array_equal(np.sort(perm[poisson_disk_subset(points[perm], m)]), base)


def test_poisson_disk_spreads_the_sample():
    points = make_blob(4000, shape_seed=2)
    kept = points[poisson_disk_subset(points, 1000)]
    chance = points[np.random.default_rng(0).choice(4000, 1000, replace=False)]

    def closest(sample):
        d = np.linalg.norm(sample[:, None] - sample[None], axis=2)
        np.fill_diagonal(d, np.inf)
        return d.min(axis=1)

    # A hard-core sample: its closest pairs are far apart compared with a random one's.
    assert np.percentile(closest(kept), 1) > 4 * np.percentile(closest(chance), 1)


def test_hop_subsets_are_nested_and_auto_switches_at_the_threshold(monkeypatch):
    points = make_blob(3000, shape_seed=4)
    for method in ("fps", "poisson"):
        big, small = hop_subsets(points, [2000, 900], method)
        assert len(big) == 2000 and len(small) == 900 and np.isin(small, big).all()
    import o3d_rpointhop.descriptors.pointhop._sampling as sampling

    monkeypatch.setattr(sampling, "FPS_MAX_POINTS", 2999)
    np.testing.assert_array_equal(
        hop_subsets(points, [1500], "auto")[0], hop_subsets(points, [1500], "poisson")[0]
    )
    monkeypatch.setattr(sampling, "FPS_MAX_POINTS", 3000)
    np.testing.assert_array_equal(
        hop_subsets(points, [1500], "auto")[0], hop_subsets(points, [1500], "fps")[0]
    )


@pytest.fixture(scope="module")
def poisson_model(train_clouds):
    return RPointHopTransformer(sampling="poisson", random_state=0).fit(train_clouds)


@pytest.mark.parametrize("seed", [0, 1])
def test_poisson_descriptors_are_rigid_invariant_and_permutation_equivariant(poisson_model, seed):
    cloud = make_blob(700, shape_seed=40 + seed)
    base = poisson_model.transform(cloud)
    rot, shift = random_motion(seed, 100.0)
    assert relative_difference(base, poisson_model.transform(cloud @ rot.T + shift)) < 1e-5
    perm = np.random.default_rng(seed).permutation(len(cloud))
    np.testing.assert_array_equal(poisson_model.transform(cloud[perm]), base[perm])
    np.testing.assert_array_equal(poisson_model.transform(cloud), base)  # deterministic


# ----------------------------------------------------------------------------- chunks
def test_chunked_equals_unchunked(fitted, monkeypatch):
    cloud = make_blob(900, shape_seed=11)
    whole = fitted.transform(cloud)
    monkeypatch.setattr(hops, "GEOMETRY_CHUNK", 97)
    monkeypatch.setattr(octants, "BUILD_CHUNK", 61)
    np.testing.assert_array_equal(fitted.transform(cloud), whole)


def test_threads_give_the_same_descriptors(fitted, monkeypatch):
    cloud = make_blob(900, shape_seed=12)
    one = fitted.transform(cloud)
    monkeypatch.setattr(octants, "_BLOCKS_PER_THREAD", 1)  # threads even on a small cloud
    np.testing.assert_array_equal(fitted.set_params(n_jobs=2).transform(cloud), one)
    fitted.set_params(n_jobs=None)


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


def test_projected_descriptors_stay_exactly_permutation_equivariant(axes_model):
    cloud = make_blob(700, shape_seed=14)
    base = axes_model.transform(cloud)
    for seed in range(3):
        perm = np.random.default_rng(seed).permutation(len(cloud))
        np.testing.assert_array_equal(axes_model.transform(cloud[perm]), base[perm])


def test_pretrained_axes():
    short = RPointHopTransformer.pretrained(n_components=32)
    assert short.n_features_out_ == 32 and short.components_.shape == (128, 1624)
    assert RPointHopTransformer.pretrained().n_features_out_ == 1624
    with pytest.raises(ValueError, match="fitted with 128 principal axes"):
        RPointHopTransformer.pretrained(n_components=129)


# ----------------------------------------------------------------------------- progress
def test_progress_is_silent_in_tests_unless_asked(fitted, capfd):
    clouds = [make_blob(300, shape_seed=s) for s in range(3)]
    fitted.transform(clouds)
    RPointHopTransformer(random_state=0).fit(clouds)
    assert capfd.readouterr().err == ""  # stderr is not a terminal here: no bar
    fitted.set_params(progress=True).transform(clouds)
    assert "describe" in capfd.readouterr().err
    fitted.set_params(progress=None)
    with pytest.raises(ValueError, match="progress"):
        fitted.set_params(progress="yes").transform(clouds[0])
    fitted.set_params(progress=None)
