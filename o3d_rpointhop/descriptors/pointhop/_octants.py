"""Octant pooling: the eight octant means of each neighbourhood in its local frame.

An octant with no neighbour takes the mean of the whole neighbourhood instead, so
nothing is ever NaN and adding a constant to every value adds it to every octant mean.

The eight bins are the octants of the local frame (:func:`octant_index`, R-PointHop's
pooling), or, for ``pooling="azimuth"``, bins that use the frame's normal axis only
(:func:`azimuth_bins`: above or below the tangent plane, times four distance shells),
so that nothing depends on the in-plane axes, which indoor surfaces leave undetermined.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..._utils.compiled import kernel
from ..._utils.threads import map_threads

__all__ = [
    "N_OCTANTS",
    "POOLINGS",
    "azimuth_bins",
    "bin_index",
    "cylindrical",
    "octant_index",
    "octant_means",
    "OctantPooling",
]

#: The ways a neighbourhood is split into its eight bins.
POOLINGS = ("octants", "azimuth")
#: Squared outer radii of the azimuth bins' inner three shells, as shares of the
#: squared distance to the farthest neighbour: shells of equal area on a surface.
_SHELLS_SQ = (0.25, 0.5, 0.75)

N_OCTANTS = 8
DTYPE = np.float32  # features from hop 2 on (see RPointHopTransformer.transform)
QUERY_BLOCK = 128  # queries pooled at a time: a block of ~150 channels stays in cache
_BLOCKS_PER_THREAD = 8
BUILD_CHUNK = 65536  # queries whose sort keys are built at a time (bounded temporaries)

# Coordinates within this fraction of the neighbourhood's extent of an octant boundary
# count as positive. A point exactly on a boundary (a coplanar neighbour's normal
# coordinate, a duplicate of the query) then lands in the same octant in every frame,
# instead of flipping with the last bit of floating point rounding.
_BOUNDARY_TOLERANCE = 1e-9


def octant_index(local: np.ndarray) -> np.ndarray:
    """Octant of every neighbour: bit 2 for a positive first coordinate, bit 1 for the
    second, bit 0 for the third.

    Parameters
    ----------
    local : ndarray of shape (3, q, k)
        Neighbour coordinates in each query's local frame, as planes.

    Returns
    -------
    octant : ndarray of shape (q, k), int64, values in 0..7
    """
    extent = np.abs(local).max(axis=(0, 2))  # (q,)
    tol = -_BOUNDARY_TOLERANCE * extent[:, None]
    return (
        (local[0] >= tol).astype(np.int64) * 4
        + (local[1] >= tol).astype(np.int64) * 2
        + (local[2] >= tol).astype(np.int64)
    )


def azimuth_bins(local: np.ndarray) -> np.ndarray:
    """Bin of every neighbour from the frame's normal axis alone: bit 2 for a
    neighbour on the normal's side of the tangent plane (third coordinate >= 0, with
    the same boundary tolerance as :func:`octant_index`), bits 0-1 the shell of its
    distance, of equal area on a surface (outer radii sqrt(1/4), sqrt(1/2), sqrt(3/4)
    and 1 times the farthest neighbour's distance).

    A rotation of the frame about its normal axis leaves every bin as it is.

    Parameters
    ----------
    local : ndarray of shape (3, q, k)

    Returns
    -------
    bins : ndarray of shape (q, k), int64, values in 0..7
    """
    sq = (local**2).sum(axis=0)  # (q, k)
    extent = np.sqrt(sq.max(axis=1))  # (q,)
    tol = -_BOUNDARY_TOLERANCE * extent[:, None]
    reach = sq.max(axis=1, keepdims=True)
    shell = np.zeros(sq.shape, dtype=np.int64)
    for share in _SHELLS_SQ:
        shell += sq > share * reach
    return (local[2] >= tol).astype(np.int64) * 4 + shell


def bin_index(local: np.ndarray, pooling: str) -> np.ndarray:
    """The bins of ``pooling`` (one of :data:`POOLINGS`) of neighbours ``(3, q, k)``."""
    return azimuth_bins(local) if pooling == "azimuth" else octant_index(local)


def cylindrical(local: np.ndarray) -> np.ndarray:
    """Neighbour coordinates without the in-plane axes: distance from the normal axis,
    height along it, and distance from the point, as planes ``(3, q, k)``."""
    radial_sq = local[0] ** 2 + local[1] ** 2
    return np.stack([np.sqrt(radial_sq), local[2], np.sqrt(radial_sq + local[2] ** 2)])


@kernel(nogil=True)
def _octant_sums(values, octant):  # pragma: no cover - compiled
    """Per channel, octant and query the sum of the neighbours' values ``(c, 8, q)``,
    and the neighbour count of every octant and query ``(8, q)``. Each sum adds its
    neighbours in their order, as ``numpy.bincount`` over the raveled rows does (the
    same bytes), without raveling a copy of every channel. Runs without the GIL, so the
    chunks' threads share it."""
    c, q, k = values.shape
    sums = np.zeros((c, 8, q))
    counts = np.zeros((8, q), dtype=np.int64)
    for i in range(q):
        for b in range(k):
            counts[octant[i, b], i] += 1
    for d in range(c):
        for i in range(q):
            for b in range(k):
                sums[d, octant[i, b], i] += values[d, i, b]
    return sums, counts


def _octant_sums_numpy(values: np.ndarray, octant: np.ndarray):
    """:func:`_octant_sums` with ``numpy.bincount`` (the same bytes)."""
    c, q, _ = values.shape
    rows = (octant.astype(np.int64) * q + np.arange(q)[:, None]).ravel()
    counts = np.bincount(rows, minlength=N_OCTANTS * q).reshape(N_OCTANTS, q)
    sums = np.empty((c, N_OCTANTS, q))
    for d in range(c):
        sums[d] = np.bincount(rows, weights=values[d].ravel(), minlength=N_OCTANTS * q).reshape(
            N_OCTANTS, q
        )
    return sums, counts


def octant_means(values: np.ndarray, octant: np.ndarray, compiled: bool = False) -> np.ndarray:
    """Octant means of per-neighbour values: coordinates, normals, eigen features.

    Parameters
    ----------
    values : ndarray of shape (c, q, k)
        ``c`` channels of every neighbour of every query, as planes.
    octant : ndarray of shape (q, k)
        From :func:`octant_index`.
    compiled : bool, default=False
        Sum with the compiled kernel (:func:`_octant_sums`) rather than numpy's
        bincount: the same bytes. The scene attributes, which load numba for their
        normals anyway, take it (faster, and it releases the GIL for the chunks'
        threads); a transform of xyz alone keeps numpy, so that it never loads numba
        (about 100 MiB of libraries, and a second to compile in a new environment, for
        a few per cent at best).

    Returns
    -------
    means : ndarray of shape (q, 8 * c)
        Ordered octant-major: ``means[i, c * o + d]`` is channel ``d`` of the mean over
        octant ``o``; an empty octant takes the mean of the whole neighbourhood.
    """
    c, q, _ = values.shape
    if compiled:
        sums, counts = _octant_sums(values, octant)
    else:
        sums, counts = _octant_sums_numpy(values, octant)
    out = np.empty((q, N_OCTANTS, c))
    empty = counts == 0
    for d in range(c):
        means = sums[d] / np.maximum(counts, 1)
        if empty.any():
            whole = values[d].mean(axis=1)  # (q,)
            means = np.where(empty, whole[None, :], means)
        out[:, :, d] = means.T
    return out.reshape(q, N_OCTANTS * c)


class OctantPooling:
    """Sparse operator from per-point feature channels to per-query octant means.

    The operator is kept as consecutive blocks of :data:`QUERY_BLOCK` queries: pooling
    and reordering a block while it is in the CPU cache is much faster than doing so for
    the whole pooled tensor, which for the last hop is several megabytes. It stores each
    query's neighbour rows sorted by octant and the octant counts (4 bytes per
    neighbour and 32 per query); a block's weights are made from the counts when it is
    pooled. It is built :data:`BUILD_CHUNK` queries at a time, so building it needs
    little memory beyond its own arrays.

    Parameters
    ----------
    octant : ndarray of shape (q, k)
        Octant of every neighbour, from :func:`octant_index` (any integer type).
    neighbors : ndarray of shape (q, k), int
        Row of each neighbour among the ``n_sources`` points whose features are pooled.
    n_sources : int
    """

    def __init__(self, octant: np.ndarray, neighbors: np.ndarray, n_sources: int) -> None:
        q, k = octant.shape
        index_type = np.int32 if max(n_sources, q * k) < 2**31 else np.int64
        indices = np.empty(q * k, dtype=index_type)
        counts = np.empty((q, N_OCTANTS), dtype=np.int32)
        for lo in range(0, q, BUILD_CHUNK):
            hi = min(q, lo + BUILD_CHUNK)
            oct_block = octant[lo:hi].astype(np.uint8, copy=False)
            # Matrix rows are (query, octant) pairs, query-major. Within a row the
            # neighbours keep their distance order (a stable sort of each query's
            # octants; 8-bit keys sort by radix), so the sums run in an order that does
            # not depend on how the cloud's rows are numbered: permuting the input
            # permutes the output exactly.
            within = np.argsort(oct_block, axis=1, kind="stable")
            rows = (np.arange(hi - lo)[:, None] * N_OCTANTS + oct_block).ravel()
            counts[lo:hi] = np.bincount(rows, minlength=N_OCTANTS * (hi - lo)).reshape(
                hi - lo, N_OCTANTS
            )
            indices[lo * k : hi * k] = np.take_along_axis(neighbors[lo:hi], within, axis=1).ravel()
        indptr = np.zeros(N_OCTANTS * q + 1, dtype=index_type)
        np.cumsum(counts.ravel(), out=indptr[1:])
        self.n_queries = q
        self.n_sources = n_sources
        self.n_neighbors = k
        self._indices = indices
        self._indptr = indptr
        self._counts = counts

    @property
    def nbytes(self) -> int:
        return self._indices.nbytes + self._indptr.nbytes + self._counts.nbytes

    def _block(self, start: int, stop: int) -> sp.csr_matrix:
        """Rows of queries ``start:stop``, each neighbour weighted by one over its
        octant's count (float32, as the features)."""
        indptr = self._indptr[start * N_OCTANTS : stop * N_OCTANTS + 1]
        counts = self._counts[start:stop].ravel()
        weights = (1.0 / np.maximum(counts, 1)).astype(DTYPE)
        lo, hi = indptr[0], indptr[-1]
        return sp.csr_matrix(
            (np.repeat(weights, counts), self._indices[lo:hi], indptr - lo),
            shape=((stop - start) * N_OCTANTS, self.n_sources),
        )

    def _pool_block(self, start: int, stop: int, features: np.ndarray) -> np.ndarray:
        """Octant means of one block of queries: ``(n_channels, 8, stop - start)``."""
        n_channels = features.shape[1]
        pooled = (self._block(start, stop) @ features).reshape(stop - start, N_OCTANTS, n_channels)
        counts = self._counts[start:stop]
        empty = counts == 0
        if empty.any():
            # Empty octants take the neighbourhood mean: the count-weighted mean of the
            # octant means (a batched product over queries, so every query's sum runs the
            # same way wherever it sits).
            fill = (counts / self.n_neighbors).astype(DTYPE)
            whole = np.matmul(fill[:, None, :], pooled)[:, 0]
            qi, oi = np.nonzero(empty)
            pooled[qi, oi] = whole[qi]
        return np.ascontiguousarray(pooled.transpose(2, 1, 0))

    def map_blocks(self, features: np.ndarray, consume, n_threads: int = 1) -> None:
        """Pool block by block and hand each block to ``consume``.

        ``consume(start, stop, pooled)`` gets the octant means ``(n_channels, 8,
        stop - start)`` of queries ``start:stop``; it typically transforms them and
        writes the result into its own slice of an output array. Blocks are independent
        and the heavy numpy and scipy calls release the GIL, so ``n_threads`` threads
        (started for this call only) share them; the result does not depend on the
        order in which blocks finish.

        Parameters
        ----------
        features : ndarray of shape (n_sources, n_channels)
            One row per source point (copied only if not C-contiguous).
        consume : callable
        n_threads : int, default=1
        """
        features = np.ascontiguousarray(features)
        bounds = [
            (start, min(self.n_queries, start + QUERY_BLOCK))
            for start in range(0, self.n_queries, QUERY_BLOCK)
        ]

        def run(start, stop):
            consume(start, stop, self._pool_block(start, stop, features))

        # A thread pays off only with a few blocks to share (measured on 1k-2k point
        # clouds, two threads: 10-20 % faster from 8 blocks per thread on).
        map_threads(run, bounds, min(n_threads, 1 + len(bounds) // _BLOCKS_PER_THREAD))

    def __call__(self, features: np.ndarray, n_threads: int = 1) -> np.ndarray:
        """Pool features ``(n_sources, n_channels)`` into ``(n_channels, 8, q)``."""
        out = np.empty((features.shape[1], N_OCTANTS, self.n_queries), dtype=features.dtype)

        def store(start, stop, pooled):
            out[:, :, start:stop] = pooled

        self.map_blocks(features, store, n_threads)
        return out
