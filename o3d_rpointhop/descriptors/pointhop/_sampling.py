"""Rigid-invariant subsampling for the hops: farthest points for small clouds, Poisson
disks for large ones.

Farthest point sampling runs in Open3D's C++ code
(``PointCloud.farthest_point_down_sample``), which keeps the sequential loop out of
Python, from a start point that moves with the cloud (:func:`invariant_start`).

Farthest point sampling (FPS) picks ``m`` of ``n`` points in ``O(n m)`` time, which is
quadratic when ``m`` is a fixed share of ``n``: 66 s for 200k points. Fast FPS variants
(the ``fpsample`` package's bucket FPS) were measured here and are *not* rigid-invariant:
on a 2000-point object, 170 of 1500 picks change under a rotation, because their buckets
follow the coordinate axes. So large clouds use an ``O(n log n)`` Poisson-disk
subsample instead, built only from distances and so as invariant as FPS:

* every point gets a priority, a pseudo-random number computed from its distance to the
  cloud's centroid (rigid- and permutation-invariant, and different for neighbours);
* a point's *death radius* is its distance to the nearest of its ``k`` nearest
  neighbours that has a higher priority (infinite if none has);
* the sample is the ``m`` points with the largest death radii.

Any two kept points are at least ``r`` apart, where ``r`` is the ``m``-th largest death
radius: of two points closer than ``r`` the one with the lower priority has a death
radius below ``r``. This is Matern's hard-core thinning with the radius chosen to keep
exactly ``m`` points, so the sample is spread like a Poisson-disk sample, in one
vectorised pass.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from ._neighbors import knn

__all__ = [
    "FPS_MAX_POINTS",
    "fps_subsets",
    "hop_subsets",
    "invariant_start",
    "poisson_disk_subset",
    "priorities",
]

#: Clouds of up to this many points are sampled by exact FPS (0.3 s at this size); larger
#: clouds by Poisson disks.
FPS_MAX_POINTS = 16384
# Neighbours that compete with each point. A thinning keeps at least the local priority
# maxima among them, about n / (k + 1), so shares down to 1/9 are reachable in one step.
_COMPETITORS = 8
# Irrational step of the priority sawtooth (the golden ratio's conjugate).
_GOLDEN = 0.6180339887498949


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


def priorities(points: np.ndarray, spacing: float) -> np.ndarray:
    """Pseudo-random priorities in [0, 1) that move with the cloud.

    ``frac(golden * |p - centroid|^2 / spacing^2)``: two neighbours, whether they lie
    along or across the direction to the centroid, differ in ``|p - c|^2`` by about a
    squared spacing, so their priorities are unrelated, while a rigid motion changes
    ``|p - c|^2 / spacing^2`` only by rounding (about 1e-10 for a million-point cloud).
    """
    centred = points - points.mean(axis=0)
    radial = np.einsum("ij,ij->i", centred, centred) / (spacing * spacing)
    return np.modf(_GOLDEN * radial)[0]


def poisson_disk_subset(points: np.ndarray, m: int) -> np.ndarray:
    """Sorted indices of an ``m``-point Poisson-disk subsample of ``points``.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    m : int
        Between 1 and ``n``. Shares below about ``1 / 9`` of ``n`` take several rounds.

    Returns
    -------
    ndarray of int64, sorted
    """
    n = len(points)
    if not 1 <= m <= n:
        raise ValueError(f"cannot sample {m} of {n} points")
    current = np.arange(n, dtype=np.int64)
    while len(current) > m:
        # Each round keeps at least the local maxima, ~1/(k+1); several rounds for tiny m.
        step = max(m, int(np.ceil(len(current) / (_COMPETITORS + 1))))
        current = current[_thin(points[current], step)]
    return current


def _thin(points: np.ndarray, m: int) -> np.ndarray:
    """One hard-core thinning of ``points`` down to (at most) ``m`` of them."""
    n = len(points)
    if m >= n:
        return np.arange(n, dtype=np.int64)
    k = min(_COMPETITORS, n - 1)
    if k < 1:
        return np.arange(m, dtype=np.int64)
    idx, sq = knn(points, points, k + 1)
    idx, sq = idx[:, 1:], sq[:, 1:]  # leave out the point itself
    positive = sq[:, 0][sq[:, 0] > 0]
    spacing = float(np.sqrt(np.median(positive))) if positive.size else 1.0
    priority = priorities(points, spacing)
    stronger = priority[idx] > priority[:, None]
    death = np.where(stronger, sq, np.inf).min(axis=1)
    # The m largest death radii; ties (equal distances, and the local maxima's infinite
    # radii) by the higher priority: both move with the cloud.
    order = np.lexsort((-priority, -death))
    return np.sort(order[:m])


def hop_subsets(points: np.ndarray, sizes: list[int], method: str) -> list[np.ndarray]:
    """Nested samples of ``points``, one per size (non-increasing), by ``method``.

    ``"fps"``: exact farthest point sampling from :func:`invariant_start`;
    ``"poisson"``: :func:`poisson_disk_subset`; ``"auto"``: FPS for clouds of at most
    :data:`FPS_MAX_POINTS` points, Poisson disks above.
    """
    if method == "auto":
        method = "fps" if len(points) <= FPS_MAX_POINTS else "poisson"
    if method == "fps":
        return fps_subsets(points, sizes)
    current = np.arange(len(points), dtype=np.int64)
    out: list[np.ndarray] = []
    for m in sizes:
        if not 1 <= m <= len(current):
            raise ValueError(f"cannot sample {m} of {len(current)} points")
        if m < len(current):
            current = current[poisson_disk_subset(points[current], m)]
        out.append(current)
    return out
