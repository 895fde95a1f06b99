"""Nearest-neighbour search for the hops, on the compiled k-d tree of
:mod:`o3d_rpointhop._utils.kdtree`, and the spatial order clouds are described in.

Every hop asks, for each of its queries, for the ``k`` nearest points of a source set
other than the query itself. Queries and sources are rows of one cloud, so "itself" is
known by row: a query among the sources is left out of its own neighbourhood; a query
that is not among them leaves out one source it coincides with (a duplicate), so that
its neighbourhood means the same in both cases. One hop's search can serve several
neighbourhood sizes: the neighbours come back so that the first ``s`` are the ``s``
nearest for every size asked for (``levels``), in no particular order within.

"Nearest" compares squared distances rounded to 16 bits (:func:`tie_key`), then the
points' ranks by their distance to the centroid (:func:`tie_ranks`). Two sources at the
same distance from a query, or nearly so (common in clouds stored on a grid or in
float32), would otherwise be told apart by the last bits of rounding, which change
with the frame the cloud is given in, and the neighbourhood with them.
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

__all__ = [
    "HopSearch",
    "key_ceiling",
    "key_floor",
    "ranked_knn",
    "spatial_order",
    "tie_key",
    "tie_ranks",
]

#: Cells per axis of the grid whose Morton (Z-order) curve :func:`spatial_order` follows.
_MORTON_BITS = 21


#: Candidates searched beyond the ``k`` asked for when the ``k``-th distance ties with
#: the next: enough for most ties on a grid.
_TIE_ROOM = 16
# Tags pack a rank (high bits) and a candidate's place (low bits) in one int64, ordered
# as the ranks.
_TAG_SHIFT = 32
_TAG_MASK = (1 << _TAG_SHIFT) - 1


# Veltkamp's splitter: c - (c - x) with c = x * (2**37 + 1) is x rounded to 16 bits.
_SPLITTER = 2.0**37 + 1.0
# Above this the splitter's product overflows (squared distances of coordinates up to
# 1e154, which the input checks accept): such values are split scaled by 2**-128, exactly.
_SPLIT_MAX = 2.0**980
_SPLIT_DOWN = 2.0**-128
_SPLIT_UP = 2.0**128
# Keys round the squared distance times this irrational factor: the rounding's
# midpoints, where the last bit decides, then miss the exact dyadic values that
# squared distances take on clouds stored in float32 or on a power-of-two grid.
_STRETCH = 0.6180339887498949
# A key is within this factor of its stretched squared distance (16 bits: 2**-16).
_KEY_SLACK = 1.0 + 2.0**-15


@kernel(inline="always")
def tie_key(sq):  # pragma: no cover - compiled
    """A squared distance rounded to 16 significant bits (1.5e-5 relative, after
    multiplying it by an irrational factor). Distances that differ only by the
    rounding of the frame they were computed in (1e-16 relative near the origin,
    about 1e-8 for a centimetre-spaced cloud at survey coordinates) get the same key,
    and their order is decided by the points' ranks (:func:`tie_ranks`), which move
    with the cloud, instead of by that rounding. Keys are ordered as the distances."""
    stretched = sq * _STRETCH
    if stretched > _SPLIT_MAX:  # the splitter would overflow: round a power-of-two share
        stretched *= _SPLIT_DOWN
        c = stretched * _SPLITTER
        return (c - (c - stretched)) * _SPLIT_UP
    c = stretched * _SPLITTER
    return c - (c - stretched)


@kernel(inline="always")
def key_ceiling(key):  # pragma: no cover - compiled
    """A squared distance above every squared distance whose :func:`tie_key` is
    ``key``."""
    return key * _KEY_SLACK / _STRETCH * _KEY_SLACK


@kernel(inline="always")
def key_floor(key):  # pragma: no cover - compiled
    """A squared distance below every squared distance whose :func:`tie_key` is
    ``key``."""
    return key / _KEY_SLACK / _STRETCH / _KEY_SLACK


@kernel()
def _rank_found(dist, index, found, k, ranks, keys, tags):  # pragma: no cover - compiled
    """Key and tag the ``found`` candidates ``dist`` / ``index`` (exact squared
    distances, rows; ``tags[e] = rank << 32 | e``) and put the ``k`` smallest
    ``(key, tag)`` pairs first. Returns False when the ``k``-th key equals the largest
    found: points not found may share it."""
    widest = 0.0
    top = 0
    for e in range(found):
        keys[e] = tie_key(dist[e])
        tags[e] = (ranks[index[e]] << _TAG_SHIFT) | e
        if keys[e] >= widest:
            widest = keys[e]
            top = e
    if found == k + 1:
        # One more than asked (the usual search): the rest are the k smallest when its
        # key is above all of theirs; one pass, no selection.
        keys[top], keys[k] = keys[k], keys[top]
        tags[top], tags[k] = tags[k], tags[top]
        for e in range(k):
            if keys[e] == widest:
                break
        else:
            return True
    select_pairs(keys, tags, 0, found, k - 1)
    largest = 0.0
    for e in range(k):
        largest = max(largest, keys[e])
    return largest < widest


@kernel()
def ranked_knn(
    q0, q1, q2, k, guess, order, tree_points, nodes, boxes, ranks, scratch, stack
):  # pragma: no cover - compiled
    """The ``k`` nearest points of a query by ``(tie_key(squared distance), rank)``:
    the same points in any frame, exact ties and near ties included.

    One more point than asked is searched: when its key is above the others', nothing
    farther can tie. Otherwise (a tie at the boundary: rare, but common on a grid) the
    search widens to :data:`_TIE_ROOM` more, then doubles, until it holds the whole
    tie. ``scratch``: ``(dist, index, keys, tags)`` of :func:`search_room` entries for
    ``k + _TIE_ROOM`` points.

    Returns ``(worst, keys, tags, dist, index)``: the largest exact squared distance
    searched (the next query's guess); the ``k`` points' keys and tags in the first
    ``k`` entries of ``keys`` and ``tags`` (in no particular order; comparing ``(key,
    tag)`` pairs compares keys, then ranks), each tag's low 32 bits the point's place in
    ``dist`` (exact squared distances) and ``index`` (rows). The arrays are
    ``scratch``'s, or new ones for a wide tie."""
    dist, index, keys, tags = scratch
    n = order.shape[0]
    found = min(k + 1, n)
    worst = knn_one(q0, q1, q2, found, guess, order, tree_points, nodes, boxes, dist, index, stack)
    if not _rank_found(dist, index, found, k, ranks, keys, tags) and found < n:
        found = min(k + _TIE_ROOM, n)
        knn_one(q0, q1, q2, found, guess, order, tree_points, nodes, boxes, dist, index, stack)
        while not _rank_found(dist, index, found, k, ranks, keys, tags) and found < n:
            found = min(2 * found, n)
            room = search_room(found)
            dist = np.empty(room)
            index = np.empty(room, np.int64)
            keys = np.empty(room)
            tags = np.empty(room, np.int64)
            knn_one(q0, q1, q2, found, -1.0, order, tree_points, nodes, boxes, dist, index, stack)
    return worst, keys, tags, dist, index


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
    ranks,
    room,
    out,
    reach,
    mean_dist,
):  # pragma: no cover - compiled
    """:meth:`HopSearch.neighbours` for queries ``start:stop``; ``own[i]``: query
    ``i``'s position among the sources, or -1. Every choice among candidates compares
    ``(tie_key, rank)`` pairs, so the neighbours move with the cloud."""
    scratch = (np.empty(room), np.empty(room, np.int64), np.empty(room), np.empty(room, np.int64))
    stack = np.empty(STACK_DEPTH, np.int64)
    size = k + 1
    worst = -1.0
    for i in range(start, stop):
        guess = -1.0 if i % QUERY_CHUNK == 0 else next_guess(worst, i, i - 1, queries)
        worst, key, tag, exact, rows = ranked_knn(
            queries[i, 0],
            queries[i, 1],
            queries[i, 2],
            size,
            guess,
            order,
            tree_points,
            nodes,
            boxes,
            ranks,
            scratch,
            stack,
        )
        # Leave out the query itself, or else one source it coincides with, or else
        # the farthest of the k + 1.
        drop = -1
        nearest = 0
        farthest = 0
        for e in range(size):
            if rows[tag[e] & _TAG_MASK] == own[i]:
                drop = e
            if pair_less(key[e], tag[e], key[nearest], tag[nearest]):
                nearest = e
            if pair_less(key[farthest], tag[farthest], key[e], tag[e]):
                farthest = e
        if drop < 0:
            drop = nearest if own[i] < 0 and exact[tag[nearest] & _TAG_MASK] == 0.0 else farthest
        key[drop], key[k] = key[k], key[drop]
        tag[drop], tag[k] = tag[k], tag[drop]
        kept = k
        for level in levels[1:]:
            if level == kept - 1:  # one fewer: the farthest goes last
                last = 0
                for e in range(1, kept):
                    if pair_less(key[last], tag[last], key[e], tag[e]):
                        last = e
                key[last], key[kept - 1] = key[kept - 1], key[last]
                tag[last], tag[kept - 1] = tag[kept - 1], tag[last]
            elif level < kept:
                select_pairs(key, tag, 0, kept, level - 1)
            kept = min(kept, level)
        farthest_key = 0.0
        for e in range(k):
            out[i, e] = rows[tag[e] & _TAG_MASK]
            farthest_key = max(farthest_key, key[e])
        # Every source whose squared distance is below this has a smaller key.
        reach[i] = key_floor(farthest_key)
        if n_mean > 0:
            total = 0.0
            for e in range(n_mean):
                total += np.sqrt(exact[tag[e] & _TAG_MASK])
            mean_dist[i] = total / n_mean


