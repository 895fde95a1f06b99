"""BLAS threads: kept to one inside the descriptor's own block loop.

The transform's matrix products are small (a block of 128 points against at most 128
principal axes) and the loop runs on ``n_jobs`` threads of its own; a multi-threaded
BLAS underneath would be a second, hidden pool. Measured on the development machine
(2 cores, a 4400-point 3DMatch fragment, 128 axes): 0.72 s per transform with BLAS's
own threads against 0.42-0.46 s on one BLAS thread when another process keeps one core
busy, and the same time (0.28-0.35 s) on an idle machine.
"""

from __future__ import annotations

from contextlib import AbstractContextManager

from threadpoolctl import ThreadpoolController

__all__ = ["one_blas_thread"]

_CONTROLLER: list[ThreadpoolController] = []


def one_blas_thread() -> AbstractContextManager:
    """A context in which BLAS runs on one thread (restored on exit)."""
    if not _CONTROLLER:
        _CONTROLLER.append(ThreadpoolController())  # inspects the loaded libraries once
    return _CONTROLLER[0].limit(limits=1, user_api="blas")
