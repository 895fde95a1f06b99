"""The fitted hop tree: fitting (cached and streamed), threads, chunks, BLAS kept to one
thread."""

from __future__ import annotations

import numpy as np
import pytest

import o3d_rpointhop.descriptors.pointhop._geometry as hops
import o3d_rpointhop.descriptors.pointhop._octants as octants
import o3d_rpointhop.descriptors.pointhop._tree as tree_module
from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_blob


# ----------------------------------------------------------------------------- determinism
def test_fit_is_deterministic_and_n_jobs_independent(train_clouds, cloud):
    a = RPointHopTransformer(random_state=0).fit(train_clouds)
    b = RPointHopTransformer(random_state=0, n_jobs=2).fit(train_clouds)
    for ka, kb in zip(a.kernels_, b.kernels_, strict=True):
        np.testing.assert_array_equal(ka, kb)
    np.testing.assert_array_equal(a.transform(cloud), b.transform(cloud))
    lists = b.transform([cloud, cloud + 1.0])
    np.testing.assert_array_equal(lists[1], a.transform(cloud + 1.0))


def test_streaming_fit_equals_cached_fit(train_clouds, monkeypatch):
    """With no memory for caching, every hop recomputes the clouds: same model."""
    cached = RPointHopTransformer().fit(train_clouds)
    monkeypatch.setattr(tree_module, "FIT_CACHE_BYTES", 0)
    streamed = RPointHopTransformer().fit(train_clouds)
    for a, b in zip(cached.kernels_, streamed.kernels_, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9)
    for a, b in zip(cached.selected_, streamed.selected_, strict=True):
        np.testing.assert_array_equal(a, b)


def test_transform_in_a_forked_child_after_the_parent_used_its_threads(fitted, cloud):
    """The pooling threads do not survive a fork; a forked child must start its own
    instead of waiting forever on the parent's."""
    import multiprocessing

    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("no fork on this platform")
    expected = fitted.transform(cloud)  # the parent's thread pool now exists
    with multiprocessing.get_context("fork").Pool(1) as pool:
        result = pool.apply_async(fitted.transform, (cloud,)).get(timeout=60)
    np.testing.assert_array_equal(result, expected)


def test_transform_keeps_blas_to_one_thread(fitted, cloud, monkeypatch):
    """No hidden pool: BLAS runs on one thread inside the transform, and the caller's
    setting is back afterwards."""
    from threadpoolctl import threadpool_info, threadpool_limits

    module = tree_module

    def blas_threads():
        return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}

    seen = []
    original = module.apply_saab

    def spy(*args):
        seen.append(blas_threads())
        return original(*args)

    monkeypatch.setattr(module, "apply_saab", spy)
    with threadpool_limits(2, user_api="blas"):
        before = blas_threads()
        fitted.transform(cloud)
        assert blas_threads() == before
    assert seen and all(s <= {1} for s in seen)


# ----------------------------------------------------------------------------- chunks
def test_chunked_equals_unchunked(fitted, monkeypatch):
    cloud = make_blob(900, shape_seed=11)
    whole = fitted.transform(cloud)
    monkeypatch.setattr(hops, "GEOMETRY_CHUNK", 97)
    monkeypatch.setattr(octants, "BUILD_CHUNK", 61)
    np.testing.assert_array_equal(fitted.transform(cloud), whole)


def test_descriptors_do_not_depend_on_the_internal_order(fitted, monkeypatch):
    cloud = make_blob(900, shape_seed=14)
    spatial = fitted.transform(cloud)
    reverse = lambda points: np.arange(len(points))[::-1]  # noqa: E731
    monkeypatch.setattr(tree_module, "spatial_order", reverse)
    np.testing.assert_array_equal(fitted.transform(cloud), spatial)


@pytest.mark.parametrize("model", ["fitted", "scene"])
def test_threads_give_the_same_descriptors(model, fitted, monkeypatch):
    """Pooling blocks and geometry chunks shared between threads: the same bytes as on
    one thread (the scene model also threads its normal and eigenvalue attributes)."""
    model = fitted if model == "fitted" else RPointHopTransformer.pretrained("scene")
    cloud = make_blob(900, shape_seed=12)
    one = model.transform(cloud)
    # Threads even on a small cloud, in uneven chunks.
    monkeypatch.setattr(octants, "_BLOCKS_PER_THREAD", 1)
    monkeypatch.setattr(hops, "THREAD_CHUNK", 50)
    monkeypatch.setattr(hops, "GEOMETRY_CHUNK", 333)
    calls = []
    original = hops.map_threads

    def spy(func, items, n_threads):
        calls.append((len(items), n_threads))
        return original(func, items, n_threads)

    monkeypatch.setattr(hops, "map_threads", spy)
    threaded = model.set_params(n_jobs=2).transform(cloud)
    model.set_params(n_jobs=None)
    assert calls and all(n == 2 and items >= 2 for items, n in calls)
    np.testing.assert_array_equal(threaded, one)


@pytest.mark.parametrize("n_threads", [1, 2])
def test_map_threads_runs_every_item_and_raises_a_failure(n_threads):
    from o3d_rpointhop._utils.threads import map_threads

    out = np.zeros(10)

    def fill(lo, hi):
        out[lo:hi] = np.arange(lo, hi)

    map_threads(fill, [(0, 3), (3, 7), (7, 10)], n_threads)
    np.testing.assert_array_equal(out, np.arange(10))

    def fail(lo, hi):
        if lo == 3:
            raise ValueError("chunk 3:7 failed")

    with pytest.raises(ValueError, match="chunk 3:7"):
        map_threads(fail, [(0, 3), (3, 7), (7, 10)], n_threads)


def test_even_chunks_cover_the_range_in_balanced_pieces():
    from o3d_rpointhop._utils.threads import even_chunks

    for n, largest, threads, smallest in [(10, 4, 2, 1), (1000, 300, 3, 1), (5, 100, 4, 2)]:
        bounds = even_chunks(n, largest, threads, smallest)
        assert bounds[0][0] == 0 and bounds[-1][1] == n
        assert all(a[1] == b[0] for a, b in zip(bounds, bounds[1:], strict=False))
        sizes = [hi - lo for lo, hi in bounds]
        # Each thread's share of at most `largest` items, unless that is under `smallest`.
        assert max(sizes) <= max(smallest, -(-largest // threads))
        assert len(bounds) >= min(threads, n // smallest)
    assert even_chunks(8000, 16384, 2, 4096) == [(0, 8000)]  # too small to share
    assert len(even_chunks(20000, 16384, 2, 4096)) == 4
    assert even_chunks(0, 10, 2) == []


# ----------------------------------------------------------------------------- memory
def test_describing_holds_little_beyond_the_output(monkeypatch):
    """Peak traced memory of one transform per point, with small neighbourhood chunks so
    that the per-point structure dominates: about 2.2 kB (0.5 kB of it the 128-axis
    output). Holding every hop's raw neighbours, or a transposed copy of a hop's
    output, puts it above 3.3 kB."""
    import tracemalloc

    from o3d_rpointhop.datasets import make_object

    monkeypatch.setattr(hops, "GEOMETRY_CHUNK", 1024)
    points = make_object(20000, shape_seed=3, sample_seed=1)
    model = RPointHopTransformer.pretrained(n_components=128)
    tracemalloc.start()
    try:
        out = model.transform(points)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert out.shape == (20000, 128)
    assert peak / len(points) < 2600
