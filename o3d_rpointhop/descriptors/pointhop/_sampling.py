"""Rigid-invariant subsampling for the hops: farthest points for small clouds, Poisson
disks for large ones.

Farthest point sampling runs compiled, from a start point that moves with the cloud
(:func:`invariant_start`). Given the cloud's k-nearest lists (which the hops search
anyway), a pick updates only the neighbours it can affect once the sample is dense
enough, and a heap finds the next pick: the exact FPS picks, at a small share of the
``O(n m)`` full updates (1500 of 2000 points: 0.4 ms instead of 3 ms).

Without the lists, FPS picks ``m`` of ``n`` points in ``O(n m)`` time, which is
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

from ..._utils.compiled import kernel
from ..._utils.kdtree import insert_ranked, pair_less
from ..._utils.threads import run_blocks
from ._neighbors import HopSearch, key_ceiling, tie_key, tie_ranks

__all__ = [
    "FPS_MAX_POINTS",
    "fps_subsets",
    "hop_subsets",
    "invariant_start",
    "poisson_disk_subset",
    "priorities",
    "resolve_method",
]

#: Clouds of up to this many points are sampled by exact FPS (0.3 s at this size); larger
#: clouds by Poisson disks.
FPS_MAX_POINTS = 16384
# Neighbours that compete with each point. A thinning keeps at least the local priority
# maxima among them, about n / (k + 1), so shares down to 1/9 are reachable in one step.
_COMPETITORS = 8
# Irrational step of the priority sawtooth (the golden ratio's conjugate).
_GOLDEN = 0.6180339887498949


def invariant_start(points: np.ndarray, ranks: np.ndarray | None = None) -> int:
    """Index of the point farthest from the centroid (the highest of its
    :func:`~._neighbors.tie_ranks`, given as ``ranks`` or computed): the same point
    after any rigid motion or permutation."""
    return int(np.argmax(tie_ranks(points) if ranks is None else ranks))


@kernel()
def _heap_push(keys, items, size, key, item):  # pragma: no cover - compiled
    """Push onto a max-heap of ``(key, -item)`` (the larger key, then the lower item,
    on top); returns the new size."""
    c = size
    while c > 0:
        p = (c - 1) >> 1
        if keys[p] > key or (keys[p] == key and items[p] < item):
            break
        keys[c] = keys[p]
        items[c] = items[p]
        c = p
    keys[c] = key
    items[c] = item
    return size + 1


@kernel()
def _heap_pop(keys, items, size):  # pragma: no cover - compiled
    """Remove the top of the heap; returns the new size."""
    size -= 1
    key = keys[size]
    item = items[size]
    c = 0
    while True:
        a = 2 * c + 1
        if a >= size:
            break
        b = a + 1
        if b < size and (keys[b] > keys[a] or (keys[b] == keys[a] and items[b] < items[a])):
            a = b
        if keys[a] > key or (keys[a] == key and items[a] < item):
            keys[c] = keys[a]
            items[c] = items[a]
            c = a
        else:
            break
    if size > 0:
        keys[c] = key
        items[c] = item
    return size


@kernel(nogil=True)
def _farthest_points(
    points, candidates, m, start, neighbours, reach, ranks
):  # pragma: no cover - compiled
    """Positions (among ``candidates``, rows of ``points``) of the ``m``-point farthest
    point sample from position ``start``, in the order picked.

    Every step picks the candidate farthest from those picked (by the distance's
    :func:`~._neighbors.tie_key`, then the lowest of the rows' ``ranks``, so that the
    same point is picked in any frame) and lowers the others' distances to the picked
    set. A pick can only lower the distances of candidates closer to it than the
    distance it was picked at (the largest of all); when those all lie within its
    ``neighbours`` (a row of the cloud's k-nearest lists, ``reach`` a squared distance
    within which every point is among them: empty arrays for none), only they are
    updated and the next pick comes from a lazy max-heap. Either
    way the picks are those of the full update, to the bit.
    """
    c = candidates.shape[0]
    k = neighbours.shape[1]
    rank = np.empty(c, np.int64)  # heap items: rank * c + position, lower on top
    for t in range(c):
        rank[t] = ranks[candidates[t]]
    position = np.full(points.shape[0], -1, np.int64)
    for t in range(c):
        position[candidates[t]] = t
    nearest = np.full(c, np.inf)  # squared distance to the picked set; -1 once picked
    picked = np.empty(m, np.int64)
    capacity = 2 * c + 16
    keys = np.empty(capacity)
    items = np.empty(capacity, np.int64)
    size = 0
    heaped = False  # the heap holds every candidate's current distance
    current = start
    radius = np.inf
    for step in range(m):
        picked[step] = current
        row = candidates[current]
        nearest[current] = -1.0
        p0 = points[row, 0]
        p1 = points[row, 1]
        p2 = points[row, 2]
        if k > 0 and radius <= reach[row]:
            if not heaped or size + k > capacity:
                size = 0
                for t in range(c):
                    if nearest[t] >= 0.0:
                        size = _heap_push(keys, items, size, tie_key(nearest[t]), rank[t] * c + t)
                heaped = True
            for e in range(k):
                j = neighbours[row, e]
                t = position[j]
                if t >= 0 and nearest[t] >= 0.0:
                    d0 = points[j, 0] - p0
                    d1 = points[j, 1] - p1
                    d2 = points[j, 2] - p2
                    d = (d0 * d0 + d1 * d1) + d2 * d2
                    if d < nearest[t]:
                        nearest[t] = d
                        size = _heap_push(keys, items, size, tie_key(d), rank[t] * c + t)
            while size > 0 and keys[0] != tie_key(nearest[items[0] % c]):
                size = _heap_pop(keys, items, size)  # stale: lowered since, or picked
            if step + 1 < m:
                current = items[0] % c
                radius = key_ceiling(keys[0])
        else:
            best = -1.0
            best_rank = 0
            for t in range(c):
                if nearest[t] >= 0.0:
                    j = candidates[t]
                    d0 = points[j, 0] - p0
                    d1 = points[j, 1] - p1
                    d2 = points[j, 2] - p2
                    d = (d0 * d0 + d1 * d1) + d2 * d2
                    if d < nearest[t]:
                        nearest[t] = d
                        if heaped:  # keep the heap current (rebuilt when it fills)
                            if size == capacity:
                                heaped = False
                            else:
                                size = _heap_push(keys, items, size, tie_key(d), rank[t] * c + t)
                    key = tie_key(nearest[t])
                    if key > best or (key == best and rank[t] < best_rank):
                        best = key
                        best_rank = rank[t]
                        current = t
            radius = key_ceiling(best)
    return picked


def fps_subsets(
    points: np.ndarray, sizes: list[int], graph=None, ranks: np.ndarray | None = None
) -> list[np.ndarray]:
    """Nested farthest point samples of ``points``, one per requested size.

    The sampling starts at :func:`invariant_start`, so the samples move with the cloud
    under rigid motions and follow its rows under permutations. Farthest point sampling
    is greedy: the first ``m`` picks from a set that contains the first ``m'`` > ``m``
    picks are those same points (the pick that is farthest in the larger set is in the
    smaller one, and the lowest ranked such point in both). So one run picks the largest sample,
    and each smaller one is its first picks: nested even when distances tie.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    sizes : list of int
        Non-increasing, each between 1 and ``n``.
    graph : tuple of ndarray, default=None
        The cloud's k-nearest lists (``(n, k)`` rows, the point itself not among them)
        and each list's largest squared distance ``(n,)``: the same samples, found
        touching only the neighbours a pick can affect (see
        :func:`_farthest_points`).
    ranks : ndarray of int64, default=None
        The rows' :func:`~._neighbors.tie_ranks` (computed if not given).

    Returns
    -------
    subsets : list of ndarray of int64
        Sorted row indices into ``points``, one array per entry of ``sizes``.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    n = len(points)
    if any(b > a for a, b in zip(sizes, sizes[1:], strict=False)):
        raise ValueError(f"sample sizes must not increase, got {sizes}")
    for m in sizes:
        if not 1 <= m <= n:
            raise ValueError(f"cannot sample {m} of {n} points")
    everything = np.arange(n, dtype=np.int64)
    drawn = [m for m in sizes if m < n]
    if not drawn:
        return [everything for _ in sizes]
    neighbours, reach = graph if graph is not None else (np.empty((0, 0), np.int32), np.empty(0))
    ranks = tie_ranks(points) if ranks is None else ranks
    start = invariant_start(points, ranks)
    picks = _farthest_points(points, everything, int(drawn[0]), start, neighbours, reach, ranks)
    return [everything if m == n else np.sort(picks[:m]) for m in sizes]


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


