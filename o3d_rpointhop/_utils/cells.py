"""Nearest neighbour within a radius on a grid of cells as wide as the radius.

Verifying registration hypotheses asks, for tens of thousands of moved points, whether
a target point lies within a fixed distance and which is nearest. A k-d tree walks
down from its root for every query; a grid whose cells are as wide as the radius
answers from the 27 cells around the query, a few points each. The answers are
``scipy.spatial.cKDTree.query(queries, distance_upper_bound=radius)``'s: the same
distances to the bit (each squared distance summed ``(dx^2 + dy^2) + dz^2`` and
compared strictly below ``radius**2``, as scipy does) and the same nearest point but
for exact ties.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .compiled import kernel

__all__ = ["CellGrid", "nearest_one"]

#: Most cells a grid allocates (an int64 start per cell: 32 MiB at most); clouds wider
#: than that, relative to the radius, are searched with a k-d tree instead.
MAX_CELLS = 1 << 22

# Cells a hair wider than the radius: a pair closer than the radius then never lies
# two cells apart along an axis, whatever the division's rounding.
_WIDEN = 1.0 + 1e-9


@kernel(inline="always")
def nearest_one(qx, qy, qz, points, starts, lo, inv_cell, dims, sq_radius):  # pragma: no cover
    """The squared distance to and row of the nearest of ``points`` (sorted by cell,
    ``starts`` the first row of every cell in C order over ``dims`` and one past the
    last) strictly closer than ``sq_radius`` to the query ``(qx, qy, qz)``; ``-1`` for
    none. A helper for kernels that search one point at a time."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    fx = np.floor((qx - lo[0]) * inv_cell)
    fy = np.floor((qy - lo[1]) * inv_cell)
    fz = np.floor((qz - lo[2]) * inv_cell)
    best = sq_radius
    found = -1
    if not (-1.0 <= fx <= nx and -1.0 <= fy <= ny and -1.0 <= fz <= nz):
        return best, found  # far outside the grid (or not a number)
    cx, cy, cz = int(fx), int(fy), int(fz)
    for x in range(max(cx - 1, 0), min(cx + 2, nx)):
        for y in range(max(cy - 1, 0), min(cy + 2, ny)):
            row = (x * ny + y) * nz
            for j in range(starts[row + max(cz - 1, 0)], starts[row + min(cz + 2, nz)]):
                dx = qx - points[j, 0]
                dy = qy - points[j, 1]
                dz = qz - points[j, 2]
                d = (dx * dx + dy * dy) + dz * dz
                if d < best:
                    best = d
                    found = j
    return best, found


@kernel(nogil=True)
def _nearest_in_cells(
    queries, points, starts, lo, inv_cell, dims, sq_radius
):  # pragma: no cover - compiled
    """Distance to and row of each query's nearest point closer than the radius
    (``inf`` and ``len(points)`` for none), by :func:`nearest_one`."""
    n = queries.shape[0]
    dist = np.full(n, np.inf)
    index = np.full(n, points.shape[0], dtype=np.int64)
    for i in range(n):
        best, found = nearest_one(
            queries[i, 0],
            queries[i, 1],
            queries[i, 2],
            points,
            starts,
            lo,
            inv_cell,
            dims,
            sq_radius,
        )
        if found >= 0:
            dist[i] = np.sqrt(best)
            index[i] = found
    return dist, index


