"""Point correspondences from descriptors: nearest neighbour, ratio test, mutual filter."""

from __future__ import annotations

import numbers
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from numbers import Integral, Real

import numpy as np
import open3d as o3d

from .._utils.compiled import kernel
from .._utils.kdtree import insert_ranked
from .._utils.params import Interval, validate_params
from ..descriptors import unit_rows

__all__ = [
    "SALIENT_NEIGHBOURS",
    "Correspondences",
    "as_features",
    "correspondences_both_ways",
    "count_of",
    "distinctiveness",
    "find_correspondences",
    "k_best_correspondences",
    "nearest_both_ways",
    "nearest_descriptors",
    "salient",
    "shared_matches",
    "spread_indices",
    "turned_correspondences",
    "unit_rows",
]

#: The neighbour whose descriptor distance measures a point's distinctiveness: a point
#: whose descriptor has ten near twins in its own cloud (a wall, a floor, a table top)
#: says little about where it is.
SALIENT_NEIGHBOURS = 10

# Rows of the distance matrix computed at a time (bounded memory for large clouds).
_CHUNK_ELEMENTS = 2**23

# Inside shared_matches(): both ways' matches of descriptor arrays already matched, by
# (id of the source array, id of the target array, max_ratio, k); each entry holds its
# arrays, so that their ids stay theirs.
_SHARED: ContextVar[dict | None] = ContextVar("o3d_rpointhop_shared_matches", default=None)


@contextmanager
def shared_matches() -> Iterator[None]:
    """Within it, :func:`correspondences_both_ways` asked for two descriptor arrays it
    has matched the other way round answers from those matches, swapped: the nearest
    descriptors both ways are the same whichever array is the source (to the bit), so
    registering a pair in both directions (a scan set's screening) matches it once. The
    arrays must not change inside; each thread has its own."""
    token = _SHARED.set({})
    try:
        yield
    finally:
        _SHARED.reset(token)


@dataclass
class Correspondences:
    """Matched point pairs.

    Attributes
    ----------
    pairs : ndarray of shape (m, 2), int64
        ``(source index, target index)`` per match: the layout of Open3D's
        ``CorrespondenceSet``.
    distances : ndarray of shape (m,)
        Descriptor distance of each match.
    ratios : ndarray of shape (m,)
        Distance to the nearest target descriptor over the distance to the second
        nearest (the ratio test's statistic; smaller is more distinctive).
    """

    pairs: np.ndarray
    distances: np.ndarray
    ratios: np.ndarray

    def __len__(self) -> int:
        return len(self.pairs)

    def rows(self, index: np.ndarray) -> Correspondences:
        """The matches ``index`` selects (a boolean mask or row indices), in its order."""
        return Correspondences(self.pairs[index], self.distances[index], self.ratios[index])

    def strongest(
        self, top_k: int | None = None, top_k_ratio: int | None = None
    ) -> Correspondences:
        """The R-PointHop paper's selection (Sec. III-B): the ``top_k`` matches with the
        smallest descriptor distance (M1), then the ``top_k_ratio`` of those with the
        smallest ratio (M2); counts, ``None`` for no limit. The rows keep their order."""
        chosen = np.arange(len(self))
        if top_k is not None and chosen.size > top_k:
            chosen = chosen[np.argsort(self.distances, kind="stable")[:top_k]]
        if top_k_ratio is not None and chosen.size > top_k_ratio:
            chosen = chosen[np.argsort(self.ratios[chosen], kind="stable")[:top_k_ratio]]
        return self.rows(np.sort(chosen))

    def __array__(self, dtype=None, copy=None):
        return self.pairs if dtype is None else self.pairs.astype(dtype)

    def to_open3d(self) -> o3d.utility.Vector2iVector:
        """The pairs as Open3D's ``Vector2iVector`` (a ``CorrespondenceSet``)."""
        return o3d.utility.Vector2iVector(self.pairs.astype(np.int32))


def as_features(x, name: str) -> np.ndarray:
    """``x`` as an ``(n_points, n_features)`` float array (an Open3D ``Feature`` read as
    ``data.T``; float32 kept, other types as float64), refused when empty, of another
    shape, or holding NaN or infinite values (``name`` says which argument)."""
    arr = np.asarray(x.data.T if isinstance(x, o3d.pipelines.registration.Feature) else x)
    if arr.ndim != 2 or arr.shape[0] == 0:
        raise ValueError(
            f"{name} must be a non-empty (n_points, n_features) array, got {arr.shape}"
        )
    if not np.issubdtype(arr.dtype, np.floating):
        arr = arr.astype(np.float64)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} holds NaN or infinite values")
    return arr


