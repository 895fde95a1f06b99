"""Many clouds and pairs at once, on joblib and Dask."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from helpers import dask_cluster

from o3d_rpointhop import RPointHopTransformer, register
from o3d_rpointhop.batch import register_many, transform_many
from o3d_rpointhop.datasets import make_object


@pytest.fixture(scope="module")
def model():
    return RPointHopTransformer.pretrained(n_components=16).set_params(n_jobs=2)


@pytest.fixture(scope="module")
def clouds():
    return [make_object(400 + 50 * s, shape_seed=s) for s in range(4)]


@pytest.mark.slow
def test_transform_many_equals_one_by_one_in_order(model, clouds):
    expected = [model.transform(c) for c in clouds]
    legacy = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(clouds[1]))
    for n_jobs in (None, 2):
        got = transform_many(model, [clouds[0], legacy, *clouds[2:]], n_jobs=n_jobs)
        assert [g.shape for g in got] == [e.shape for e in expected]
        for g, e in zip(got, expected, strict=True):
            np.testing.assert_array_equal(g, e)
    assert model.n_jobs == 2  # the caller's estimator is left alone


def test_register_many_equals_register(clouds):
    pairs = [(c @ np.diag([1.0, -1.0, -1.0]) + 0.2, c) for c in clouds[:2]]
    alone = [register(s, t, random_state=1) for s, t in pairs]
    for n_jobs in (None, 2):
        together = register_many(pairs, n_jobs=n_jobs, random_state=1)
        for a, b in zip(alone, together, strict=True):
            np.testing.assert_allclose(a.transformation, b.transformation, rtol=0, atol=1e-12)
            assert a.fitness == pytest.approx(b.fitness, abs=1e-12)


def test_register_many_names_a_bad_pair(clouds):
    with pytest.raises(ValueError, match=r"pairs\[1\] is not a \(source, target\) pair"):
        register_many([(clouds[0], clouds[1]), clouds[2]])
    with pytest.raises(ValueError, match=r"pairs\[0\]\[1\]"):
        register_many([(clouds[0], np.full((50, 3), np.nan))])


@pytest.mark.slow
def test_batch_api_runs_on_a_dask_localcluster(model, clouds):
    expected = [model.transform(c) for c in clouds]
    pairs = [(clouds[0] + 0.1, clouds[0])]
    alone = register(*pairs[0], random_state=0)
    with dask_cluster() as client:
        got = transform_many(model, clouds)
        results = register_many(pairs, random_state=0)
        # The work really ran on the cluster's workers.
        assert sum(len(v) for v in client.run(lambda: [1]).values()) == 2
        assert client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.task_prefixes)) > 0
    for g, e in zip(got, expected, strict=True):
        np.testing.assert_array_equal(g, e)
    np.testing.assert_allclose(results[0].transformation, alone.transformation, atol=1e-12)
