"""Local reference frames: orthonormal, right-handed, rotating with the cloud, oriented by
the moment rule, and the compiled frames equal to a numpy reference (LAPACK's
eigenvectors, numpy's median)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_motion
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from o3d_rpointhop.datasets import make_blob, make_object
from o3d_rpointhop.descriptors.pointhop._frames import (
    _skew_sign,
    eigh3,
    local_reference_frames,
    median_of,
)


def _offsets(points, m):
    """Offsets of every point's ``m`` nearest other points, ``(3, n, m)``, nearest first."""
    _, idx = cKDTree(points).query(points, m + 1)
    idx = idx[:, 1:]  # the point itself left out
    return points.T[:, idx] - points.T[:, :, None]


def _towards(points):
    return points.mean(axis=0)[:, None] - points.T


def _reference_frames(offsets, k, towards):
    """The frame rule in numpy: PCA of the point and its k - 1 nearest, axes 0 and 2
    pointing to the side of the larger first moment about the median (else towards the
    reference), axis 1 completing a right-handed frame."""
    q = offsets.shape[1]
    support = np.concatenate([np.zeros((3, q, 1)), offsets[:, :, : k - 1]], axis=2)
    centred = support - support.mean(axis=2, keepdims=True)
    cov = np.einsum("iqk,jqk->qij", centred, centred) / k
    _, vecs = np.linalg.eigh(cov)
    axes = vecs[:, :, ::-1]
    local = np.einsum("dqk,qdj->jqk", support, axes)
    skew = local.mean(axis=2) - np.median(local, axis=2)
    tol = 1e-9 * np.abs(local).max(axis=(0, 2))
    fallback = np.einsum("dq,qdj->jq", towards, axes)
    skew = np.where(np.abs(skew) > tol, skew, fallback)
    sign = np.where(skew < 0, -1.0, 1.0)
    sign[1] = sign[0] * sign[2] * np.sign(np.linalg.det(axes))
    return axes * sign.T[:, None, :]


# ----------------------------------------------------------------------------- LRF
def test_frames_equal_the_numpy_reference():
    pts = make_object(600, shape_seed=2, sample_seed=1)
    offsets = _offsets(pts, 40)
    frames, local = local_reference_frames(offsets, 32, _towards(pts))
    expected = _reference_frames(offsets, 32, _towards(pts))
    # Up to rounding, except where two eigenvalues (nearly) coincide and any axes fit.
    close = np.abs(frames - expected).max(axis=(1, 2)) < 1e-8
    assert close.mean() > 0.99
    np.testing.assert_allclose(local, np.einsum("dqk,qdj->jqk", offsets, frames), atol=1e-12)


