"""Nearest neighbour within a radius on a grid of cells as wide as the radius.

Verifying registration hypotheses asks, for tens of thousands of moved points, whether
a target point lies within a fixed distance and which is nearest. A k-d tree walks
down from its root for every query; a grid whose cells are as wide as the radius
answers from the 27 cells around the query, a few points each. Where the cells would
hold many points (a dense scan searched at a wide radius: hundreds per cell), they are
``m`` times narrower (:data:`MAX_REACH` at most) and the search walks the cells ring by
ring around the query's, skipping every column of cells, and every cell of a column,
that lies farther than the nearest point found so far. The answers are
``scipy.spatial.cKDTree.query(queries, distance_upper_bound=radius)``'s: the same
distances to the bit (each squared distance summed ``(dx^2 + dy^2) + dz^2`` and
compared strictly below ``radius**2``, as scipy does) and the same nearest point but
for exact ties, which go to the point first in the grid's order, on any grid.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .compiled import kernel

__all__ = ["CellGrid", "nearest_one"]

#: Most cells a grid allocates (an int64 start per cell: 32 MiB at most); clouds wider
#: than that, relative to the radius, are searched with a k-d tree instead.
MAX_CELLS = 1 << 22

#: Most cells per radius along an axis (``m``): a dense grid's cells are ``radius / m``
#: wide, ``m`` chosen so that an occupied cell holds about :data:`DENSE_CELL` points.
MAX_REACH = 4
#: Points an occupied cell as wide as the radius holds, on average, above which the
#: cells are made narrower (to hold about a quarter as many).
DENSE_CELL = 32

# Cells a hair wider than the radius (over ``m``): a pair closer than the radius then
# never lies more than ``m`` cells apart along an axis, whatever the division's rounding.
_WIDEN = 1.0 + 1e-9


@kernel(inline="always")
def nearest_one(qx, qy, qz, points, starts, lo, inv_cell, dims, sq_radius):  # pragma: no cover
    """The squared distance to and row of the nearest of ``points`` (sorted by cell,
    ``starts`` the first row of every cell in C order over ``dims[:3]`` and one past the
    last) strictly closer than ``sq_radius`` to the query ``(qx, qy, qz)``; ``-1`` for
    none; of equally near points, the first row. ``dims[3]``: the cells per radius
    (``m``; 1: the 27 cells around the query's). A helper for kernels that search one
    point at a time."""
    nx, ny, nz, m = dims[0], dims[1], dims[2], dims[3]
    fx = np.floor((qx - lo[0]) * inv_cell)
    fy = np.floor((qy - lo[1]) * inv_cell)
    fz = np.floor((qz - lo[2]) * inv_cell)
    best = sq_radius
    found = -1
    if not (-m <= fx <= nx + m - 1 and -m <= fy <= ny + m - 1 and -m <= fz <= nz + m - 1):
        return best, found  # far outside the grid (or not a number)
    cx, cy, cz = int(fx), int(fy), int(fz)
    if m == 1:
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
    return _nearest_in_rings(qx, qy, qz, cx, cy, cz, points, starts, inv_cell, dims, best)


@kernel()
def _nearest_in_rings(
    qx, qy, qz, cx, cy, cz, points, starts, inv_cell, dims, best
):  # pragma: no cover - compiled
    """:func:`nearest_one` on narrow cells (``dims[3]`` = m > 1) for a query in cell
    ``(cx, cy, cz)``; compiled once, not into every kernel that searches."""
    nx, ny, nz, m = dims[0], dims[1], dims[2], dims[3]
    found = -1
    # Ring by ring of columns around the query's. A cell ``k`` cells away along an
    # axis is at least ``(k - 1) * step`` away along it (``step``: the radius over m,
    # a hair under the cells' width); a column or cell whose bound is beyond the best
    # so far holds no nearer point, nor one as near (the bound is strictly under every
    # distance), so skipping it changes nothing, and ties go to the first row whatever
    # the order the cells are read in.
    step = 1.0 / (inv_cell * _WIDEN)
    for ring in range(m + 1):
        if ring >= 2:
            gap = (ring - 1) * step
            if gap * gap > best:
                break
        for x in range(max(cx - ring, 0), min(cx + ring + 1, nx)):
            ax = abs(x - cx)
            gx = max(ax - 1, 0) * step
            for y in range(max(cy - ring, 0), min(cy + ring + 1, ny)):
                ay = abs(y - cy)
                if max(ax, ay) != ring:
                    continue
                gy = max(ay - 1, 0) * step
                column = gx * gx + gy * gy
                if column > best:
                    continue
                reach = min(m, int(np.sqrt(best - column) / step) + 1)
                row = (x * ny + y) * nz
                z0 = min(max(cz - reach, 0), nz)
                z1 = max(min(cz + reach + 1, nz), z0)
                for j in range(starts[row + z0], starts[row + z1]):
                    dx = qx - points[j, 0]
                    dy = qy - points[j, 1]
                    dz = qz - points[j, 2]
                    d = (dx * dx + dy * dy) + dz * dz
                    if d < best or (d == best and found >= 0 and j < found):
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


def _cells(points: np.ndarray, lo: np.ndarray, inv_cell: float):
    """Every point's cell at ``inv_cell`` cells per unit, as ``(linear index, dims,
    points per cell)``; None when the grid would exceed :data:`MAX_CELLS`."""
    cells = np.floor((points - lo) * inv_cell)  # float: no integer overflow yet
    extent = cells.max(axis=0) + 1 if len(points) else np.ones(3)
    if float(np.prod(extent)) > MAX_CELLS:
        return None
    keys = cells.astype(np.int64)
    dims = extent.astype(np.int64)
    linear = (keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2]
    return linear, dims, np.bincount(linear, minlength=int(np.prod(dims)))


def _reach(linear: np.ndarray, dims: np.ndarray, counts: np.ndarray) -> int:
    """Cells per radius for points that fill ``counts`` cells as wide as the radius: 1
    while an occupied cell holds at most :data:`DENSE_CELL` points on average, else
    enough narrower cells (a surface's points per cell fall with its square) to hold
    about a quarter of that, within :data:`MAX_REACH` and :data:`MAX_CELLS`."""
    occupied = int(np.count_nonzero(counts))
    per_cell = len(linear) / max(occupied, 1)
    if per_cell <= DENSE_CELL:
        return 1
    reach = min(MAX_REACH, int(np.ceil(np.sqrt(4.0 * per_cell / DENSE_CELL))))
    while reach > 1 and float(np.prod(dims.astype(np.float64) * reach)) > MAX_CELLS:
        reach -= 1
    return reach


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
        self._tree = None
        cells = _cells(points, lo, 1.0 / (self.radius * _WIDEN))
        if cells is None:
            self._tree = cKDTree(points)
            return
        reach = _reach(*cells)
        narrow = _cells(points, lo, reach / (self.radius * _WIDEN)) if reach > 1 else None
        if narrow is None:  # rounding could put the narrow grid over MAX_CELLS
            reach = 1
        else:
            cells = narrow
        linear, dims, counts = cells
        order = np.argsort(linear, kind="stable")
        starts = np.zeros(len(counts) + 1, dtype=np.int64)
        np.cumsum(counts, out=starts[1:])
        self._order = order
        self._sorted = np.ascontiguousarray(points[order])
        self._starts = starts
        self._lo = lo
        self._inv_cell = reach / (self.radius * _WIDEN)
        self._dims = np.array([*dims, reach], dtype=np.int64)

    @property
    def reach(self) -> int:
        """Cells per radius along an axis (1: cells as wide as the radius); a grid
        :attr:`on_cells`."""
        return int(self._dims[3]) if self._tree is None else 0

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
