"""RPointHopTransformer: invariance, robustness, errors, determinism, persistence."""

from __future__ import annotations

import pickle

import joblib
import numpy as np
import open3d as o3d
import pytest
from conftest import random_motion, relative_difference
from scipy.spatial import cKDTree

import o3d_rpointhop.descriptors.pointhop._tree as tree_module
from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_blob, make_object

# ----------------------------------------------------------------------------- outputs


def test_one_row_per_input_point_in_every_input_form(fitted, cloud):
    desc = fitted.transform(cloud)
    assert desc.shape == (len(cloud), fitted.n_features_out_)
    assert desc.dtype == np.float32
    assert np.isfinite(desc).all()

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud))
    np.testing.assert_array_equal(fitted.transform(pcd), desc)
    tpcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(cloud))
    np.testing.assert_array_equal(fitted.transform(tpcd), desc)
    np.testing.assert_array_equal(fitted.transform(cloud.tolist()), desc)

    other = make_blob(250, shape_seed=43)
    as_list = fitted.transform([cloud, other, pcd])
    assert isinstance(as_list, list) and len(as_list) == 3
    np.testing.assert_array_equal(as_list[0], desc)
    assert as_list[1].shape == (250, fitted.n_features_out_)

    batch = fitted.transform(np.stack([cloud, cloud[::-1]]))
    assert batch.shape == (2, len(cloud), fitted.n_features_out_)
    np.testing.assert_array_equal(batch[0], desc)


def test_descriptor_dimension_matches_the_energy_tree(fitted):
    assert fitted.n_features_out_ == fitted.selected_[-1].size
    assert fitted.kernels_[0].shape == (1, 24, 24)
    for h in range(1, len(fitted.kernels_)):
        assert fitted.kernels_[h].shape == (fitted.selected_[h - 1].size, 8, 8)
        # every channel passed on had energy above the threshold
        passed = fitted.energies_[h - 1].ravel()[fitted.selected_[h - 1]]
        assert passed.min() >= fitted.energy_threshold
    # the last hop keeps all eight outputs of every channel it receives
    assert fitted.n_features_out_ == 8 * fitted.selected_[-2].size


# ----------------------------------------------------------------------------- invariance
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rigid_motion_invariance(fitted, cloud, seed):
    rot, shift = random_motion(seed, translation_scale=10.0**seed)
    base = fitted.transform(cloud)
    moved = fitted.transform(cloud @ rot.T + shift)
    assert relative_difference(base, moved) < 1e-6


@pytest.mark.parametrize("shape", range(100, 106))
def test_flat_faced_objects_are_invariant(fitted, shape):
    """Box faces are exactly planar: their normals' skew is pure rounding, so the frame
    must be oriented by something that moves with the cloud (shape 104 broke without)."""
    obj = make_object(600, shape_seed=shape)
    rot, shift = random_motion(shape)
    assert relative_difference(fitted.transform(obj), fitted.transform(obj @ rot.T + shift)) < 1e-6


def test_permutation_equivariance(fitted, cloud):
    perm = np.random.default_rng(0).permutation(len(cloud))
    base = fitted.transform(cloud)
    assert relative_difference(base[perm], fitted.transform(cloud[perm])) < 1e-6


def test_auto_scale_makes_descriptors_unit_free(fitted, cloud):
    base = fitted.transform(cloud)
    # the same shape in millimetres, far from the origin
    assert relative_difference(base, fitted.transform(cloud * 1000.0 + 5000.0)) < 1e-5


def test_fixed_scale_sees_units(train_clouds, cloud):
    model = RPointHopTransformer(scale=1.0).fit(train_clouds)
    assert relative_difference(model.transform(cloud), model.transform(cloud * 3.0)) > 1e-2


def test_mirror_image_is_not_identical(fitted, cloud):
    mirrored = cloud * np.array([1.0, 1.0, -1.0])
    assert relative_difference(fitted.transform(cloud), fitted.transform(mirrored)) > 1e-2


