"""Octant assignment and octant pooling."""

from __future__ import annotations

import numpy as np

from o3d_rpointhop.descriptors.pointhop._octants import OctantPooling, octant_index, octant_means


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
    pooled = OctantPooling(octant, nb, n_src)(feats.T)
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
    np.testing.assert_allclose(pool(feats.T + 7.0), pool(feats.T) + 7.0, rtol=1e-5)
