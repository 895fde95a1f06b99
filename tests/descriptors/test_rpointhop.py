"""RPointHopTransformer: one row per point, invariance, equivariance, scale, degenerate
geometry, bad input and parameters."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from helpers import CONTRACT, random_motion, relative_difference
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial import cKDTree

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_blob, make_object

any_float = st.floats(allow_nan=True, allow_infinity=True, width=64)


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
    assert relative_difference(base, moved) < CONTRACT


@pytest.mark.parametrize("shape", range(100, 106))
def test_flat_faced_objects_are_invariant(fitted, shape):
    """Box faces are exactly planar: their normals' skew is pure rounding, so the frame
    must be oriented by something that moves with the cloud (shape 104 broke without)."""
    obj = make_object(600, shape_seed=shape)
    rot, shift = random_motion(shape)
    assert (
        relative_difference(fitted.transform(obj), fitted.transform(obj @ rot.T + shift)) < CONTRACT
    )


def test_permutation_equivariance(fitted, cloud):
    perm = np.random.default_rng(0).permutation(len(cloud))
    base = fitted.transform(cloud)
    assert relative_difference(base[perm], fitted.transform(cloud[perm])) < CONTRACT
    np.testing.assert_array_equal(fitted.transform(cloud), base)  # the same input: same bytes


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
        (np.array([["a", "b", "c"]] * 200, dtype=object), "must hold real numbers: could not"),
        ([[0.0, 0.0, 0.0], [1.0, 2.0]], "could not be read as an array of points"),
        (np.zeros((0, 200, 3)), "empty batch of point clouds"),
        (make_blob(200) * 1e200, "beyond 1e.150 squared distances overflow; rescale"),
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


def test_bad_viewpoints_and_tensor_clouds_without_points_are_named(fitted):
    import open3d as o3d

    with pytest.raises(ValueError, match="viewpoints must be None, 'origin' or positions"):
        fitted.transform(make_blob(200), viewpoints=[[1.0, "x"]])
    with pytest.raises(ValueError, match="tensor PointCloud has no 'positions'"):
        fitted.transform(o3d.t.geometry.PointCloud())


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


def test_fit_subsample_is_seeded():
    clouds = [make_blob(600, shape_seed=s) for s in range(4)]
    a = RPointHopTransformer(fit_subsample=300, random_state=3).fit(clouds)
    b = RPointHopTransformer(fit_subsample=300, random_state=3).fit(clouds)
    c = RPointHopTransformer(fit_subsample=300, random_state=4).fit(clouds)
    np.testing.assert_array_equal(a.kernels_[1], b.kernels_[1])
    assert not np.array_equal(a.kernels_[0], c.kernels_[0])


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


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(arrays(np.float64, st.tuples(st.integers(0, 300), st.integers(1, 4)), elements=any_float))
def test_transform_gives_a_result_or_a_clear_value_error(points):
    model = RPointHopTransformer.pretrained(n_components=8)
    try:
        out = model.transform(points)
    except ValueError as exc:
        assert str(exc)  # a message, not a crash deep in numpy
        return
    assert out.shape == (len(points), 8) and np.isfinite(out).all()


def test_a_patch_without_skew_is_oriented_towards_the_reference_point():
    """The zero-skew fallback, reached on purpose: a flat, centrally symmetric patch has
    no skew along its normal (nor across it), so the normal must point towards
    ``towards`` (the centroid) whichever side that is, and turn with the patch."""
    from o3d_rpointhop.descriptors.pointhop._frames import local_reference_frames

    grid = np.array([[x, y, 0.0] for x in (-2, -1, 0, 1, 2) for y in (-1, 0, 1)], float)
    grid[:, 0] *= 1.5  # distinct eigenvalues: x first, then y, the normal z last
    offsets = grid[np.any(grid != 0, axis=1)].T[:, None, :]  # the origin's 14 neighbours
    for side in (1.0, -1.0):
        towards = np.array([[0.3], [0.2], [side]])
        frames, _ = local_reference_frames(offsets, 15, towards)
        normal = frames[0, :, 2]
        assert np.allclose(np.abs(normal), [0, 0, 1])
        assert np.sign(normal[2]) == side  # the fallback decided, not rounding
        assert np.sign(frames[0, 0, 0]) == 1.0  # the x axis towards +0.3, likewise
        rot, _ = random_motion(int(side > 0) + 3)
        turned, _ = local_reference_frames(
            np.einsum("ij,jqm->iqm", rot, offsets), 15, rot @ towards
        )
        np.testing.assert_allclose(turned[0], rot @ frames[0], atol=1e-9)
