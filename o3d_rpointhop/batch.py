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

from collections.abc import Iterable
from numbers import Integral
from typing import Any

import numpy as np

from ._utils.parallel import parallel_map, worker_copy
from ._utils.params import HasMethods, validate_params
from ._utils.validation import as_points
from .registration import register
from .registration.defaults import default_descriptor

__all__ = ["parallel_map", "transform_many", "register_many"]


def _describe(descriptor: Any, points: np.ndarray) -> np.ndarray:
    return descriptor.transform(points)


@validate_params(
    {
        "descriptor": [HasMethods(["transform"])],
        "clouds": "no_validation",
        "n_jobs": [None, Integral],
        "progress": [None, "boolean"],
    },
    prefer_skip_nested_validation=False,  # the descriptor is the caller's, checked by itself
)
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
        Cores to use: ``None`` every core, one cloud after another on the compiled
        kernels' threads; an int ``k``, ``k`` joblib tasks of one thread each; ``-1``
        every core, or every Dask worker.
    progress : bool, default=None

    Returns
    -------
    list of ndarray of shape (n_i, n_features)
    """
    arrays = [as_points(c, f"clouds[{i}]") for i, c in enumerate(clouds)]
    worker = worker_copy(descriptor)
    return parallel_map(
        _describe,
        [(worker, a) for a in arrays],
        n_jobs=n_jobs,
        progress=progress,
        desc="describe",
        unit="cloud",
    )


def _register(source: np.ndarray, target: np.ndarray, descriptor: Any, options: dict):
    return register(source, target, descriptor, **options)


@validate_params(
    {
        "pairs": "no_validation",
        "descriptor": [None, HasMethods(["transform"])],
        "n_jobs": [None, Integral],
        "progress": [None, "boolean"],
    },
    prefer_skip_nested_validation=False,  # register() checks its options
)
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
        Cores to use, as in :func:`transform_many`, over the pairs.
    progress : bool, default=None
    **options
        Any other keyword of :func:`~o3d_rpointhop.register` (``global_method``,
        ``refine``, ``voxel_size``, ``random_state``, ...).

    Returns
    -------
    list of RegistrationResult
        In the order of ``pairs``; the same as registering each pair alone.
    """
    items = []
    for k, pair in enumerate(pairs):
        try:
            source, target = pair
        except (TypeError, ValueError):
            raise ValueError(f"pairs[{k}] is not a (source, target) pair") from None
        items.append((as_points(source, f"pairs[{k}][0]"), as_points(target, f"pairs[{k}][1]")))
    worker = worker_copy(descriptor if descriptor is not None else default_descriptor())
    return parallel_map(
        _register,
        [(s, t, worker, options) for s, t in items],
        n_jobs=n_jobs,
        progress=progress,
        desc="register",
        unit="pair",
    )
