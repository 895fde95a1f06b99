"""Parallel maps over clouds and pairs, on joblib (local processes, or a Dask cluster
through ``joblib.parallel_config(backend="dask")``)."""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from joblib import Parallel, delayed

from .progress import progress_bar

__all__ = ["parallel_map", "worker_copy", "map_clouds"]


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


def worker_copy(estimator: Any) -> Any:
    """A shallow copy for one task of a joblib map: ``n_jobs=None`` (one thread inside a
    worker process, where the tasks are the parallelism; every core when the map runs
    in this process, one task after another) and no bar per task. The caller's object
    is left as it is."""
    if estimator is None or not hasattr(estimator, "get_params"):
        return estimator
    params = estimator.get_params(deep=False)
    updates = {k: v for k, v in (("n_jobs", None), ("progress", False)) if k in params}
    if not updates:
        return estimator
    worker = copy.copy(estimator)
    worker.set_params(**updates)
    return worker


def map_clouds(describe: Callable, clouds: list, kind: str, n_jobs: int | None, *per_cloud: list):
    """Apply ``describe(cloud, *extras)`` to every cloud and answer in the input's form.

    ``describe`` is an estimator's bound method. One cloud runs in this process; several
    run as ``n_jobs`` joblib tasks (:func:`parallel_map`), each on a copy of the
    estimator (:func:`worker_copy`: one thread in a worker process, every core when the
    tasks run here one after another), with a progress bar when the estimator's
    ``progress`` asks for one. The result is one array for ``kind="single"``, a stacked
    3-D array for ``"batch"`` and a list for ``"list"`` (see
    :func:`~o3d_rpointhop._utils.validation.as_cloud_list`).
    """
    args = list(zip(clouds, *per_cloud, strict=True))
    if len(args) == 1:
        out = [describe(*args[0])]
    else:
        owner = describe.__self__
        worker = getattr(worker_copy(owner), describe.__name__)
        out = parallel_map(
            worker,
            args,
            n_jobs=n_jobs,
            progress=getattr(owner, "progress", False),
            desc="describe",
            unit="cloud",
        )
    if kind == "single":
        return out[0]
    if kind == "batch":
        return np.stack(out)
    return out