def test_descriptors_match_across_resampled_rotated_copies(fitted):
    """Two different point samples of one surface, one rotated: the nearest descriptor
    must point near the true position far more often than chance (about 7 % against
    0.6 % here; a descriptor that ignored geometry would sit at chance)."""
    target = make_blob(1024, shape_seed=77, sample_seed=1)
    source_true = make_blob(1024, shape_seed=77, sample_seed=2)
    rot, shift = random_motion(3)
    d_src = fitted.transform(source_true @ rot.T + shift).astype(np.float64)
    d_tgt = fitted.transform(target).astype(np.float64)
    match = cKDTree(d_tgt).query(d_src)[1]
    good = np.mean(np.linalg.norm(target[match] - source_true, axis=1) < 0.1)
    shuffled = target[np.random.default_rng(0).permutation(len(target))]
    chance = np.mean(np.linalg.norm(shuffled - source_true, axis=1) < 0.1)
    assert good > 0.04 and good > 5 * chance


# ----------------------------------------------------------------------------- robustness
def test_duplicates_planes_lines_and_empty_octants_stay_finite(fitted):
    rng = np.random.default_rng(0)
    blob = make_blob(200, shape_seed=5)
    duplicated = np.concatenate([blob, blob[:150], blob[:50]])  # many exact duplicates
    plane = np.c_[rng.uniform(-1, 1, (300, 2)), np.zeros(300)]
    grid = np.stack(np.meshgrid(np.arange(15.0), np.arange(15.0), [0.0]), -1).reshape(-1, 3)
    line = np.c_[np.linspace(0, 1, 200), np.zeros((200, 2))]
    line_noisy = line + rng.normal(scale=1e-9, size=line.shape)
    hemisphere = blob[blob[:, 2] > 0.0]  # one-sided neighbourhoods along the rim
    for pts in (duplicated, plane, grid, line, line_noisy, hemisphere):
        desc = fitted.transform(pts)
        assert desc.shape == (len(pts), fitted.n_features_out_)
        assert np.isfinite(desc).all()


def test_duplicated_points_get_equal_descriptors(fitted):
    blob = make_blob(250, shape_seed=6)
    pts = np.concatenate([blob, blob[:10]])
    desc = fitted.transform(pts)
    assert relative_difference(desc[:10], desc[250:]) < 1e-5


@pytest.mark.parametrize(
    "bad, message",
    [
        (np.full((200, 3), np.nan), "NaN or infinite"),
        (np.r_[make_blob(200), [[np.inf, 0, 0]]], r"1 point\(s\) with NaN or infinite.*rows 200"),
        (np.zeros((200, 2)), r"2 feature\(s\)"),
        (np.zeros((200, 3, 1)), r"X\[0\] has 1 feature\(s\)"),
        (np.zeros(30), "Reshape your data"),
        (np.zeros((0, 3)), "empty"),
        ([], "empty list"),
        (make_blob(60), "60 points, too few.*at least 98 points"),
        (np.zeros((200, 3)), "no spatial extent"),
        (np.full((200, 3), "a"), "real numbers"),
        (make_blob(200) + 0j, "Complex data not supported"),
    ],
)
def test_bad_input_raises_a_clear_error(fitted, bad, message):
    with pytest.raises(ValueError, match=message):
        fitted.transform(bad)


def test_bad_cloud_in_a_list_is_named(fitted):
    with pytest.raises(ValueError, match=r"X\[1\] has 50 points"):
        fitted.transform([make_blob(200), make_blob(50)])
    with pytest.raises(ValueError, match=r"X\[1\].*NaN"):
        RPointHopTransformer().fit([make_blob(200), np.full((200, 3), np.nan)])


def test_sparse_input_is_refused(fitted):
    import scipy.sparse as sp

    with pytest.raises(TypeError, match="sparse"):
        fitted.transform(sp.csr_matrix(make_blob(200)))