def tie_ranks(points: np.ndarray) -> np.ndarray:
    """Every point's rank by its squared distance to the cloud's centroid, then by
    row: the order in which neighbours at the same :func:`tie_key` are chosen. It moves
    with the cloud under rigid motions (two points swap only if their distances to the
    centroid differ by less than rounding: a symmetric pair) and follows its rows under
    permutations given in a spatial order (:func:`spatial_order`), by which such
    pairs are ordered. The distances are compared exactly: a key as coarse as
    :func:`tie_key` would tie a few pairs in every thousand points.

    Parameters
    ----------
    points : ndarray of shape (n, 3), float64

    Returns
    -------
    ranks : ndarray of shape (n,), int64
        A permutation of ``0..n-1``.
    """
    centred = points - points.mean(axis=0)
    radial = np.einsum("ij,ij->i", centred, centred)
    order = np.argsort(radial, kind="stable")  # equal distances by row
    ranks = np.empty(len(points), dtype=np.int64)
    ranks[order] = np.arange(len(points))
    return ranks


class HopSearch:
    """The k-d tree over one hop's source points, and the searches the hops make in it.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        The cloud (float64, C-contiguous).
    sources : ndarray of int64, or None
        Rows of the cloud searched (sorted); None for every row.
    ranks : ndarray of int64, default=None
        Every row's :func:`tie_ranks` (computed if not given): among sources at the
        same :func:`tie_key` distance, the lower rank is nearer.
    """

    def __init__(
        self,
        points: np.ndarray,
        sources: np.ndarray | None = None,
        ranks: np.ndarray | None = None,
    ) -> None:
        self.points = points
        self.n_points = len(points)
        self.sources = sources
        self.ranks = tie_ranks(points) if ranks is None else ranks
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
            A squared distance every source closer than which is among a query's
            ``k`` neighbours (the farthest neighbour's, less the key's rounding).
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
            np.ascontiguousarray(self.ranks if self.sources is None else self.ranks[self.sources]),
            search_room(k + 1 + _TIE_ROOM),
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