class CellGrid:
    """Each query's nearest point closer than ``radius``, looked up on a grid of cells.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        Finite coordinates.
    radius : float
        Positive; only neighbours strictly closer are reported.
    """

    def __init__(self, points: np.ndarray, radius: float) -> None:
        points = np.ascontiguousarray(points, dtype=np.float64)
        self.points = points
        self.radius = float(radius)
        self.n_points = len(points)
        lo = points.min(axis=0) if len(points) else np.zeros(3)
        inv_cell = 1.0 / (self.radius * _WIDEN)
        cells = np.floor((points - lo) * inv_cell)  # float: no integer overflow yet
        extent = cells.max(axis=0) + 1 if len(points) else np.ones(3)
        self._tree = None
        if float(np.prod(extent)) > MAX_CELLS:
            self._tree = cKDTree(points)
            return
        keys = cells.astype(np.int64)
        dims = extent.astype(np.int64)
        linear = (keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2]
        order = np.argsort(linear, kind="stable")
        counts = np.bincount(linear, minlength=int(np.prod(dims)))
        starts = np.zeros(len(counts) + 1, dtype=np.int64)
        np.cumsum(counts, out=starts[1:])
        self._order = order
        self._sorted = np.ascontiguousarray(points[order])
        self._starts = starts
        self._lo = lo
        self._inv_cell = inv_cell
        self._dims = dims

    @property
    def on_cells(self) -> bool:
        """Whether the grid was built (False: too wide for :data:`MAX_CELLS`, searched
        with a k-d tree)."""
        return self._tree is None

    def kernel_arguments(self) -> tuple:
        """What a kernel passes :func:`nearest_one` after the query: the points sorted
        by cell, the cells' starts, the grid's corner, inverse cell width, dimensions
        and the squared radius. Rows it finds index :attr:`order` (the sorted row's
        original row). Only for a grid :attr:`on_cells`."""
        if self._tree is not None:
            raise ValueError("the points are searched with a k-d tree, not on cells")
        return (
            self._sorted,
            self._starts,
            self._lo,
            self._inv_cell,
            self._dims,
            self.radius * self.radius,
        )

    @property
    def order(self) -> np.ndarray:
        """The original row of every sorted row (a grid :attr:`on_cells`)."""
        if self._tree is not None:
            raise ValueError("the points are searched with a k-d tree, not on cells")
        return self._order

    def moved_pairs(
        self, queries: np.ndarray, transformation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The queries moved by ``transformation`` (4, 4) that have a point closer than
        the radius, as Open3D's ``evaluate_registration`` finds them on one thread.

        Each moved coordinate is summed x, y, z, then the shift, as Open3D moves points
        (numpy's matrix product rounds differently), and each squared distance x, y, z,
        as the search sums it.

        Returns
        -------
        pairs : ndarray of shape (k, 2), int64
            ``(query row, nearest point's row)``, in query order.
        squared : ndarray of shape (k,)
            Their squared distances.
        """
        queries = np.asarray(queries, dtype=np.float64)
        rot, shift = transformation[:3, :3], transformation[:3, 3]
        moved = (
            (queries[:, :1] * rot[:, 0] + queries[:, 1:2] * rot[:, 1]) + queries[:, 2:] * rot[:, 2]
        ) + shift
        _, index = self.nearest(moved)
        hit = np.flatnonzero(index < self.n_points)
        diff = moved[hit] - self.points[index[hit]]
        squared = (diff[:, 0] * diff[:, 0] + diff[:, 1] * diff[:, 1]) + diff[:, 2] * diff[:, 2]
        return np.stack([hit, index[hit]], axis=1).astype(np.int64), squared

    def nearest(self, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance to and index of every query's nearest point closer than the radius.

        Parameters
        ----------
        queries : ndarray of shape (q, 3)

        Returns
        -------
        dist : ndarray of shape (q,)
            ``inf`` where no point is closer than the radius.
        index : ndarray of shape (q,), int64
            The nearest point's row; ``n_points`` where none.
        """
        queries = np.ascontiguousarray(queries, dtype=np.float64)
        if self._tree is not None:
            dist, index = self._tree.query(queries, distance_upper_bound=self.radius, workers=-1)
            return dist, index.astype(np.int64, copy=False)
        dist, found = _nearest_in_cells(queries, *self.kernel_arguments())
        index = np.full(len(queries), self.n_points, dtype=np.int64)
        hit = found < self.n_points
        index[hit] = self._order[found[hit]]
        return dist, index
