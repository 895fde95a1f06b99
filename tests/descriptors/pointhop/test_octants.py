"""The bins of a neighbourhood (octants of the frame, or azimuth bins about its normal)
and the octant means over them, against numpy references."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.descriptors.pointhop._octants import (
    N_OCTANTS,
    bin_index,
    cylindrical_of,
    octant_means,
)


def _reference_means(values, octant):
    """Octant means by numpy.bincount, an empty octant taking the neighbourhood mean."""
    c, q, _ = values.shape
    rows = (octant.astype(np.int64) * q + np.arange(q)[:, None]).ravel()
    counts = np.bincount(rows, minlength=N_OCTANTS * q).reshape(N_OCTANTS, q)
    out = np.empty((q, N_OCTANTS, c))
    for d in range(c):
        sums = np.bincount(rows, weights=values[d].ravel(), minlength=N_OCTANTS * q)
        means = sums.reshape(N_OCTANTS, q) / np.maximum(counts, 1)
        means = np.where(counts == 0, values[d].mean(axis=1)[None, :], means)
        out[:, :, d] = means.T
    return out.reshape(q, N_OCTANTS * c)


# ----------------------------------------------------------------------------- bins
def test_octant_bits():
    local = np.array([[[1.0, -1.0, 1.0]], [[1.0, 1.0, -1.0]], [[1.0, -1.0, -1.0]]])  # (3,1,3)
    np.testing.assert_array_equal(bin_index(local, "octants"), [[7, 2, 4]])


def test_octant_boundary_points_count_as_positive():
    # A coordinate of exactly zero, or within rounding of zero, lands on the positive side.
    local = np.array([[[0.0, 1.0, -1e-20]], [[1.0, 1.0, 1.0]], [[1.0, 1.0, 1.0]]])
    np.testing.assert_array_equal(bin_index(local, "octants"), [[7, 7, 7]])


def test_azimuth_bins_by_hand():
    """Above or below the tangent plane (bit 2), then four shells of equal area of the
    distance to the farthest neighbour (radii 1/2, sqrt(1/2), sqrt(3/4), 1)."""
    radii = np.array([0.1, 0.6, 0.8, 0.95, 1.0, 0.4])
    heights = np.array([0.0, -0.1, 0.1, -0.2, 0.0, 0.2])
    radial = np.sqrt(radii**2 - heights**2)
    local = np.stack([radial * 0.6, radial * 0.8, heights])[:, None, :]
    np.testing.assert_array_equal(bin_index(local, "azimuth"), [[4, 1, 6, 3, 7, 4]])


def test_cylindrical_coordinates_by_hand():
    local = np.array([[3.0, 0.0], [4.0, 0.0], [12.0, -2.0]])
    out = np.empty((3, 2))
    cylindrical_of(local, 2, out)
    np.testing.assert_allclose(out, [[5.0, 0.0], [12.0, -2.0], [13.0, 2.0]])


# ----------------------------------------------------------------------------- means
@pytest.mark.parametrize(("q", "k", "c"), [(300, 64, 3), (97, 5, 7)])
def test_octant_means_are_bincount_s(q, k, c):
    rng = np.random.default_rng(q)
    octant = rng.integers(0, N_OCTANTS, (q, k)).astype(np.uint8)
    octant[: q // 3] %= 3  # many empty octants
    planes = rng.normal(size=(c, q, k))
    for values in (planes, np.moveaxis(rng.normal(size=(q, k, c)), 2, 0)):  # any layout
        np.testing.assert_allclose(
            octant_means(values, octant), _reference_means(values, octant), rtol=1e-12
        )


def test_octant_means_of_coordinates_against_a_loop():
    rng = np.random.default_rng(3)
    local = rng.normal(size=(3, 4, 10))
    local[0, 2] = np.abs(local[0, 2])  # query 2: every first coordinate positive
    octant = bin_index(local, "octants")
    attrs = octant_means(local, octant)
    for q in range(4):
        for o in range(8):
            members = octant[q] == o
            expected = local[:, q, members].mean(axis=1) if members.any() else local[:, q].mean(1)
            np.testing.assert_allclose(attrs[q, 3 * o : 3 * o + 3], expected)
