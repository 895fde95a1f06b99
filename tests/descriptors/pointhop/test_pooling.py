"""The compiled hops: octant pooling, the selected Saab outputs, and the last hop folded
with the principal axes, each against a numpy reference."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.descriptors.pointhop._pooling import (
    fold_first_hop,
    fold_projection,
    matmul_blocks,
    pool,
    pool_project,
    pool_saab,
)
from o3d_rpointhop.descriptors.pointhop._saab import apply_saab


def _case(seed, q=40, k=9, n_src=30, c=5):
    rng = np.random.default_rng(seed)
    bins = rng.integers(0, 8, (q, k)).astype(np.uint8)
    bins[0] = 3  # query 0: seven empty bins
    nb = np.stack([rng.choice(n_src, k, replace=False) for _ in range(q)]).astype(np.int32)
    feats = rng.normal(size=(n_src, c)).astype(np.float32)
    return feats, nb, bins


def _reference_pool(feats, nb, bins):
    q = len(nb)
    out = np.empty((feats.shape[1], 8, q))
    for i in range(q):
        whole = feats[nb[i]].mean(axis=0)
        for o in range(8):
            members = nb[i][bins[i] == o]
            out[:, o, i] = feats[members].mean(axis=0) if members.size else whole
    return out


def test_pooling_against_a_loop():
    feats, nb, bins = _case(4)
    pooled = pool(feats, nb, bins)
    assert pooled.shape == (5, 8, 40) and pooled.dtype == np.float32
    np.testing.assert_allclose(pooled, _reference_pool(feats, nb, bins), rtol=1e-5, atol=1e-6)


def test_pooling_is_shift_equivariant():
    feats, nb, bins = _case(5)
    np.testing.assert_allclose(pool(feats + 7.0, nb, bins), pool(feats, nb, bins) + 7.0, rtol=1e-5)


@pytest.fixture
def saab():
    rng = np.random.default_rng(6)
    kernels = np.linalg.qr(rng.normal(size=(5, 8, 8)))[0]
    means = rng.normal(size=(5, 8))
    return kernels, means


def test_selected_saab_outputs_are_apply_saab_s(saab):
    feats, nb, bins = _case(7)
    kernels, means = saab
    selected = np.array([0, 3, 9, 17, 39, 8])  # any outputs, in any order
    out = pool_saab(feats, nb, bins, kernels, means, selected)
    full = apply_saab(pool(feats, nb, bins).astype(np.float64), kernels, means)
    expected = full.reshape(-1, len(nb))[selected].T
    np.testing.assert_allclose(out, expected, rtol=1e-5, atol=1e-5)


def test_the_folded_last_hop_is_the_projection_of_its_outputs(saab):
    feats, nb, bins = _case(8)
    kernels, means = saab
    selected = np.arange(40)[::-1]
    rng = np.random.default_rng(9)
    axes = rng.normal(size=(40, 6)).astype(np.float32)
    centre = rng.normal(size=40).astype(np.float32)
    weights, bias = fold_projection(kernels, means, selected, centre, axes)
    folded = matmul_blocks(feats, weights)
    out = pool_project(folded, nb, bins, bias)
    outputs = pool_saab(feats, nb, bins, kernels, means, selected)
    np.testing.assert_allclose(out, (outputs - centre) @ axes, rtol=1e-4, atol=1e-4)


def test_a_folded_only_hop_is_the_projection_of_its_outputs():
    rng = np.random.default_rng(11)
    dim = 24
    kernels = np.linalg.qr(rng.normal(size=(dim, dim)))[0][None]
    means = rng.normal(size=(1, dim))
    selected = np.array([5, 0, 23, 7, 11])
    axes = rng.normal(size=(5, 3))
    centre = rng.normal(size=5)
    attributes = rng.normal(size=(50, dim)).astype(np.float32)
    outputs = apply_saab(attributes.T[None].astype(np.float64), kernels, means)[0][selected].T
    weights, bias = fold_first_hop(kernels, means, selected, centre, axes)
    np.testing.assert_allclose(
        attributes @ weights + bias, (outputs - centre) @ axes, rtol=1e-5, atol=1e-5
    )


def test_matmul_blocks_are_the_same_bytes_on_any_number_of_threads():
    rng = np.random.default_rng(10)
    a = rng.normal(size=(1500, 33)).astype(np.float32)
    b = rng.normal(size=(33, 70)).astype(np.float32)
    one = matmul_blocks(a, b, 1)
    np.testing.assert_array_equal(matmul_blocks(a, b, 2), one)
    np.testing.assert_allclose(one, a @ b, rtol=1e-5, atol=1e-4)