def test_frames_are_right_handed_orthonormal():
    pts = make_blob(200, shape_seed=1)
    frames, _ = local_reference_frames(_offsets(pts, 31), 32, _towards(pts))
    eye = np.einsum("qij,qik->qjk", frames, frames)
    np.testing.assert_allclose(eye, np.broadcast_to(np.eye(3), eye.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(frames), 1.0, atol=1e-12)


def test_frames_rotate_with_the_cloud():
    pts = make_blob(200, shape_seed=2)
    rot, shift = random_motion(5, 100.0)
    offsets = _offsets(pts, 40)
    frames, local = local_reference_frames(offsets, 32, _towards(pts))
    moved_pts = pts @ rot.T + shift
    moved, moved_local = local_reference_frames(_offsets(moved_pts, 40), 32, _towards(moved_pts))
    np.testing.assert_allclose(moved, rot[None] @ frames, atol=1e-8)
    np.testing.assert_allclose(moved_local, local, atol=1e-10)


def test_frame_axes_follow_pca_and_moment_rule():
    rng = np.random.default_rng(0)
    # A skewed neighbourhood stretched along x, then y, then z.
    nb = rng.exponential(size=(1, 40, 3)) * np.array([5.0, 2.0, 0.5])
    frames = local_reference_frames(nb.transpose(2, 0, 1), 41, np.zeros((3, 1)))[0][0]
    # Largest variance first: the axes are (up to sign) x, y, z.
    np.testing.assert_allclose(np.abs(frames), np.eye(3), atol=0.2)
    # Exponential samples have mean > median, so the first and third axes point to +x, +z.
    assert frames[0, 0] > 0 and frames[2, 2] > 0


def test_flat_patch_normal_points_to_the_reference():
    rng = np.random.default_rng(3)
    patch = np.c_[rng.uniform(-1, 1, (60, 2)), np.zeros(60)]  # exactly flat: no skew
    offsets = (patch[1:] - patch[0]).T[:, None, :]
    for side in (1.0, -1.0):
        towards = np.array([[0.2], [0.1], [side * 5.0]])
        frames, local = local_reference_frames(offsets, 60, towards)
        assert np.sign(frames[0, 2, 2]) == side  # normal axis points at the reference
        np.testing.assert_allclose(np.linalg.det(frames), 1.0)


def test_degenerate_neighbourhoods_give_finite_frames():
    planar = np.c_[np.random.default_rng(0).normal(size=(50, 2)), np.zeros(50)]
    line = np.c_[np.linspace(0, 1, 50), np.zeros((50, 2))]
    same = np.zeros((50, 3))
    for pts in (planar, line, same):
        offsets = (pts[1:] - pts[0]).T[:, None, :]
        frames, local = local_reference_frames(offsets, 50, np.ones((3, 1)))
        assert np.isfinite(frames).all() and np.isfinite(local).all()
        np.testing.assert_allclose(frames[0].T @ frames[0], np.eye(3), atol=1e-12)


def test_frame_sizes_are_checked():
    with pytest.raises(ValueError, match="k=12 needs between 1 and 10"):
        local_reference_frames(np.zeros((3, 2, 10)), 12, np.zeros((3, 2)))


# ----------------------------------------------------------------------------- helpers
def test_eigh3_matches_lapack_and_stays_orthonormal_on_repeated_eigenvalues():
    rng = np.random.default_rng(4)
    matrices = [a @ a.T for a in rng.normal(size=(50, 3, 3))]
    matrices += [np.diag([2.0, 2.0, 1.0]), np.eye(3), np.zeros((3, 3)), np.diag([0, 0, 5.0])]
    for a in matrices:
        vectors, values = np.empty((3, 3)), np.empty(3)
        eigh3(a.copy(), vectors, values)
        np.testing.assert_allclose(values, np.linalg.eigvalsh(a)[::-1], atol=1e-12)
        np.testing.assert_allclose(vectors.T @ vectors, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(a @ vectors, vectors * values, atol=1e-10)
        assert values[0] >= values[1] >= values[2]


def test_median_matches_numpy():
    rng = np.random.default_rng(1)
    for k in (1, 2, 5, 6, 33, 64):
        for values in (rng.normal(size=k), rng.integers(0, 3, k).astype(float)):  # ties too
            assert median_of(values.copy(), k) == np.median(values)


@settings(max_examples=60, deadline=None)
@given(
    st.integers(2, 70),
    st.integers(0, 10_000),
    st.sampled_from([0.0, 1e-9, 1e-3, 0.3]),
)
def test_the_skew_sign_by_counting_is_the_sign_of_mean_minus_median(k, seed, tol):
    """Counting decides ``mean - median`` against the tolerance as sorting does, for odd
    and even counts, ties, values on the threshold and the point itself at 0."""
    rng = np.random.default_rng(seed)
    values = (
        rng.choice([-1.0, -0.5, 0.0, 0.5, 1.0, 2.0], k - 1) if seed % 2 else rng.normal(size=k - 1)
    )
    local = np.zeros((3, k - 1))
    local[1] = values
    towards = np.array([0.0, -1.0 if seed % 3 else 1.0, 0.0])
    frame = np.eye(3)
    every = np.append(values, 0.0)
    skew = every.mean() - np.median(every)
    expected = (1.0 if skew > 0 else -1.0) if abs(skew) > tol else towards[1]
    if abs(abs(skew) - tol) > 1e-12:  # away from the tolerance's edge, where rounding decides
        assert _skew_sign(local, 1, k - 1, k, tol, towards, frame) == expected


def test_frame_size_bounds_and_float32_inputs():
    """k from 2 (the point and one neighbour) to m + 1 (every neighbour), refused outside
    with the neighbour count in the message; float32 inputs give what their float64
    values give (the kernel computes in float64)."""
    from o3d_rpointhop.descriptors.pointhop._frames import local_reference_frames

    rng = np.random.default_rng(2)
    offsets = rng.normal(size=(3, 40, 5))
    towards = rng.normal(size=(3, 40))
    sensor = rng.normal(size=(3, 40))
    for k in (2, 6):
        local_reference_frames(offsets, k, towards)
    for k in (1, 7):
        with pytest.raises(ValueError, match=f"k={k} needs between 1 and 5 neighbours"):
            local_reference_frames(offsets, k, towards)
    o32, t32, s32 = (a.astype(np.float32) for a in (offsets, towards, sensor))
    wide = local_reference_frames(o32.astype(np.float64), 6, t32.astype(np.float64),
                                  sensor=s32.astype(np.float64))  # fmt: skip
    narrow = local_reference_frames(o32, 6, t32, sensor=s32)
    for a, b in zip(wide, narrow, strict=True):
        assert b.dtype == np.float64
        np.testing.assert_array_equal(a, b)
