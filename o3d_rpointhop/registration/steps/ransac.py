"""RANSAC on descriptor matches: the step (the vectorised kernel is in :mod:`._ransac`)."""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any

import numpy as np

from ..._utils.params import Interval, StrOptions
from ..context import RegistrationContext
from ..matching import Matcher
from ..result import StepResult
from ._base import OPTIONAL_DISTANCE
from ._global import DESCRIPTOR, HYPOTHESES, MATCHER, GlobalStep, with_shared_docs
from ._ransac import ransac

__all__ = ["RANSACGlobal"]


@with_shared_docs
class RANSACGlobal(GlobalStep):
    """RANSAC on descriptor matches.

    Correspondences come from the step's matcher (by default each source point's
    nearest target descriptor, unfiltered). Hypotheses are drawn, checked
    with Open3D's two checkers (edge-length similarity, then the distance of the
    sample's own points) and scored on the correspondences in vectorised batches, and
    the best one is refitted on its inliers (``o3d_rpointhop.registration.steps._ransac``):
    the same semantics as Open3D's ``registration_ransac_based_on_correspondence``
    at a fraction of its cost per iteration, repeatable on any number of threads.
    Seeded from the pipeline's ``seed``: the same input gives the same result.

    Parameters
    ----------
    descriptor : transformer, default=None
        ``None`` uses the pipeline's descriptor.
    {matcher}
    max_correspondence_distance : float, default=None
        Inlier distance; ``None`` is the settings' ``ransac_distance`` (1.5 x
        ``voxel_size``, Open3D's tutorial ratio).
    max_iteration : int, default=1000000
        Upper bound; drawing stops as soon as ``confidence`` is reached, so easy pairs
        take a few hundred iterations. Hard pairs need the room: with 1 % inlier
        matches (the Stanford Bunny scans bun270 and bun000, 90 deg apart) the tutorial's
        100000 stops on a wrong pose, one million finds the right one.
    confidence : float, default=0.999
    ransac_n : int, default=3
        Pairs per hypothesis (at least 3).
    edge_length : float, default=0.9
        Edge-length checker similarity in [0, 1) (0 disables the checker).
    selection : {"fitness", "matches"}, default="fitness"
        How the winner is chosen among the 64 hypotheses that carry the most matches:
        ``"fitness"``, by the share of the whole source cloud it brings within the
        inlier distance of the target (Open3D's rule), then refitted on those cloud
        pairs; ``"matches"``, by the matches it carries (then their residuals), then
        refitted on those matches, as correspondence-graph estimators score.
    {n_hypotheses}
    """

    name = "ransac"

    _parameter_constraints = {
        "descriptor": DESCRIPTOR,
        "matcher": MATCHER,
        "max_correspondence_distance": OPTIONAL_DISTANCE,
        "max_iteration": [Interval(Integral, 1, None, closed="left")],
        "confidence": [Interval(Real, 0, 1, closed="neither")],
        "ransac_n": [Interval(Integral, 3, None, closed="left")],
        "edge_length": [Interval(Real, 0, 1, closed="left")],
        "selection": [StrOptions({"fitness", "matches"})],
        "n_hypotheses": HYPOTHESES,
    }

    def __init__(
        self,
        descriptor: Any = None,
        *,
        matcher: Matcher | None = None,
        max_correspondence_distance: float | None = None,
        max_iteration: int = 1_000_000,
        confidence: float = 0.999,
        ransac_n: int = 3,
        edge_length: float = 0.9,
        selection: str = "fitness",
        n_hypotheses: int = 1,
    ) -> None:
        self.descriptor = descriptor
        self.matcher = matcher
        self.max_correspondence_distance = max_correspondence_distance
        self.max_iteration = max_iteration
        self.confidence = confidence
        self.ransac_n = ransac_n
        self.edge_length = edge_length
        self.selection = selection
        self.n_hypotheses = n_hypotheses

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        distance = self.max_correspondence_distance or context.settings.ransac_distance
        corr = self._matches(context)
        clouds = tuple(np.asarray(c.points) for c in context.clouds("global"))
        found = ransac(
            *self._matched(context, corr),
            distance,
            max_iteration=int(self.max_iteration),
            confidence=float(self.confidence),
            edge_length=float(self.edge_length),
            seed=context.random_state,
            ransac_n=int(self.ransac_n),
            clouds=clouds if self.selection == "fitness" else None,
            upright=None if context.up is None else context.upright,
            n_hypotheses=int(self.n_hypotheses),
        )
        return self._result_of(context, found, distance, corr, iterations=found.iterations)[0]
