"""The pieces R-PointHop is built from: LRF, octant pooling, Saab, sampling, neighbours."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_motion

from o3d_rpointhop.datasets import make_blob
from o3d_rpointhop.descriptors.pointhop._frames import (
    local_reference_frames,
    median_along_last,
    project,
)
from o3d_rpointhop.descriptors.pointhop._neighbors import drop_self, knn
from o3d_rpointhop.descriptors.pointhop._octants import OctantPooling, octant_index, octant_means
from o3d_rpointhop.descriptors.pointhop._saab import MomentAccumulator, apply_saab, fit_saab
from o3d_rpointhop.descriptors.pointhop._sampling import fps_subsets


def _offsets(points, k):
    idx, _ = knn(points, points, k)
    return points.T[:, idx] - points.T[:, :, None], idx


def _towards(points):
    return points.mean(axis=0)[:, None] - points.T


# ----------------------------------------------------------------------------- LRF
def test_frames_are_right_handed_orthonormal():
    pts = make_blob(200, shape_seed=1)
    frames, _ = local_reference_frames(_offsets(pts, 32)[0], 32, _towards(pts))
    eye = np.einsum("qij,qik->qjk", frames, frames)
    np.testing.assert_allclose(eye, np.broadcast_to(np.eye(3), eye.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(frames), 1.0, atol=1e-12)


def test_frames_rotate_with_the_cloud():
    pts = make_blob(200, shape_seed=2)
    rot, shift = random_motion(5, 100.0)
    offsets = _offsets(pts, 40)[0]
    frames, local = local_reference_frames(offsets, 32, _towards(pts))
    moved_pts = pts @ rot.T + shift
    moved, moved_local = local_reference_frames(_offsets(moved_pts, 40)[0], 32, _towards(moved_pts))
    np.testing.assert_allclose(moved, rot[None] @ frames, atol=1e-8)
    np.testing.assert_allclose(moved_local, local, atol=1e-10)
    # the local coordinates are the offsets seen in each frame, all 40 neighbours
    np.testing.assert_allclose(local, project(offsets, frames), atol=1e-12)


def test_frame_axes_follow_pca_and_moment_rule():
    rng = np.random.default_rng(0)
    # A skewed neighbourhood stretched along x, then y, then z.
    nb = rng.exponential(size=(1, 40, 3)) * np.array([5.0, 2.0, 0.5])
    frames = local_reference_frames(nb.transpose(2, 0, 1), 40, np.zeros((3, 1)))[0][0]
    # Largest variance first: the axes are (up to sign) x, y, z.
    np.testing.assert_allclose(np.abs(frames), np.eye(3), atol=0.2)
    # Exponential samples have mean > median, so the first and third axes point to +x, +z.
    assert frames[0, 0] > 0 and frames[2, 2] > 0


def test_flat_patch_normal_points_to_the_reference():
    rng = np.random.default_rng(3)
    patch = np.c_[rng.uniform(-1, 1, (60, 2)), np.zeros(60)]  # exactly flat: no skew
    offsets = (patch - patch[0]).T[:, None, :]
    for side in (1.0, -1.0):
        towards = np.array([[0.2], [0.1], [side * 5.0]])
        frames, local = local_reference_frames(offsets, 60, towards)
        assert np.sign(frames[0, 2, 2]) == side  # normal axis points at the reference
        np.testing.assert_allclose(np.linalg.det(frames), 1.0)


def test_median_matches_numpy():
    rng = np.random.default_rng(1)
    for k in (5, 6, 33, 64):
        v = rng.normal(size=(3, 7, k))
        np.testing.assert_allclose(median_along_last(v), np.median(v, axis=-1))


def test_degenerate_neighbourhoods_give_finite_frames():
    planar = np.c_[np.random.default_rng(0).normal(size=(50, 2)), np.zeros(50)]
    line = np.c_[np.linspace(0, 1, 50), np.zeros((50, 2))]
    same = np.zeros((50, 3))
    for pts in (planar, line, same):
        offsets = (pts - pts[0]).T[:, None, :]
        frames, local = local_reference_frames(offsets, 50, np.ones((3, 1)))
        assert np.isfinite(frames).all() and np.isfinite(local).all()
        np.testing.assert_allclose(frames[0].T @ frames[0], np.eye(3), atol=1e-12)


# ----------------------------------------------------------------------------- octants
def test_octant_index_bits():
    local = np.array([[[1.0, -1.0, 1.0]], [[1.0, 1.0, -1.0]], [[1.0, -1.0, -1.0]]])  # (3,1,3)
    np.testing.assert_array_equal(octant_index(local), [[7, 2, 4]])


def test_octant_boundary_points_count_as_positive():
    # A coordinate of exactly zero, or within rounding of zero, lands on the positive side.
    local = np.array([[[0.0, 1.0, -1e-20]], [[1.0, 1.0, 1.0]], [[1.0, 1.0, 1.0]]])
    np.testing.assert_array_equal(octant_index(local), [[7, 7, 7]])


def test_octant_means_of_coordinates_against_loop():
    rng = np.random.default_rng(3)
    local = rng.normal(size=(3, 4, 10))
    local[0, 2] = np.abs(local[0, 2])  # query 2: every first coordinate positive
    octant = octant_index(local)
    attrs = octant_means(local, octant)
    for q in range(4):
        for o in range(8):
            members = octant[q] == o
            expected = local[:, q, members].mean(axis=1) if members.any() else local[:, q].mean(1)
            np.testing.assert_allclose(attrs[q, 3 * o : 3 * o + 3], expected)


def test_octant_pooling_against_loop():
    rng = np.random.default_rng(4)
    q, k, n_src, c = 6, 9, 20, 5
    local = rng.normal(size=(3, q, k))
    local[:, 0] = np.abs(local[:, 0])  # query 0 has seven empty octants
    octant = octant_index(local)
    nb = np.stack([rng.choice(n_src, k, replace=False) for _ in range(q)])
    feats = rng.normal(size=(c, n_src)).astype(np.float32)
    pooled = OctantPooling(octant, nb, n_src)(feats)
    assert pooled.shape == (c, 8, q)
    for i in range(q):
        whole = feats[:, nb[i]].mean(axis=1)
        for o in range(8):
            members = nb[i][octant[i] == o]
            expected = feats[:, members].mean(axis=1) if members.size else whole
            np.testing.assert_allclose(pooled[:, o, i], expected, rtol=1e-5, atol=1e-6)


def test_octant_pooling_is_shift_equivariant():
    rng = np.random.default_rng(5)
    local = rng.normal(size=(3, 8, 12))
    octant = octant_index(local)
    nb = rng.integers(0, 30, size=(8, 12))
    pool = OctantPooling(octant, nb, 30)
    feats = rng.normal(size=(4, 30)).astype(np.float32)
    np.testing.assert_allclose(pool(feats + 7.0), pool(feats) + 7.0, rtol=1e-5)


# ----------------------------------------------------------------------------- Saab
def test_moments_merge_like_one_batch():
    rng = np.random.default_rng(6)
    data = rng.normal(size=(3, 8, 1000)) * 3 + 1000.0  # large mean: tests the merge precision
    acc = MomentAccumulator(3, 8)
    for part in np.array_split(data, 7, axis=2):
        acc.update(part)
    expected = np.stack([np.cov(d, bias=True) for d in data])
    np.testing.assert_allclose(acc.covariance(), expected, rtol=1e-9, atol=1e-9)


def test_saab_kernels_and_energies():
    rng = np.random.default_rng(7)
    mixing = rng.normal(size=(8, 8))
    data = (rng.normal(size=(5000, 8)) @ mixing).T[None]  # (1, 8, n)
    acc = MomentAccumulator(1, 8)
    acc.update(data)
    saab = fit_saab(acc)
    kernels = saab.kernels[0]
    np.testing.assert_allclose(kernels.T @ kernels, np.eye(8), atol=1e-10)
    np.testing.assert_allclose(kernels[:, 0], np.full(8, 8**-0.5))
    np.testing.assert_allclose(kernels[:, 1:].sum(axis=0), 0.0, atol=1e-10)  # AC ⟂ DC
    assert saab.energy.sum() == pytest.approx(1.0)
    assert np.all(np.diff(saab.energy[0, 1:]) <= 1e-12)  # AC by decreasing variance
    out = apply_saab(data, saab.kernels, saab.mean)
    variances = out[0].var(axis=1)
    np.testing.assert_allclose(variances / variances.sum(), saab.energy[0], rtol=1e-6)
    np.testing.assert_allclose(out[0].mean(axis=1), 0.0, atol=1e-9)  # centred outputs
    np.testing.assert_allclose(out[0].T, (data[0].T - data[0].mean(axis=1)) @ kernels, atol=1e-9)


def test_saab_of_constant_data_has_no_energy():
    acc = MomentAccumulator(2, 8)
    acc.update(np.ones((2, 8, 50)))
    saab = fit_saab(acc)
    assert np.all(saab.energy == 0.0)
    assert np.isfinite(saab.kernels).all()


# ----------------------------------------------------------------------------- sampling
def _reference_fps(points, m, start):
    chosen = [start]
    dist = np.linalg.norm(points - points[start], axis=1)
    for _ in range(m - 1):
        j = int(np.argmax(dist))
        chosen.append(j)
        dist = np.minimum(dist, np.linalg.norm(points - points[j], axis=1))
    return np.sort(chosen)


def test_fps_matches_reference_and_is_nested():
    pts = make_blob(400, shape_seed=8)
    start = int(np.argmax(np.linalg.norm(pts - pts.mean(0), axis=1)))
    big, small = fps_subsets(pts, [300, 120])
    np.testing.assert_array_equal(big, _reference_fps(pts, 300, start))
    np.testing.assert_array_equal(small, _reference_fps(pts, 120, start))
    assert np.isin(small, big).all()


def test_fps_is_rigid_and_permutation_invariant():
    pts = make_blob(400, shape_seed=9)
    rot, shift = random_motion(1, 50.0)
    perm = np.random.default_rng(2).permutation(400)
    (base,) = fps_subsets(pts, [150])
    (moved,) = fps_subsets(pts @ rot.T + shift, [150])
    (permuted,) = fps_subsets(pts[perm], [150])
    np.testing.assert_array_equal(base, moved)
    np.testing.assert_array_equal(np.sort(perm[permuted]), base)


def test_knn_and_drop_self():
    pts = make_blob(100, shape_seed=10)
    idx, sq = knn(pts, pts, 5)
    np.testing.assert_array_equal(idx[:, 0], np.arange(100))
    brute = np.argsort(((pts[:, None] - pts[None]) ** 2).sum(-1), axis=1)[:, :5]
    np.testing.assert_array_equal(idx, brute)
    assert np.all(np.diff(sq, axis=1) >= 0)
    kept = drop_self(idx, sq, 4)
    np.testing.assert_array_equal(kept, idx[:, 1:])
    # A query that is not one of the points keeps its k nearest.
    far_idx, far_sq = knn(pts, pts[:3] + 10.0, 5)
    np.testing.assert_array_equal(drop_self(far_idx, far_sq, 4), far_idx[:, :4])
    with pytest.raises(ValueError, match="cannot take"):
        knn(pts[:3], pts, 5)


def test_project_is_per_query_change_of_basis():
    rng = np.random.default_rng(11)
    offsets = rng.normal(size=(3, 4, 6))
    frames = np.linalg.qr(rng.normal(size=(4, 3, 3)))[0]
    expected = np.einsum("dqk,qdj->jqk", offsets, frames)
    np.testing.assert_allclose(project(offsets, frames), expected)
