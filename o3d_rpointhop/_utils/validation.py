"""Input checking shared by every public entry point.

Everything that accepts point clouds goes through :func:`as_points` (one cloud) or
:func:`as_cloud_list` (one or many), so the error messages are the same everywhere.
"""

from __future__ import annotations

import numbers
import warnings
from typing import Any

import numpy as np
import scipy.sparse as sp

__all__ = [
    "as_points",
    "as_cloud_list",
    "as_viewpoints",
    "check_rigid_transformation",
    "coarse_float32",
    "renamed_seed",
    "PrecisionWarning",
    "is_open3d_cloud",
    "is_positive_number",
    "MAX_COORDINATE",
]


def renamed_seed(random_state: Any, seed: Any, where: str) -> Any:
    """``random_state``, or the deprecated ``seed`` when one is given (``None`` and
    ``"deprecated"`` mean not given), with a ``FutureWarning`` naming ``where``."""
    if seed is None or (isinstance(seed, str) and seed == "deprecated"):
        return random_state
    warnings.warn(
        f"{where}: 'seed' was renamed 'random_state' (scikit-learn's name); 'seed' will "
        "be removed in a future release",
        FutureWarning,
        stacklevel=3,
    )
    return seed


#: Largest coordinate accepted: squared distances of larger ones overflow float64.
MAX_COORDINATE = 1e150


def is_open3d_cloud(obj: Any) -> bool:
    """Return True for a legacy or tensor Open3D ``PointCloud``."""
    module = type(obj).__module__ or ""
    return type(obj).__name__ == "PointCloud" and module.startswith("open3d")


def _points_of_open3d(cloud: Any) -> np.ndarray:
    if hasattr(cloud, "points"):  # legacy open3d.geometry.PointCloud
        return np.asarray(cloud.points)
    # tensor open3d.t.geometry.PointCloud
    if "positions" not in cloud.point:
        raise ValueError("the Open3D tensor PointCloud has no 'positions' attribute")
    return cloud.point.positions.cpu().numpy()


def as_points(X: Any, name: str = "X", min_points: int = 1) -> np.ndarray:
    """Validate one point cloud and return it as a C-contiguous float64 ``(n, 3)`` array.

    Parameters
    ----------
    X : array-like of shape (n_points, 3) or open3d.geometry.PointCloud
        The cloud.
    name : str, default="X"
        How the cloud is called in error messages.
    min_points : int, default=1
        Fewest points accepted.

    Returns
    -------
    points : ndarray of shape (n_points, 3), dtype float64
        C-contiguous, writeable, in a buffer format Open3D accepts: ``X`` itself when it
        already is such an array (so callers must not write to it), else one copy.

    Raises
    ------
    ValueError
        If the cloud is not real-valued, is not of shape ``(n, 3)``, has fewer than
        ``min_points`` points, or holds NaN or infinite coordinates.
    TypeError
        If the cloud is a scipy sparse matrix.
    """
    if is_open3d_cloud(X):
        arr = _points_of_open3d(X)
    elif sp.issparse(X):
        raise TypeError(
            f"{name} is a sparse matrix; sparse input is not supported: pass a dense "
            "(n_points, 3) array of xyz coordinates"
        )
    else:
        try:
            arr = np.asarray(X)
        except Exception as exc:  # ragged nested sequences and the like
            raise ValueError(f"{name} could not be read as an array of points: {exc}") from exc
    if np.iscomplexobj(arr):
        raise ValueError(f"Complex data not supported: {name} must hold real xyz coordinates")
    if arr.dtype == object:
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{name} must hold real numbers: {exc}") from exc
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    if arr.ndim != 2:
        raise ValueError(
            f"{name} must be an (n_points, 3) array of xyz coordinates, got shape {arr.shape}. "
            "Reshape your data, e.g. with X.reshape(-1, 3) for a flat list of coordinates"
        )
    if arr.shape[1] < 3:  # worded as scikit-learn's check_array, which its checks expect
        raise ValueError(
            f"{name} has {arr.shape[1]} feature(s) (shape={arr.shape}) while a minimum of 3 is "
            "required: it must be an (n_points, 3) array of xyz coordinates"
        )
    if arr.shape[1] > 3:
        raise ValueError(
            f"{name} has {arr.shape[1]} feature(s) (shape={arr.shape}), not 3: it must be an "
            "(n_points, 3) array of xyz coordinates; pass X[:, :3] for the coordinates alone"
        )
    n = arr.shape[0]
    if n == 0:
        raise ValueError(f"{name} is an empty point cloud")
    if n < min_points:
        raise ValueError(f"{name} has {n} points; at least {min_points} are needed")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if not arr.flags.writeable or memoryview(arr).format != "d":
        # Read-only and memory-mapped arrays, and arrays rebuilt from pickle buffers
        # (joblib's Dask backend: format "=d"), which Open3D's converters refuse: one
        # copy, and the caller's array is never written to.
        arr = arr.copy()
    finite = np.isfinite(arr).all(axis=1)
    if finite.all() and np.abs(arr).max() > MAX_COORDINATE:
        raise ValueError(
            f"{name} has coordinates up to {np.abs(arr).max():.3g}: beyond "
            f"{MAX_COORDINATE:.0e} squared distances overflow; rescale the cloud"
        )
    if not finite.all():
        bad = np.flatnonzero(~finite)
        shown = ", ".join(str(i) for i in bad[:5]) + (", ..." if bad.size > 5 else "")
        raise ValueError(
            f"{name} has {bad.size} point(s) with NaN or infinite coordinates (rows {shown}); "
            "remove them first, e.g. with PointCloud.remove_non_finite_points()"
        )
    return arr


