"""BLAS threads: kept to one inside the descriptor's own block loop.

The transform's matrix products are small (a block of 128 points against at most 128
principal axes) and the loop runs on ``n_jobs`` threads of its own; a multi-threaded
BLAS underneath would be a second, hidden pool. Measured on the development machine
(2 cores, 128 axes): a 4400-point 3DMatch fragment took 0.72 s per transform with
BLAS's own threads against 0.42-0.46 s on one BLAS thread while another process kept
one core busy; on an idle machine one BLAS thread costs 8-10 % (median of 7: 269
against 245 ms at 4400 points, 66 against 61 ms at 1024), the price of honouring
``n_jobs``.
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
