"""Nearest-neighbour search for the hops, on the compiled k-d tree of
:mod:`o3d_rpointhop._utils.kdtree`, and the spatial order clouds are described in.

Every hop asks, for each of its queries, for the ``k`` nearest points of a source set
other than the query itself. Queries and sources are rows of one cloud, so "itself" is
known by row: a query among the sources is left out of its own neighbourhood; a query
that is not among them leaves out one source it coincides with (a duplicate), so that
its neighbourhood means the same in both cases. One hop's search can serve several
neighbourhood sizes: the neighbours come back so that the first ``s`` are the ``s``
nearest for every size asked for (``levels``), in no particular order within.
"""

from __future__ import annotations

import numpy as np

from ..._utils.compiled import kernel
from ..._utils.kdtree import (
    QUERY_CHUNK,
    STACK_DEPTH,
    KDTree,
    knn_one,
    next_guess,
    pair_less,
    search_room,
    select_pairs,
)
from ..._utils.threads import run_blocks

__all__ = ["HopSearch", "spatial_order"]

#: Cells per axis of the grid whose Morton (Z-order) curve :func:`spatial_order` follows.
_MORTON_BITS = 21


@kernel(nogil=True)
def _hop_neighbours(
    start,
    stop,
    queries,
    own,
    k,
    levels,
    n_mean,
    order,
    tree_points,
    nodes,
    boxes,
    room,
    out,
    reach,
    mean_dist,
):  # pragma: no cover - compiled
    """:meth:`HopSearch.neighbours` for queries ``start:stop``; ``own[i]``: query
    ``i``'s position among the sources, or -1."""
    dist = np.empty(room)
    index = np.empty(room, np.int64)
    stack = np.empty(STACK_DEPTH, np.int64)
    worst = -1.0
    for i in range(start, stop):
        guess = -1.0 if i % QUERY_CHUNK == 0 else next_guess(worst, i, i - 1, queries)
        worst = knn_one(
            queries[i, 0],
            queries[i, 1],
            queries[i, 2],
            k + 1,
            guess,
            order,
            tree_points,
            nodes,
            boxes,
            dist,
            index,
            stack,
        )
        # Leave out the query itself, or else one source it coincides with, or else
        # the farthest of the k + 1.
        drop = -1
        nearest = 0
        farthest = 0
        for e in range(k + 1):
            if index[e] == own[i]:
                drop = e
            if pair_less(dist[e], index[e], dist[nearest], index[nearest]):
                nearest = e
            if pair_less(dist[farthest], index[farthest], dist[e], index[e]):
                farthest = e
        if drop < 0:
            drop = nearest if own[i] < 0 and dist[nearest] == 0.0 else farthest
        dist[drop], dist[k] = dist[k], dist[drop]
        index[drop], index[k] = index[k], index[drop]
        size = k
        for level in levels[1:]:
            if level == size - 1:  # one fewer: the farthest goes last
                last = 0
                for e in range(1, size):
                    if pair_less(dist[last], index[last], dist[e], index[e]):
                        last = e
                dist[last], dist[size - 1] = dist[size - 1], dist[last]
                index[last], index[size - 1] = index[size - 1], index[last]
            elif level < size:
                select_pairs(dist, index, 0, size, level - 1)
            size = min(size, level)
        farthest_sq = 0.0
        for e in range(k):
            out[i, e] = index[e]
            farthest_sq = max(farthest_sq, dist[e])
        reach[i] = farthest_sq
        if n_mean > 0:
            total = 0.0
            for e in range(n_mean):
                total += np.sqrt(dist[e])
            mean_dist[i] = total / n_mean