def _feature_pair(source_features, target_features) -> tuple[np.ndarray, np.ndarray]:
    """Both sides' descriptors as arrays (:func:`as_features`), refused when their
    lengths differ."""
    src = as_features(source_features, "source_features")
    tgt = as_features(target_features, "target_features")
    if src.shape[1] != tgt.shape[1]:
        raise ValueError(
            f"source and target descriptors differ in length: {src.shape[1]} vs {tgt.shape[1]}"
        )
    return src, tgt


def nearest_descriptors(
    queries: np.ndarray, references: np.ndarray, k: int = 2
) -> tuple[np.ndarray, np.ndarray]:
    """Exact ``k`` nearest reference rows (Euclidean) of every query row.

    Candidates come from blocks of the distance matrix computed with matrix products,
    which for descriptors of hundreds of dimensions is far faster than a k-d tree; the
    few best candidates are then re-measured directly in float64, so rounding in the
    fast pass (``|q|^2 + |r|^2 - 2 q.r`` cancels badly for near-equal rows) cannot
    reorder near-ties.

    Returns
    -------
    indices : ndarray of shape (n_queries, k)
    distances : ndarray of shape (n_queries, k)
        Nearest first.
    """
    forward, _ = _nearest(queries, references, k, 0)
    return forward


def nearest_both_ways(
    a: np.ndarray, b: np.ndarray, k: int = 2, k_back: int = 2
) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """:func:`nearest_descriptors` both ways, ``(a, b, k)`` and ``(b, a, k_back)``, from one
    pass over the distance matrix: the products ``a . b`` are computed once and each
    block gives its rows' candidates and its columns' (the same candidates, so the same
    answers, as the two calls).

    Returns
    -------
    (indices, distances), (back_indices, back_distances)
        As :func:`nearest_descriptors` returns them, for ``a``'s rows among ``b``'s and
        for ``b``'s rows among ``a``'s.
    """
    return _nearest(a, b, k, max(1, int(k_back)))


