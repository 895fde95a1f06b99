"""The fitted hop tree: fitting (cached and streamed), threads, chunks, BLAS kept to one
thread."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import CONTRACT, relative_difference

import o3d_rpointhop._utils.threads as threads_module
import o3d_rpointhop.descriptors.pointhop._geometry as hops
import o3d_rpointhop.descriptors.pointhop._tree as tree_module
from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_blob, make_object


# ----------------------------------------------------------------------------- determinism
@pytest.mark.slow
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
    """The kernels' threads do not survive a fork; a forked child must start its own
    instead of waiting forever on the parent's."""
    import multiprocessing

    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("no fork on this platform")
    expected = fitted.set_params(n_jobs=2).transform(cloud)  # the parent's pool now exists
    fitted.set_params(n_jobs=None)
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
@pytest.mark.parametrize("sampling", ["fps", "poisson"])
def test_chunked_equals_unchunked(fitted, sampling, monkeypatch):
    """The frames pass in chunks of any size: the same bytes (with Poisson disks the
    search runs chunk by chunk too)."""
    model = RPointHopTransformer(**{**fitted.get_params(), "sampling": sampling})
    model.__dict__.update({k: v for k, v in vars(fitted).items() if k.endswith("_")})
    cloud = make_blob(900, shape_seed=11)
    whole = model.transform(cloud)
    monkeypatch.setattr(hops, "GEOMETRY_CHUNK", 97)
    np.testing.assert_array_equal(model.transform(cloud), whole)


def test_descriptors_do_not_depend_on_the_internal_order_beyond_rounding(fitted, monkeypatch):
    cloud = make_blob(900, shape_seed=14)
    spatial = fitted.transform(cloud)
    reverse = lambda points: np.arange(len(points))[::-1]  # noqa: E731
    monkeypatch.setattr(tree_module, "spatial_order", reverse)
    assert relative_difference(fitted.transform(cloud), spatial) < CONTRACT


def test_a_permuted_cloud_gets_the_same_bytes_permuted():
    """Every cloud is described in its Morton arrangement, which a permutation does not
    change (no two points of these clouds share a cell), so the sums run in the same
    order: the same bytes, not just the same values to rounding."""
    model = RPointHopTransformer.pretrained(n_components=128)
    for seed in (0, 5, 9):
        cloud = make_object(2000, shape_seed=seed, sample_seed=seed)
        perm = np.random.default_rng(seed).permutation(len(cloud))
        np.testing.assert_array_equal(model.transform(cloud[perm]), model.transform(cloud)[perm])


@pytest.mark.parametrize("model", ["fitted", "scene"])
def test_threads_give_the_same_descriptors(model, fitted, monkeypatch):
    """The compiled passes shared between threads: the same bytes as on one thread (the
    scene model also threads its normal and eigenvalue attributes)."""
    model = fitted if model == "fitted" else RPointHopTransformer.pretrained("scene")
    cloud = make_blob(900, shape_seed=12)
    one = model.set_params(n_jobs=1).transform(cloud)
    calls = []
    original = threads_module.map_threads

    def spy(func, items, n_threads):
        calls.append((len(items), n_threads))
        return original(func, items, n_threads)

    monkeypatch.setattr(threads_module, "map_threads", spy)
    beside = []
    start = hops.start_beside
    monkeypatch.setattr(hops, "start_beside", lambda f, *a: beside.append(f) or start(f, *a))
    for n_jobs in (2, 3):
        threaded = model.set_params(n_jobs=n_jobs).transform(cloud)
        np.testing.assert_array_equal(threaded, one)
    model.set_params(n_jobs=None)
    assert calls and all(n >= 2 for _, n in calls) and any(items >= 2 for items, _ in calls)
    # The farthest point sample was drawn beside the frames pass, and changed nothing.
    assert len(beside) == 2


@pytest.mark.parametrize("for_fit", [True, False])
def test_samples_drawn_beside_the_frames_pass_give_the_same_geometry(fitted, for_fit, monkeypatch):
    """On two threads the farthest point sample is drawn while the frames pass runs,
    which keeps every row's neighbours until the samples select theirs: the same hop
    structure, to the bit, as on one thread (where the sample comes first)."""
    config = fitted._hop_config()
    points = make_blob(700, shape_seed=3)
    one = hops.build_geometry(points, config, for_fit, n_threads=1)
    beside = []
    start = hops.start_beside
    monkeypatch.setattr(hops, "start_beside", lambda f, *a: beside.append(f) or start(f, *a))
    two = hops.build_geometry(points, config, for_fit, n_threads=2)
    assert len(beside) == 1
    np.testing.assert_array_equal(one.hop1_attributes, two.hop1_attributes)
    assert len(one.hops) == len(two.hops) >= 2
    for a, b in zip(one.hops, two.hops, strict=True):
        np.testing.assert_array_equal(a.neighbours, b.neighbours)
        np.testing.assert_array_equal(a.bins, b.bins)
        assert a.n_sources == b.n_sources


