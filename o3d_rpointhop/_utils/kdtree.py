"""A compiled k-d tree for the k nearest neighbours of many queries in 3-D.

The tree splits at the median of the widest side of each node's bounding box down to
leaves of at most ``leaf_size`` points, stored contiguously in tree order, with every
node's tight bounding box. A query visits the nodes whose box lies within its current
search radius:

* given an upper bound on its k-th neighbour's distance (the previous query's k-th
  distance plus the distance between the two queries: the previous query's
  neighbours all lie that close), it gathers every point within the bound and
  selects the k nearest (one branch-light pass and a linear-time selection);
* otherwise it walks the tree nearest box first with a bounded max-heap.

Both give the same k points: the k smallest ``(squared distance, index)`` pairs, so
even ties are decided the same way whatever the route. Distances are summed
``(dx^2 + dy^2) + dz^2``. The helpers here are compiled kernels that other kernels call
(the descriptor's hop passes search this way without leaving compiled code);
:class:`KDTree` is the same search from Python.
"""

from __future__ import annotations

import numpy as np

from .compiled import kernel
from .threads import run_blocks

__all__ = ["KDTree"]

#: Points per leaf (measured on 2k-20k point objects with k = 49-65: 32 is 5-15 %
#: faster than 16, and 16 than 8).
LEAF_SIZE = 32
#: A search's guess starts afresh at every multiple of this many queries, and threads
#: share the queries in pieces that start there: every result is the same whatever the
#: number of threads.
QUERY_CHUNK = 64
#: Depth of the traversal stacks (two entries a level: enough for 2**60 leaves).
STACK_DEPTH = 128
# A gathered radius is widened by this relative amount, so that the rounding of the
# bound never leaves out a point that lies exactly on it.
_SLACK = 1.0 + 1e-12
# A guessed radius that holds fewer than k points grows by this factor, at most this
# many times before the heap search takes over.
_GROWTH = 1.25
_GROWTHS = 3
# A guess widens the previous query's k-th distance by at most this factor.
_WIDEST = 1.15


