"""Nearest-neighbour search and rigid-invariant farthest point sampling.

Both run in Open3D's C++ code: the tensor ``NearestNeighborSearch`` (nanoflann, several
threads) is 2-3x faster than ``scipy.spatial.cKDTree`` for the k = 32..64 queries used
here, and ``PointCloud.farthest_point_down_sample`` keeps the sequential farthest point
loop out of Python.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d
import open3d.core as o3c

__all__ = [
    "NeighborIndex",
    "knn",
    "drop_self",
    "fps_subsets",
    "invariant_start",
    "point_spacing",
]


class NeighborIndex:
    """A k-d tree over ``points`` for many k-nearest-neighbour queries (built once).

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    """

    def __init__(self, points: np.ndarray) -> None:
        self.n_points = len(points)
        self._search = o3c.nns.NearestNeighborSearch(o3c.Tensor(np.ascontiguousarray(points)))
        self._search.knn_index()

    def query(self, queries: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest points of every query, nearest first: indices ``(q, k)``
        int64 and squared distances ``(q, k)`` float64."""
        if k > self.n_points:
            raise ValueError(f"cannot take {k} neighbours among {self.n_points} points")
        idx, sq = self._search.knn_search(o3c.Tensor(np.ascontiguousarray(queries)), k)
        return idx.numpy().astype(np.int64, copy=False), sq.numpy()


def knn(points: np.ndarray, queries: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the ``k`` nearest ``points`` of every query, nearest first.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    queries : ndarray of shape (q, 3)
    k : int
        At most ``n``.

    Returns
    -------
    indices : ndarray of shape (q, k), int64
    sq_distances : ndarray of shape (q, k), float64
    """
    if k > len(points):
        raise ValueError(f"cannot take {k} neighbours among {len(points)} points")
    return NeighborIndex(points).query(queries, k)


def drop_self(idx: np.ndarray, sq_distances: np.ndarray, k: int) -> np.ndarray:
    """``k`` neighbours per row of a ``k + 1``-NN result, leaving out one zero-distance hit.

    A query that is itself one of the searched points (or coincides with one) finds
    itself first. Leaving out the first hit when its distance is exactly zero, and the
    last hit otherwise, gives every query ``k`` neighbours with the same meaning whether
    or not it belongs to the searched set.
    """
    start = (sq_distances[:, 0] == 0.0).astype(np.int64)
    cols = start[:, None] + np.arange(k)[None, :]
    return np.take_along_axis(idx, cols, axis=1)


def invariant_start(points: np.ndarray) -> int:
    """Index of the point farthest from the centroid: the same point after any rigid motion
    or permutation (barring exact ties)."""
    centred = points - points.mean(axis=0)
    return int(np.argmax(np.einsum("ij,ij->i", centred, centred)))


def _fps(points: np.ndarray, m: int, start: int) -> np.ndarray:
    """Sorted indices of the ``m``-point farthest point sample starting at ``start``."""
    n = len(points)
    if m == n:
        return np.arange(n, dtype=np.int64)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    # Carry each row's index through the sampling in the normals channel.
    tags = np.zeros((n, 3))
    tags[:, 0] = np.arange(n)
    cloud.normals = o3d.utility.Vector3dVector(tags)
    sample = cloud.farthest_point_down_sample(m, start)
    chosen = np.asarray(sample.normals)[:, 0].astype(np.int64)
    if len(chosen) < m:
        # Open3D stops once every remaining point duplicates a chosen one; those
        # duplicates (lowest rows first) fill the sample up to its size.
        rest = np.setdiff1d(np.arange(n), chosen, assume_unique=True)[: m - len(chosen)]
        chosen = np.sort(np.concatenate([chosen, rest]))
    return chosen


def fps_subsets(points: np.ndarray, sizes: list[int]) -> list[np.ndarray]:
    """Nested farthest point samples of ``points``, one per requested size.

    The sampling starts at :func:`invariant_start`, so the samples move with the cloud
    under rigid motions and follow its rows under permutations. Farthest point sampling
    is greedy: the first ``m`` picks from a set that contains the first ``m'`` > ``m``
    picks are those same points. Each sample is therefore drawn from the previous one,
    which is cheaper and keeps the samples nested even when distances tie.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    sizes : list of int
        Non-increasing, each between 1 and ``n``.

    Returns
    -------
    subsets : list of ndarray of int64
        Sorted row indices into ``points``, one array per entry of ``sizes``.
    """
    n = len(points)
    start = invariant_start(points)
    current = np.arange(n, dtype=np.int64)
    out: list[np.ndarray] = []
    for m in sizes:
        if not 1 <= m <= len(current):
            raise ValueError(f"cannot sample {m} of {len(current)} points")
        local_start = int(np.searchsorted(current, start))
        current = current[_fps(points[current], m, local_start)]
        out.append(current)
    return out


def point_spacing(points: np.ndarray) -> float:
    """Median distance from a point to its nearest neighbour."""
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    dist = np.asarray(cloud.compute_nearest_neighbor_distance())
    positive = dist[dist > 0]
    if positive.size == 0:
        raise ValueError("the cloud has no spatial extent: all its points coincide")
    return float(np.median(positive))