@pytest.mark.parametrize(
    "params, message",
    [
        (dict(n_neighbors=(64, 32), hop_sizes=(1.0,)), "1 entries but n_neighbors has 2"),
        (dict(hop_sizes=(1.0, 0.5, 0.75, 0.375)), "must not increase"),
        (dict(hop_sizes=(1.0, 0.75, 0.5, 1.5)), r"all fractions in \(0, 1\]"),
        (dict(hop_sizes=(1024, 768, 0.5, 384)), "all fractions"),
        (dict(hop_sizes=(1024, 768, 0, 384)), "all point counts >= 1"),
        (dict(n_neighbors=(64, 0, 48, 48)), "ints >= 1"),
        (dict(lrf_neighbors=2), "lrf_neighbors"),
        (dict(energy_threshold=1.0), "energy_threshold"),
        (dict(scale="metres"), "scale"),
        (dict(scale=-1.0), "scale"),
        (dict(fit_subsample=0), "fit_subsample"),
    ],
)
def test_bad_parameters_raise_on_fit(train_clouds, params, message):
    with pytest.raises(ValueError, match=message):
        RPointHopTransformer(**params).fit(train_clouds)


def test_degenerate_training_data_raises():
    flat = [np.c_[np.random.default_rng(s).uniform(size=(200, 2)), np.zeros(200)] for s in range(2)]
    # planar clouds still vary; a threshold no channel can pass is the degenerate case
    with pytest.raises(ValueError, match="no channel of hop"):
        RPointHopTransformer(energy_threshold=0.99).fit(flat)


def test_integer_hop_sizes_cap_at_the_cloud(train_clouds, cloud):
    model = RPointHopTransformer(hop_sizes=(1000, 200, 150, 100)).fit(train_clouds)
    desc = model.transform(cloud)  # 300 points: hop 1 uses all of them
    assert desc.shape == (300, model.n_features_out_)
    assert np.isfinite(desc).all()


def test_min_points_is_exact(train_clouds):
    model = RPointHopTransformer().fit(train_clouds)
    model.transform(make_blob(98))
    with pytest.raises(ValueError, match="97 points, too few"):
        model.transform(make_blob(97))


# ----------------------------------------------------------------------------- determinism
def test_fit_is_deterministic_and_n_jobs_independent(train_clouds, cloud):
    a = RPointHopTransformer(random_state=0).fit(train_clouds)
    b = RPointHopTransformer(random_state=0, n_jobs=2).fit(train_clouds)
    for ka, kb in zip(a.kernels_, b.kernels_, strict=True):
        np.testing.assert_array_equal(ka, kb)
    np.testing.assert_array_equal(a.transform(cloud), b.transform(cloud))
    lists = b.transform([cloud, cloud + 1.0])
    np.testing.assert_array_equal(lists[1], a.transform(cloud + 1.0))


def test_fit_subsample_is_seeded():
    clouds = [make_blob(600, shape_seed=s) for s in range(4)]
    a = RPointHopTransformer(fit_subsample=300, random_state=3).fit(clouds)
    b = RPointHopTransformer(fit_subsample=300, random_state=3).fit(clouds)
    c = RPointHopTransformer(fit_subsample=300, random_state=4).fit(clouds)
    np.testing.assert_array_equal(a.kernels_[1], b.kernels_[1])
    assert not np.array_equal(a.kernels_[0], c.kernels_[0])


def test_streaming_fit_equals_cached_fit(train_clouds, monkeypatch):
    """With no memory for caching, every hop recomputes the clouds: same model."""
    cached = RPointHopTransformer().fit(train_clouds)
    monkeypatch.setattr(tree_module, "FIT_CACHE_BYTES", 0)
    streamed = RPointHopTransformer().fit(train_clouds)
    for a, b in zip(cached.kernels_, streamed.kernels_, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9)
    for a, b in zip(cached.selected_, streamed.selected_, strict=True):
        np.testing.assert_array_equal(a, b)


# ----------------------------------------------------------------------------- persistence
def test_save_load_round_trip(fitted, cloud, tmp_path):
    path = tmp_path / "model.npz"
    fitted.save(path)
    loaded = RPointHopTransformer.load(path)
    assert loaded.get_params() == {**fitted.get_params(), "n_jobs": None}
    np.testing.assert_array_equal(loaded.transform(cloud), fitted.transform(cloud))
    with np.load(path, allow_pickle=False) as archive:  # readable without pickle
        assert "metadata" in archive.files


