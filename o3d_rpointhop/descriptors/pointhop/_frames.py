"""Local reference frames (LRF): batched PCA axes with R-PointHop's sign disambiguation.

Neighbourhoods are passed as coordinate planes: ``offsets[d, i, j]`` is coordinate ``d``
of neighbour ``j`` of point ``i`` minus the point's own coordinate. Keeping x, y and z in
separate contiguous planes turns every step into a few elementwise passes instead of
many tiny matrix products.
"""

from __future__ import annotations

import numpy as np

__all__ = ["local_reference_frames", "project", "median_along_last"]


def median_along_last(values: np.ndarray) -> np.ndarray:
    """Median over the last axis (the mean of the two middle values for an even count)."""
    k = values.shape[-1]
    # For the short rows here a full sort is as fast as one partition and several times
    # faster than a partition about both middle positions.
    ordered = np.sort(values, axis=-1)
    return 0.5 * (ordered[..., (k - 1) // 2] + ordered[..., k // 2])


def project(offsets: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Coordinates of neighbour offsets ``(3, q, k)`` in each query's frame, as planes.

    Parameters
    ----------
    offsets : ndarray of shape (3, q, k)
    frames : ndarray of shape (q, 3, 3)
        ``frames[i, :, j]`` is axis ``j`` of query ``i``.

    Returns
    -------
    local : ndarray of shape (3, q, k)
    """
    local = np.empty_like(offsets)
    for j in range(3):
        local[j] = (
            offsets[0] * frames[:, 0, j, None]
            + offsets[1] * frames[:, 1, j, None]
            + offsets[2] * frames[:, 2, j, None]
        )
    return local


# A skew (mean minus median) smaller than this fraction of the neighbourhood's extent is
# treated as no skew at all: on a perfectly flat or symmetric patch it is rounding noise,
# whose sign would change with any rotation of the cloud.
_SKEW_TOLERANCE = 1e-9


def local_reference_frames(
    offsets: np.ndarray,
    k: int,
    towards: np.ndarray,
    return_eigenvalues: bool = False,
    sensor: np.ndarray | None = None,
) -> tuple[np.ndarray, ...]:
    """Oriented, right-handed PCA frame of every neighbourhood, and the neighbours in it.

    The axes are the eigenvectors of the covariance of the first ``k`` neighbours,
    largest eigenvalue first. As in R-PointHop, the sign of an axis is set by the
    first-order moments of the neighbours' projections about their median: the axis
    points to the side with the larger moment. The right moment minus the left moment is
    ``k * (mean - median)``, so that is the test used. Where the projections have no
    skew (a perfectly flat patch's normal, an exactly symmetric spread), the axis points
    towards ``towards`` instead (the cloud's centroid), which is just as invariant. Only
    the first and third axes are oriented this way; the second follows from them so
    that the frame is right-handed. A
    proper rotation of the cloud therefore leaves local coordinates unchanged, while a
    mirror image does not map onto its original, so mirror-symmetric parts of a shape
    stay distinguishable. (On resampled ModelNet40 pairs this raises the share of correct
    nearest-descriptor matches from 10 % to 15 % over orienting all three axes
    independently.)

    Parameters
    ----------
    offsets : ndarray of shape (3, q, m)
        Neighbour offsets from each point, nearest first (offsets keep the numbers small,
        so clouds far from the origin lose no precision).
    k : int
        How many of the ``m`` neighbours define the frame.
    towards : ndarray of shape (3, q)
        Offset from each point to a reference point that moves with the cloud (its
        centroid), used to orient axes along which the neighbours have no skew.
    return_eigenvalues : bool, default=False
        Also return the covariance eigenvalues.
    sensor : ndarray of shape (3, q), default=None
        Offset from each point to the sensor that saw it (a scan's viewpoint). Given,
        the third axis (the normal) points towards the sensor, as a scanned surface
        faces its scanner, instead of following the moment rule; where the normal is
        perpendicular to the line of sight (to :data:`_SKEW_TOLERANCE` of its length)
        the moment rule decides. The first axis keeps the moment rule.

    Returns
    -------
    frames : ndarray of shape (q, 3, 3)
        ``frames[i, :, j]`` is unit axis ``j`` of point ``i``; ``det = +1``. A degenerate
        neighbourhood (all points equal, collinear, or with repeated eigenvalues) still
        gets a finite orthonormal frame, though not a unique one.
    local : ndarray of shape (3, q, m)
        All ``m`` neighbours in these frames.
    eigenvalues : ndarray of shape (q, 3)
        Only with ``return_eigenvalues``: the covariance's eigenvalues, largest first,
        clipped at 0 (the variances along the three axes).
    """
    support = offsets[:, :, :k]
    centred = support - support.mean(axis=2, keepdims=True)
    q = offsets.shape[1]
    cov = np.empty((q, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            cov[:, i, j] = cov[:, j, i] = np.einsum("qk,qk->q", centred[i], centred[j])
    cov /= k
    vals, vecs = np.linalg.eigh(cov)  # ascending eigenvalues
    axes = np.ascontiguousarray(vecs[:, :, ::-1])
    local = project(offsets, axes)
    support = local[:, :, :k]
    skew = support.mean(axis=2) - median_along_last(support)  # (3, q)
    tol = _SKEW_TOLERANCE * np.abs(support).max(axis=(0, 2))  # (q,)
    fallback = project(towards[:, :, None], axes)[:, :, 0]  # (3, q)
    skew = np.where(np.abs(skew) > tol, skew, fallback)
    if sensor is not None:
        facing = np.einsum("dq,qd->q", sensor, axes[:, :, 2])
        seen = np.abs(facing) > _SKEW_TOLERANCE * np.sqrt((sensor**2).sum(axis=0))
        skew[2] = np.where(seen, facing, skew[2])
    sign = np.where(skew < 0.0, -1.0, 1.0)
    # eigh's axes are orthonormal: the triple product is their determinant, +1 or -1.
    det = np.einsum("qi,qi->q", axes[:, :, 0], np.cross(axes[:, :, 1], axes[:, :, 2]))
    sign[1] = sign[0] * sign[2] * np.sign(det)
    local *= sign[:, :, None]
    if return_eigenvalues:
        return axes * sign.T[:, None, :], local, np.clip(vals[:, ::-1], 0.0, None)
    return axes * sign.T[:, None, :], local
