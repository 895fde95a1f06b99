"""A correspondence-graph global step: the rigid motion most matches agree on (the kernel
is in :mod:`._consensus`)."""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any

import numpy as np

from ..._utils.params import Interval, StrOptions
from ..._utils.threads import kernel_threads
from ..context import RegistrationContext
from ..correspondences import (
    Correspondences,
    correspondences_both_ways,
    k_best_correspondences,
    salient,
    turned_correspondences,
)
from ..result import StepResult
from ._base import OPTIONAL_DISTANCE
from ._consensus import consensus
from ._global import DESCRIPTOR, FRAME_TURNS, HYPOTHESES, METRIC, GlobalStep, with_shared_docs

__all__ = ["ConsensusGlobal"]

#: A distance that may also be 0 (off), or ``None`` (from the settings).
_OPTIONAL_LENGTH = [None, Interval(Real, 0, None, closed="left")]


@with_shared_docs
class ConsensusGlobal(GlobalStep):
    """The rigid motion the largest set of mutually consistent matches agrees on.

    Matches are nearest descriptors (source to target and, with ``both_directions``,
    target to source too), optionally mutual and ratio-filtered, at most
    ``max_matches`` of them. Two matches are compatible when they keep their length (to
    within ``compatibility_distance``), lie far enough apart to say something about
    the rotation (``min_span``) and do not share an endpoint: true matches form
    the densest cluster of that graph. The ``n_seeds`` matches compatible with the most
    others seed hypotheses; each seed grows into a consensus set by second-order
    compatibility (the number of matches compatible with both, at the tighter
    ``second_order_distance``), each set gives a weighted SVD fit, every fit is scored
    on all matches by a truncated quadratic of their residuals (within
    ``score_distance``), and the best one is refitted on its matches within
    ``max_correspondence_distance`` (after SC2-PCR, Chen et al. 2022; see
    docs/consensus.md). Deterministic: no random draw.

    The defaults won on every official pair of the training scenes of 3DMatch, for FPFH
    and for the scene model (docs/consensus.md, "Chosen settings").

    Parameters
    ----------
    descriptor : transformer, default=None
        ``None`` uses the pipeline's descriptor.
    max_correspondence_distance : float, default=None
        Inlier distance of a match under a hypothesis; ``None`` is the settings'
        ``ransac_distance``.
    compatibility_distance : float, default=None
        Largest length difference of two compatible matches (the first-order graph);
        ``None`` is the settings' ``consensus_distance`` (2 resolutions).
    mutual_filter : bool, default=False
        Keep only mutual nearest descriptors.
    both_directions : bool, default=True
        Also match every target point to its nearest source descriptor (ignored with
        ``mutual_filter``, where both directions agree by definition).
    max_ratio : float, default=None
        Ratio-test threshold on the matches.
    n_nearest : int, default=1
        Matches per point: each point to its ``n_nearest`` nearest descriptors of the
        other cloud (k-best matching,
        :func:`~o3d_rpointhop.registration.correspondences.k_best_correspondences`), so
        a right partner that is only second nearest is still matched. Above 1 it
        cannot be combined with ``mutual_filter`` or ``max_ratio``, which are defined
        on the nearest alone.
    salient_share : float, default=None
        Keep only the matches between two salient points: each among this share (in
        (0, 1]) of its cloud's points whose descriptors are the most distinct within
        the cloud (the distance to the 10th nearest descriptor of the same cloud,
        :func:`~o3d_rpointhop.registration.correspondences.distinctiveness`). Walls,
        floors and table tops, whose descriptors repeat, then stop drowning the few
        right matches of a pair that overlaps little. ``None``: every match
        (docs/registration.md, "Pairs that overlap little").
    {metric}
    {frame_turns}
    max_matches : int, default=8000
        Most matches the graph is built on; its two bit matrices take ``max_matches**2 /
        4`` bytes (16 MB at 8000).
    cap : {"index", "distance"}, default="index"
        Which matches stay when there are more than ``max_matches``: evenly spread by
        index (no region favoured), or the smallest descriptor distances (which favours
        flat, repeated regions, whose descriptors are the most alike).
    score_distance : float, default=None
        Truncation of the hypotheses' score; ``None`` is the settings'
        ``score_distance``.
    second_order_distance : float, default=None
        Length difference within which two matches count as compatible when a seed's
        set is grown (the second-order graph); ``None`` is the settings'
        ``second_order_distance`` (1 resolution).
    min_span : float, default=None
        Two matches are compatible only when their lengths (source side plus target
        side) sum to at least this: pairs close on both sides say nothing about the
        rotation. ``None`` is the settings' ``span_distance`` (3 resolutions), 0 turns
        the mask off.
    distinct_endpoints : bool, default=True
        Two matches that share a source or a target point are not compatible.
    n_seeds : int, default=5000
        Most hypotheses: the matches compatible with the most others seed them.
    seed_radius : float, default=0.0
        Seed suppression: a seed closer than this (in the source) to a better seed is
        dropped; 0 turns it off, ``None`` is the settings' ``seed_distance``.
    set_size : int, default=30
        Partners of a seed in its consensus set.
    weighted_refit : bool, default=False
        Weight the final refit's matches by their residual (a truncated quadratic)
        instead of equally.
    n_jobs : int, default=None
        Threads of the compiled graph, set building and scoring (``None``: every core,
        within ``OMP_NUM_THREADS``, ``threadpoolctl``'s limits, ``joblib.parallel_config``
        and, inside a joblib worker, one; ``-1``: all cores); the result does not
        depend on it.
    {n_hypotheses}
    """

    name = "consensus"

    _parameter_constraints = {
        "descriptor": DESCRIPTOR,
        "max_correspondence_distance": OPTIONAL_DISTANCE,
        "compatibility_distance": OPTIONAL_DISTANCE,
        "mutual_filter": ["boolean"],
        "both_directions": ["boolean"],
        "max_ratio": [None, Interval(Real, 0, None, closed="neither")],
        "n_nearest": [Interval(Integral, 1, None, closed="left")],
        "salient_share": [None, Interval(Real, 0, 1, closed="right")],
        "metric": METRIC,
        "frame_turns": FRAME_TURNS,
        "max_matches": [Interval(Integral, 3, None, closed="left")],
        "cap": [StrOptions({"index", "distance"})],
        "score_distance": OPTIONAL_DISTANCE,
        "second_order_distance": OPTIONAL_DISTANCE,
        "min_span": _OPTIONAL_LENGTH,
        "distinct_endpoints": ["boolean"],
        "n_seeds": [Interval(Integral, 1, None, closed="left")],
        "seed_radius": _OPTIONAL_LENGTH,
        "set_size": [Interval(Integral, 2, None, closed="left")],
        "weighted_refit": ["boolean"],
        "n_jobs": [None, Integral],
        "n_hypotheses": HYPOTHESES,
    }

    def __init__(
        self,
        descriptor: Any = None,
        *,
        max_correspondence_distance: float | None = None,
        compatibility_distance: float | None = None,
        mutual_filter: bool = False,
        both_directions: bool = True,
        max_ratio: float | None = None,
        n_nearest: int = 1,
        salient_share: float | None = None,
        metric: str = "euclidean",
        frame_turns: int = 1,
        max_matches: int = 8000,
        cap: str = "index",
        score_distance: float | None = None,
        second_order_distance: float | None = None,
        min_span: float | None = None,
        distinct_endpoints: bool = True,
        n_seeds: int = 5000,
        seed_radius: float | None = 0.0,
        set_size: int = 30,
        weighted_refit: bool = False,
        n_jobs: int | None = None,
        n_hypotheses: int = 1,
    ) -> None:
        self.descriptor = descriptor
        self.max_correspondence_distance = max_correspondence_distance
        self.compatibility_distance = compatibility_distance
        self.mutual_filter = mutual_filter
        self.both_directions = both_directions
        self.max_ratio = max_ratio
        self.n_nearest = n_nearest
        self.salient_share = salient_share
        self.metric = metric
        self.frame_turns = frame_turns
        self.max_matches = max_matches
        self.cap = cap
        self.score_distance = score_distance
        self.second_order_distance = second_order_distance
        self.min_span = min_span
        self.distinct_endpoints = distinct_endpoints
        self.n_seeds = n_seeds
        self.seed_radius = seed_radius
        self.set_size = set_size
        self.weighted_refit = weighted_refit
        self.n_jobs = n_jobs
        self.n_hypotheses = n_hypotheses

    def _check_params(self) -> None:
        if self.n_nearest > 1 and (self.mutual_filter or self.max_ratio is not None):
            raise ValueError(
                f"{type(self).__name__}: n_nearest={self.n_nearest} cannot be combined "
                "with mutual_filter or max_ratio (both are defined on the nearest "
                "descriptor alone)"
            )
        super()._check_params()

    def _matches(self, context: RegistrationContext) -> Correspondences:
        """The matches the graph is built on (source index, target index)."""
        src, tgt = self._describe(context)
        both_ways = self.both_directions and not self.mutual_filter
        back = None
        if both_ways and self.frame_turns == 1:
            # Both directions from one pass over the descriptors' distances.
            corr, back = correspondences_both_ways(
                src, tgt, max_ratio=self.max_ratio, k=self.n_nearest
            )
            if self.n_nearest == 1:
                self._filters_left_enough(corr)
        elif self.n_nearest > 1:
            corr = k_best_correspondences(src, tgt, self.n_nearest)
        else:
            corr = self._correspond(
                context, mutual_filter=self.mutual_filter, max_ratio=self.max_ratio
            )
            if both_ways:  # over turns
                back = turned_correspondences(tgt, self._turned(context)[0])
        if back is not None:
            both = Correspondences(
                np.concatenate([corr.pairs, back.pairs[:, ::-1]]),
                np.concatenate([corr.distances, back.distances]),
                np.concatenate([corr.ratios, back.ratios]),
            )
            _, first = np.unique(both.pairs, axis=0, return_index=True)
            corr = both.rows(np.sort(first))
        if self.salient_share is not None:
            corr = self._between_salient(context, corr)
        if len(corr) > self.max_matches:
            if self.cap == "distance":
                keep = np.sort(np.argsort(corr.distances, kind="stable")[: self.max_matches])
            else:  # evenly by index: no region is favoured for its similar descriptors
                keep = np.unique(np.linspace(0, len(corr) - 1, self.max_matches).astype(np.int64))
            corr = corr.rows(keep)
        return corr

    def _between_salient(self, context: RegistrationContext, corr: Correspondences):
        """The matches whose two points are both among the ``salient_share`` most
        distinct of their cloud (:func:`~o3d_rpointhop.registration.correspondences.salient`)."""
        src, tgt = self._describe(context)
        share = float(self.salient_share)
        keep = salient(src, share)[corr.pairs[:, 0]] & salient(tgt, share)[corr.pairs[:, 1]]
        self._enough(
            int(keep.sum()), "matches join two salient points", f"raise salient_share={share}"
        )
        return corr.rows(keep)

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        settings = context.settings
        distance = self.max_correspondence_distance or settings.ransac_distance
        corr = self._matches(context)
        first = self.compatibility_distance or settings.consensus_distance
        found = consensus(
            *self._matched(context, corr),
            compatibility_threshold=first,
            inlier_threshold=distance,
            score_threshold=self.score_distance or settings.score_distance,
            second_order_threshold=self.second_order_distance or settings.second_order_distance,
            min_span=settings.span_distance if self.min_span is None else self.min_span,
            endpoints=(corr.pairs[:, 0], corr.pairs[:, 1]) if self.distinct_endpoints else None,
            n_seeds=int(self.n_seeds),
            seed_radius=settings.seed_distance if self.seed_radius is None else self.seed_radius,
            set_size=int(self.set_size),
            weighted_refit=self.weighted_refit,
            upright=None if context.up is None else context.upright,
            n_hypotheses=int(self.n_hypotheses),
            n_threads=kernel_threads(self.n_jobs),
        )
        return self._result_of(context, found, distance, corr, hypotheses=found.n_hypotheses)
