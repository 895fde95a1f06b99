"""The R-PointHop paper's one-shot estimate: filtered matches, one SVD."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...transforms import rigid_transform
from ..context import RegistrationContext
from ..correspondences import count_of
from ..matching import Matcher
from ..result import StepResult
from ._global import COUNT, DESCRIPTOR, MATCHER, GlobalStep, with_shared_docs

__all__ = ["SVDGlobal"]


@with_shared_docs
class SVDGlobal(GlobalStep):
    """The R-PointHop paper's one-shot estimate: matches, filters, one SVD.

    Every source point is matched to the target point with the nearest descriptor; the
    ``top_k`` matches with the smallest descriptor distance are kept, then the
    ``top_k_ratio`` of those with the best ratio test, and the rigid transform is the
    least-squares (Kabsch) fit of the kept pairs, centred on the pairs themselves (the
    authors' code centres on the whole clouds, which is wrong unless both clouds cover
    the same surface). No RANSAC: fast, exact on clean copies, fragile on real data.

    Parameters
    ----------
    descriptor : transformer, default=None
        ``None`` uses the pipeline's descriptor.
    top_k : int or float, default=0.25
        Matches kept by descriptor distance (the paper's M1: 256 of 1024 points). As
        in :func:`~o3d_rpointhop.find_correspondences`: an int is a count, a float in
        (0, 1] a share of the source points.
    top_k_ratio : int or float, default=0.125
        Matches then kept by ratio test (M2: 128 of 1024); a count or a share.
    {matcher}
    """

    name = "svd"

    _parameter_constraints = {
        "descriptor": DESCRIPTOR,
        "top_k": COUNT,
        "top_k_ratio": COUNT,
        "matcher": MATCHER,
    }

    def __init__(
        self,
        descriptor: Any = None,
        *,
        top_k: int | float = 0.25,
        top_k_ratio: int | float = 0.125,
        matcher: Matcher | None = None,
    ) -> None:
        self.descriptor = descriptor
        self.top_k = top_k
        self.top_k_ratio = top_k_ratio
        self.matcher = matcher

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        n = len(context.global_cloud("source").points)
        top_k = count_of(self.top_k, n, minimum=3)
        top_k_ratio = min(top_k, count_of(self.top_k_ratio, n, minimum=3))
        corr = self._matches(context).strongest(top_k, top_k_ratio)
        estimate = rigid_transform(*self._matched(context, corr))
        distance = context.settings.evaluation_distance
        check = context.evaluate(estimate, distance, which="global")
        return StepResult(
            name=self.name,
            transformation=estimate,
            fitness=check.fitness,
            inlier_rmse=check.inlier_rmse,
            correspondence_set=corr.pairs,
            info={"matches_used": len(corr), "max_correspondence_distance": distance},
            distance=distance,
        )
