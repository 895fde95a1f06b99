"""Running one benchmark method on one pair, on a thread budget both sides share."""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
import open3d as o3d

from .._utils.threads import core_budget
from ..registration import RegistrationResult, RegistrationWarning
from .methods import METHODS, claimed_by

__all__ = [
    "THREAD_BUDGETS",
    "MethodRun",
    "current_thread_budget",
    "run_method",
    "thread_budget",
]


#: The thread budgets a benchmark can give both sides: ``"one"`` thread each (this
#: library's kernels and Open3D's code alike), or ``"all"``: every core each (this
#: library's kernels, and Open3D's normals, features and ICP; Open3D's RANSAC and FGR
#: stay on one thread, the only way a seed repeats them).
THREAD_BUDGETS = ("one", "all")
_BUDGET = ["one"]


@contextmanager
def thread_budget(name: str) -> Iterator[None]:
    """Run the benchmarks inside on the thread budget ``name`` (see
    :data:`THREAD_BUDGETS`)."""
    if name not in THREAD_BUDGETS:
        raise ValueError(f"thread budget must be one of {THREAD_BUDGETS}, got {name!r}")
    previous = _BUDGET[0]
    _BUDGET[0] = name
    try:
        yield
    finally:
        _BUDGET[0] = previous


def current_thread_budget() -> str:
    """The thread budget methods run on now."""
    return _BUDGET[0]


@contextmanager
def _budgeted() -> Iterator[None]:
    """This library's kernels (``joblib.parallel_config``) and Open3D on the budget."""
    with core_budget(1 if _BUDGET[0] == "one" else -1):
        yield


@dataclass(frozen=True)
class MethodRun:
    """What one method did on one pair.

    Attributes
    ----------
    transformation : ndarray of shape (4, 4)
        Source to target.
    seconds : float
        Wall time, model loading left out.
    claimed : bool or None
        Whether the method's own flags call the result trustworthy (``register()``:
        converged and not ambiguous; KISS-Matcher: valid); None for a method without
        such a flag. Precision is measured over the claimed results.
    result : RegistrationResult or None
        The whole result, for the methods that run through ``register()`` (what the
        records' per-pair diagnostics read); None for the others.
    """

    transformation: np.ndarray
    seconds: float
    claimed: bool | None
    result: Any = None


def run_method(
    name: str,
    source: np.ndarray,
    target: np.ndarray,
    *,
    descriptor,
    voxel: float,
    seed: int = 0,
    viewpoints=None,
) -> MethodRun:
    """Run one method on one pair.

    Parameters
    ----------
    descriptor : RPointHopTransformer
        The model the R-PointHop methods use (``rpointhop-loso``: the pair's
        leave-one-scene-out model; ``rpointhop-scene`` always uses the shipped scene
        model).
    voxel : float
        Resolution of the FPFH recipe and of ICP alone (0.05 for unit-sphere objects, as
        in the Open3D tutorial).
    viewpoints : None or (array-like, array-like), default=None
        The sensor positions of the source and the target, each in its own
        coordinates: passed to every descriptor (R-PointHop's frames, FPFH's normals, in
        this library and in Open3D's recipes); KISS-Matcher takes none.

    Returns
    -------
    MethodRun
    """
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; choose from {sorted(METHODS)}")
    method = METHODS[name]
    if not method.available():
        raise ValueError(f"{name} is not installed: {method.install}")
    descriptor = method.preload(descriptor)
    # Flagged results are scored like any other; the flags' warnings would only repeat.
    # Open3D's recipe warns when its mutual filter leaves few matches; the result says
    # it. Both sides run on the same thread budget (thread_budget).
    with (
        warnings.catch_warnings(),
        o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error),
        _budgeted(),
    ):
        warnings.simplefilter("ignore", RegistrationWarning)
        start = time.perf_counter()
        out = method.run(source, target, descriptor, voxel, seed, viewpoints)
        seconds = time.perf_counter() - start
    if isinstance(out, RegistrationResult):
        return MethodRun(out.transformation, seconds, claimed_by(out), out)
    transformation, claimed = out
    return MethodRun(transformation, seconds, claimed)
