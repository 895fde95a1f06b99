"""How far a registration can be trusted: refused and risky input geometry, and the
``converged`` / ``ambiguous`` flags of a result, with their thresholds.

Measured on training data (docs/registration.md, "Flags"): unrelated objects registered
to each other leave their inliers spread over the threshold (0.53-0.58 of it, RMS), true
poses of two different samples of an object 0.24-0.40; a symmetric shape or a
featureless plane fits about as well turned by 180 degrees.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .context import RegistrationContext

__all__ = [
    "AMBIGUITY_RATIO",
    "MAX_SPREAD",
    "MIN_FITNESS",
    "Quality",
    "RegistrationWarning",
    "assess",
    "check_geometry",
    "twin_transformations",
]


class RegistrationWarning(UserWarning):
    """A registration result to treat with care: degenerate input, or a flagged result."""


# A cloud whose second principal extent is below this share of its first is a line, and
# whose third is below it, a plane (relative standard deviations).
_COLLINEAR = 1e-6
_PLANAR = 1e-4
# float32 coordinates whose rounding step exceeds this share of the cloud's extent.
_FLOAT32_RESOLUTION = 1e-5


def _raw_float32(cloud: Any) -> np.ndarray | None:
    """The caller's coordinates when they are float32 (numpy or tensor Open3D)."""
    if isinstance(cloud, np.ndarray) and cloud.dtype == np.float32:
        return cloud
    point = getattr(cloud, "point", None)
    if point is not None and "positions" in point:
        positions = point.positions
        if "Float32" in str(positions.dtype):
            return positions.cpu().numpy()
    return None


def check_geometry(points: np.ndarray, name: str, raw: Any = None) -> None:
    """Refuse clouds a rigid registration cannot be defined on, warn about risky ones.

    Raises
    ------
    ValueError
        If every point coincides, or the points lie on one line (a rotation about it
        cannot be recovered).

    Warns
    -----
    RegistrationWarning
        For a planar cloud (in-plane turns and flips may be undetermined; see
        ``RegistrationResult.ambiguous``), and for float32 coordinates whose rounding
        step is coarse for the cloud's size (survey coordinates: pass float64).
    """
    if not np.any(points != points[0]):
        raise ValueError(f"{name} has no spatial extent: all its points coincide")
    spread = np.sqrt(np.clip(np.linalg.eigvalsh(np.cov(points.T)), 0.0, None))[::-1]
    if spread[1] <= _COLLINEAR * spread[0]:
        raise ValueError(
            f"{name} is collinear (its points lie on one line): a rotation about that line "
            "cannot be recovered, so there is no rigid registration to find"
        )
    if spread[2] <= _PLANAR * spread[0]:
        warnings.warn(
            f"{name} is planar (flat to {spread[2] / spread[0]:.1e} of its size): turns "
            "within the plane and flips may be undetermined; check result.ambiguous",
            RegistrationWarning,
            stacklevel=4,
        )
    raw32 = _raw_float32(raw)
    if raw32 is not None:
        step = float(np.spacing(np.float32(np.abs(raw32).max())))
        extent = float(points.max(axis=0).max() - points.min(axis=0).min())
        if step > _FLOAT32_RESOLUTION * extent:
            warnings.warn(
                f"{name} holds float32 coordinates up to {np.abs(raw32).max():.6g}, where "
                f"float32 resolves only {step:.3g}, coarse for a cloud {extent:.3g} across: "
                "its points were already rounded before registration; pass float64 "
                "(or coordinates relative to a local origin) for full precision",
                RegistrationWarning,
                stacklevel=4,
            )


#: Fitness below which a result is flagged as not converged.
MIN_FITNESS = 0.02
#: Inlier RMSE within the settings' ``spread_distance`` (3 resolutions), as a share of
#: that distance, above which a result is flagged as not converged (a chance alignment).
MAX_SPREAD = 0.47
#: A 180-degree twin with at least this share of the result's fitness makes it ambiguous.
AMBIGUITY_RATIO = 0.9


