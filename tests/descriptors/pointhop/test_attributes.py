"""The eigenvalue features and attribute names of the scene variant."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.descriptors.pointhop._attributes import (
    check_attributes,
    eigen_features,
    fpfh_features,
)


def test_eigen_features_of_known_shapes():
    out = eigen_features(np.array([[1.0, 0, 0], [1, 1, 0], [1, 1, 1], [0, 0, 0], [2, 1, 0.5]]))
    line, plane, ball, point, general = out
    np.testing.assert_allclose(line, [1, 0, 0, 0, 1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(plane, [0, 1, 0, 0, 1, np.log(2), 0], atol=1e-12)
    np.testing.assert_allclose(ball, [0, 0, 1, 1 / 3, 0, np.log(3), 1 / 3], atol=1e-12)
    np.testing.assert_array_equal(point, np.zeros(7))
    e = np.array([2, 1, 0.5]) / 3.5
    assert general[3] == pytest.approx(np.cbrt(e.prod()))
    assert general[5] == pytest.approx(-(e * np.log(e)).sum())
    # Scale-free: the same shape at any size has the same features.
    np.testing.assert_allclose(eigen_features(np.array([[2e6, 1e6, 5e5]]))[0], general)


def test_attribute_names_are_checked():
    assert check_attributes("xyz") == ("xyz",)
    assert check_attributes(["xyz", "eigen"]) == ("xyz", "eigen")
    assert check_attributes(("xyz", "fpfh")) == ("xyz", "fpfh")
    for bad in [(), ("normal",), ("xyz", "xyz"), ("xyz", "colour"), 3]:
        with pytest.raises(ValueError, match="attributes"):
            RPointHopTransformer(attributes=bad).fit(make_object(300))


def _centre_of_mass(histogram: np.ndarray) -> float:
    return float(np.arange(11) @ histogram / histogram.sum())


def test_fpfh_of_one_pair_by_hand():
    # Two points a unit apart along x, normals z and z turned by t about y. Seen from
    # the first end the angles are (theta, alpha, phi) = (t, 0, 0); from the second
    # (t, 0, -sin t). A value v of [low, high] sits at 11 (v - low) / (high - low) - 0.5
    # among the bins, split between the two nearest.
    t = 0.3
    points = np.array([[0.0, 0, 0], [1, 0, 0]])
    normals = np.array([[0.0, 0, 1], [np.sin(t), 0, np.cos(t)]])
    out = fpfh_features(points, normals, np.array([[1], [0]]))
    assert out.shape == (2, 33)
    np.testing.assert_allclose(out[0], out[1], atol=1e-15)  # the pair is the same
    theta, alpha, phi = out[0, :11], out[0, 11:22], out[0, 22:]
    for part in (theta, alpha, phi):
        assert part.sum() == pytest.approx(1.0)
    assert _centre_of_mass(theta) == pytest.approx(11 * (t + np.pi) / (2 * np.pi) - 0.5)
    np.testing.assert_allclose(alpha, np.eye(11)[5], atol=1e-12)
    expected_phi = (5.0 + (11 * (1 - np.sin(t)) / 2 - 0.5)) / 2
    assert _centre_of_mass(phi) == pytest.approx(expected_phi)


def test_fpfh_is_continuous_and_moves_with_the_cloud():
    rng = np.random.default_rng(0)
    # A plane with equal normals: every angle is 0, the middle bin of each part.
    plane = np.c_[rng.random((200, 2)), np.zeros(200)]
    normals = np.tile([0.0, 0, 1], (200, 1))
    near = np.argsort(((plane[:, None] - plane[None]) ** 2).sum(-1), axis=1)[:, 1:17]
    out = fpfh_features(plane, normals, near)
    np.testing.assert_allclose(out, np.tile(np.eye(11)[5], 3)[None].repeat(200, 0), atol=1e-9)
    # Normals that alternate in sign put theta at +-180 deg: the wrapped bins agree
    # however the last bit falls, and a rotation changes nothing beyond rounding.
    flipped = normals * np.where(rng.random(200) < 0.5, -1.0, 1.0)[:, None]
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    base = fpfh_features(plane, flipped, near)
    moved = fpfh_features(plane @ rot.T + 5.0, flipped @ rot.T, near)
    np.testing.assert_allclose(moved, base, atol=1e-9)
    assert np.isfinite(base).all()
    # Coincident neighbours are skipped; a point with none left gets zeros.
    doubled = fpfh_features(np.zeros((2, 3)), normals[:2], np.array([[1], [0]]))
    np.testing.assert_array_equal(doubled, 0.0)
