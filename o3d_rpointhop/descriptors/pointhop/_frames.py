"""Local reference frames (LRF): PCA axes with R-PointHop's sign disambiguation, one
neighbourhood at a time in compiled code.

A neighbourhood is given as the offsets of its neighbours from the point, coordinate
planes ``offsets[d, j]`` (x, y and z apart), nearest first as far as the frame's
support goes. :func:`frame_of` orients one neighbourhood; the descriptor's hop passes
call it from their own compiled loops, and :func:`local_reference_frames` runs it over
a batch from Python.
"""

from __future__ import annotations

import numpy as np

from ..._utils.compiled import kernel

__all__ = ["frame_of", "local_reference_frames", "median_of"]

# A skew (mean minus median) smaller than this fraction of the neighbourhood's extent is
# treated as no skew at all: on a perfectly flat or symmetric patch it is rounding noise,
# whose sign would change with any rotation of the cloud. A millionth: a cloud moved to
# survey coordinates is rounded there to about 1e-9 m, under it for neighbourhoods
# down to a few millimetres.
_SKEW_TOLERANCE = 1e-6
# Jacobi sweeps stop once the off-diagonal part is this small against the diagonal
# (a few sweeps: the method converges quadratically).
_JACOBI_TOLERANCE = 1e-30
_JACOBI_SWEEPS = 32


@kernel()
def eigh3(a, vectors, values):  # pragma: no cover - compiled
    """Eigenvalues (largest first) into ``values`` and unit eigenvectors into the
    columns of ``vectors`` of the symmetric 3x3 matrix ``a`` (overwritten), by cyclic
    Jacobi rotations: orthonormal to rounding, finite for any finite matrix."""
    for i in range(3):
        for j in range(3):
            vectors[i, j] = 1.0 if i == j else 0.0
    for _ in range(_JACOBI_SWEEPS):
        off = a[0, 1] * a[0, 1] + a[0, 2] * a[0, 2] + a[1, 2] * a[1, 2]
        diag = a[0, 0] * a[0, 0] + a[1, 1] * a[1, 1] + a[2, 2] * a[2, 2]
        if off <= _JACOBI_TOLERANCE * diag or off == 0.0:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq = a[p, q]
            if apq == 0.0:
                continue
            theta = (a[q, q] - a[p, p]) / (2.0 * apq)
            t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
            if theta < 0.0:
                t = -t
            c = 1.0 / np.sqrt(t * t + 1.0)
            s = t * c
            for r in range(3):  # a <- a J
                arp = a[r, p]
                arq = a[r, q]
                a[r, p] = c * arp - s * arq
                a[r, q] = s * arp + c * arq
            for r in range(3):  # a <- J^T a
                apr = a[p, r]
                aqr = a[q, r]
                a[p, r] = c * apr - s * aqr
                a[q, r] = s * apr + c * aqr
            for r in range(3):
                vrp = vectors[r, p]
                vrq = vectors[r, q]
                vectors[r, p] = c * vrp - s * vrq
                vectors[r, q] = s * vrp + c * vrq
    for i in range(3):
        values[i] = a[i, i]
    for i in range(2):  # largest first (selection sort of three)
        best = i
        for j in range(i + 1, 3):
            if values[j] > values[best]:
                best = j
        if best != i:
            values[i], values[best] = values[best], values[i]
            for r in range(3):
                vectors[r, i], vectors[r, best] = vectors[r, best], vectors[r, i]


