"""Small geometry helpers shared by the descriptors and the registration."""

from __future__ import annotations

import numpy as np
import open3d as o3d

__all__ = ["point_spacing", "vectors"]


def vectors(array) -> o3d.utility.Vector3dVector:
    """``array`` (n, 3) as Open3D's ``Vector3dVector`` (a copy), read-only arrays too:
    Open3D refuses those, and joblib hands its workers large arrays as read-only
    memory maps."""
    array = np.asarray(array, dtype=np.float64)
    if not array.flags.writeable:
        array = array.copy()
    return o3d.utility.Vector3dVector(array)


def point_spacing(points: np.ndarray) -> float:
    """Median distance from a point to its nearest neighbour (coincident points left out).

    Raises
    ------
    ValueError
        If every point coincides.
    """
    cloud = o3d.geometry.PointCloud(vectors(points))
    dist = np.asarray(cloud.compute_nearest_neighbor_distance())
    positive = dist[dist > 0]
    if positive.size == 0:
        raise ValueError("the cloud has no spatial extent: all its points coincide")
    return float(np.median(positive))
