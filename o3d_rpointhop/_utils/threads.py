"""Thread limits: how many threads the compiled kernels run on (every core unless told
otherwise), BLAS kept to one thread inside the descriptor's own blocks, and Open3D's
registration code run on one thread so that seeded runs repeat bit for bit.

BLAS: the transform's matrix products are small (a block of 128 points against at most 128
principal axes) and the loop runs on ``n_jobs`` threads of its own; a multi-threaded
BLAS underneath would be a second, hidden pool. Measured on the development machine
(2 cores, 128 axes): a 4400-point 3DMatch fragment took 0.72 s per transform with
BLAS's own threads against 0.42-0.46 s on one BLAS thread while another process kept
one core busy; on an idle machine one BLAS thread costs 8-10 % (median of 7: 269
against 245 ms at 4400 points, 66 against 61 ms at 1024), the price of honouring
``n_jobs``.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor, wait
from contextlib import AbstractContextManager, contextmanager

import open3d as o3d
from joblib import cpu_count, effective_n_jobs, parallel_config
from joblib.parallel import get_active_backend
from threadpoolctl import ThreadpoolController

__all__ = [
    "available_threads",
    "kernel_threads",
    "map_threads",
    "run_blocks",
    "start_beside",
    "one_blas_thread",
    "blas_threads",
    "repeatable_open3d",
    "core_budget",
]

_CONTROLLER: list[ThreadpoolController] = []
_OPENMP: list[ThreadpoolController] = []


def available_threads() -> int:
    """The threads compiled kernels may use when nothing says otherwise: every core
    this process may run on (``joblib.cpu_count``: affinity and container limits),
    within OpenMP's limit as scikit-learn's OpenMP code reads it (``OMP_NUM_THREADS``,
    which joblib's and Dask's workers set to their share, and
    ``threadpoolctl.threadpool_limits(..., user_api="openmp")``)."""
    limits = [cpu_count(), *_openmp_limits()]
    env = os.environ.get("OMP_NUM_THREADS", "")
    if env.strip().isdigit() and int(env) > 0:
        limits.append(int(env))
    return max(1, min(limits))


def _openmp_limits() -> list[int]:
    """The current thread limit of every OpenMP library loaded (scikit-learn's)."""
    if not _OPENMP:
        _OPENMP.append(ThreadpoolController())
    return [lib.num_threads for lib in _OPENMP[0].select(user_api="openmp").lib_controllers]


def kernel_threads(n_jobs: int | None) -> int:
    """Threads for one cloud's compiled kernels, from an estimator's ``n_jobs``.

    ``None`` means :func:`available_threads` (every core, as Open3D's and scikit-learn's
    compiled code use), unless ``joblib.parallel_config(n_jobs=...)`` sets a number, or
    one thread inside a joblib worker (the workers are the parallelism); an int is
    joblib's (``-1`` every core), at most the available threads. The results do not
    depend on it: every kernel splits its work into pieces of a fixed size.
    """
    if n_jobs is None:
        backend, n_jobs = get_active_backend()
        if n_jobs is None:
            return 1 if getattr(backend, "nesting_level", 0) > 0 else available_threads()
    return max(1, min(effective_n_jobs(n_jobs), available_threads()))


def one_blas_thread() -> AbstractContextManager:
    """A context in which BLAS runs on one thread (restored on exit)."""
    return blas_threads(1)


def blas_threads(n_threads: int) -> AbstractContextManager:
    """A context in which BLAS runs on at most ``n_threads`` threads (restored on
    exit)."""
    if not _CONTROLLER:
        _CONTROLLER.append(ThreadpoolController())  # inspects the loaded libraries once
    return _CONTROLLER[0].limit(limits=max(1, int(n_threads)), user_api="blas")


@contextmanager
def repeatable_open3d() -> Iterator[None]:
    """Run Open3D's registration code on one thread, so a seeded run repeats bit for bit.

    With several threads, Open3D's RANSAC draws from one shared random generator in an
    order set by thread timing (different results from one seed: 3 of 53 ModelNet40
    pairs), and ICP sums its residuals in a timing-dependent order (last-digit
    differences). One thread costs about 10 % on RANSAC and ICP over 40k points takes
    50 ms instead of 30 ms.
    """
    previous = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(1)
    try:
        yield
    finally:
        o3d.utility.set_max_threads(previous)


@contextmanager
def core_budget(n_jobs: int | None) -> Iterator[None]:
    """Run the enclosed work on ``n_jobs`` cores: the compiled kernels and joblib tasks
    of every component whose own ``n_jobs`` is None (``joblib.parallel_config``),
    Open3D's threads (normals, k-d tree searches) and BLAS's (the descriptor matches'
    products). ``None`` changes nothing: every core, or what an enclosing
    ``parallel_config`` says; ``-1`` is every core."""
    if n_jobs is None:
        yield
        return
    cores = max(1, min(effective_n_jobs(n_jobs), available_threads()))
    previous = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(cores)
    try:
        with parallel_config(n_jobs=n_jobs), blas_threads(cores):
            yield
    finally:
        o3d.utility.set_max_threads(previous)


def map_threads(func: Callable, items: Sequence, n_threads: int) -> None:
    """``func(*item)`` for every item, on up to ``n_threads`` threads: the calling thread
    and a pool kept for the process (the calling thread alone when ``n_threads <= 1``,
    and inside the pool's own threads). Every thread takes the next item not yet taken
    until none is left, so many small items (blocks of a matrix product, hypotheses to
    score) are shared evenly. Each call writes its own part of some output, so which
    thread runs it and the order in which calls finish do not matter; an exception
    raised by a call is raised here (the first failing item's, in item order), after
    the other calls have ended. The work is compiled kernels, numpy and Open3D calls
    that release the GIL. A process forked from this one starts a pool of its own
    (threads do not survive a fork)."""
    inside = threading.current_thread().name.startswith(_PREFIX)
    if n_threads <= 1 or len(items) <= 1 or inside:
        for item in items:
            func(*item)
        return
    taken = iter(range(len(items)))
    lock = threading.Lock()
    errors: dict[int, Exception] = {}
    stop = threading.Event()

    def drain() -> None:
        while not stop.is_set():
            with lock:
                k = next(taken, None)
            if k is None:
                return
            try:
                func(*items[k])
            except Exception as error:  # raised by the caller once every call has ended
                errors[k] = error
            except BaseException:
                stop.set()  # an interrupt: take no more items
                raise

    workers = min(n_threads, len(items))
    pool = _executor(workers - 1)  # the calling thread is one
    futures = [pool.submit(drain) for _ in range(workers - 1)]
    try:
        drain()
    finally:
        wait(futures)
    for future in futures:
        future.result()
    if errors:
        raise errors[min(errors)]


def run_blocks(
    func: Callable, n: int, n_threads: int, *args, align: int = 1, per_thread: int = 1
) -> None:
    """``func(start, stop, *args)`` over ``range(n)`` cut into ``per_thread`` contiguous
    pieces per thread, every piece starting at a multiple of ``align`` (for kernels
    whose work restarts there, so that any cut gives the same result). More pieces than
    threads let a thread that joins late (busy with work started by
    :func:`start_beside`) still take a share."""
    if n <= 0:
        return
    align = max(1, align)
    pieces = max(1, min(n_threads * max(1, per_thread), _ceil_div(n, align)))
    size = _ceil_div(_ceil_div(n, pieces), align) * align
    bounds = [(start, min(n, start + size), *args) for start in range(0, n, size)]
    map_threads(func, bounds, n_threads)


def start_beside(func: Callable, *args) -> Future:
    """Start ``func(*args)`` on a thread of the process's pool and return its future:
    the caller works meanwhile (its :func:`map_threads` calls find the pool thread busy
    until ``func`` returns, and take that thread's items themselves). ``func`` should
    release the GIL (a ``nogil`` kernel); only worth it with two threads or more. In a
    thread of the pool itself it runs at once (it would otherwise wait for a thread
    that may be the caller)."""
    if threading.current_thread().name.startswith(_PREFIX):
        done: Future = Future()
        done.set_result(func(*args))
        return done
    return _executor(1).submit(func, *args)


def _ceil_div(a: int, b: int) -> int:
    return -(-a // b)


_PREFIX = "o3d-rpointhop"
_POOL: dict = {}


def _executor(workers: int) -> ThreadPoolExecutor:
    """The process's pool, grown to at least ``workers`` threads."""
    with _POOL_LOCK:
        pool = _POOL.get("executor")
        if pool is None or _POOL["workers"] < workers:
            if pool is not None:
                pool.shutdown(wait=False)
            pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix=_PREFIX)
            _POOL.update(executor=pool, workers=workers)
        return pool


_POOL_LOCK = threading.Lock()
os.register_at_fork(after_in_child=_POOL.clear)