def as_cloud_list(X: Any, name: str = "X") -> tuple[list[np.ndarray], str]:
    """Split ``X`` into a list of validated clouds.

    Parameters
    ----------
    X : array-like or open3d.geometry.PointCloud or sequence of those
        One cloud ``(n, 3)``, a batch ``(n_clouds, n, 3)``, or a list or tuple of clouds
        (arrays or Open3D point clouds, sizes may differ).
    name : str, default="X"
        How the input is called in error messages.

    Returns
    -------
    clouds : list of ndarray of shape (n_i, 3)
    kind : {"single", "batch", "list"}
        What the input was, so results can be returned in the same form.
    """
    if is_open3d_cloud(X) or sp.issparse(X):
        return [as_points(X, name)], "single"
    if isinstance(X, (list, tuple)):
        if len(X) == 0:
            raise ValueError(f"{name} is an empty list of point clouds")
        # A list of 3 numbers per row is one cloud written as nested lists.
        if all(np.ndim(c) == 1 for c in X if not is_open3d_cloud(c)) and not any(
            is_open3d_cloud(c) for c in X
        ):
            return [as_points(X, name)], "single"
        return [as_points(c, f"{name}[{i}]") for i, c in enumerate(X)], "list"
    arr = np.asarray(X) if not isinstance(X, np.ndarray) else X
    if arr.ndim == 3:
        if arr.shape[0] == 0:
            raise ValueError(f"{name} is an empty batch of point clouds")
        return [as_points(c, f"{name}[{i}]") for i, c in enumerate(arr)], "batch"
    return [as_points(arr, name)], "single"


def as_viewpoints(viewpoints: Any, n_clouds: int, name: str = "viewpoints") -> list:
    """Each cloud's sensor position, or None for each, from a user's ``viewpoints``.

    Parameters
    ----------
    viewpoints : None, "origin", array-like of shape (3,) or (n_clouds, 3)
        ``None``: no sensor is known. ``"origin"``: every cloud was seen from its own
        coordinate origin (a scan in its sensor's frame, such as a 3DMatch fragment or
        a LiDAR sweep). One position serves every cloud; ``(n_clouds, 3)`` gives one per
        cloud, in that cloud's coordinates.
    n_clouds : int
    name : str, default="viewpoints"
        How the argument is called in error messages.

    Returns
    -------
    list of (ndarray of shape (3,) or None), one per cloud
    """
    if viewpoints is None:
        return [None] * n_clouds
    if isinstance(viewpoints, str):
        if viewpoints != "origin":
            raise ValueError(f"{name} must be None, 'origin' or positions, got {viewpoints!r}")
        return [np.zeros(3)] * n_clouds
    try:
        arr = np.asarray(viewpoints, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be None, 'origin' or positions: {exc}") from None
    if arr.shape == (3,):
        arr = np.broadcast_to(arr, (n_clouds, 3))
    if arr.shape != (n_clouds, 3):
        raise ValueError(
            f"{name} must be 'origin', one position (3,) or one per cloud ({n_clouds}, 3), "
            f"got shape {arr.shape}"
        )
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} holds NaN or infinite coordinates")
    return [np.array(v) for v in arr]


def is_positive_number(value: Any) -> bool:
    """A finite real number above zero (not a bool)."""
    return (
        isinstance(value, numbers.Real)
        and not isinstance(value, bool)
        and bool(np.isfinite(value))
        and value > 0
    )


def check_rigid_transformation(value: Any, name: str = "init") -> np.ndarray:
    """``value`` as a float64 4x4 rigid transformation; a ValueError naming ``name``
    unless it is finite, 4x4, and its upper-left block a rotation (orthonormal within
    1e-6, determinant +1)."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (4, 4) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be a finite 4x4 matrix, got shape {arr.shape}")
    rot = arr[:3, :3]
    if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
        raise ValueError(f"{name}'s upper-left 3x3 block must be a rotation matrix")
    return arr


class PrecisionWarning(UserWarning):
    """Coordinates stored with less precision than the cloud needs (float32 at survey
    offsets): the points were rounded before any computation could help."""


#: float32 coordinates whose rounding step exceeds this share of the cloud's own extent
#: were rounded too coarsely to register at full precision (survey coordinates).
FLOAT32_RESOLUTION = 1e-5


def coarse_float32(points32: np.ndarray, name: str) -> str | None:
    """What is wrong with float32 coordinates too coarse for their cloud, or None.

    The rounding step of float32 at the cloud's largest coordinate is compared with the
    cloud's own extent (its largest side along an axis), so a small cloud far from the
    origin (a scan in UTM coordinates) is caught, and a large one near it is not.
    """
    points32 = np.asarray(points32)
    if points32.dtype != np.float32 or not len(points32):
        return None
    largest = float(np.abs(points32).max())
    step = float(np.spacing(np.float32(largest)))
    extent = float(np.ptp(points32.astype(np.float64), axis=0).max())
    if step <= FLOAT32_RESOLUTION * extent:
        return None
    return (
        f"{name} holds float32 coordinates up to {largest:.6g}, where float32 resolves "
        f"only {step:.3g}, coarse for a cloud {extent:.3g} across: its points were "
        "already rounded before registration; pass float64 (or coordinates relative to "
        "a local origin) for full precision"
    )