@kernel()
def median_of(values, n):  # pragma: no cover - compiled
    """Median of ``values[:n]`` (reordered in place): the middle value, or the mean of
    the two middle values for an even count."""
    upper = _select_value(values, n, n // 2)
    if n % 2:
        return upper
    lower = values[0]  # the largest of the lower half
    for i in range(1, n // 2):
        lower = max(lower, values[i])
    return 0.5 * (lower + upper)


@kernel()
def _select_value(values, n, kth):  # pragma: no cover - compiled
    """The value of rank ``kth`` in ``values[:n]``, smaller values moved before it."""
    lo = 0
    hi = n
    while hi - lo > 1:
        pivot = values[(lo + hi - 1) >> 1]
        i = lo
        j = hi - 1
        while i <= j:
            while values[i] < pivot:
                i += 1
            while values[j] > pivot:
                j -= 1
            if i <= j:
                values[i], values[j] = values[j], values[i]
                i += 1
                j -= 1
        if kth <= j:
            hi = j + 1
        elif kth >= i:
            lo = i
        else:
            break
    return values[kth]


@kernel()
def frame_of(
    offsets, m, k, towards, sensor, has_sensor, frame, eigenvalues, local, cov, work
):  # pragma: no cover - compiled
    """Orient one neighbourhood; see :func:`local_reference_frames`.

    ``offsets[:, :m]``: the neighbours' offsets, the first ``k - 1`` the frame's
    support besides the point itself (offset 0). ``towards``, ``sensor``: 3-vectors
    (``sensor`` read when ``has_sensor``). Writes ``frame`` (3x3, axis ``j`` in column
    ``j``), ``eigenvalues`` (3, largest first, at least 0) and ``local[:, :m]`` (the
    neighbours in the frame); ``cov`` (3x3) and ``work`` (``k`` values) are scratch.
    """
    support = k - 1
    mean0 = 0.0
    mean1 = 0.0
    mean2 = 0.0
    for j in range(support):
        mean0 += offsets[0, j]
        mean1 += offsets[1, j]
        mean2 += offsets[2, j]
    mean0 /= k
    mean1 /= k
    mean2 /= k
    # The point itself, at offset 0, contributes (0 - mean)(0 - mean).
    c00 = mean0 * mean0
    c01 = mean0 * mean1
    c02 = mean0 * mean2
    c11 = mean1 * mean1
    c12 = mean1 * mean2
    c22 = mean2 * mean2
    for j in range(support):
        x = offsets[0, j] - mean0
        y = offsets[1, j] - mean1
        z = offsets[2, j] - mean2
        c00 += x * x
        c01 += x * y
        c02 += x * z
        c11 += y * y
        c12 += y * z
        c22 += z * z
    cov[0, 0] = c00 / k
    cov[0, 1] = cov[1, 0] = c01 / k
    cov[0, 2] = cov[2, 0] = c02 / k
    cov[1, 1] = c11 / k
    cov[1, 2] = cov[2, 1] = c12 / k
    cov[2, 2] = c22 / k
    eigh3(cov, frame, eigenvalues)
    for a in range(3):
        eigenvalues[a] = max(eigenvalues[a], 0.0)
    for j in range(m):
        x = offsets[0, j]
        y = offsets[1, j]
        z = offsets[2, j]
        for a in range(3):
            local[a, j] = x * frame[0, a] + y * frame[1, a] + z * frame[2, a]
    extent = 0.0
    for a in range(3):
        for j in range(support):
            extent = max(extent, abs(local[a, j]))
    tol = _SKEW_TOLERANCE * extent
    sign0 = _skew_sign(local, 0, support, k, tol, towards, frame)
    sign2 = _skew_sign(local, 2, support, k, tol, towards, frame)
    if has_sensor:
        facing = sensor[0] * frame[0, 2] + sensor[1] * frame[1, 2] + sensor[2] * frame[2, 2]
        reach = np.sqrt(sensor[0] * sensor[0] + sensor[1] * sensor[1] + sensor[2] * sensor[2])
        if abs(facing) > _SKEW_TOLERANCE * reach:
            sign2 = -1.0 if facing < 0.0 else 1.0
    # The axes are orthonormal: the triple product is their determinant, +1 or -1.
    det = (
        frame[0, 0] * (frame[1, 1] * frame[2, 2] - frame[2, 1] * frame[1, 2])
        - frame[1, 0] * (frame[0, 1] * frame[2, 2] - frame[2, 1] * frame[0, 2])
        + frame[2, 0] * (frame[0, 1] * frame[1, 2] - frame[1, 1] * frame[0, 2])
    )
    sign1 = sign0 * sign2 * (1.0 if det >= 0.0 else -1.0)
    _flip(frame, local, m, 0, sign0)
    _flip(frame, local, m, 1, sign1)
    _flip(frame, local, m, 2, sign2)


@kernel()
def _skew_sign(local, a, support, k, tol, towards, frame):  # pragma: no cover - compiled
    """The sign of mean minus median of the frame's ``k`` points (the point itself at 0
    and the ``support`` nearest) along axis ``a``; within ``tol`` of 0, the sign of
    ``towards`` along the axis instead.

    ``mean - median > tol`` is ``median < mean - tol``, which counting decides: with
    ``c`` values below the threshold, the median is below it when ``c`` passes the
    middle, above when ``c`` stops short of it, and for an even count with ``c`` at the
    middle, when the largest value below plus the smallest one above (the two middle
    values) sum to less than twice the threshold. One pass, no sorting.
    """
    total = 0.0
    for j in range(support):
        total += local[a, j]
    mean = total / k
    if _median_below(local, a, support, k, mean - tol):
        return 1.0
    if _median_above(local, a, support, k, mean + tol):
        return -1.0
    toward = towards[0] * frame[0, a] + towards[1] * frame[1, a] + towards[2] * frame[2, a]
    return -1.0 if toward < 0.0 else 1.0


@kernel()
def _median_below(local, a, support, k, threshold):  # pragma: no cover - compiled
    """Whether the median of ``local[a, :support]`` and 0 is below ``threshold``."""
    count = 1 if 0.0 < threshold else 0
    below = 0.0 if count else -np.inf  # the largest value below the threshold
    above = np.inf if count else 0.0  # the smallest value at or above it
    for j in range(support):  # selects, not branches: the comparisons are coin tosses
        v = local[a, j]
        under = v < threshold
        count += under
        below = max(below, v if under else -np.inf)
        above = min(above, np.inf if under else v)
    half = k // 2
    if k % 2:
        return count >= half + 1
    if count != half:
        return count > half
    return below + above < 2.0 * threshold


@kernel()
def _median_above(local, a, support, k, threshold):  # pragma: no cover - compiled
    """Whether the median of ``local[a, :support]`` and 0 is above ``threshold``."""
    count = 1 if 0.0 > threshold else 0
    above = 0.0 if count else np.inf  # the smallest value above the threshold
    below = -np.inf if count else 0.0  # the largest value at or below it
    for j in range(support):  # selects, not branches
        v = local[a, j]
        over = v > threshold
        count += over
        above = min(above, v if over else np.inf)
        below = max(below, -np.inf if over else v)
    half = k // 2
    if k % 2:
        return count >= half + 1
    if count != half:
        return count > half
    return below + above > 2.0 * threshold


@kernel()
def _flip(frame, local, m, a, sign):  # pragma: no cover - compiled
    """Axis ``a`` of the frame, and the neighbours' coordinates along it, times ``sign``."""
    if sign < 0.0:
        for r in range(3):
            frame[r, a] = -frame[r, a]
        for j in range(m):
            local[a, j] = -local[a, j]


@kernel(nogil=True)
def _batch_frames(offsets, k, towards, sensor, has_sensor):  # pragma: no cover - compiled
    """:func:`frame_of` for every neighbourhood of a batch."""
    q = offsets.shape[1]
    m = offsets.shape[2]
    frames = np.empty((q, 3, 3))
    eigenvalues = np.empty((q, 3))
    local = np.empty((3, q, m))
    cov = np.empty((3, 3))
    work = np.empty(k)
    block = np.empty((3, m))
    out = np.empty((3, m))
    for i in range(q):
        block[:, :] = offsets[:, i, :]
        frame_of(
            block,
            m,
            k,
            towards[:, i].copy(),
            sensor[:, i].copy(),
            has_sensor,
            frames[i],
            eigenvalues[i],
            out,
            cov,
            work,
        )
        local[:, i, :] = out
    return frames, eigenvalues, local


def local_reference_frames(
    offsets: np.ndarray,
    k: int,
    towards: np.ndarray,
    return_eigenvalues: bool = False,
    sensor: np.ndarray | None = None,
) -> tuple[np.ndarray, ...]:
    """Oriented, right-handed PCA frame of every neighbourhood, and the neighbours in it.

    The axes are the eigenvectors of the covariance of the point and its ``k - 1``
    nearest neighbours, largest eigenvalue first. As in R-PointHop, the sign of an axis
    is set by the first-order moments of those ``k`` points' projections about their
    median: the axis points to the side with the larger moment. The right moment minus
    the left moment is ``k * (mean - median)``, so that is the test used. Where the
    projections have no skew (a perfectly flat patch's normal, an exactly symmetric
    spread), the axis points towards ``towards`` instead (the cloud's centroid), which
    is just as invariant. Only the first and third axes are oriented this way; the
    second follows from them so that the frame is right-handed. A proper rotation of
    the cloud therefore leaves local coordinates unchanged, while a mirror image does
    not map onto its original, so mirror-symmetric parts of a shape stay
    distinguishable. (On resampled ModelNet40 pairs this raises the share of correct
    nearest-descriptor matches from 10 % to 15 % over orienting all three axes
    independently.)

    Parameters
    ----------
    offsets : ndarray of shape (3, q, m)
        Neighbour offsets from each point (the point itself not among them), the
        ``k - 1`` nearest first (offsets keep the numbers small, so clouds far from the
        origin lose no precision).
    k : int
        How many points define the frame: the point and its ``k - 1`` nearest
        neighbours (``2 <= k <= m + 1``).
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
    offsets = np.ascontiguousarray(offsets, dtype=np.float64)
    if not 2 <= k <= offsets.shape[2] + 1:
        raise ValueError(f"k={k} needs between 1 and {offsets.shape[2]} neighbours")
    towards = np.ascontiguousarray(towards, dtype=np.float64)
    has_sensor = sensor is not None
    sensor = np.ascontiguousarray(towards if sensor is None else sensor, dtype=np.float64)
    frames, eigenvalues, local = _batch_frames(offsets, int(k), towards, sensor, has_sensor)
    if return_eigenvalues:
        return frames, local, eigenvalues
    return frames, local
