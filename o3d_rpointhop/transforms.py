"""Rigid transforms: the SVD (Kabsch) fit, applying them, and measuring their error."""

from __future__ import annotations

import numpy as np

from ._utils.validation import renamed_seed

__all__ = [
    "rigid_transform",
    "rigid_transforms",
    "apply_transform",
    "rotation_error_deg",
    "translation_error",
    "rms_displacement",
    "from_centred",
    "euler_angles_deg",
    "random_rigid_motion",
]


def rigid_transform(
    source: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None
) -> np.ndarray:
    """Least-squares rotation and translation taking ``source`` points onto ``target``.

    The closed form of the R-PointHop paper (Sec. III-C, after Schoenemann 1966): centre
    both sets on their (weighted) means, take the SVD of the cross-covariance and fix a
    reflection, should the SVD return one, by flipping the last singular direction.

    Parameters
    ----------
    source, target : ndarray of shape (n, 3)
        Matched points, row ``i`` of one with row ``i`` of the other.
    weights : ndarray of shape (n,), default=None

    Returns
    -------
    transformation : ndarray of shape (4, 4)
        ``T`` with ``target ~ source @ T[:3, :3].T + T[:3, 3]``.

    Raises
    ------
    ValueError
        For mismatched shapes, fewer than 3 pairs, or pairs that do not fix a rotation
        (all on one line).
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3:
        raise ValueError(
            f"source and target must be matching (n, 3) arrays, got {source.shape} and "
            f"{target.shape}"
        )
    if len(source) < 3:
        raise ValueError(f"a rigid transform needs at least 3 point pairs, got {len(source)}")
    w = np.ones(len(source)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(source),) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError("weights must be non-negative, one per pair, and not all zero")
    w = w / w.sum()
    mu_s = w @ source
    mu_t = w @ target
    cov = (source - mu_s).T @ ((target - mu_t) * w[:, None])
    u, s, vt = np.linalg.svd(cov)
    if s[1] <= 1e-12 * max(s[0], 1e-300):
        raise ValueError("the point pairs are collinear (or coincide): no unique rotation")
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = mu_t - rotation @ mu_s
    return out


def rigid_transforms(
    source: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Many least-squares rigid fits at once, the batched form of :func:`rigid_transform`
    without its checks (for the global steps' hypotheses).

    Parameters
    ----------
    source, target : ndarray of shape (b, k, 3)
        ``b`` sets of ``k`` matched points.
    weights : ndarray of shape (b, k), default=None
        Per-point weights of each set (normalised here); ``None`` weighs points equally.

    Returns
    -------
    rotations : ndarray of shape (b, 3, 3)
    translations : ndarray of shape (b, 3)
        ``target[i] ~ source[i] @ rotations[i].T + translations[i]``.
    """
    if weights is None:
        cs, ct = source.mean(axis=1), target.mean(axis=1)
        cov = np.einsum("bki,bkj->bij", source - cs[:, None], target - ct[:, None])
    else:
        w = weights / np.maximum(weights.sum(axis=1, keepdims=True), 1e-12)
        cs = np.einsum("bk,bki->bi", w, source)
        ct = np.einsum("bk,bki->bi", w, target)
        cov = np.einsum("bk,bki,bkj->bij", w, source - cs[:, None], target - ct[:, None])
    u, _, vt = np.linalg.svd(cov)
    # A reflection, should the SVD return one, is fixed by flipping the last direction.
    d = np.sign(np.linalg.det(np.matmul(vt.transpose(0, 2, 1), u.transpose(0, 2, 1))))
    d[d == 0] = 1.0
    vt[:, 2, :] *= d[:, None]
    rot = np.matmul(vt.transpose(0, 2, 1), u.transpose(0, 2, 1))
    return rot, ct - np.einsum("bij,bj->bi", rot, cs)


def apply_transform(points: np.ndarray, transformation: np.ndarray) -> np.ndarray:
    """``points @ R.T + t`` for a 4x4 ``transformation``."""
    t = np.asarray(transformation, dtype=np.float64)
    return np.asarray(points, dtype=np.float64) @ t[:3, :3].T + t[:3, 3]


