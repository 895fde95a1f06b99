"""Octant pooling: the eight bins of each neighbourhood in its local frame, and the
means of per-neighbour values over them.

An octant with no neighbour takes the mean of the whole neighbourhood instead, so
nothing is ever NaN and adding a constant to every value adds it to every octant mean.

The eight bins are the octants of the local frame (R-PointHop's pooling), or, for
``pooling="azimuth"``, bins that use the frame's normal axis only (above or below the
tangent plane, times four distance shells), so that nothing depends on the in-plane
axes, which indoor surfaces leave undetermined.

:func:`bins_of` and :func:`means_of` work on one neighbourhood and are called from the
hop passes' compiled loops; :func:`bin_index` and :func:`octant_means` run them over a
batch from Python.
"""

from __future__ import annotations

import numpy as np

from ..._utils.compiled import kernel

__all__ = [
    "N_OCTANTS",
    "POOLINGS",
    "bin_index",
    "bins_of",
    "cylindrical_of",
    "means_of",
    "octant_means",
]

#: The ways a neighbourhood is split into its eight bins.
POOLINGS = ("octants", "azimuth")
N_OCTANTS = 8
#: Squared outer radii of the azimuth bins' inner three shells, as shares of the
#: squared distance to the farthest neighbour: shells of equal area on a surface.
_SHELLS_SQ = (0.25, 0.5, 0.75)
# Coordinates within this fraction of the neighbourhood's extent of an octant boundary
# count as positive. A point exactly on a boundary (a coplanar neighbour's normal
# coordinate, a duplicate of the query) then lands in the same octant in every frame,
# instead of flipping with the last bit of floating point rounding (at survey
# coordinates, about 1e-9 m: under a millionth of neighbourhoods down to millimetres).
_BOUNDARY_TOLERANCE = 1e-6


@kernel()
def bins_of(local, k, azimuth, bins):  # pragma: no cover - compiled
    """The bin (0..7) of each of the neighbours ``local[:, :k]`` (coordinates in the
    query's frame) into ``bins[:k]``.

    Octants: bit 2 for a first coordinate >= 0, bit 1 for the second, bit 0 for the
    third, each within :data:`_BOUNDARY_TOLERANCE` of the neighbourhood's largest
    coordinate counting as positive. Azimuth (``azimuth`` true): bit 2 for the normal's
    side of the tangent plane (the same tolerance, against the farthest neighbour's
    distance), bits 0-1 the shell of the neighbour's distance, of equal area on a
    surface (outer radii sqrt(1/4), sqrt(1/2), sqrt(3/4) and 1 times the farthest
    neighbour's distance): a turn of the frame about its normal leaves every bin as
    it is.
    """
    if azimuth:
        reach = 0.0
        for j in range(k):
            sq = (local[0, j] * local[0, j] + local[1, j] * local[1, j]) + local[2, j] * local[2, j]
            reach = max(reach, sq)
        tol = -_BOUNDARY_TOLERANCE * np.sqrt(reach)
        for j in range(k):
            sq = (local[0, j] * local[0, j] + local[1, j] * local[1, j]) + local[2, j] * local[2, j]
            shell = 0
            for share in _SHELLS_SQ:
                if sq > share * reach:
                    shell += 1
            bins[j] = shell + (4 if local[2, j] >= tol else 0)
        return
    extent = 0.0
    for a in range(3):
        for j in range(k):
            extent = max(extent, abs(local[a, j]))
    tol = -_BOUNDARY_TOLERANCE * extent
    for j in range(k):
        b = 4 if local[0, j] >= tol else 0
        if local[1, j] >= tol:
            b += 2
        if local[2, j] >= tol:
            b += 1
        bins[j] = b


@kernel()
def means_of(values, k, bins, counts, out, offset):  # pragma: no cover - compiled
    """Octant means of the neighbours' values ``values[:, :k]`` (``c`` channels, one
    row each) into ``out[offset + c * o + d]`` (octant-major); an empty octant takes
    the mean of the whole neighbourhood (the sum of the octants' sums over ``k``).
    Each sum adds its neighbours in their order; ``counts`` (8 integers) is scratch."""
    c = values.shape[0]
    width = N_OCTANTS * c
    for o in range(N_OCTANTS):
        counts[o] = 0
    for e in range(width):
        out[offset + e] = 0.0
    for j in range(k):
        b = bins[j]
        counts[b] += 1
        base = offset + c * b
        for d in range(c):
            out[base + d] += values[d, j]
    for d in range(c):
        whole = 0.0
        for o in range(N_OCTANTS):
            whole += out[offset + c * o + d]
        whole /= k
        for o in range(N_OCTANTS):
            e = offset + c * o + d
            out[e] = out[e] / counts[o] if counts[o] else whole


@kernel()
def cylindrical_of(local, k, out):  # pragma: no cover - compiled
    """Neighbour coordinates without the in-plane axes into ``out[:, :k]``: distance
    from the normal axis, height along it, and distance from the point."""
    for j in range(k):
        radial_sq = local[0, j] * local[0, j] + local[1, j] * local[1, j]
        out[0, j] = np.sqrt(radial_sq)
        out[1, j] = local[2, j]
        out[2, j] = np.sqrt(radial_sq + local[2, j] * local[2, j])


@kernel(nogil=True)
def _batch_bins(local, azimuth):  # pragma: no cover - compiled
    q = local.shape[1]
    k = local.shape[2]
    out = np.empty((q, k), np.uint8)
    block = np.empty((3, k))
    for i in range(q):
        block[:, :] = local[:, i, :]
        bins_of(block, k, azimuth, out[i])
    return out


@kernel(nogil=True)
def _batch_means(values, bins):  # pragma: no cover - compiled
    c = values.shape[0]
    q = values.shape[1]
    k = values.shape[2]
    out = np.empty((q, N_OCTANTS * c))
    block = np.empty((c, k))
    counts = np.empty(N_OCTANTS, np.int64)
    for i in range(q):
        block[:, :] = values[:, i, :]
        means_of(block, k, bins[i], counts, out[i], 0)
    return out


def bin_index(local: np.ndarray, pooling: str) -> np.ndarray:
    """The bins of ``pooling`` (one of :data:`POOLINGS`) of neighbours ``(3, q, k)``
    (see :func:`bins_of`): ``(q, k)`` uint8."""
    local = np.ascontiguousarray(local, dtype=np.float64)
    return _batch_bins(local, pooling == "azimuth")


def octant_means(values: np.ndarray, bins: np.ndarray) -> np.ndarray:
    """Octant means of per-neighbour values ``(c, q, k)`` over ``bins`` ``(q, k)``:
    ``(q, 8 * c)``, ``means[i, c * o + d]`` channel ``d`` of octant ``o`` (see
    :func:`means_of`)."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    return _batch_means(values, np.ascontiguousarray(bins, dtype=np.uint8))
