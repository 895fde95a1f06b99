"""What the global steps share: their descriptor, their matches and the constraints of
their parameters."""

from __future__ import annotations

import inspect
from numbers import Integral, Real

import numpy as np

from ..._utils.params import HasMethods, Interval
from ..._utils.threads import kernel_threads
from ..context import RegistrationContext
from ..correspondences import Correspondences
from ..matching import Matcher, PooledMatcher
from ..result import StepResult
from ._base import RegistrationStep
from ._verification import verify

__all__ = [
    "COUNT",
    "DESCRIPTOR",
    "GlobalStep",
    "HYPOTHESES",
    "MATCHER",
    "MATCHER_DOC",
    "N_HYPOTHESES_DOC",
    "with_shared_docs",
]

#: The constraint of a step's own descriptor: ``None`` (the pipeline's) or a transformer.
DESCRIPTOR = [None, HasMethods(["transform"])]
#: The constraint of a count of matches: at least 3, or a share in (0, 1].
COUNT = [Interval(Integral, 3, None, closed="left"), Interval(Real, 0, 1, closed="right")]
#: The constraint of a count of hypotheses verified by overlap.
HYPOTHESES = [Interval(Integral, 1, None, closed="left")]

#: The constraint of a step's matcher: ``None`` (the step's default), a Matcher, or a
#: PooledMatcher (several descriptors' matches pooled).
MATCHER = [None, Matcher, PooledMatcher]

#: The docstring of ``matcher``, shared by the global steps.
MATCHER_DOC = """matcher : Matcher, default=None
        Which descriptor pairs the step registers
        (:class:`~o3d_rpointhop.registration.Matcher`: metric, mutual and ratio
        filters, both directions, k nearest, salient points, frame turns, cap), or a
        :class:`~o3d_rpointhop.registration.PooledMatcher` pooling the matches of
        several descriptors. ``None``: the step's :meth:`default_matcher`, {default}."""

#: The docstring of ``n_hypotheses``, shared by the steps that have it.
N_HYPOTHESES_DOC = """n_hypotheses : {kind}, default={default}
        How many of the step's best distinct hypotheses are verified by overlap: each
        is refined by a short point-to-plane ICP on the global clouds and scored by
        how much of both clouds it brings together (inliers both ways where the
        normals agree, each weighted by its distance) times the matches it explains;
        one ranked below the step's own choice replaces it only when it scores 30 %
        higher. The step's ``info`` then holds every score, the chosen hypothesis and
        its ``margin`` over its best distinct rival (``result.margin``; one under
        ``1 - AMBIGUITY_RATIO`` makes the result ``ambiguous``). 1: the step's own
        ranking decides, nothing is verified (docs/registration.md, "Pairs that
        overlap little")."""


def with_shared_docs(cls: type) -> type:
    """Write the shared parameter texts (``{n_hypotheses}``, ``{matcher}``) into a global
    step's docstring (absent under ``python -OO``)."""
    if cls.__doc__:
        default = repr(cls.default_matcher()).replace("\n", "").replace("  ", "")
        own = inspect.signature(cls.__init__).parameters.get("n_hypotheses")
        hypotheses = 1 if own is None else own.default
        cls.__doc__ = cls.__doc__.replace(
            "{n_hypotheses}",
            N_HYPOTHESES_DOC.format(
                kind='int or "auto"' if isinstance(hypotheses, str) else "int",
                default=f'"{hypotheses}"' if isinstance(hypotheses, str) else hypotheses,
            ),
        ).replace("{matcher}", MATCHER_DOC.format(default=f"``{default}``"))
    return cls


