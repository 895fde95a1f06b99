"""Turning a frame about its normal: the octants' relabelling and the hop-1 attributes
turned, against bins and means recomputed in the turned frame."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.descriptors.pointhop._octants import bin_index, octant_means
from o3d_rpointhop.descriptors.pointhop._turns import octant_turn, turn_hop1


def _quarter(local: np.ndarray, quarters: int) -> np.ndarray:
    """Coordinates ``(3, ...)`` in the frame turned by ``quarters`` (x' = y, y' = -x)."""
    out = np.array(local, dtype=float)
    for _ in range(quarters):
        out[0], out[1] = out[1].copy(), -out[0]
    return out


def test_a_quarter_turn_relabels_octants_as_recomputed_bins_do():
    rng = np.random.default_rng(0)
    local = rng.normal(size=(3, 50, 20))
    before = bin_index(local, "octants")
    for quarters in range(4):
        after = bin_index(_quarter(local, quarters), "octants")
        np.testing.assert_array_equal(octant_turn(quarters)[before], after)


def test_turn_tables_compose_and_four_quarters_are_none():
    one = octant_turn(1)
    np.testing.assert_array_equal(np.sort(one), np.arange(8))  # a permutation
    np.testing.assert_array_equal(octant_turn(2), one[one])
    np.testing.assert_array_equal(octant_turn(3), one[one[one]])
    np.testing.assert_array_equal(octant_turn(4), np.arange(8))
    assert not np.array_equal(one, np.arange(8))


@pytest.mark.parametrize("quarters", [0, 1, 2, 3])
def test_turned_attributes_equal_the_means_recomputed_in_the_turned_frame(quarters):
    """Coordinates and normals (vectors in the frame) and seven scalars, pooled over
    octants: relabelling and turning the pooled means is pooling in the turned frame."""
    rng = np.random.default_rng(quarters)
    q, k = 40, 24
    local = rng.normal(size=(3, q, k))
    local[:, :5, :] = np.abs(local[:, :5, :])  # some queries with empty octants
    normals = rng.normal(size=(3, q, k))
    scalars = rng.normal(size=(7, q, k))

    def pooled(coords, vectors):
        bins = bin_index(coords, "octants")
        return np.hstack(
            [octant_means(coords, bins), octant_means(vectors, bins), octant_means(scalars, bins)]
        )

    names = ("xyz", "normal", "eigen")
    expected = pooled(_quarter(local, quarters), _quarter(normals, quarters))
    turned = turn_hop1(pooled(local, normals), names, quarters)
    np.testing.assert_allclose(turned, expected, rtol=0, atol=1e-12)


def test_turning_leaves_the_input_as_it_was():
    attrs = np.random.default_rng(1).normal(size=(5, 24))
    kept = attrs.copy()
    turn_hop1(attrs, ("xyz",), 1)
    np.testing.assert_array_equal(attrs, kept)