def test_every_core_by_default_within_the_limits_a_user_sets(monkeypatch):
    """``n_jobs=None`` means every core for one cloud's kernels, as Open3D's code uses;
    joblib's ``parallel_config``, an explicit ``n_jobs``, OpenMP's limits and joblib's
    workers bound it."""
    from joblib import Parallel, delayed, effective_n_jobs, parallel_config
    from threadpoolctl import threadpool_limits

    openmp_limits = threads_module._openmp_limits
    monkeypatch.setattr(threads_module, "cpu_count", lambda: 8)
    monkeypatch.setattr(threads_module, "_openmp_limits", lambda: [])
    kernel_threads = threads_module.kernel_threads
    assert kernel_threads(None) == threads_module.available_threads()
    assert kernel_threads(1) == 1 and kernel_threads(3) == 3
    assert kernel_threads(-1) == effective_n_jobs(-1)  # joblib's count of the cores
    with parallel_config(n_jobs=2):
        assert kernel_threads(None) == 2
    in_workers = Parallel(n_jobs=2, backend="threading")(
        delayed(kernel_threads)(None) for _ in "ab"
    )
    assert in_workers == [1, 1]
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert kernel_threads(None) == 3
    monkeypatch.delenv("OMP_NUM_THREADS")
    monkeypatch.setattr(threads_module, "_openmp_limits", openmp_limits)
    with threadpool_limits(limits=1, user_api="openmp"):
        if openmp_limits():  # an OpenMP library is loaded (scikit-learn's)
            assert kernel_threads(None) == 1


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


def test_map_threads_shares_many_items_between_the_threads():
    """The calling thread keeps taking items while the pool's thread works, instead of
    running the first and waiting for the other thread to run all the rest."""
    import threading
    import time

    from o3d_rpointhop._utils.threads import map_threads

    ran = []

    def step(k):
        time.sleep(0.01)  # releases the GIL, as the kernels do
        ran.append((k, threading.current_thread() is threading.main_thread()))

    map_threads(step, [(k,) for k in range(12)], 2)
    assert sorted(k for k, _ in ran) == list(range(12))
    on_caller = sum(caller for _, caller in ran)
    assert 2 <= on_caller <= 10


def test_start_beside_runs_beside_the_callers_blocks():
    """Work started beside holds a pool thread: every block still runs while it is held
    (the caller takes the busy thread's share), and the future gives the result."""
    import threading

    from o3d_rpointhop._utils.threads import run_blocks, start_beside

    release = threading.Event()
    future = start_beside(lambda x: x * 2 if release.wait(30) else None, 21)
    seen = []

    def block(lo, hi):
        seen.append((lo, hi, release.is_set()))
        if len(seen) == 8:
            release.set()  # every block ran while the pool's thread was held

    run_blocks(block, 100, 2, per_thread=4)
    assert sorted(seen) == [(lo, min(lo + 13, 100), False) for lo in range(0, 100, 13)]
    assert future.result(timeout=30) == 42


def test_start_beside_inside_the_pool_runs_at_once():
    """Started from a thread of the pool, the work runs in that thread at once: no
    wait for a pool thread that may be the caller."""
    from o3d_rpointhop._utils.threads import map_threads, start_beside

    results = []

    def item(k):
        results.append(start_beside(lambda x: x + 1, k).result(timeout=30))

    map_threads(item, [(k,) for k in range(6)], 2)
    assert sorted(results) == [1, 2, 3, 4, 5, 6]


def test_run_blocks_cuts_at_multiples_of_the_alignment():
    from o3d_rpointhop._utils.threads import run_blocks

    seen = []
    run_blocks(lambda lo, hi, tag: seen.append((lo, hi, tag)), 1000, 3, "x", align=64)
    assert sorted(seen) == [(0, 384, "x"), (384, 768, "x"), (768, 1000, "x")]
    seen.clear()
    run_blocks(lambda lo, hi: seen.append((lo, hi)), 10, 4, align=64)
    assert seen == [(0, 10)]
    run_blocks(lambda lo, hi: seen.append((lo, hi)), 0, 4)
    assert seen == [(0, 10)]


# ----------------------------------------------------------------------------- memory
@pytest.mark.slow
def test_describing_holds_little_beyond_the_output():
    """Peak resident memory of describing 100k points, over the process's peak after
    describing a small cloud (libraries and compiled kernels loaded): about 1.5 kB per
    point, 0.5 kB of it the 128-axis output. Folding the last hop at this size (3.3
    kB), or holding the output twice, puts it above 2 kB. (Measured in a fresh
    process: numba's arrays are not seen by tracemalloc.)"""
    import subprocess
    import sys

    code = (
        "import resource\n"
        "from o3d_rpointhop import RPointHopTransformer\n"
        "from o3d_rpointhop.datasets import make_object\n"
        "model = RPointHopTransformer.pretrained(n_components=128).set_params(n_jobs=1)\n"
        "model.transform(make_object(3000, shape_seed=3, sample_seed=2))\n"
        "points = make_object(100000, shape_seed=3, sample_seed=1)\n"
        "before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "out = model.transform(points)\n"
        "after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "print(out.shape[0], (after - before) * 1024 / len(points))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    n, per_point = out.stdout.split()
    assert int(n) == 100000
    assert float(per_point) < 2000
