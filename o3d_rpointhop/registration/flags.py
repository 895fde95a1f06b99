"""How far a registration result can be trusted: the ``converged`` / ``ambiguous`` flags
and their thresholds.

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

from .checks import RegistrationWarning

if TYPE_CHECKING:
    from .context import RegistrationContext

__all__ = [
    "AMBIGUITY_RATIO",
    "MAX_SPREAD",
    "MIN_FITNESS",
    "Quality",
    "assess",
    "twin_transformations",
    "warn_flags",
]


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
    margin: float = 1.0,
) -> Quality:
    """Measure ``transformation`` (in the context's centred frame) and set its flags:
    not converged when fewer than :data:`MIN_FITNESS` of the source points have a partner
    within ``distance`` or the partners within three resolutions spread like a chance
    alignment's (:data:`MAX_SPREAD`); ambiguous (only measured with ``ambiguity``) when
    a 180-degree twin keeps :data:`AMBIGUITY_RATIO` of the fitness, or when the global
    step's verified hypotheses left the winner a ``margin`` under ``1 -
    AMBIGUITY_RATIO`` over a distinct runner-up."""
    final = context.evaluate(transformation, distance)
    wide = max(distance, context.settings.spread_distance)
    spread = context.evaluate(transformation, wide).inlier_rmse / wide
    converged = final.fitness >= MIN_FITNESS and spread <= MAX_SPREAD
    ambiguous = (
        ambiguity
        and converged
        and (margin < 1.0 - AMBIGUITY_RATIO or _ambiguous(context, transformation, wide))
    )
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
