"""Local reference frames: orthonormal, right-handed, rotating with the cloud, oriented by
the moment rule."""

from __future__ import annotations

import numpy as np
from helpers import random_motion

from o3d_rpointhop.datasets import make_blob
from o3d_rpointhop.descriptors.pointhop._frames import (
    local_reference_frames,
    median_along_last,
    project,
)
from o3d_rpointhop.descriptors.pointhop._neighbors import knn


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


def test_project_is_per_query_change_of_basis():
    rng = np.random.default_rng(11)
    offsets = rng.normal(size=(3, 4, 6))
    frames = np.linalg.qr(rng.normal(size=(4, 3, 3)))[0]
    expected = np.einsum("dqk,qdj->jqk", offsets, frames)
    np.testing.assert_allclose(project(offsets, frames), expected)
