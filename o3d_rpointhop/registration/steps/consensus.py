"""A correspondence-graph global step: the rigid motion most matches agree on (the kernel
is in :mod:`._consensus`)."""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any

import numpy as np

from ..._utils.params import Interval, StrOptions
from ..._utils.threads import kernel_threads
from ..context import RegistrationContext
from ..matching import Matcher, PooledMatcher
from ..result import StepResult
from ._base import OPTIONAL_DISTANCE
from ._consensus import consensus, pooled
from ._global import DESCRIPTOR, HYPOTHESES, MATCHER, GlobalStep, with_shared_docs

__all__ = ["SENSOR_HYPOTHESES", "SENSOR_MAX_VIOLATION", "ConsensusGlobal"]

#: Hypotheses ``n_hypotheses="auto"`` verifies when the sensors are known, and the
#: free-space limit they are verified with: chosen on every official pair of the scene
#: model's four training scenes (docs/benchmarks_3dmatch.md, "Free space").
SENSOR_HYPOTHESES = 16
SENSOR_MAX_VIOLATION = 0.1

#: A distance that may also be 0 (off), or ``None`` (from the settings).
_OPTIONAL_LENGTH = [None, Interval(Real, 0, None, closed="left")]


@with_shared_docs
class ConsensusGlobal(GlobalStep):
    """The rigid motion the largest set of mutually consistent matches agrees on.

    Matches are the step's matcher's (by default nearest descriptors both ways, at most
    4000). Two matches are compatible when they keep their length (to within the
    settings' ``consensus_distance``), lie far enough apart to say something about the
    rotation (``span_distance``) and do not share an endpoint: true matches form the
    densest cluster of that graph. The ``n_seeds`` matches compatible with the most
    others seed hypotheses; each seed grows into a consensus set by second-order
    compatibility (the number of matches compatible with both, at the tighter
    ``second_order_distance``), each set gives a weighted SVD fit, every fit is scored
    on all matches by a truncated quadratic of their residuals (within
    ``score_distance``), and the best one is refitted on its matches within
    ``max_correspondence_distance`` (after SC2-PCR, Chen et al. 2022; see
    docs/consensus.md). Deterministic: no random draw. The graph's distances are
    multiples of the resolution, set through
    :class:`~o3d_rpointhop.registration.RegistrationSettings` (``consensus_factor``,
    ``span_factor``, ``second_order_factor``, ``score_factor``).

    The defaults won on every official pair of the training scenes of 3DMatch, for FPFH
    and for the scene model (docs/consensus.md, "Chosen settings").

    Parameters
    ----------
    descriptor : transformer, default=None
        ``None`` uses the pipeline's descriptor.
    {matcher}
    max_correspondence_distance : float, default=None
        Inlier distance of a match under a hypothesis; ``None`` is the settings'
        ``ransac_distance``.
    distinct_endpoints : bool, default=True
        Two matches that share a source or a target point are not compatible.
    n_seeds : int, default=5000
        Most hypotheses: the matches compatible with the most others seed them.
    seed_radius : float, default=0.0
        Seed suppression: a seed closer than this (in the source) to a better seed is
        dropped; 0 turns it off, ``None`` is the settings' ``seed_distance``.
    set_size : int, default=30
        Partners of a seed in its consensus set.
    n_jobs : int, default=None
        Threads of the compiled graph, set building and scoring (``None``: every core,
        within ``OMP_NUM_THREADS``, ``threadpoolctl``'s limits, ``joblib.parallel_config``
        and, inside a joblib worker, one; ``-1``: all cores); the result does not
        depend on it.
    {n_hypotheses} ``"auto"`` (the default): :data:`SENSOR_HYPOTHESES` when the
        sensors are known (``viewpoints``), where the free-space check below can tell
        the right hypothesis from wrong ones that fit as well, else 1.
    max_violation : float or None, default=0.1
        With several hypotheses and the sensors known, a hypothesis that puts more than
        this share of either cloud where the other sensor saw empty space scores 0 in
        the verification (:mod:`~o3d_rpointhop.registration.free_space`); ``None``: no
        such check.
    """

    name = "consensus"
    pools_hypotheses = True

    _parameter_constraints = {
        "descriptor": DESCRIPTOR,
        "matcher": MATCHER,
        "max_correspondence_distance": OPTIONAL_DISTANCE,
        "distinct_endpoints": ["boolean"],
        "n_seeds": [Interval(Integral, 1, None, closed="left")],
        "seed_radius": _OPTIONAL_LENGTH,
        "set_size": [Interval(Integral, 2, None, closed="left")],
        "n_jobs": [None, Integral],
        "n_hypotheses": [*HYPOTHESES, StrOptions({"auto"})],
        "max_violation": [Interval(Real, 0, 1, closed="both"), None],
    }

    def __init__(
        self,
        descriptor: Any = None,
        *,
        matcher: Matcher | None = None,
        max_correspondence_distance: float | None = None,
        distinct_endpoints: bool = True,
        n_seeds: int = 5000,
        seed_radius: float | None = 0.0,
        set_size: int = 30,
        n_jobs: int | None = None,
        n_hypotheses: int | str = "auto",
        max_violation: float | None = SENSOR_MAX_VIOLATION,
    ) -> None:
        self.descriptor = descriptor
        self.matcher = matcher
        self.max_correspondence_distance = max_correspondence_distance
        self.distinct_endpoints = distinct_endpoints
        self.n_seeds = n_seeds
        self.seed_radius = seed_radius
        self.set_size = set_size
        self.n_jobs = n_jobs
        self.n_hypotheses = n_hypotheses
        self.max_violation = max_violation

    @classmethod
    def default_matcher(cls) -> Matcher:
        """Nearest descriptors both ways, at most 4000 matches spread by index (the
        graph's two bit matrices then take 4 MB). Chosen on the scene model's training
        scenes: 8000 registered as many pairs, with R-PointHop and with FPFH, for a
        third more time (docs/benchmarks_3dmatch.md)."""
        return Matcher(both_directions=True, max_matches=4000)

    def _n_hypotheses(self, context: RegistrationContext) -> int:
        """How many hypotheses are verified: ``"auto"`` is :data:`SENSOR_HYPOTHESES`
        with the sensors known, else 1."""
        if self.n_hypotheses != "auto":
            return int(self.n_hypotheses)
        return SENSOR_HYPOTHESES if context.viewpoints is not None else 1

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        distance = self.max_correspondence_distance or context.settings.ransac_distance
        info = {}
        if self._pooled_hypotheses():
            matcher = self._matcher()
            parts = self._part_matches(context, slice(1))
            runs = [self._consensus(context, parts[0], distance)]
            known = None
            if matcher.combine == "fallback":
                # The first part alone, kept when its estimate explains enough of its
                # matches; else the others are asked too, and the verification of its
                # hypotheses is built on.
                first, known = self._result_of(
                    context, runs[0], distance, parts[0], hypotheses=runs[0].n_hypotheses
                )
                if np.mean(first.match_inliers) >= matcher.min_support:
                    first.info["fallback"] = False
                    return first
                info["fallback"] = True
            more = self._part_matches(context, slice(1, None))
            runs += [self._consensus(context, corr, distance) for corr in more]
            parts += more
            found, corr = pooled(runs), PooledMatcher.pool(parts)
            # Which part each verified hypothesis came from, in their order.
            names = [name for name, _, _ in matcher.parts]
            info["hypothesis_parts"] = [
                n for n, r in zip(names, runs, strict=True) for _ in r.hypotheses
            ]
        else:
            corr = self._matches(context)
            found, known = self._consensus(context, corr, distance), None
        return self._result_of(
            context, found, distance, corr, known, hypotheses=found.n_hypotheses, **info
        )[0]

    def _consensus(self, context: RegistrationContext, corr, distance: float):
        """The consensus on the matches ``corr``."""
        settings = context.settings
        return consensus(
            *self._matched(context, corr),
            compatibility_threshold=settings.consensus_distance,
            inlier_threshold=distance,
            score_threshold=settings.score_distance,
            second_order_threshold=settings.second_order_distance,
            min_span=settings.span_distance,
            endpoints=(corr.pairs[:, 0], corr.pairs[:, 1]) if self.distinct_endpoints else None,
            n_seeds=int(self.n_seeds),
            seed_radius=settings.seed_distance if self.seed_radius is None else self.seed_radius,
            set_size=int(self.set_size),
            upright=None if context.up is None else context.upright,
            n_hypotheses=self._n_hypotheses(context),
            n_threads=kernel_threads(self.n_jobs),
        )