class HopSearch:
    """The k-d tree over one hop's source points, and the searches the hops make in it.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        The cloud (float64, C-contiguous).
    sources : ndarray of int64, or None
        Rows of the cloud searched (sorted); None for every row.
    """

    def __init__(self, points: np.ndarray, sources: np.ndarray | None = None) -> None:
        self.points = points
        self.n_points = len(points)
        self.sources = sources
        self.tree = KDTree(points if sources is None else points[sources])
        if sources is not None:
            self._position = np.full(len(points), -1, dtype=np.int64)
            self._position[sources] = np.arange(len(sources))

    def neighbours(
        self,
        queries: np.ndarray | None,
        k: int,
        levels: tuple[int, ...] = (),
        n_mean: int = 0,
        n_threads: int = 1,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ``k`` nearest sources of every query row but the query itself.

        Parameters
        ----------
        queries : ndarray of int64, or None
            Rows of the cloud (sorted); None for every row.
        k : int
            Neighbours per query; at most the number of sources minus one.
        levels : tuple of int
            Smaller neighbourhood sizes served by the same search: for each ``s``, the
            first ``s`` neighbours are the ``s`` nearest.
        n_mean : int, default=0
            Also return every query's mean distance to its ``n_mean`` nearest.
        n_threads : int, default=1

        Returns
        -------
        neighbours : ndarray of shape (n_queries, k), int32
            Positions among the sources (the rows of a feature array with one row per
            source).
        reach : ndarray of shape (n_queries,)
            The largest squared distance to a query's ``k`` neighbours: every source
            closer than that is among them.
        mean_dist : ndarray of shape (n_queries,)
            Empty without ``n_mean``.
        """
        n_sources = self.tree.n_points
        if k + 1 > n_sources:
            raise ValueError(f"cannot take {k} neighbours among {n_sources} points")
        rows = np.arange(self.n_points) if queries is None else queries
        if self.sources is None:
            own = rows
        else:
            own = self._position[rows]
        query_points = self.points if queries is None else self.points[queries]
        wanted = sorted({int(s) for s in (*levels, n_mean) if 0 < s < k}, reverse=True)
        q = len(rows)
        out = np.empty((q, k), np.int32)
        reach = np.empty(q)
        mean_dist = np.empty(q if n_mean > 0 else 0)
        arrays = (
            np.ascontiguousarray(query_points),
            np.ascontiguousarray(own, dtype=np.int64),
            int(k),
            np.array([k, *wanted], dtype=np.int64),
            int(n_mean),
            *self.tree.arrays,
            search_room(k + 1),
            out,
            reach,
            mean_dist,
        )
        run_blocks(_hop_neighbours, q, n_threads, *arrays, align=QUERY_CHUNK)
        return out, reach, mean_dist


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """Move bit ``b`` of every value (21 bits) to bit ``3 * b``."""
    v = v.astype(np.uint64)
    for shift, mask in (
        (32, 0x1F00000000FFFF),
        (16, 0x1F0000FF0000FF),
        (8, 0x100F00F00F00F00F),
        (4, 0x10C30C30C30C30C3),
        (2, 0x1249249249249249),
    ):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def spatial_order(points: np.ndarray) -> np.ndarray:
    """A permutation that puts nearby points next to each other: the order of their
    cells on a Morton (Z-order) curve through a ``2**21``-cell grid per axis.

    Neighbour searches and the pooling's gathers then read memory mostly in order,
    which makes describing a large cloud in scattered order about a quarter faster.
    The descriptors do not depend on it beyond rounding (each query sums its
    neighbours in the order its search found them). The cells are fine enough that
    only points a two-millionth of the cloud's extent apart share one, so a permuted
    cloud takes the same arrangement, and gets the same bytes, unless it holds such
    near-duplicates (those keep their input order).

    Parameters
    ----------
    points : ndarray of shape (n, 3)

    Returns
    -------
    order : ndarray of shape (n,), int64
    """
    low = points.min(axis=0)
    extent = float((points.max(axis=0) - low).max())
    cells = (1 << _MORTON_BITS) - 1
    scale = cells / extent if extent > 0 else 0.0
    grid = np.clip(((points - low) * scale).astype(np.int64), 0, cells)
    code = _spread_bits(grid[:, 0]) | _spread_bits(grid[:, 1]) << np.uint64(1)
    code |= _spread_bits(grid[:, 2]) << np.uint64(2)
    return np.argsort(code, kind="stable")
