"""Per-point attributes beside the coordinates, for the paper's scene variant.

R-PointHop's indoor variant (Sec. IV of the paper) describes a point not by its
neighbours' coordinates alone but also by their surface normals and covariance
eigenvalue features. Every attribute here is rigid-invariant by construction:

* ``"xyz"``: the neighbour's coordinates in the point's local reference frame (LRF),
  divided by the cloud's scale (the original R-PointHop input);
* ``"normal"``: the neighbour's normal, its own LRF's third axis (oriented by the LRF's
  sign rule, so no arbitrary flip), expressed in the point's LRF;
* ``"eigen"``: seven features of the neighbour's covariance eigenvalues
  ``l1 >= l2 >= l3`` normalised to sum 1 (``e_i``): linearity ``(e1 - e2) / e1``,
  planarity ``(e2 - e3) / e1``, scattering ``e3 / e1``, omnivariance
  ``(e1 e2 e3)^(1/3)``, anisotropy ``(e1 - e3) / e1``, eigenentropy ``-sum e_i ln e_i``
  and change of curvature ``e3``. All are scale-free and defined everywhere: on a wall
  (``e3 = 0``) ``0 ln 0`` is 0; a neighbourhood whose points all coincide gets zeros;
* ``"fpfh"``: the neighbour's Fast Point Feature Histogram (Rusu et al. 2009; 33 bins
  as Open3D's) over its own hop-1 neighbourhood, with the frames' normal axes as
  normals, each of its three sub-histograms summing to 1. The angles it bins are
  rigid-invariant and scale-free; pooling it over the octants is what PCRP (Kadam et
  al., the authors' retrieval work after R-PointHop) puts in the first hop.

Hop 1 pools each attribute group into the eight octants of the point's LRF: 24 numbers
for ``"xyz"``, 24 for ``"normal"``, 56 for ``"eigen"``, 264 for ``"fpfh"``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._utils.compiled import kernel
from ..._utils.threads import run_blocks

__all__ = [
    "ATTRIBUTE_CHANNELS",
    "check_attributes",
    "eigen_features",
    "fpfh_features",
    "N_EIGEN_FEATURES",
]

#: Channels each attribute group contributes per neighbour (8 octant means each).
ATTRIBUTE_CHANNELS = {"xyz": 3, "normal": 3, "eigen": 7, "fpfh": 33}
N_EIGEN_FEATURES = ATTRIBUTE_CHANNELS["eigen"]


def check_attributes(value: Any) -> tuple[str, ...]:
    """``value`` as a tuple of attribute names: ``"xyz"`` first, no repeats.

    Raises
    ------
    ValueError
        For an unknown name, a repeated one, or a tuple without ``"xyz"``.
    """
    names = (value,) if isinstance(value, str) else value
    try:
        names = tuple(names)
    except TypeError:
        raise ValueError(f"attributes must be a sequence of names, got {value!r}") from None
    unknown = [n for n in names if n not in ATTRIBUTE_CHANNELS]
    if unknown or len(set(names)) != len(names) or not names or names[0] != "xyz":
        raise ValueError(
            "attributes must start with 'xyz' and may add 'normal', 'eigen' and 'fpfh', "
            f"each once; got {value!r}"
        )
    return names


def eigen_features(eigenvalues: np.ndarray) -> np.ndarray:
    """The seven eigenvalue features of every point.

    Parameters
    ----------
    eigenvalues : ndarray of shape (n, 3)
        Covariance eigenvalues, largest first, non-negative.

    Returns
    -------
    ndarray of shape (n, 7)
        Linearity, planarity, scattering, omnivariance, anisotropy, eigenentropy and
        change of curvature; finite for every input (zeros where all three are 0).
    """
    total = eigenvalues.sum(axis=1, keepdims=True)
    flat = total[:, 0] <= 0.0
    e = eigenvalues / np.where(total > 0.0, total, 1.0)
    e1 = np.where(flat, 1.0, e[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        log = np.where(e > 0.0, np.log(np.where(e > 0.0, e, 1.0)), 0.0)
    out = np.stack(
        [
            (e[:, 0] - e[:, 1]) / e1,
            (e[:, 1] - e[:, 2]) / e1,
            e[:, 2] / e1,
            np.cbrt(e[:, 0] * e[:, 1] * e[:, 2]),
            (e[:, 0] - e[:, 2]) / e1,
            -(e * log).sum(axis=1),
            e[:, 2],
        ],
        axis=1,
    )
    out[flat] = 0.0
    return out


_FPFH_BINS = 11


@kernel(inline="always")
def _add_binned(out, i, offset, value, low, high, circular, weight):  # pragma: no cover
    """Add ``weight`` for ``value`` to the :data:`_FPFH_BINS` equal bins of ``[low,
    high]`` in ``out[i, offset:]``, shared between the two bins whose centres it lies
    between (so that the histogram moves continuously with the value); ``circular``:
    the first and last bins are neighbours (an angle)."""
    t = (value - low) * (_FPFH_BINS / (high - low)) - 0.5
    below = np.floor(t)
    share = t - below
    first = int(below)
    second = first + 1
    if circular:
        first = (first + _FPFH_BINS) % _FPFH_BINS
        second = second % _FPFH_BINS
    else:
        first = min(max(first, 0), _FPFH_BINS - 1)
        second = min(max(second, 0), _FPFH_BINS - 1)
    out[i, offset + first] += weight * (1.0 - share)
    out[i, offset + second] += weight * share


@kernel(inline="always")
def _add_pair(out, i, a, b, d0, d1, d2, weight):  # pragma: no cover - compiled
    """Bin the three angles of the pair seen from its end with normal ``a`` (the other
    end's normal ``b``, the unit direction ``d`` towards it); returns False when the
    direction lies along ``a`` (no angles)."""
    v0 = d1 * a[2] - d2 * a[1]
    v1 = d2 * a[0] - d0 * a[2]
    v2 = d0 * a[1] - d1 * a[0]
    norm = v0 * v0 + v1 * v1 + v2 * v2
    if norm == 0.0:
        return False
    norm = 1.0 / np.sqrt(norm)
    v0 *= norm
    v1 *= norm
    v2 *= norm
    w0 = a[1] * v2 - a[2] * v1
    w1 = a[2] * v0 - a[0] * v2
    w2 = a[0] * v1 - a[1] * v0
    theta = np.arctan2(w0 * b[0] + w1 * b[1] + w2 * b[2], a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
    _add_binned(out, i, 0, theta, -np.pi, np.pi, True, weight)
    _add_binned(out, i, _FPFH_BINS, v0 * b[0] + v1 * b[1] + v2 * b[2], -1.0, 1.0, False, weight)
    _add_binned(out, i, 2 * _FPFH_BINS, a[0] * d0 + a[1] * d1 + a[2] * d2, -1.0, 1.0, False, weight)
    return True


@kernel(nogil=True)
def _spfh(start, stop, points, normals, neighbours, out):  # pragma: no cover - compiled
    """Simplified point feature histograms of points ``start:stop`` over their
    neighbour lists: every pair's three angles (Rusu et al.) seen from each of its two
    ends, half a count each, shared between two of 11 bins; every sub-histogram sums
    to 1. Rusu et al. see a pair from the end whose normal is nearer perpendicular to
    the line joining them, a choice that flips with the last bit where the two are
    equally so (two points of a smooth surface whose normals agree); both ends at once
    leave nothing to choose."""
    k = neighbours.shape[1]
    for i in range(start, stop):
        for b in range(3 * _FPFH_BINS):
            out[i, b] = 0.0
        total = 0.0
        for e in range(k):
            j = neighbours[i, e]
            d0 = points[j, 0] - points[i, 0]
            d1 = points[j, 1] - points[i, 1]
            d2 = points[j, 2] - points[i, 2]
            length = d0 * d0 + d1 * d1 + d2 * d2
            if length == 0.0:
                continue
            length = 1.0 / np.sqrt(length)
            d0 *= length
            d1 *= length
            d2 *= length
            if _add_pair(out, i, normals[i], normals[j], d0, d1, d2, 0.5):
                total += 0.5
            if _add_pair(out, i, normals[j], normals[i], -d0, -d1, -d2, 0.5):
                total += 0.5
        if total > 0.0:
            for b in range(3 * _FPFH_BINS):
                out[i, b] /= total


@kernel(nogil=True)
def _fpfh(start, stop, points, neighbours, spfh, out):  # pragma: no cover - compiled
    """FPFH of points ``start:stop``: half its own SPFH, half its neighbours' weighted
    by the inverse of their distance (each sub-histogram summing to 1 where any pair
    was binned)."""
    k = neighbours.shape[1]
    n_bins = spfh.shape[1]
    mixed = np.empty(n_bins)
    sums = np.empty(3)
    for i in range(start, stop):
        mixed[:] = 0.0
        for e in range(k):
            j = neighbours[i, e]
            d0 = points[j, 0] - points[i, 0]
            d1 = points[j, 1] - points[i, 1]
            d2 = points[j, 2] - points[i, 2]
            length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if length == 0.0:
                continue
            weight = 1.0 / length
            for b in range(n_bins):
                mixed[b] += weight * spfh[j, b]
        for part in range(3):
            total = 0.0
            for b in range(part * _FPFH_BINS, (part + 1) * _FPFH_BINS):
                total += mixed[b]
            sums[part] = 0.5 / total if total > 0.0 else 0.0
        for b in range(n_bins):
            out[i, b] = 0.5 * spfh[i, b] + sums[b // _FPFH_BINS] * mixed[b]


def fpfh_features(
    points: np.ndarray, normals: np.ndarray, neighbours: np.ndarray, n_threads: int = 1
) -> np.ndarray:
    """Every point's Fast Point Feature Histogram over its neighbour list.

    The histograms of Rusu et al. (2009) with Open3D's 33 bins (three angles, 11 bins
    each), over neighbour lists chosen the same in any frame (the hops' search), made
    continuous in the cloud so that they move with it to rounding: every pair is seen
    from both ends (see :func:`_spfh`), and each angle is shared between its two
    nearest bins (the first angle's bins wrap around) rather than counted in one, since
    a hard bin flips with the last bit of an angle on a bin's edge, as on a plane whose
    normals alternate in sign (the angle is then +-180 deg). Every sub-histogram sums
    to 1.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
    normals : ndarray of shape (n, 3)
        Unit normals (the frames' third axes: oriented the same in any frame).
    neighbours : ndarray of shape (n, k), int
        Every point's neighbours (rows), itself not among them.
    n_threads : int, default=1

    Returns
    -------
    ndarray of shape (n, 33)
    """
    n = len(points)
    normals = np.ascontiguousarray(normals, dtype=np.float64)
    spfh = np.empty((n, 3 * _FPFH_BINS))
    run_blocks(_spfh, n, n_threads, points, normals, neighbours, spfh)
    out = np.empty_like(spfh)
    run_blocks(_fpfh, n, n_threads, points, neighbours, spfh, out)
    return out
