"""What the global steps share: their descriptor, their matches and the constraints of
their parameters."""

from __future__ import annotations

from numbers import Integral, Real

import numpy as np

from ..._utils.params import HasMethods, Interval
from ..context import RegistrationContext
from ..correspondences import Correspondences, find_correspondences
from ..result import StepResult
from ._base import RegistrationStep

__all__ = ["GlobalStep", "DESCRIPTOR", "COUNT"]

#: The constraint of a step's own descriptor: ``None`` (the pipeline's) or a transformer.
DESCRIPTOR = [None, HasMethods(["transform"])]
#: The constraint of a count of matches: at least 3, or a share in (0, 1].
COUNT = [Interval(Integral, 3, None, closed="left"), Interval(Real, 0, 1, closed="right")]


class GlobalStep(RegistrationStep):
    """Base of the global steps: the descriptor they match with and their matches.

    A global step ignores the incoming transformation. Its descriptor is its own
    ``descriptor`` parameter, else the context's (the pipeline's), else
    :func:`~o3d_rpointhop.registration.defaults.default_descriptor`; descriptors are
    computed once per registration and descriptor (``context.features``).
    """

    kind = "global"

    def _descriptors(self) -> tuple:
        return (self.descriptor,)

    def _describe(self, context: RegistrationContext) -> tuple[np.ndarray, np.ndarray]:
        # None: the context's descriptors (prepared, or its descriptor's).
        return (
            context.features(self.descriptor, "source"),
            context.features(self.descriptor, "target"),
        )

    def _correspond(self, context: RegistrationContext, **filters) -> Correspondences:
        src, tgt = self._describe(context)
        corr = find_correspondences(src, tgt, **filters)
        if len(corr) < 3:
            raise ValueError(
                f"{type(self).__name__}: only {len(corr)} correspondences survived the "
                "filters; at least 3 are needed (relax mutual_filter / max_ratio / top_k)"
            )
        return corr

    @staticmethod
    def _measured(
        context: RegistrationContext,
        name: str,
        transformation: np.ndarray,
        distance: float,
        corr: Correspondences,
        **info,
    ) -> StepResult:
        """The step's estimate measured like every global step's: fitness and inliers on
        the global clouds within ``distance``, reported with its match count, the step's
        own ``info`` and the distance."""
        check = context.evaluate(transformation, distance, which="global")
        check.name = name
        check.info = {
            "candidate_matches": len(corr),
            **info,
            "max_correspondence_distance": distance,
        }
        # The matches themselves, in the caller's coordinates, and which of them the
        # estimate explains (for looking at a result: o3d_rpointhop.viewer).
        src, tgt = (np.asarray(c.points) for c in context.clouds("global"))
        a, b = src[corr.pairs[:, 0]], tgt[corr.pairs[:, 1]]
        moved = a @ transformation[:3, :3].T + transformation[:3, 3]
        check.match_inliers = ((moved - b) ** 2).sum(axis=1) < distance * distance
        check.matches = np.stack([a, b], axis=1) + context.origin
        return check