def _ambiguous(context: RegistrationContext, transformation: np.ndarray, distance: float) -> bool:
    """Whether a 180-degree twin of ``transformation`` fits about as well, measured on
    the global clouds (cheap: about ``n_global_points`` points)."""
    source = np.asarray(context.global_cloud("source").points)
    base = context.evaluate(transformation, distance, which="global").fitness
    if base <= 0.0:
        return False
    twins = twin_transformations(source, transformation)
    best = max(context.evaluate(t, distance, which="global").fitness for t in twins)
    return best >= AMBIGUITY_RATIO * base


def twin_transformations(points: np.ndarray, transformation: np.ndarray) -> np.ndarray:
    """The three 180-degree twins of ``transformation`` about the moved source's axes.

    Parameters
    ----------
    points : ndarray of shape (n, 3)
        Source points (before ``transformation``).
    transformation : ndarray of shape (4, 4)
        Current source-to-target estimate.

    Returns
    -------
    ndarray of shape (3, 4, 4)
        ``F_k @ transformation``, where ``F_k`` turns by 180 degrees about the k-th
        principal axis of the moved source, through its centroid. A shape symmetric
        under such a half-turn looks the same in the estimate and in its twin.
    """
    moved = points @ transformation[:3, :3].T + transformation[:3, 3]
    centre = moved.mean(axis=0)
    _, axes = np.linalg.eigh(np.cov((moved - centre).T))
    # A half-turn about unit axis a is 2 a a^T - I.
    flips = 2.0 * np.einsum("ik,jk->kij", axes, axes) - np.eye(3)
    twins = np.tile(np.eye(4), (3, 1, 1))
    twins[:, :3, :3] = flips
    twins[:, :3, 3] = centre - flips @ centre
    return twins @ transformation


@dataclass
class Quality:
    """The measurements behind a result's flags.

    Attributes
    ----------
    final : StepResult
        Fitness, inlier RMSE and inlier pairs at the last step's distance, on the full
        clouds.
    spread : float
        Inlier RMSE within ``wide`` as a share of it.
    wide : float
        The distance the spread was measured at.
    converged, ambiguous : bool
        See :class:`~o3d_rpointhop.RegistrationResult`.
    """

    final: Any
    spread: float
    wide: float
    converged: bool
    ambiguous: bool


def assess(
    context: RegistrationContext,
    transformation: np.ndarray,
    distance: float,
    ambiguity: bool = True,
) -> Quality:
    """Measure ``transformation`` (in the context's centred frame) and set its flags:
    not converged when fewer than :data:`MIN_FITNESS` of the source points have a partner
    within ``distance`` or the partners within three resolutions spread like a chance
    alignment's (:data:`MAX_SPREAD`); ambiguous (only measured with ``ambiguity``) when
    a 180-degree twin keeps :data:`AMBIGUITY_RATIO` of the fitness."""
    final = context.evaluate(transformation, distance)
    wide = max(distance, context.settings.spread_distance)
    spread = context.evaluate(transformation, wide).inlier_rmse / wide
    converged = final.fitness >= MIN_FITNESS and spread <= MAX_SPREAD
    ambiguous = ambiguity and converged and _ambiguous(context, transformation, wide)
    return Quality(final=final, spread=spread, wide=wide, converged=converged, ambiguous=ambiguous)


def warn_flags(quality: Quality, distance: float, stacklevel: int) -> None:
    """One :class:`RegistrationWarning` for a flagged result, pointing ``stacklevel``
    frames above the caller."""
    if not quality.converged:
        warnings.warn(
            f"the registration did not converge: {quality.final.fitness:.1%} of the source "
            f"points have a target point within {distance:.4g}, and within "
            f"{quality.wide:.4g} their RMS distance is {quality.spread:.2f} of it (no "
            "overlap, or a chance alignment); result.converged is False",
            RegistrationWarning,
            stacklevel=stacklevel + 1,
        )
    elif quality.ambiguous:
        warnings.warn(
            "the registration is ambiguous: the result turned by 180 degrees fits about "
            "as well (a symmetric shape or a featureless plane); result.ambiguous is True",
            RegistrationWarning,
            stacklevel=stacklevel + 1,
        )