class GlobalStep(RegistrationStep):
    """Base of the global steps: the descriptor they match with and their matcher.

    A global step ignores the incoming transformation. Its descriptor is its own
    ``descriptor`` parameter, else the context's (the pipeline's), else
    :func:`~o3d_rpointhop.registration.defaults.default_descriptor`; descriptors are
    computed once per registration and descriptor (``context.features``).
    """

    kind = "global"
    #: Free-space limit of the hypotheses' verification (a step that has the parameter
    #: sets it; :func:`~._verification.verify`).
    max_violation: float | None = None
    #: Threads of the verification (a step that has the parameter sets it; ``None``:
    #: every core, as :func:`~o3d_rpointhop._utils.threads.kernel_threads` reads it).
    n_jobs: int | None = None

    @classmethod
    def default_matcher(cls) -> Matcher:
        """The matcher the step uses when its ``matcher`` is ``None``: nearest
        descriptors source to target, unfiltered."""
        return Matcher()

    def _matcher(self) -> Matcher:
        return self.default_matcher() if self.matcher is None else self.matcher

    def _parts(self) -> list[tuple]:
        """Each descriptor the step matches with (``None``: the pipeline's) and its
        matcher: one, or a pooled matcher's parts."""
        matcher = self._matcher()
        if isinstance(matcher, PooledMatcher):
            return matcher.descriptors(self.descriptor)
        return [(self.descriptor, matcher)]

    def _descriptors(self) -> tuple:
        """The descriptors prepared before the steps run: every part's, but a fallback's
        first only (the others are described when asked)."""
        parts = self._parts()
        matcher = self._matcher()
        if isinstance(matcher, PooledMatcher) and matcher.combine == "fallback":
            parts = parts[:1]
        return tuple((descriptor, matcher.frame_turns) for descriptor, matcher in parts)

    #: Whether the step can run once per part of a matcher that pools hypotheses
    #: (``PooledMatcher(..., combine="hypotheses")`` or ``"fallback"``).
    pools_hypotheses = False

    def _check_params(self) -> None:
        matcher = self._matcher()
        matcher.validate()
        if self._pooled_hypotheses() and not self.pools_hypotheses:
            raise ValueError(
                f"{type(self).__name__} pools matches only: a PooledMatcher with "
                f"combine={matcher.combine!r} needs ConsensusGlobal"
            )

    def _pooled_hypotheses(self) -> bool:
        """Whether the matcher pools the hypotheses of one run per part (always, or as
        a fallback)."""
        matcher = self._matcher()
        return isinstance(matcher, PooledMatcher) and matcher.combine != "matches"

    def _part_matches(
        self, context: RegistrationContext, parts: slice = slice(None)
    ) -> list[Correspondences]:
        """Each part's matches (source index, target index), of the parts ``parts``
        selects: its matcher on both clouds' descriptors as it compares them (under
        every turn, ``(frame_turns, n, width)``, or plain; scaled to unit length for the
        cosine metric: the context computes and scales them once per registration)."""
        return [
            matcher._match(
                *(
                    context.features(descriptor, which, matcher.frame_turns, matcher.unit)
                    for which in ("source", "target")
                ),
                who=type(self).__name__,
            )
            for descriptor, matcher in self._parts()[parts]
        ]

    def _matches(self, context: RegistrationContext) -> Correspondences:
        """The step's matches: :meth:`_part_matches`, pooled when there are several."""
        found = self._part_matches(context)
        return found[0] if len(found) == 1 else PooledMatcher.pool(found)

    @staticmethod
    def _matched(context: RegistrationContext, corr: Correspondences):
        """The matched points of ``corr`` on the global clouds (centred frame): the
        source's and the target's, row by row."""
        src, tgt = (np.asarray(c.points) for c in context.clouds("global"))
        return src[corr.pairs[:, 0]], tgt[corr.pairs[:, 1]]

    def _chosen(
        self,
        context: RegistrationContext,
        hypotheses: np.ndarray,
        estimate: np.ndarray,
        distance: float,
        corr: Correspondences,
        known=None,
    ) -> tuple[np.ndarray, dict, object]:
        """The estimate the step returns, what its choice reports, and the verification
        (None without one): with several hypotheses (best first, ``estimate`` the
        first), the winner of their verification (:func:`~._verification.verify`,
        against the step's matches ``corr``; ``known``: a verification of the first
        ones to build on) as the step estimated it (the short ICP only scores it: the
        steps after it refine; the step's own choice, kept, is the result
        ``n_hypotheses=1`` gives); else ``estimate``."""
        if len(hypotheses) < 2:
            return estimate, {}, None
        matched = GlobalStep._matched(context, corr)
        threads = kernel_threads(self.n_jobs)
        check = verify(context, hypotheses, distance, matched, self.max_violation, threads, known)
        info = {
            "hypothesis_scores": [round(float(s), 6) for s in check.scores],
            "chosen_hypothesis": check.best,
            "margin": check.margin,
        }
        return hypotheses[check.best], info, check

    def _result_of(
        self,
        context: RegistrationContext,
        found,
        distance: float,
        corr: Correspondences,
        known=None,
        **info,
    ) -> tuple[StepResult, object]:
        """The step's result from what its estimator ``found`` (``hypotheses`` best first,
        ``transformation``, the matches' ``inliers``): the choice among the hypotheses
        (:meth:`_chosen`, building on the verification ``known``), measured
        (:meth:`_measured`) with the step's own ``info``; and the verification."""
        estimate, chosen, check = self._chosen(
            context, found.hypotheses, found.transformation, distance, corr, known
        )
        result = self._measured(
            context,
            self.name,
            estimate,
            distance,
            corr,
            inlier_matches=int(found.inliers.sum()),
            **info,
            **chosen,
        )
        return result, check

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
        a, b = GlobalStep._matched(context, corr)
        moved = a @ transformation[:3, :3].T + transformation[:3, 3]
        check.match_inliers = ((moved - b) ** 2).sum(axis=1) < distance * distance
        if check.info.get("chosen_hypothesis", 0):  # the step's count was of its own choice
            check.info["inlier_matches"] = int(check.match_inliers.sum())
        check.matches = np.stack([a, b], axis=1) + context.origin
        return check
