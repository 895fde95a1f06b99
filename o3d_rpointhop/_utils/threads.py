"""Thread limits: BLAS kept to one thread inside the descriptor's own block loop, and
Open3D's registration code run on one thread so that seeded runs repeat bit for bit.

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

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import AbstractContextManager, contextmanager

import open3d as o3d
from threadpoolctl import ThreadpoolController

__all__ = ["even_chunks", "map_threads", "one_blas_thread", "repeatable_open3d"]

_CONTROLLER: list[ThreadpoolController] = []


def one_blas_thread() -> AbstractContextManager:
    """A context in which BLAS runs on one thread (restored on exit)."""
    if not _CONTROLLER:
        _CONTROLLER.append(ThreadpoolController())  # inspects the loaded libraries once
    return _CONTROLLER[0].limit(limits=1, user_api="blas")


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


def map_threads(func: Callable, items: Sequence, n_threads: int) -> None:
    """``func(*item)`` for every item, on ``n_threads`` threads started for this call only
    (in the calling thread when ``n_threads <= 1``). Each call writes its own part of
    some output, so the order in which calls finish does not matter; an exception
    raised by a call is raised here (the first failing item's, in item order), after
    the other calls have ended. The work is numpy, scipy and Open3D calls that release
    the GIL."""
    if n_threads <= 1 or len(items) <= 1:
        for item in items:
            func(*item)
        return
    workers = min(n_threads, len(items))
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="rpointhop") as pool:
        for future in [pool.submit(func, *item) for item in items]:
            future.result()


def even_chunks(n: int, largest: int, n_threads: int, smallest: int = 1) -> list[tuple[int, int]]:
    """``(start, stop)`` bounds of ``range(n)`` in equal chunks for ``n_threads``
    threads: ``n_threads`` times as many chunks as chunks of at most ``largest`` need
    (so the threads finish together and the chunks in flight at once hold about
    ``largest`` items in all), but none under ``smallest`` items unless ``n`` is."""
    n_threads = max(1, n_threads)
    count = n_threads * max(1, -(-n // largest))
    count = max(1, min(count, n // max(1, smallest)))
    size = max(1, -(-n // count))
    return [(start, min(n, start + size)) for start in range(0, n, size)]