def poisson_disk_subset(
    points: np.ndarray,
    m: int,
    lists: np.ndarray | None = None,
    n_threads: int = 1,
    ranks: np.ndarray | None = None,
) -> np.ndarray:
    """Sorted indices of an ``m``-point Poisson-disk subsample of ``points``.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    m : int
        Between 1 and ``n``. Shares below about ``1 / 9`` of ``n`` take several rounds.
    lists : ndarray of shape (n, k), default=None
        Every point's ``k`` nearest others, in any order (the hops' search of the whole
        cloud), ``k`` at least the competitors: the first round takes each point's
        competitors from them instead of searching again (the same competitors).
    n_threads : int, default=1
        Threads of the searches (the sample does not depend on it).
    ranks : ndarray of int64, default=None
        The points' :func:`~._neighbors.tie_ranks`, if known (computed otherwise).

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
        first = lists if len(current) == n else None
        current = current[_thin(points[current], step, first, n_threads, ranks)]
    return current


@kernel(nogil=True)
def _nearest_of_lists(
    start, stop, points, lists, ranks, rows, out_index, out_sq
):  # pragma: no cover - compiled
    """For the rows ``start:stop``, the ``k`` nearest of each row's candidates
    ``lists[i]`` (by the squared distance's ``tie_key``, then rank, as the searches
    rank them; ``k`` the width of ``out_index``; ``rows``: the row of each rank), with
    their squared distances, nearest first."""
    k = out_index.shape[1]
    keys = np.empty(k)
    kept_ranks = np.empty(k, np.int64)
    for i in range(start, stop):
        size = 0
        for e in range(lists.shape[1]):
            j = lists[i, e]
            o0 = points[j, 0] - points[i, 0]
            o1 = points[j, 1] - points[i, 1]
            o2 = points[j, 2] - points[i, 2]
            key = tie_key((o0 * o0 + o1 * o1) + o2 * o2)
            if size < k or pair_less(key, ranks[j], keys[k - 1], kept_ranks[k - 1]):
                size = insert_ranked(keys, kept_ranks, size, key, ranks[j])
        for e in range(k):
            j = rows[kept_ranks[e]]
            o0 = points[j, 0] - points[i, 0]
            o1 = points[j, 1] - points[i, 1]
            o2 = points[j, 2] - points[i, 2]
            out_index[i, e] = j
            out_sq[i, e] = (o0 * o0 + o1 * o1) + o2 * o2


@kernel(nogil=True)
def _death_radii(start, stop, sq, idx, priority, death):  # pragma: no cover - compiled
    """For the rows ``start:stop``, the squared distance to the nearest competitor of
    higher priority (infinite if none has)."""
    for i in range(start, stop):
        radius = np.inf
        for e in range(idx.shape[1]):
            if priority[idx[i, e]] > priority[i] and sq[i, e] < radius:
                radius = sq[i, e]
        death[i] = radius


def _thin(
    points: np.ndarray,
    m: int,
    lists: np.ndarray | None = None,
    n_threads: int = 1,
    ranks: np.ndarray | None = None,
) -> np.ndarray:
    """One hard-core thinning of ``points`` down to (at most) ``m`` of them; each point's
    competitors are its ``k`` nearest, taken from ``lists`` (see
    :func:`poisson_disk_subset`; ``ranks``: the whole cloud's, which the lists come
    with) or searched."""
    n = len(points)
    if m >= n:
        return np.arange(n, dtype=np.int64)
    k = min(_COMPETITORS, n - 1)
    if k < 1:
        return np.arange(m, dtype=np.int64)
    if lists is not None and lists.shape[1] >= k:
        idx = np.empty((n, k), np.int64)
        sq = np.empty((n, k))
        ranks = tie_ranks(points) if ranks is None else ranks
        rows = np.empty_like(ranks)  # the row of each rank: the inverse permutation
        rows[ranks] = np.arange(n)
        run_blocks(_nearest_of_lists, n, n_threads, points, lists, ranks, rows, idx, sq)
    else:
        # The point itself left out.
        idx = HopSearch(points).neighbours(None, k, n_threads=n_threads)[0]
        offsets = points[idx] - points[:, None, :]
        sq = (offsets[..., 0] ** 2 + offsets[..., 1] ** 2) + offsets[..., 2] ** 2
    # Only minima of the competitors are taken: their order does not matter.
    nearest = sq.min(axis=1)
    positive = nearest[nearest > 0]
    spacing = float(np.sqrt(np.median(positive))) if positive.size else 1.0
    priority = priorities(points, spacing)
    death = np.empty(n)
    run_blocks(_death_radii, n, n_threads, sq, idx, priority, death)
    # The m largest death radii; ties (equal distances, and the local maxima's infinite
    # radii) by the higher priority: both move with the cloud.
    order = np.lexsort((-priority, -death))
    return np.sort(order[:m])


def resolve_method(method: str, n_points: int) -> str:
    """``"fps"`` or ``"poisson"``: ``method``, with ``"auto"`` decided by the cloud's size
    (FPS up to :data:`FPS_MAX_POINTS` points)."""
    if method == "auto":
        return "fps" if n_points <= FPS_MAX_POINTS else "poisson"
    return method


def hop_subsets(
    points: np.ndarray,
    sizes: list[int],
    method: str,
    graph=None,
    n_threads: int = 1,
    ranks: np.ndarray | None = None,
) -> list[np.ndarray]:
    """Nested samples of ``points``, one per size (non-increasing), by ``method``.

    ``"fps"``: exact farthest point sampling from :func:`invariant_start`;
    ``"poisson"``: :func:`poisson_disk_subset`; ``"auto"``: FPS for clouds of at most
    :data:`FPS_MAX_POINTS` points, Poisson disks above. ``graph``: the cloud's k-nearest
    lists and their reach (:meth:`HopSearch.neighbours`), which both methods use;
    ``n_threads``: the Poisson disks' searches; ``ranks``: the rows'
    :func:`~._neighbors.tie_ranks`, which FPS breaks ties by.
    """
    method = resolve_method(method, len(points))
    if method == "fps":
        return fps_subsets(points, sizes, graph, ranks)
    current = np.arange(len(points), dtype=np.int64)
    out: list[np.ndarray] = []
    for m in sizes:
        if not 1 <= m <= len(current):
            raise ValueError(f"cannot sample {m} of {len(current)} points")
        if m < len(current):
            lists = graph[0] if graph is not None and len(current) == len(points) else None
            whole = ranks if len(current) == len(points) else None
            current = current[poisson_disk_subset(points[current], m, lists, n_threads, whole)]
        out.append(current)
    return out
