"""The hops from hop 2 on, compiled: octant pooling of the previous hop's features and
the channel-wise Saab transform, one query at a time.

For every query, its neighbours' feature rows (float32) are summed into its eight
bins, each sum divided by its bin's count (an empty bin takes the mean of the whole
neighbourhood), and every channel's eight means go through that channel's Saab
kernels. Three forms:

* :func:`pool`: the octant means alone, channel-major ``(n_channels, 8, n_queries)``,
  what fitting gathers the moments of;
* :func:`pool_saab`: the selected Saab outputs of every query, ``(n_queries,
  n_selected)``, what the next hop pools;
* :func:`pool_project`: the last hop followed by the descriptor's principal axes.
  Everything after the pooling is linear, so the Saab kernels and the axes fold into
  one matrix per bin, which each *source* point's features go through once (a matrix
  product); a query then only averages its neighbours' rows of it. With the default
  object model that is 2.7 times less arithmetic than projecting every query's
  pooled features (the last hop's sources are 3/8 of the queries).

Every query's sums run over its neighbours in their order, so a result does not
depend on the number of threads.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..._utils.compiled import kernel
from ..._utils.threads import map_threads, run_blocks
from ._octants import N_OCTANTS

__all__ = [
    "fold_first_hop",
    "fold_projection",
    "folded_projection",
    "matmul_blocks",
    "pool",
    "pool_project",
    "pool_saab",
    "remembered",
]

#: Rows of one matrix product in :func:`matmul_blocks`: a fixed size, so that a row's
#: rounding does not depend on how many threads share the product.
MATMUL_ROWS = 512


@kernel()
def _bin_means(features, neighbours, bins, i, sums, counts):  # pragma: no cover - compiled
    """Query ``i``'s octant means of ``features`` (``(n_sources, c)``) into ``sums``
    ``(8, c)`` float32 (``counts``: 8 integers, scratch)."""
    k = neighbours.shape[1]
    c = features.shape[1]
    for o in range(N_OCTANTS):
        counts[o] = 0
        for d in range(c):
            sums[o, d] = 0.0
    for j in range(k):
        b = bins[i, j]
        counts[b] += 1
        row = features[neighbours[i, j]]
        for d in range(c):
            sums[b, d] += row[d]
    for d in range(c):
        whole = np.float32(0.0)
        for o in range(N_OCTANTS):
            whole += sums[o, d]
        whole /= np.float32(k)
        for o in range(N_OCTANTS):
            if counts[o]:
                sums[o, d] /= np.float32(counts[o])
            else:
                sums[o, d] = whole


@kernel(nogil=True)
def _pool(start, stop, features, neighbours, bins, out):  # pragma: no cover - compiled
    c = features.shape[1]
    sums = np.empty((N_OCTANTS, c), np.float32)
    counts = np.empty(N_OCTANTS, np.int64)
    for i in range(start, stop):
        _bin_means(features, neighbours, bins, i, sums, counts)
        for o in range(N_OCTANTS):
            for d in range(c):
                out[d, o, i] = sums[o, d]


@kernel(nogil=True)
def _pool_saab(
    start, stop, features, neighbours, bins, channel, weights, offsets, out, rows
):  # pragma: no cover - compiled
    """Selected output ``s`` of queries ``start:stop`` into row ``rows[i]`` of ``out``:
    ``weights[s] . means[channel[s]] - offsets[s]``, its channel's eight octant means
    through its Saab kernel."""
    c = features.shape[1]
    n_out = channel.shape[0]
    sums = np.empty((N_OCTANTS, c), np.float32)
    by_channel = np.empty((c, N_OCTANTS), np.float32)
    counts = np.empty(N_OCTANTS, np.int64)
    for i in range(start, stop):
        _bin_means(features, neighbours, bins, i, sums, counts)
        for o in range(N_OCTANTS):
            for d in range(c):
                by_channel[d, o] = sums[o, d]
        target = rows[i]
        for s in range(n_out):
            row = by_channel[channel[s]]
            value = -offsets[s]
            for o in range(N_OCTANTS):
                value += weights[s, o] * row[o]
            out[target, s] = value


@kernel(nogil=True)
def _pool_project(start, stop, folded, neighbours, bins, bias, out, rows):  # pragma: no cover
    k = neighbours.shape[1]
    p = bias.shape[0]
    counts = np.empty(N_OCTANTS, np.int64)
    weight = np.empty(N_OCTANTS, np.float32)
    acc = np.empty(p, np.float32)
    for i in range(start, stop):
        for o in range(N_OCTANTS):
            counts[o] = 0
        for j in range(k):
            counts[bins[i, j]] += 1
        for o in range(N_OCTANTS):
            weight[o] = np.float32(1.0) / np.float32(max(counts[o], 1))
        for e in range(p):
            acc[e] = bias[e]
        for j in range(k):
            b = bins[i, j]
            row = folded[neighbours[i, j]]
            w = weight[b]
            for e in range(p):
                acc[e] += w * row[b * p + e]
        for o in range(N_OCTANTS):
            if counts[o] == 0:  # the whole neighbourhood's mean in this bin
                w = np.float32(1.0) / np.float32(k)
                for j in range(k):
                    row = folded[neighbours[i, j]]
                    for e in range(p):
                        acc[e] += w * row[o * p + e]
        target = rows[i]
        for e in range(p):
            out[target, e] = acc[e]


def _check(features: np.ndarray, neighbours: np.ndarray, bins: np.ndarray):
    return (
        np.ascontiguousarray(features, dtype=np.float32),
        np.ascontiguousarray(neighbours, dtype=np.int32),
        np.ascontiguousarray(bins, dtype=np.uint8),
    )


def pool(
    features: np.ndarray, neighbours: np.ndarray, bins: np.ndarray, n_threads: int = 1
) -> np.ndarray:
    """Octant means ``(n_channels, 8, n_queries)`` float32 of ``features``
    ``(n_sources, n_channels)`` over each query's ``neighbours`` (positions among the
    sources) by ``bins`` (both ``(n_queries, k)``)."""
    features, neighbours, bins = _check(features, neighbours, bins)
    out = np.empty((features.shape[1], N_OCTANTS, len(neighbours)), np.float32)
    run_blocks(_pool, len(neighbours), n_threads, features, neighbours, bins, out)
    return out


def pool_saab(
    features: np.ndarray,
    neighbours: np.ndarray,
    bins: np.ndarray,
    kernels: np.ndarray,
    means: np.ndarray,
    selected: np.ndarray,
    n_threads: int = 1,
    out: np.ndarray | None = None,
    rows: np.ndarray | None = None,
) -> np.ndarray:
    """The selected channel-wise Saab outputs of the octant means (see :func:`pool`):
    ``(n_queries, len(selected))`` float32, output ``selected[s]`` (flat index ``8 c +
    j``) being ``sum_o kernels[c, o, j] * mean[c, o] - means[c, j]``. Given ``out`` and
    ``rows``, query ``i`` is written to row ``rows[i]`` of ``out`` instead."""
    selected = np.asarray(selected, dtype=np.int64)
    channel, output = np.divmod(selected, N_OCTANTS)
    weights = np.ascontiguousarray(kernels[channel, :, output], dtype=np.float32)  # (s, 8)
    offsets = np.ascontiguousarray(means[channel, output], dtype=np.float32)
    features, neighbours, bins = _check(features, neighbours, bins)
    out, rows = _output(out, rows, len(neighbours), len(selected))
    arrays = (features, neighbours, bins, channel, weights, offsets, out, rows)
    run_blocks(_pool_saab, len(neighbours), n_threads, *arrays)
    return out


def folded_projection(
    kernels: np.ndarray,
    means: np.ndarray,
    selected: np.ndarray,
    components: np.ndarray,
    centre: np.ndarray,
    axes: np.ndarray,
    *,
    first_hop: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fold_projection` (or, with ``first_hop``, :func:`fold_first_hop`),
    remembered for the last few models: the same arrays of a fitted model (its last hop
    and its ``components``, not copies) and the same number of axes give the same
    folded map without computing it again (about 1 ms for the object model, a fortieth
    of describing 2k points)."""
    fold = fold_first_hop if first_hop else fold_projection
    return remembered(
        _FOLDS,
        (kernels, means, selected, components),
        (axes.shape[1], first_hop),
        lambda: fold(kernels, means, selected, centre, axes),
    )