def _nearest(queries, references, k: int, k_back: int):
    """The ``k`` nearest references of every query and, with ``k_back`` > 0, the
    ``k_back`` nearest queries of every reference (else None)."""
    dtype = np.result_type(np.asarray(queries).dtype, np.asarray(references).dtype, np.float32)
    # Row-major copies: the candidate gathers below read whole rows.
    fast_q = np.ascontiguousarray(queries, dtype=dtype)
    fast_r = np.ascontiguousarray(references, dtype=dtype)
    k = min(k, len(fast_r))
    n_candidates = min(len(fast_r), k + 2)
    ref_sq = np.einsum("ij,ij->i", fast_r, fast_r)
    columns = None
    if k_back:
        k_back = min(k_back, len(fast_q))
        columns = _ColumnCandidates(fast_q, len(fast_r), min(len(fast_q), k_back + 2))
    rows = max(1, _CHUNK_ELEMENTS // max(1, len(fast_r) + n_candidates * fast_q.shape[1]))
    indices = np.empty((len(fast_q), k), dtype=np.int64)
    distances = np.empty((len(fast_q), k), dtype=np.float64)
    for start in range(0, len(fast_q), rows):
        stop = min(len(fast_q), start + rows)
        block = fast_q[start:stop] @ fast_r.T
        if columns is not None:
            # The block's products serve both ways: its columns' candidates first.
            cand = columns.add(block, ref_sq, start, n_candidates)
        else:
            # |r|^2 - 2 q.r (+ |q|^2), in place: the same bits as the expression,
            # without its two temporaries of the block's size.
            block *= -2.0
            block += ref_sq
            cand = _all_columns(block.shape, n_candidates)
            if cand is None:
                cand = _smallest(block, n_candidates)
        indices[start:stop], distances[start:stop] = _exact(fast_q[start:stop], fast_r, cand, k)
    if columns is None:
        return (indices, distances), None
    return (indices, distances), columns.nearest(fast_r, k_back)


def _all_columns(shape, n: int) -> np.ndarray | None:
    """Every column as every row's candidate when a row has no more than ``n`` of them."""
    if n < shape[1]:
        return None
    return np.broadcast_to(np.arange(shape[1]), shape)


def _exact(queries, references, cand, k: int):
    """Each query's ``k`` nearest among its candidate references, measured exactly:
    differences of near-equal numbers are exact in floating point, and the squares are
    summed in float64."""
    diff = references[cand] - queries[:, None, :]
    exact = np.sqrt(np.einsum("qcd,qcd->qc", diff, diff, dtype=np.float64))
    order = np.argsort(exact, axis=1, kind="stable")[:, :k]
    return np.take_along_axis(cand, order, axis=1), np.take_along_axis(exact, order, axis=1)


class _ColumnCandidates:
    """Every reference's candidate queries, gathered block by block of the products
    (blocks of consecutive query rows, in order): each column's ``n`` smallest of
    ``|q|^2 - 2 q.r`` kept in order, as :func:`_smallest` would keep them from the
    reference's own row of the distance matrix."""

    def __init__(self, queries: np.ndarray, n_references: int, n: int) -> None:
        self.queries = queries
        self.query_sq = np.einsum("ij,ij->i", queries, queries)
        self.n = n
        self.every = n >= len(queries)  # then every query is a candidate
        self.values = np.full((n_references, n), np.inf, dtype=queries.dtype)
        self.rows = np.zeros((n_references, n), dtype=np.int64)
        self.kept = np.zeros(n_references, dtype=np.int64)
        # The values' last column, contiguous for the kernel's vectorised pass; minus
        # infinity when every query is a candidate (no column keeps any).
        self.last = np.full(n_references, -np.inf if self.every else np.inf, dtype=queries.dtype)

    def add(self, block, ref_sq, start: int, n_row: int) -> np.ndarray:
        """Take a block's columns' candidates; return its rows' ``n_row`` candidates."""
        every_row = n_row >= block.shape[1]
        minus_two = np.full(1, -2.0, dtype=block.dtype)
        row_cand = _candidates_both_ways(
            block,
            ref_sq,
            self.query_sq[start : start + len(block)],
            0 if every_row else n_row,
            start,
            0 if self.every else self.n,
            self.values,
            self.rows,
            self.kept,
            self.last,
            minus_two,
        )
        return _all_columns(block.shape, n_row) if every_row else row_cand

    def nearest(self, references: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Every reference's ``k`` nearest queries, exactly, from its candidates."""
        if self.every:
            cand = _all_columns((len(references), len(self.queries)), self.n)
        else:
            cand = self.rows
        indices = np.empty((len(references), k), dtype=np.int64)
        distances = np.empty((len(references), k), dtype=np.float64)
        size = self.queries.shape[1]
        rows = max(1, _CHUNK_ELEMENTS // max(1, len(self.queries) + self.n * size))
        for start in range(0, len(references), rows):
            stop = min(len(references), start + rows)
            indices[start:stop], distances[start:stop] = _exact(
                references[start:stop], self.queries, cand[start:stop], k
            )
        return indices, distances


#: Distance blocks from this many entries take their candidates from the compiled
#: kernel (the same columns as the argmin passes): below, the passes are as quick, and
#: an object pair of a few thousand points does not wait for the kernel to compile.
COMPILED_FROM = 6_000_000


def _smallest(values: np.ndarray, n: int) -> np.ndarray:
    """Column indices of the ``n`` smallest entries of every row (first index among
    ties), ``values`` possibly overwritten: ``n`` passes of ``argmin`` (for the few
    candidates matching needs, 6x faster than ``argpartition``, measured on 512 x 4400
    rows), or one compiled pass over each row for large blocks."""
    if values.size >= COMPILED_FROM:
        return _smallest_rows(values, n)
    rows = np.arange(len(values))
    out = np.empty((len(values), n), dtype=np.int64)
    for j in range(n):
        pick = values.argmin(axis=1)
        out[:, j] = pick
        values[rows, pick] = np.inf
    return out


@kernel()
def _smallest_rows(values, n):  # pragma: no cover - compiled
    """:func:`_smallest` in one pass per row: each row's ``n`` smallest kept in order as
    the row is read, a newcomer going after the ones it does not beat, which is the
    order of the argmin passes (value, then index). One thread: matching takes no
    ``n_jobs``, so it starts no threads of its own."""
    q, m = values.shape
    out = np.empty((q, n), dtype=np.int64)
    for i in range(q):
        best = np.empty(n, dtype=values.dtype)
        kept = 0
        for j in range(m):
            v = values[i, j]
            if kept < n or v < best[n - 1]:
                kept = insert_ranked(best, out[i], kept, v, j)
    return out


#: Entries of a row, spread evenly over it, whose smallest give the bound under which
#: the row's candidates lie (:func:`_candidates_both_ways`).
ROW_SAMPLE = 512


@kernel()
def _candidates_both_ways(
    block,
    ref_sq,
    query_sq,
    n_row,
    first,
    n_col,
    col_values,
    col_rows,
    col_kept,
    col_last,
    minus_two,
):  # pragma: no cover - compiled
    """One pass over a block of products ``q . r`` (rows: queries ``first`` on): each
    row's ``n_row`` smallest of ``-2 q.r + |r|^2`` (returned, ``(rows, n_row)``; none
    when ``n_row`` is 0) and, into the running lists ``col_values`` / ``col_rows`` /
    ``col_kept``, each column's ``n_col`` smallest of ``-2 q.r + |q|^2`` (none when 0;
    ``col_last``: a contiguous copy of ``col_values``' last column, which is infinite
    until a list is full, or minus infinity when no column keeps any). ``minus_two``
    holds -2 in the block's dtype, so each value is computed in that dtype as the numpy
    passes compute it. Both keep a newcomer after the ones it does not beat: value,
    then index, as :func:`_smallest`.

    Few entries of a row can enter either list, so each row is first marked where one
    might, in a loop the compiler vectorises: a column's entry when it beats the
    column's largest kept value, a row's when it is no larger than the ``n_row``-th
    smallest of :data:`ROW_SAMPLE` of the row's entries (that many entries are no
    larger, so nothing above it is among the row's smallest). Only the marked entries
    are then offered to the lists, in the order of the plain pass, which gives the same
    lists to the bit."""
    q, m = block.shape
    out = np.empty((q, max(n_row, 1)), dtype=np.int64)
    best = np.empty(max(n_row, 1), dtype=block.dtype)
    factor = minus_two[0]
    words = (m + 7) // 8
    marks = np.zeros(words * 8, dtype=np.uint8)
    marked = marks.view(np.uint64)  # eight marks a word: unmarked stretches skip fast
    step = max(1, m // ROW_SAMPLE)
    for i in range(q):
        own = query_sq[i]
        row = block[i]
        bound = -np.inf
        if n_row:
            kept = 0
            for j in range(0, m, step):
                v = row[j] * factor + ref_sq[j]
                if kept < n_row or v < best[n_row - 1]:
                    kept = insert_ranked(best, out[i], kept, v, j)
            bound = best[n_row - 1] if kept == n_row else np.inf
        for j in range(m):
            g = row[j] * factor
            marks[j] = (g + ref_sq[j] <= bound) | ((g + own < col_last[j]) << 1)
        kept = 0
        for word in range(words):
            if not marked[word]:
                continue
            for j in range(8 * word, min(m, 8 * word + 8)):
                mark = marks[j]
                if not mark:
                    continue
                g = row[j] * factor
                if mark & 1:
                    v = g + ref_sq[j]
                    if kept < n_row or v < best[n_row - 1]:
                        kept = insert_ranked(best, out[i], kept, v, j)
                if mark & 2:
                    col_kept[j] = insert_ranked(
                        col_values[j], col_rows[j], col_kept[j], g + own, first + i
                    )
                    col_last[j] = col_values[j, n_col - 1]
    return out


def count_of(value: int | float, n: int, minimum: int = 1) -> int:
    """A count given as an int, or as a share in (0, 1] of ``n`` (at least ``minimum``).

    Raises
    ------
    ValueError
        For anything else (a bool, zero, a negative number, a float above 1).
    """
    if isinstance(value, numbers.Integral) and not isinstance(value, bool) and value >= 1:
        return int(value)
    if isinstance(value, numbers.Real) and not isinstance(value, bool) and 0 < value <= 1:
        return max(minimum, int(round(float(value) * n)))
    raise ValueError(f"a count must be an int >= 1 or a share in (0, 1], got {value!r}")


_COUNT = [None, Interval(Integral, 1, None, closed="left"), Interval(Real, 0, 1, closed="right")]
_POSITIVE = [None, Interval(Real, 0, None, closed="neither")]


def _ratio_test(nearest: np.ndarray, second: np.ndarray) -> np.ndarray:
    """The ratio test's statistic: the nearest distance over the second nearest (the
    nearest of another point); 1 where both are 0 (two identical nearest descriptors:
    ambiguous)."""
    ratio = np.divide(nearest, second, out=np.zeros_like(nearest), where=second > 0)
    ratio[(second == 0) & (nearest == 0)] = 1.0
    return ratio


@validate_params(
    {
        "source_features": "no_validation",
        "target_features": "no_validation",
        "mutual_filter": ["boolean"],
        "max_distance": _POSITIVE,
        "max_ratio": _POSITIVE,
        "top_k": _COUNT,
        "top_k_ratio": _COUNT,
    },
    prefer_skip_nested_validation=True,
)
def find_correspondences(
    source_features,
    target_features,
    *,
    mutual_filter: bool = False,
    max_distance: float | None = None,
    max_ratio: float | None = None,
    top_k: int | float | None = None,
    top_k_ratio: int | float | None = None,
) -> Correspondences:
    """Match every source point to the target point with the nearest descriptor, then filter.

    The filters follow R-PointHop (Sec. III-B): keep the ``top_k`` matches with the
    smallest descriptor distance (the paper's M1), then the ``top_k_ratio`` of those with
    the smallest ratio between the nearest and the second nearest distance (M2); or, by
    threshold, matches with distance at most ``max_distance`` (t1) and ratio at most
    ``max_ratio`` (t2). ``mutual_filter`` keeps only pairs that are each other's nearest
    (Open3D's name for the filter).

    Parameters
    ----------
    source_features, target_features : array-like of shape (n, d) or open3d Feature
        Descriptors, one row per point (an Open3D ``Feature`` is read as ``data.T``).
    mutual_filter : bool, default=False
    max_distance, max_ratio : float, default=None
    top_k, top_k_ratio : int or float, default=None
        Counts: an int is a number of matches, a float in (0, 1] a share of the source
        points (``top_k_ratio`` counts the matches kept by ratio test, not a ratio).

    Returns
    -------
    Correspondences
        Sorted by source index.

    Examples
    --------
    >>> import numpy as np
    >>> from o3d_rpointhop import find_correspondences
    >>> a = np.eye(4)
    >>> find_correspondences(a, a[::-1]).pairs[:, 1].tolist()
    [3, 2, 1, 0]
    """
    src, tgt = _feature_pair(source_features, target_features)
    if mutual_filter:
        (idx, dist), (back, _) = nearest_both_ways(src, tgt, k=2, k_back=1)
    else:
        (idx, dist), back = nearest_descriptors(src, tgt, k=2), None
    return _filtered(idx, dist, back, max_distance, max_ratio, top_k, top_k_ratio)


def correspondences_both_ways(
    source_features,
    target_features,
    *,
    max_ratio: float | None = None,
    k: int = 1,
    max_queries: int | None = None,
) -> tuple[Correspondences, Correspondences]:
    """``find_correspondences(source, target)`` and ``find_correspondences(target,
    source)`` (each with ``max_ratio``), or with ``k`` above 1 the two directions'
    :func:`k_best_correspondences`, from one pass over the descriptors' distances
    (:func:`nearest_both_ways`): the same matches as the two calls, for half the
    products.

    With ``max_queries``, a direction whose query cloud has more points than that
    searches from that many of them, spread evenly by index, each against every point
    of the other cloud (for a caller that keeps a few thousand matches of clouds
    several times larger).

    Returns
    -------
    forward, backward : Correspondences
        Source to target; target to source (pairs ``(target index, source index)``).
    """
    k = _checked_count(k, "k")
    if max_queries is not None:
        max_queries = _checked_count(max_queries, "max_queries")
    if k > 1 and max_ratio is not None:
        raise ValueError("max_ratio is defined on the nearest descriptor alone: not with k > 1")
    memo = _SHARED.get()
    if memo is not None:
        swapped = memo.get((id(target_features), id(source_features), max_ratio, k, max_queries))
        if swapped is not None:
            return swapped[1], swapped[0]
    found = _both_ways(source_features, target_features, max_ratio, k, max_queries)
    if memo is not None:
        key = (id(source_features), id(target_features), max_ratio, k, max_queries)
        memo[key] = (*found, source_features, target_features)
    return found


def spread_indices(n: int, count: int | None) -> np.ndarray | None:
    """``count`` of the indices ``0 .. n - 1``, spread evenly, ascending (a matcher's cap
    and its thinned queries); None when ``count`` is None or not below ``n``: every
    index."""
    if count is None or count >= n:
        return None
    return np.unique(np.linspace(0, n - 1, count).astype(np.int64))


def _one_way(queries, references, rows, max_ratio, k: int) -> Correspondences:
    """The matches of the query rows ``rows`` (None: all) among every reference, as
    one direction of :func:`_both_ways` gives them, indexed in the whole query cloud."""
    chosen = queries if rows is None else queries[rows]
    if k > 1:
        k_ref = min(k, len(references))
        found = _k_best(*nearest_descriptors(chosen, references, k_ref + 1), k_ref)
    else:
        idx, dist = nearest_descriptors(chosen, references, k=2)
        found = _filtered(idx, dist, None, None, max_ratio, None, None)
    if rows is not None:
        found.pairs[:, 0] = rows[found.pairs[:, 0]]
    return found


def _both_ways(source_features, target_features, max_ratio, k: int, max_queries=None):
    """:func:`correspondences_both_ways`, computed."""
    src, tgt = _feature_pair(source_features, target_features)
    rows, columns = spread_indices(len(src), max_queries), spread_indices(len(tgt), max_queries)
    if rows is not None or columns is not None:
        forward = _one_way(src, tgt, rows, max_ratio, k)
        return forward, _one_way(tgt, src, columns, max_ratio, k)
    if k > 1:
        k_src, k_tgt = min(k, len(tgt)), min(k, len(src))
        (idx, dist), (back_idx, back_dist) = nearest_both_ways(src, tgt, k_src + 1, k_tgt + 1)
        return _k_best(idx, dist, k_src), _k_best(back_idx, back_dist, k_tgt)
    (idx, dist), (back_idx, back_dist) = nearest_both_ways(src, tgt, k=2, k_back=2)
    forward = _filtered(idx, dist, None, None, max_ratio, None, None)
    return forward, _filtered(back_idx, back_dist, None, None, max_ratio, None, None)


def _filtered(idx, dist, back, max_distance, max_ratio, top_k, top_k_ratio) -> Correspondences:
    """:func:`find_correspondences`' filters on every query's nearest rows ``idx`` /
    ``dist`` (``back``: each reference's nearest query, for the mutual filter)."""
    n = len(idx)
    top_k = None if top_k is None else count_of(top_k, n)
    top_k_ratio = None if top_k_ratio is None else count_of(top_k_ratio, n)
    nearest = idx[:, 0]
    d1 = dist[:, 0]
    d2 = dist[:, 1] if dist.shape[1] > 1 else np.full_like(d1, np.inf)
    ratio = _ratio_test(d1, d2)
    keep = np.ones(n, dtype=bool)
    if back is not None:
        keep &= back[nearest, 0] == np.arange(n)
    if max_distance is not None:
        keep &= d1 <= max_distance
    if max_ratio is not None:
        keep &= ratio <= max_ratio
    chosen = np.flatnonzero(keep)
    kept = Correspondences(
        pairs=np.c_[chosen, nearest[chosen]].astype(np.int64),
        distances=d1[chosen],
        ratios=ratio[chosen],
    )
    return kept.strongest(top_k, top_k_ratio)


def k_best_correspondences(source_features, target_features, k: int) -> Correspondences:
    """Match every source point to each of its ``k`` nearest target descriptors (k-best
    matching): where the right partner is only the second or third nearest, as on a
    pair that overlaps little, it is still among the matches.

    Parameters
    ----------
    source_features, target_features : array-like of shape (n, d) or open3d Feature
    k : int
        Matches per source point (at least 1; capped at the target's size). 1 gives the
        matches of :func:`find_correspondences` without filters.

    Returns
    -------
    Correspondences
        Sorted by source index, then nearest first; each match's ratio is its distance
        over the next nearest's.
    """
    k = _checked_count(k, "k")
    src, tgt = _feature_pair(source_features, target_features)
    k = min(k, len(tgt))
    idx, dist = nearest_descriptors(src, tgt, k=k + 1)
    return _k_best(idx, dist, k)


def _checked_count(value, name: str) -> int:
    """A count (``k``, ``max_queries``): an int of at least 1, else a clear error."""
    if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
        raise ValueError(f"{name} must be an int >= 1, got {value!r}")
    return int(value)


def _k_best(idx, dist, k: int) -> Correspondences:
    """Every query's ``k`` nearest rows as matches, from its ``k + 1`` nearest (fewer
    where the references run out) ``idx`` / ``dist``: each ratio is the distance over
    the next nearest's."""
    if dist.shape[1] == k:  # no next nearest: the last match's ratio is 1
        dist = np.c_[dist, dist[:, -1:]]
    d, following = dist[:, :k], dist[:, 1 : k + 1]
    ratio = np.divide(d, following, out=np.ones_like(d), where=following > 0)
    return Correspondences(
        pairs=np.c_[np.repeat(np.arange(len(idx)), k), idx[:, :k].ravel()].astype(np.int64),
        distances=d.ravel(),
        ratios=ratio.ravel(),
    )


def turned_correspondences(source_features, target_turns) -> Correspondences:
    """Match every source point to the target point one of whose turned descriptors is
    nearest (``RPointHopTransformer.transform_turns``): where the two points' frames
    agree only up to a turn about the normal, one of the target's turns matches.

    Parameters
    ----------
    source_features : array-like of shape (n, d)
        The source's descriptors (turn 0).
    target_turns : array-like of shape (n_turns, m, d)
        The target's descriptors under each turn of its frames.

    Returns
    -------
    Correspondences
        One match per source point, sorted by source index: the target point, the
        smallest distance over its turns and the ratio of that distance to the
        nearest one of any other target point (the ratio test's statistic).
    """
    turns = np.asarray(target_turns)
    if turns.ndim != 3:
        raise ValueError(f"target_turns must be (n_turns, m, d), got shape {turns.shape}")
    n_turns, m = turns.shape[:2]
    src, stacked = _feature_pair(source_features, turns.reshape(n_turns * m, -1))
    # Among the n_turns + 1 nearest rows at least one is of another point (m >= 2).
    idx, dist = nearest_descriptors(src, stacked, k=n_turns + 1)
    point = idx % m
    nearest = point[:, 0]
    d1 = dist[:, 0]
    # Distances come nearest first: the nearest row of another point is the least of them.
    d2 = np.where(point != nearest[:, None], dist, np.inf).min(axis=1)
    ratio = _ratio_test(d1, d2)
    return Correspondences(
        pairs=np.c_[np.arange(len(src)), nearest].astype(np.int64),
        distances=d1,
        ratios=ratio,
    )


def distinctiveness(features: np.ndarray, k: int = SALIENT_NEIGHBOURS) -> np.ndarray:
    """How distinct each row of ``features`` is within its own set: the distance to its
    ``k``-th nearest other row (exact, :func:`nearest_descriptors`). Points of flat,
    repeated regions have many near twins and score low.

    Parameters
    ----------
    features : array-like of shape (n, d)
    k : int, default=SALIENT_NEIGHBOURS
        Capped at ``n - 1``.

    Returns
    -------
    ndarray of shape (n,)
    """
    features = as_features(features, "features")
    k = max(1, min(int(k), len(features) - 1))
    _, dist = nearest_descriptors(features, features, k=k + 1)  # the row itself first
    return dist[:, -1]


def salient(features: np.ndarray, share: float, k: int = SALIENT_NEIGHBOURS) -> np.ndarray:
    """Which rows are among the ``share`` (in (0, 1]) most distinct of ``features``
    (:func:`distinctiveness`; ties broken by row order, so exactly
    ``ceil(share * n)`` rows are kept).

    Returns
    -------
    ndarray of shape (n,), bool
    """
    if not 0.0 < share <= 1.0:
        raise ValueError(f"share must be in (0, 1], got {share}")
    score = distinctiveness(features, k)
    keep = np.zeros(len(score), dtype=bool)
    keep[np.argsort(-score, kind="stable")[: int(np.ceil(share * len(score)))]] = True
    return keep
