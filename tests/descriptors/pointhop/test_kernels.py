"""The descriptor's compiled kernels give the bytes of the numpy expressions they
replace (the descriptors are unchanged by them to the last bit)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from o3d_rpointhop.descriptors.pointhop._geometry import _normals_in_frames
from o3d_rpointhop.descriptors.pointhop._octants import N_OCTANTS, octant_means


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


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize(("q", "k", "c"), [(300, 64, 3), (97, 5, 7)])
def test_octant_means_are_bincount_s_bytes(q, k, c, compiled):
    rng = np.random.default_rng(q)
    octant = rng.integers(0, N_OCTANTS, (q, k)).astype(np.uint8)
    octant[: q // 3] %= 3  # many empty octants
    planes = rng.normal(size=(c, q, k))
    for values in (planes, np.moveaxis(rng.normal(size=(q, k, c)), 2, 0)):  # any layout
        np.testing.assert_array_equal(
            octant_means(values, octant), _reference_means(values, octant)
        )


def test_normals_in_frames_are_einsum_s_bytes():
    rng = np.random.default_rng(0)
    frames = Rotation.random(500, random_state=1).as_matrix()
    neighbours = rng.integers(0, 500, (200, 48)).astype(np.int32)
    queries = np.sort(rng.choice(500, 200, replace=False))
    expected = np.einsum("qkd,qdj->jqk", frames[neighbours, :, 2], frames[queries])
    np.testing.assert_array_equal(_normals_in_frames(frames, neighbours, queries), expected)