def rotation_error_deg(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Angle of the rotation ``R_truth^T R_estimate``, in degrees (isotropic error)."""
    rel = np.asarray(truth)[:3, :3].T @ np.asarray(estimate)[:3, :3]
    cos = np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos)))


def translation_error(
    estimate: np.ndarray, truth: np.ndarray, about: np.ndarray | None = None
) -> float:
    """How far apart the two transformations carry the point ``about``.

    Parameters
    ----------
    estimate, truth : ndarray of shape (4, 4)
    about : array-like of shape (3,), default=None
        ``None``: the origin, where this is the distance between the two translations
        (the benchmarks' measure, for clouds near the origin). Far from the origin (survey
        coordinates) pass the cloud's centroid: at the origin a rotation error's last
        digits are magnified by the distance to the data.

    Returns
    -------
    float
    """
    estimate, truth = np.asarray(estimate, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    gap = estimate[:3, 3] - truth[:3, 3]
    if about is not None:
        gap = gap + (estimate[:3, :3] - truth[:3, :3]) @ np.asarray(about, dtype=np.float64)
    return float(np.linalg.norm(gap))


def from_centred(
    transformation: np.ndarray, centre: np.ndarray, source_centre: np.ndarray | None = None
) -> np.ndarray:
    """A transformation of coordinates centred on ``centre`` (``x - centre``), for the
    coordinates they were centred from: ``x -> R (x - c) + t + c``; a stack ``(k, 4, 4)``
    transformation by transformation. A new float64 array; ``from_centred(T, -centre)``
    goes the other way. ``source_centre``: the points it moves were centred on another
    point (``x -> R (x - c_source) + t + c``), as between two scans each centred on its
    own centroid."""
    out = np.array(transformation, dtype=np.float64)
    source = centre if source_centre is None else np.asarray(source_centre, dtype=np.float64)
    out[..., :3, 3] += centre - out[..., :3, :3] @ source
    return out


def rms_displacement(estimate: np.ndarray, truth: np.ndarray, points: np.ndarray) -> float:
    """Root mean square distance between where ``estimate`` and ``truth`` carry each of
    ``points``: the error of a registration in the data's own unit, wherever the data
    lie."""
    estimate, truth = np.asarray(estimate, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    centre = points.mean(axis=0)
    rot = estimate[:3, :3] - truth[:3, :3]
    gap = (points - centre) @ rot.T + (rot @ centre + estimate[:3, 3] - truth[:3, 3])
    return float(np.sqrt(np.mean(np.sum(gap * gap, axis=1))))


def euler_angles_deg(transformation: np.ndarray) -> np.ndarray:
    """The rotation as ``xyz`` Euler angles in degrees (the ModelNet40 protocols' unit)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(np.asarray(transformation)[:3, :3]).as_euler("xyz", degrees=True)


def random_rigid_motion(
    random_state: int | np.random.Generator | None = None,
    max_translation: float = 1.0,
    *,
    seed: int | np.random.Generator | None = None,
) -> np.ndarray:
    """A random rigid motion: rotation uniform over SO(3), translation uniform in the cube
    ``[-max_translation, max_translation]^3``.

    ``random_state``: an int (or None) seeds a generator of its own; a
    ``numpy.random.Generator`` is drawn from (one integer that seeds the rotation, then
    the three translation components), so that a sequence of motions comes from one
    generator. ``seed`` is its former name (a ``FutureWarning``).

    Returns
    -------
    ndarray of shape (4, 4)

    Examples
    --------
    >>> from o3d_rpointhop.transforms import random_rigid_motion
    >>> motion = random_rigid_motion(random_state=0)
    >>> bool(abs(np.linalg.det(motion[:3, :3]) - 1.0) < 1e-12)
    True
    """
    from scipy.spatial.transform import Rotation

    rng = renamed_seed(random_state, seed, "random_rigid_motion")
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(rng)
    motion = np.eye(4)
    motion[:3, :3] = Rotation.random(random_state=int(rng.integers(2**31))).as_matrix()
    motion[:3, 3] = rng.uniform(-max_translation, max_translation, 3)
    return motion