@kernel()
def _build(points, leaf_size):  # pragma: no cover - compiled
    """The tree over ``points`` ``(n, 3)``: ``order`` (tree position -> row),
    ``tree_points`` (the points in tree order), ``nodes`` ``(m, 3)`` int64 rows
    ``[start, stop, left child or -1]`` (the right child is ``left + 1``) and
    ``boxes`` ``(m, 6)``: each node's lower then upper corner."""
    n = points.shape[0]
    order = np.arange(n)
    capacity = 2 * (n // max(1, leaf_size) + 1) * 2 + 1
    nodes = np.empty((capacity, 3), np.int64)
    boxes = np.empty((capacity, 6))
    stack = np.empty(STACK_DEPTH, np.int64)
    nodes[0, 0] = 0
    nodes[0, 1] = n
    count = 1
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        lo = nodes[node, 0]
        hi = nodes[node, 1]
        nodes[node, 2] = -1
        for d in range(3):
            low = np.inf
            high = -np.inf
            for t in range(lo, hi):
                v = points[order[t], d]
                low = min(low, v)
                high = max(high, v)
            boxes[node, d] = low
            boxes[node, 3 + d] = high
        if hi - lo <= leaf_size:
            continue
        dim = 0
        for d in range(1, 3):
            if boxes[node, 3 + d] - boxes[node, d] > boxes[node, 3 + dim] - boxes[node, dim]:
                dim = d
        if boxes[node, 3 + dim] <= boxes[node, dim]:
            continue  # every point of the node coincides: a leaf, however large
        mid = (lo + hi) // 2
        _split(order, points, lo, hi, mid, dim)
        left = count
        count += 2
        nodes[node, 2] = left
        nodes[left, 0] = lo
        nodes[left, 1] = mid
        nodes[left + 1, 0] = mid
        nodes[left + 1, 1] = hi
        stack[top] = left + 1
        stack[top + 1] = left
        top += 2
    tree_points = np.empty((n, 3))
    for t in range(n):
        for d in range(3):
            tree_points[t, d] = points[order[t], d]
    return order, tree_points, nodes[:count].copy(), boxes[:count].copy()


@kernel(inline="always")
def _split(order, points, lo, hi, kth, dim):  # pragma: no cover - compiled
    """Reorder ``order[lo:hi]`` so that position ``kth`` holds the point of rank ``kth``
    along ``dim``, smaller coordinates before it and larger after (quickselect)."""
    while hi - lo > 1:
        a = points[order[lo], dim]
        b = points[order[(lo + hi - 1) // 2], dim]
        c = points[order[hi - 1], dim]
        pivot = max(min(a, b), min(max(a, b), c))  # the median of the three
        i = lo
        j = hi - 1
        while i <= j:
            while points[order[i], dim] < pivot:
                i += 1
            while points[order[j], dim] > pivot:
                j -= 1
            if i <= j:
                order[i], order[j] = order[j], order[i]
                i += 1
                j -= 1
        if kth <= j:
            hi = j + 1
        elif kth >= i:
            lo = i
        else:
            return


@kernel(inline="always")
def box_sq_distance(q0, q1, q2, boxes, node):  # pragma: no cover - compiled
    """Squared distance from a point to a node's box (0 inside it)."""
    s = 0.0
    below = boxes[node, 0] - q0
    above = q0 - boxes[node, 3]
    if below > 0.0:
        s += below * below
    elif above > 0.0:
        s += above * above
    below = boxes[node, 1] - q1
    above = q1 - boxes[node, 4]
    if below > 0.0:
        s += below * below
    elif above > 0.0:
        s += above * above
    below = boxes[node, 2] - q2
    above = q2 - boxes[node, 5]
    if below > 0.0:
        s += below * below
    elif above > 0.0:
        s += above * above
    return s


@kernel(inline="always")
def pair_less(da, ia, db, ib):  # pragma: no cover - compiled
    """``(da, ia) < (db, ib)``: distance first, then index."""
    return da < db or (da == db and ia < ib)


@kernel(inline="always")
def insert_ranked(values, rows, kept, v, index):  # pragma: no cover - compiled
    """Put ``(v, index)`` into the list ``values[:kept]`` / ``rows[:kept]``, ascending by
    value, then index (:func:`pair_less`), at most ``len(values)`` long (the last one
    dropped when it is full); the caller checked that it belongs there. Returns the
    list's new length. Candidates offered in increasing index go after the equal values
    already kept."""
    n = values.shape[0]
    r = kept if kept < n else n - 1
    while r > 0 and pair_less(v, index, values[r - 1], rows[r - 1]):
        values[r] = values[r - 1]
        rows[r] = rows[r - 1]
        r -= 1
    values[r] = v
    rows[r] = index
    return kept + 1 if kept < n else kept


@kernel()
def select_pairs(dist, index, lo, hi, kth):  # pragma: no cover - compiled
    """Reorder ``dist[lo:hi]`` and ``index[lo:hi]`` together so that position ``kth``
    holds the pair of rank ``kth`` (by :func:`pair_less`), the smaller pairs before
    it (in no particular order) and the larger after (quickselect)."""
    while hi - lo > 1:
        m = (lo + hi - 1) >> 1
        pd = dist[m]
        pi = index[m]
        i = lo
        j = hi - 1
        while i <= j:
            while pair_less(dist[i], index[i], pd, pi):
                i += 1
            while pair_less(pd, pi, dist[j], index[j]):
                j -= 1
            if i <= j:
                dist[i], dist[j] = dist[j], dist[i]
                index[i], index[j] = index[j], index[i]
                i += 1
                j -= 1
        if kth <= j:
            hi = j + 1
        elif kth >= i:
            lo = i
        else:
            return


@kernel()
def sort_pairs(dist, index, lo, hi):  # pragma: no cover - compiled
    """Sort ``dist[lo:hi]`` and ``index[lo:hi]`` together by :func:`pair_less`
    (insertion sort: the runs sorted here are a few dozen pairs)."""
    for i in range(lo + 1, hi):
        d = dist[i]
        x = index[i]
        j = i - 1
        while j >= lo and pair_less(d, x, dist[j], index[j]):
            dist[j + 1] = dist[j]
            index[j + 1] = index[j]
            j -= 1
        dist[j + 1] = d
        index[j + 1] = x


@kernel()
def _heap_search(
    q0, q1, q2, k, order, tree_points, nodes, boxes, dist, index, stack
):  # pragma: no cover - compiled
    """The k nearest pairs of a query, nearest box first with a max-heap (in
    ``dist[:k]``, ``index[:k]``, unordered)."""
    size = 0
    worst = np.inf
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        if box_sq_distance(q0, q1, q2, boxes, node) > worst:
            continue
        left = nodes[node, 2]
        if left >= 0:
            near_left = box_sq_distance(q0, q1, q2, boxes, left) <= box_sq_distance(
                q0, q1, q2, boxes, left + 1
            )
            stack[top] = left + 1 if near_left else left
            stack[top + 1] = left if near_left else left + 1
            top += 2
            continue
        for t in range(nodes[node, 0], nodes[node, 1]):
            e0 = tree_points[t, 0] - q0
            e1 = tree_points[t, 1] - q1
            e2 = tree_points[t, 2] - q2
            d = (e0 * e0 + e1 * e1) + e2 * e2
            j = order[t]
            if size < k:
                c = size  # sift up
                size += 1
                while c > 0:
                    p = (c - 1) >> 1
                    if pair_less(dist[p], index[p], d, j):
                        dist[c] = dist[p]
                        index[c] = index[p]
                        c = p
                    else:
                        break
                dist[c] = d
                index[c] = j
                if size == k:
                    worst = dist[0]
            elif pair_less(d, j, dist[0], index[0]):
                c = 0  # replace the root and sift down
                while True:
                    a = 2 * c + 1
                    if a >= k:
                        break
                    if a + 1 < k and pair_less(dist[a], index[a], dist[a + 1], index[a + 1]):
                        a += 1
                    if pair_less(d, j, dist[a], index[a]):
                        dist[c] = dist[a]
                        index[c] = index[a]
                        c = a
                    else:
                        break
                dist[c] = d
                index[c] = j
                worst = dist[0]


@kernel()
def _gather(
    q0, q1, q2, sq_radius, order, tree_points, nodes, boxes, dist, index, stack
):  # pragma: no cover - compiled
    """Every point within ``sq_radius`` of a query into ``dist``/``index``; returns
    how many there are, or ``len(dist) + 1`` as soon as they do not fit."""
    m = 0
    capacity = dist.shape[0]
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        if box_sq_distance(q0, q1, q2, boxes, node) > sq_radius:
            continue
        left = nodes[node, 2]
        if left >= 0:
            stack[top] = left + 1
            stack[top + 1] = left
            top += 2
            continue
        start = nodes[node, 0]
        stop = nodes[node, 1]
        if m + stop - start > capacity:
            return capacity + 1
        for t in range(start, stop):  # written always, kept when near: no branch
            e0 = tree_points[t, 0] - q0
            e1 = tree_points[t, 1] - q1
            e2 = tree_points[t, 2] - q2
            d = (e0 * e0 + e1 * e1) + e2 * e2
            dist[m] = d
            index[m] = order[t]
            m += d <= sq_radius
    return m


@kernel()
def knn_one(
    q0, q1, q2, k, guess, order, tree_points, nodes, boxes, dist, index, stack
):  # pragma: no cover - compiled
    """The k nearest points of a query, as ``dist[:k]`` (squared) and ``index[:k]``
    (rows of the tree's points), in no particular order; returns the largest of the k
    distances (squared).

    ``guess``: a radius likely to hold a little more than k points (a neighbouring
    query's k-th distance), or a negative number for none. Every point within it is
    gathered; when that is at least k points, the k nearest are among them, whatever
    the guess. Too few: the radius grows; too many for the scratch buffers ``dist``
    and ``index`` (at least ``k`` entries): a heap search.
    """
    found = False
    radius = guess
    for _ in range(_GROWTHS):
        if radius < 0.0:
            break
        sq_radius = radius * radius * _SLACK
        m = _gather(q0, q1, q2, sq_radius, order, tree_points, nodes, boxes, dist, index, stack)
        if m > dist.shape[0]:
            break
        if m >= k:
            select_pairs(dist, index, 0, m, k - 1)
            found = True
            break
        radius *= _GROWTH
    if not found:
        _heap_search(q0, q1, q2, k, order, tree_points, nodes, boxes, dist, index, stack)
    worst = 0.0
    for e in range(k):
        worst = max(worst, dist[e])
    return worst


@kernel(inline="always")
def next_guess(worst, q, previous, queries):  # pragma: no cover - compiled
    """The radius to gather query ``q``'s neighbours in after query ``previous``'s,
    whose k-th squared distance was ``worst``: that distance widened by the step
    between the two queries, at most by :data:`_WIDEST` (a long step crosses to
    another part of the cloud, where the previous radius says little)."""
    e0 = queries[q, 0] - queries[previous, 0]
    e1 = queries[q, 1] - queries[previous, 1]
    e2 = queries[q, 2] - queries[previous, 2]
    radius = np.sqrt(worst)
    return min(radius + np.sqrt((e0 * e0 + e1 * e1) + e2 * e2), _WIDEST * radius)


@kernel(nogil=True)
def _query(
    start, stop, queries, k, order, tree_points, nodes, boxes, sort, room, out_index, out_dist
):  # pragma: no cover - compiled
    """:meth:`KDTree.query` for queries ``start:stop``; each guess comes from the
    previous query, afresh at every multiple of :data:`QUERY_CHUNK`."""
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
            k,
            guess,
            order,
            tree_points,
            nodes,
            boxes,
            dist,
            index,
            stack,
        )
        if sort:
            sort_pairs(dist, index, 0, k)
        for e in range(k):
            out_index[i, e] = index[e]
            out_dist[i, e] = dist[e]


@kernel(inline="always")
def search_room(k: int) -> int:  # pragma: no cover - compiled
    """Scratch entries a query of ``k`` neighbours gathers into: every point of the
    leaves its guessed radius reaches (a few times ``k``) is written there."""
    return 8 * k + 128


class KDTree:
    """A k-d tree over 3-D points for many k-nearest-neighbour queries (built once).

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        Finite coordinates (converted to C-contiguous float64).
    leaf_size : int, default=LEAF_SIZE

    Attributes
    ----------
    n_points : int
    arrays : tuple of ndarray
        ``(order, tree_points, nodes, boxes)``, what the compiled helpers take.
    """

    def __init__(self, points: np.ndarray, leaf_size: int = LEAF_SIZE) -> None:
        points = np.ascontiguousarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must have shape (n, 3), got {points.shape}")
        self.n_points = len(points)
        self.arrays = _build(points, int(leaf_size))

    def query(
        self, queries: np.ndarray, k: int, *, sort: bool = True, n_threads: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest points of every query.

        Parameters
        ----------
        queries : ndarray of shape (q, 3)
            Best in a spatial order (each query's search starts from the previous
            one's radius).
        k : int
            At most the number of points.
        sort : bool, default=True
            Nearest first (by distance, then index); otherwise in no particular order
            (the same set, and the same order for the same input).
        n_threads : int, default=1

        Returns
        -------
        indices : ndarray of shape (q, k), int64
        sq_distances : ndarray of shape (q, k), float64
        """
        if not 1 <= k <= self.n_points:
            raise ValueError(f"cannot take {k} neighbours among {self.n_points} points")
        queries = np.ascontiguousarray(queries, dtype=np.float64)
        index = np.empty((len(queries), k), dtype=np.int64)
        dist = np.empty((len(queries), k))
        arrays = (queries, int(k), *self.arrays, bool(sort), search_room(k), index, dist)
        run_blocks(_query, len(queries), n_threads, *arrays, align=QUERY_CHUNK)
        return index, dist