#: Folded maps kept (each holds its model's arrays alive, about 1 MB for 128 axes).
_FOLDS: dict = {}


def remembered(cache: dict, arrays: tuple, extra: tuple, compute: Callable[[], Any]) -> Any:
    """``compute()``, remembered in ``cache`` for the same ``arrays`` (the same objects,
    not equal copies: a fitted model's) and ``extra``; beyond :data:`REMEMBERED` entries
    the oldest is dropped (each holds its arrays alive)."""
    key = (*map(id, arrays), *extra)
    hit = cache.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], arrays, strict=True)):
        return hit[1]
    value = compute()
    cache[key] = (arrays, value)
    while len(cache) > REMEMBERED:
        del cache[next(iter(cache))]
    return value


#: Entries a :func:`remembered` cache keeps: the last few models.
REMEMBERED = 4


def fold_projection(
    kernels: np.ndarray,
    means: np.ndarray,
    selected: np.ndarray,
    centre: np.ndarray,
    axes: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The last hop's Saab kernels and the principal axes as one linear map per bin.

    Returns ``weights`` ``(n_channels, 8 * n_axes)`` float32 and ``bias`` ``(n_axes,)``
    float32 such that the projection ``(outputs[selected] - centre) @ axes`` of a
    query's Saab outputs equals ``sum_o mean_o @ weights[:, o * n_axes : (o + 1) *
    n_axes] + bias``, ``mean_o`` the query's octant means (``(n_channels,)`` each).
    Computed in float64.
    """
    # The kernels and means as the hops apply them (float32, as a model file holds
    # them): a reloaded model folds to the same bytes.
    kernels = np.asarray(kernels, dtype=np.float32).astype(np.float64)
    means = np.asarray(means, dtype=np.float32).astype(np.float64)
    n_channels = kernels.shape[0]
    n_axes = axes.shape[1]
    spread = np.zeros((n_channels * N_OCTANTS, n_axes))
    spread[selected] = axes
    spread = spread.reshape(n_channels, N_OCTANTS, n_axes)
    weights = np.matmul(kernels, spread).reshape(n_channels, -1)
    bias = -(means.reshape(1, -1) @ spread.reshape(-1, n_axes))[0] - centre @ axes
    return weights.astype(np.float32), bias.astype(np.float32)


def fold_first_hop(
    kernels: np.ndarray,
    means: np.ndarray,
    selected: np.ndarray,
    centre: np.ndarray,
    axes: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """A first hop that is the last one and the principal axes as one linear map.

    Returns ``weights`` ``(dim, n_axes)`` float32 and ``bias`` ``(n_axes,)`` float32
    such that the projection ``(outputs[selected] - centre) @ axes`` of a query's hop-1
    Saab outputs (``attributes @ kernels[0] - means[0]``) equals ``attributes @ weights
    + bias``: one product of the attributes' width by the axes' instead of the Saab
    transform's square and then the projection. Computed in float64.
    """
    kernels = np.asarray(kernels[0], dtype=np.float32).astype(np.float64)
    means = np.asarray(means[0], dtype=np.float32).astype(np.float64)
    weights = kernels[:, selected] @ axes
    bias = -(means[selected] @ axes) - centre @ axes
    return weights.astype(np.float32), bias.astype(np.float32)


def matmul_blocks(a: np.ndarray, b: np.ndarray, n_threads: int = 1) -> np.ndarray:
    """``a @ b`` in float32, in blocks of :data:`MATMUL_ROWS` rows of ``a`` shared by
    ``n_threads`` threads (BLAS on one thread each: the caller limits it), so that every
    row is computed the same way whatever the number of threads."""
    out = np.empty((a.shape[0], b.shape[1]), dtype=np.float32)
    bounds = [(s, min(len(a), s + MATMUL_ROWS)) for s in range(0, len(a), MATMUL_ROWS)]

    def product(start: int, stop: int) -> None:
        np.matmul(a[start:stop], b, out=out[start:stop])

    map_threads(product, bounds, n_threads)
    return out


def pool_project(
    folded: np.ndarray,
    neighbours: np.ndarray,
    bins: np.ndarray,
    bias: np.ndarray,
    n_threads: int = 1,
    out: np.ndarray | None = None,
    rows: np.ndarray | None = None,
) -> np.ndarray:
    """Descriptors ``(n_queries, n_axes)`` float32 from the sources' folded rows
    ``features @ weights`` (``(n_sources, 8 * n_axes)``, see :func:`fold_projection`):
    each query's bin means of them, summed over the bins, plus ``bias``. Given ``out``
    and ``rows``, query ``i`` is written to row ``rows[i]`` of ``out`` instead."""
    folded, neighbours, bins = _check(folded, neighbours, bins)
    bias = np.ascontiguousarray(bias, dtype=np.float32)
    out, rows = _output(out, rows, len(neighbours), len(bias))
    arrays = (folded, neighbours, bins, bias, out, rows)
    run_blocks(_pool_project, len(neighbours), n_threads, *arrays)
    return out


def _output(out, rows, n_queries: int, width: int):
    """``out`` and ``rows`` for a kernel: a new ``(n_queries, width)`` array written in
    query order when none is given."""
    if out is None:
        return np.empty((n_queries, width), np.float32), np.arange(n_queries)
    return out, np.ascontiguousarray(rows, dtype=np.int64)
