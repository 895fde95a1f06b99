"""Reading and writing point clouds, with errors that say what went wrong."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import open3d as o3d

from ._validation import as_points

__all__ = ["read_cloud", "write_cloud", "OPEN3D_FORMATS"]

# Extensions open3d.io.read_point_cloud understands.
OPEN3D_FORMATS = (".ply", ".pcd", ".xyz", ".xyzn", ".xyzrgb", ".pts")
_NUMPY_FORMATS = (".npy", ".npz", ".txt", ".csv")


def read_cloud(path: str | os.PathLike) -> o3d.geometry.PointCloud:
    """Read a point cloud from any format Open3D reads, or from numpy/text files.

    Parameters
    ----------
    path : str or path-like
        ``.ply``, ``.pcd``, ``.xyz``, ``.xyzn``, ``.xyzrgb``, ``.pts`` (through Open3D),
        ``.npy`` (an ``(n, 3+)`` array), ``.npz`` (its ``points`` array, or its only
        array), ``.txt`` or ``.csv`` (whitespace- or comma-separated, first three columns).

    Returns
    -------
    open3d.geometry.PointCloud
        With the file's normals and colours when Open3D read any.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the format is unknown, or the file holds no readable points, or non-finite
        coordinates.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such file: {path}")
    suffix = path.suffix.lower()
    if suffix in OPEN3D_FORMATS:
        cloud = o3d.io.read_point_cloud(str(path))
        if not cloud.has_points():
            raise ValueError(f"{path}: Open3D read no points from this file (damaged or empty?)")
        as_points(cloud, name=str(path))  # finiteness check
        return cloud
    if suffix in _NUMPY_FORMATS:
        try:
            if suffix == ".npy":
                arr = np.load(path, allow_pickle=False)
            elif suffix == ".npz":
                with np.load(path, allow_pickle=False) as archive:
                    if "points" in archive.files:
                        arr = archive["points"]
                    elif len(archive.files) == 1:
                        arr = archive[archive.files[0]]
                    else:
                        raise ValueError(f"has arrays {archive.files} but none named 'points'")
            else:
                arr = np.loadtxt(path, delimiter="," if suffix == ".csv" else None, ndmin=2)
        except ValueError as exc:
            raise ValueError(f"{path}: cannot read points ({exc})") from exc
        arr = np.asarray(arr)
        if arr.ndim == 2 and arr.shape[1] > 3:
            arr = arr[:, :3]
        points = as_points(arr, name=str(path))
        return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    raise ValueError(
        f"{path}: unknown point cloud format {suffix!r}; use one of "
        f"{', '.join(OPEN3D_FORMATS + _NUMPY_FORMATS)}"
    )


def write_cloud(path: str | os.PathLike, cloud) -> None:
    """Write a cloud (array or Open3D point cloud) in the format its extension names."""
    path = Path(path)
    if not isinstance(cloud, o3d.geometry.PointCloud):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(as_points(cloud)))
    suffix = path.suffix.lower()
    if suffix == ".npy":
        np.save(path, np.asarray(cloud.points))
        return
    if suffix not in OPEN3D_FORMATS:
        raise ValueError(f"{path}: cannot write format {suffix!r}; use .npy or {OPEN3D_FORMATS}")
    if not o3d.io.write_point_cloud(str(path), cloud):
        raise OSError(f"Open3D could not write {path}")
