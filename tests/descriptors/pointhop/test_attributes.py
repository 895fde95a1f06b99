"""The eigenvalue features and attribute names of the scene variant."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.descriptors.pointhop._attributes import check_attributes, eigen_features


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
    for bad in [(), ("normal",), ("xyz", "xyz"), ("xyz", "colour"), 3]:
        with pytest.raises(ValueError, match="attributes"):
            RPointHopTransformer(attributes=bad).fit(make_object(300))