def test_joblib_and_pickle_round_trip(fitted, cloud, tmp_path):
    joblib.dump(fitted, tmp_path / "m.joblib")
    np.testing.assert_array_equal(
        joblib.load(tmp_path / "m.joblib").transform(cloud), fitted.transform(cloud)
    )
    np.testing.assert_array_equal(
        pickle.loads(pickle.dumps(fitted)).transform(cloud), fitted.transform(cloud)
    )


def test_load_rejects_foreign_and_damaged_files(fitted, tmp_path):
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, a=np.arange(3))
    with pytest.raises(ValueError, match="not a valid o3d-rpointhop-model file"):
        RPointHopTransformer.load(foreign)

    text = tmp_path / "text.npz"
    text.write_text("hello")
    with pytest.raises(ValueError, match="cannot be read"):
        RPointHopTransformer.load(text)

    good = tmp_path / "good.npz"
    fitted.save(good)
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(ValueError, match="not a valid"):
        RPointHopTransformer.load(truncated)

    with pytest.raises(FileNotFoundError):
        RPointHopTransformer.load(tmp_path / "missing.npz")


def _rewrite(src, dst, **changes):
    with np.load(src, allow_pickle=False) as archive:
        arrays = {k: archive[k] for k in archive.files}
    arrays.update(changes)
    np.savez(dst, **arrays)


def test_load_rejects_newer_format_and_inconsistent_arrays(fitted, tmp_path):
    import json

    good = tmp_path / "good.npz"
    fitted.save(good)
    with np.load(good, allow_pickle=False) as archive:
        meta = json.loads(str(archive["metadata"]))
    newer = tmp_path / "newer.npz"
    _rewrite(good, newer, metadata=np.array(json.dumps({**meta, "format_version": 99})))
    with pytest.raises(ValueError, match="format version 99.*upgrade"):
        RPointHopTransformer.load(newer)

    broken = tmp_path / "broken.npz"
    _rewrite(good, broken, hop1_kernels=np.zeros((3, 8, 8)))
    with pytest.raises(ValueError, match="inconsistent shapes"):
        RPointHopTransformer.load(broken)

    nan = tmp_path / "nan.npz"
    kernels = np.load(good)["hop0_kernels"].copy()
    kernels[0, 0, 0] = np.nan
    _rewrite(good, nan, hop0_kernels=kernels)
    with pytest.raises(ValueError, match="non-finite"):
        RPointHopTransformer.load(nan)

    pickled = tmp_path / "pickled.npz"
    _rewrite(good, pickled, hop0_selected=np.array([object()], dtype=object))
    with pytest.raises(ValueError, match="not a valid.*pickle"):
        RPointHopTransformer.load(pickled)


def test_save_needs_a_fitted_model(tmp_path):
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        RPointHopTransformer().save(tmp_path / "m.npz")


def test_transform_in_a_forked_child_after_the_parent_used_its_threads(fitted, cloud):
    """The pooling threads do not survive a fork; a forked child must start its own
    instead of waiting forever on the parent's."""
    import multiprocessing

    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("no fork on this platform")
    expected = fitted.transform(cloud)  # the parent's thread pool now exists
    with multiprocessing.get_context("fork").Pool(1) as pool:
        result = pool.apply_async(fitted.transform, (cloud,)).get(timeout=60)
    np.testing.assert_array_equal(result, expected)


def test_transform_keeps_blas_to_one_thread(fitted, cloud, monkeypatch):
    """No hidden pool: BLAS runs on one thread inside the transform, and the caller's
    setting is back afterwards."""
    from threadpoolctl import threadpool_info, threadpool_limits

    module = tree_module

    def blas_threads():
        return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}

    seen = []
    original = module.apply_saab

    def spy(*args):
        seen.append(blas_threads())
        return original(*args)

    monkeypatch.setattr(module, "apply_saab", spy)
    with threadpool_limits(2, user_api="blas"):
        before = blas_threads()
        fitted.transform(cloud)
        assert blas_threads() == before
    assert seen and all(s <= {1} for s in seen)
