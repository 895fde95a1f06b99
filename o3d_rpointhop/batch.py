"""Many clouds and many pairs at once, on joblib: local processes, or a Dask cluster.

Everything here goes through ``joblib.Parallel``, so the backend is the caller's
choice. On one machine, ``n_jobs=-1`` uses every core. On a Dask cluster::

    from dask.distributed import Client
    from joblib import parallel_config

    client = Client("scheduler-address:8786")  # or LocalCluster()
    with parallel_config(backend="dask", n_jobs=-1):
        descriptors = transform_many(model, clouds)
        results = register_many(pairs)

Clouds become plain float64 arrays before they are sent anywhere (Open3D objects do not
cross process boundaries), and the workers run one thread each, so ``n_jobs`` is the
whole of the parallelism.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np
from joblib import Parallel, delayed

from ._progress import progress_bar
from ._validation import as_points

__all__ = ["parallel_map", "transform_many", "register_many"]


def parallel_map(
    func: Callable,
    items: Sequence[tuple],
    *,
    n_jobs: int | None = None,
    progress: bool | None = None,
    desc: str = "",
    unit: str = "item",
) -> list:
    """``[func(*item) for item in items]`` through ``joblib.Parallel``, in order.

    Parameters
    ----------
    func : callable
    items : sequence of tuple
        Positional arguments of each call.
    n_jobs : int, default=None
        joblib's ``n_jobs``; ``None`` defers to ``joblib.parallel_config`` (1 without
        one).
    progress : bool, default=None
        A bar on stderr as results come in; ``None``: only when stderr is a terminal.
    desc, unit : str
        The bar's label and unit.
    """
    items = list(items)
    bar = progress_bar(len(items), desc=desc, unit=unit, enabled=progress, large=len(items) > 1)
    results = Parallel(n_jobs=n_jobs, return_as="generator")(delayed(func)(*item) for item in items)
    out = []
    try:
        for result in results:
            out.append(result)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return out


def _single_threaded(estimator: Any) -> Any:
    """A shallow copy that runs one thread and shows no bar per task (the tasks are the
    parallelism); the caller's object is left as it is."""
    if estimator is None or not hasattr(estimator, "get_params"):
        return estimator
    params = estimator.get_params(deep=False)
    updates = {k: v for k, v in (("n_jobs", None), ("progress", False)) if k in params}
    if not updates:
        return estimator
    worker = copy.copy(estimator)
    worker.set_params(**updates)
    return worker


def _describe(descriptor: Any, points: np.ndarray) -> np.ndarray:
    return descriptor.transform(points)


def transform_many(
    descriptor: Any,
    clouds: Iterable[Any],
    *,
    n_jobs: int | None = None,
    progress: bool | None = None,
) -> list[np.ndarray]:
    """Describe many clouds in parallel; one descriptor array per cloud, in order.

    Parameters
    ----------
    descriptor : fitted transformer
        An ``RPointHopTransformer`` or ``FPFHTransformer`` (anything with ``transform``).
    clouds : iterable of array-like (n, 3) or Open3D point clouds
        Sizes may differ. Open3D clouds are read as their points (FPFH then estimates
        normals itself).
    n_jobs : int, default=None
        Parallel tasks (see :func:`parallel_map`): ``-1`` for every core or every Dask
        worker.
    progress : bool, default=None

    Returns
    -------
    list of ndarray of shape (n_i, n_features)
    """
    arrays = [as_points(c, f"clouds[{i}]") for i, c in enumerate(clouds)]
    worker = _single_threaded(descriptor)
    return parallel_map(
        _describe,
        [(worker, a) for a in arrays],
        n_jobs=n_jobs,
        progress=progress,
        desc="describe",
        unit="cloud",
    )


def _register(source: np.ndarray, target: np.ndarray, descriptor: Any, options: dict):
    from .registration import register

    return register(source, target, descriptor, **options)


def register_many(
    pairs: Iterable[tuple[Any, Any]],
    descriptor: Any = None,
    *,
    n_jobs: int | None = None,
    progress: bool | None = None,
    **options: Any,
) -> list:
    """Register many ``(source, target)`` pairs in parallel, with one setting.

    Parameters
    ----------
    pairs : iterable of (source, target)
        Arrays or Open3D point clouds.
    descriptor : transformer, default=None
        As in :func:`~o3d_rpointhop.register`; ``None`` is its default descriptor, loaded
        once and shipped to the workers.
    n_jobs : int, default=None
        Parallel tasks (see :func:`parallel_map`).
    progress : bool, default=None
    **options
        Any other keyword of :func:`~o3d_rpointhop.register` (``global_method``,
        ``refine``, ``voxel_size``, ``seed``, ...).

    Returns
    -------
    list of RegistrationResult
        In the order of ``pairs``; the same as registering each pair alone.
    """
    from .rpointhop import default_descriptor

    items = []
    for k, pair in enumerate(pairs):
        try:
            source, target = pair
        except (TypeError, ValueError):
            raise ValueError(f"pairs[{k}] is not a (source, target) pair") from None
        items.append((as_points(source, f"pairs[{k}][0]"), as_points(target, f"pairs[{k}][1]")))
    worker = _single_threaded(descriptor if descriptor is not None else default_descriptor())
    return parallel_map(
        _register,
        [(s, t, worker, options) for s, t in items],
        n_jobs=n_jobs,
        progress=progress,
        desc="register",
        unit="pair",
    )
