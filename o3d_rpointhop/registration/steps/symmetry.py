"""Choosing between an estimate and its 180-degree twins (near-symmetric shapes).

A global estimate built from local descriptors cannot tell the two halves of a
(nearly) symmetric shape apart: a keyboard or a bench can come out turned by 180
degrees, and ICP then settles in the twin's basin. Where the symmetry is only
approximate, the true pose explains the data better than the twin does, so trying the
twins and keeping the best-fitting result recovers it; where the shape is exactly
symmetric the twins fit equally well and the estimate is kept.
"""

from __future__ import annotations

from numbers import Real

import numpy as np
from sklearn.base import clone

from ..._utils.params import HasMethods, Interval
from ..context import RegistrationContext
from ..flags import twin_transformations
from ..result import StepResult
from ._base import OPTIONAL_DISTANCE, RegistrationStep
from .icp import PointToPlaneICP

__all__ = ["SymmetryCheck", "fits_better", "truncated_cost"]


def truncated_cost(fitness: float, inlier_rmse: float, threshold: float) -> float:
    """Mean truncated squared residual: inliers count their squared distance, every
    other source point ``threshold**2`` (lower is better; rewards overlap and accuracy)."""
    return fitness * inlier_rmse**2 + (1.0 - fitness) * threshold**2


def fits_better(
    candidate: StepResult, incumbent: StepResult, threshold: float, margin: float
) -> bool:
    """Whether ``candidate`` explains the data better than ``incumbent`` on every count:
    at least the same fitness, at most the same inlier RMSE, and a truncated cost
    (:func:`truncated_cost`) lower by more than ``margin`` (relative).

    Requiring both counts keeps a candidate that trades accuracy for coverage from
    winning: with partial overlaps, a turned-over twin can cover more of the other
    cloud, loosely, than the true pose covers exactly.
    """
    cost = truncated_cost(candidate.fitness, candidate.inlier_rmse, threshold)
    bar = (1.0 - margin) * truncated_cost(incumbent.fitness, incumbent.inlier_rmse, threshold)
    return (
        candidate.fitness >= incumbent.fitness
        and candidate.inlier_rmse <= incumbent.inlier_rmse
        and cost < bar
    )


class SymmetryCheck(RegistrationStep):
    """Try the estimate's 180-degree twins too, and take one that fits better throughout.

    Runs after a refinement step. The incoming estimate and its three twins (turned by
    180 degrees about each principal axis of the moved source, see
    :func:`twin_transformations`) are each refined with ``refine`` on the global step's
    clouds (cheap: about ``n_global_points`` points) and measured there within
    ``max_correspondence_distance``. A twin replaces the estimate only when it fits
    better on every count (:func:`fits_better`: fitness no lower, inlier RMSE no higher,
    mean truncated squared residual lower by more than ``margin``), so an exactly
    symmetric shape keeps the
    global step's choice, and so does a partial overlap where a twin covers more of the
    other cloud but less closely; the winning twin is then refined on the full clouds.

    On the ModelNet40 paper protocol with noise this recovers the two near-symmetric
    shapes (a keyboard, a bench) that RANSAC returned turned over; see
    ``docs/registration.md``.

    Parameters
    ----------
    refine : RegistrationStep, default=None
        How each candidate is refined; ``None`` is :class:`PointToPlaneICP` with its
        defaults. Clones are used.
    max_correspondence_distance : float, default=None
        Truncation distance of the score; ``None`` is the settings'
        ``symmetry_distance``, 2 x ``voxel_size`` (the distance of ICP's first pass).
    margin : float, default=0.1
        Relative improvement of the truncated cost a twin needs to replace the estimate.
    """

    name = "symmetry_check"

    _parameter_constraints = {
        "refine": [None, HasMethods(["run"])],
        "max_correspondence_distance": OPTIONAL_DISTANCE,
        "margin": [Interval(Real, 0, 1, closed="left")],
    }

    def __init__(
        self,
        refine: RegistrationStep | None = None,
        *,
        max_correspondence_distance: float | None = None,
        margin: float = 0.1,
    ) -> None:
        self.refine = refine
        self.max_correspondence_distance = max_correspondence_distance
        self.margin = margin

    def _check_params(self) -> None:
        refine = self.refine
        if refine is None:
            return
        if not isinstance(refine, RegistrationStep) or refine.kind != "refine":
            raise ValueError(f"refine must be None or a refinement step, got {self.refine!r}")
        if isinstance(refine, SymmetryCheck):
            raise ValueError("refine must not be another SymmetryCheck")
        refine.validate()

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        # A copy (validated with this step) refines every candidate.
        refine = PointToPlaneICP() if self.refine is None else clone(self.refine)
        margin = float(self.margin)
        threshold = self.max_correspondence_distance or context.settings.symmetry_distance
        current = transformation
        coarse = context.coarse()
        starts = [current, *twin_transformations(np.asarray(coarse.source.points), current)]
        refined = [refine._run_timed(coarse, start).transformation for start in starts]
        checks = [coarse.evaluate(t, threshold) for t in refined]
        costs = [truncated_cost(c.fitness, c.inlier_rmse, threshold) for c in checks]
        incumbent = checks[0]
        better = [
            k for k in range(1, len(checks)) if fits_better(checks[k], incumbent, threshold, margin)
        ]
        best = min(better, key=costs.__getitem__, default=0)
        chosen = best - 1
        if chosen >= 0:
            current = refined[best]
            if coarse is not context:  # the trial ran on the global clouds: finish on the full
                current = refine._run_timed(context, current).transformation
        result = context.evaluate(current, threshold)
        result.name = self.name
        result.info = {
            "max_correspondence_distance": threshold,
            "costs": costs,
            "chosen_twin": chosen,
        }
        return result
