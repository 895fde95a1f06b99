"""The Saab transform and its moment accumulator."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop.descriptors.pointhop._saab import MomentAccumulator, apply_saab, fit_saab


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
