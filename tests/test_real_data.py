"""Checks on the real datasets in ../shared/data; skipped when the data is absent."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop import FPFHTransformer, RPointHopTransformer
from o3d_rpointhop.datasets import load_modelnet40

pytestmark = pytest.mark.realdata


@pytest.fixture(scope="module")
def modelnet(shared_data):
    return load_modelnet40("train", shared_data), load_modelnet40("test", shared_data)


def test_modelnet40_loader(modelnet):
    train, test = modelnet
    assert train.points.shape == (144, 2048, 3) and test.points.shape == (53, 2048, 3)
    np.testing.assert_allclose(np.linalg.norm(train.points, axis=2).max(axis=1), 1.0)
    np.testing.assert_allclose(train.points.mean(axis=1), 0.0, atol=1e-12)
    assert train.class_names[0] == "airplane" and len(train.class_names) == 40


def test_rpointhop_beats_fpfh_on_resampled_modelnet_pairs(modelnet):
    """The descriptor-quality protocol of docs/performance.md on 10 test shapes."""
    from scipy.spatial.transform import Rotation

    train, test = modelnet
    model = RPointHopTransformer(random_state=0).fit(list(train.points[::3, :1024]))
    fpfh = FPFHTransformer()
    rng = np.random.default_rng(0)
    scores = {"rph": [], "fpfh": []}
    for shape in test.points[::5]:
        target, truth = shape[:1024], shape[1024:]
        rotation = Rotation.random(random_state=int(rng.integers(1000))).as_matrix()
        source = truth @ rotation.T + rng.uniform(-0.5, 0.5, 3)
        for name, describer in (("rph", model), ("fpfh", fpfh)):
            a = np.asarray(describer.transform(source), dtype=np.float64)
            b = np.asarray(describer.transform(target), dtype=np.float64)
            sq = (a * a).sum(1)[:, None] - 2 * a @ b.T + (b * b).sum(1)[None]
            error = np.linalg.norm(target[sq.argmin(1)] - truth, axis=1)
            scores[name].append(np.mean(error < 0.05))
    rph, fp = np.mean(scores["rph"]), np.mean(scores["fpfh"])
    assert rph > 0.10 and rph > 1.5 * fp, (rph, fp)
