"""What the global steps share: their descriptor, their matches and the constraints of
their parameters."""

from __future__ import annotations

from numbers import Integral, Real

import numpy as np

from ..._utils.params import HasMethods, Interval, Options, StrOptions
from ...descriptors.pointhop import N_TURNS_ALLOWED
from ..context import RegistrationContext
from ..correspondences import Correspondences, find_correspondences, turned_correspondences
from ..result import StepResult
from ._base import RegistrationStep
from ._hypotheses import verify

__all__ = [
    "COUNT",
    "DESCRIPTOR",
    "FRAME_TURNS",
    "FRAME_TURNS_DOC",
    "GlobalStep",
    "HYPOTHESES",
    "METRIC",
    "METRIC_DOC",
    "N_HYPOTHESES_DOC",
    "with_shared_docs",
]

#: The constraint of a step's own descriptor: ``None`` (the pipeline's) or a transformer.
DESCRIPTOR = [None, HasMethods(["transform"])]
#: The constraint of a count of matches: at least 3, or a share in (0, 1].
COUNT = [Interval(Integral, 3, None, closed="left"), Interval(Real, 0, 1, closed="right")]
#: The constraint of a count of hypotheses verified by overlap.
HYPOTHESES = [Interval(Integral, 1, None, closed="left")]

#: The constraint of the turns of the local frames matched over.
FRAME_TURNS = [Options(Integral, set(N_TURNS_ALLOWED))]

#: The constraint of the distance descriptors are matched by.
METRIC = [StrOptions({"euclidean", "cosine"})]

#: The docstring of ``metric``, shared by the steps that have it.
METRIC_DOC = """metric : {"euclidean", "cosine"}, default="euclidean"
        How descriptors are compared when they are matched (as in scikit-learn's
        ``NearestNeighbors``). ``"cosine"``: by the angle between them (the
        Euclidean distance of the descriptors scaled to unit length,
        :func:`~o3d_rpointhop.registration.correspondences.unit_rows`), so that two
        descriptors pointing the same way match whatever their lengths; distances,
        ratios and salient points are then those of the unit descriptors
        (docs/registration.md, "Matches by cosine distance")."""

#: The docstring of ``frame_turns``, shared by the steps that have it.
FRAME_TURNS_DOC = """frame_turns : {1, 2, 4}, default=1
        Match each point's descriptor against the other cloud's descriptors under
        every turn of their local frames about the normal (a half turn for 2, every
        quarter turn for 4; ``RPointHopTransformer.transform_turns``): a true
        correspondence whose frames agree only up to such a turn (on walls, floors
        and other flat parts the in-plane axes are a matter of sampling) then
        matches too. Needs a descriptor with local frames (R-PointHop); above 1 it
        cannot be combined with ``mutual_filter`` or ``max_ratio`` (nor, for the
        consensus, ``n_nearest``). Costs a Saab projection per turn when describing
        and ``frame_turns`` times the matching (docs/registration.md, "Frames that
        agree up to a turn")."""

#: The docstring of ``n_hypotheses``, shared by the steps that have it.
N_HYPOTHESES_DOC = """n_hypotheses : int, default={default}
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
    """Write the shared parameter texts (``{n_hypotheses}``, ``{frame_turns}``,
    ``{metric}``) into a global step's docstring (absent under ``python -OO``)."""
    if cls.__doc__:
        cls.__doc__ = (
            cls.__doc__.replace("{n_hypotheses}", N_HYPOTHESES_DOC.format(default=1))
            .replace("{frame_turns}", FRAME_TURNS_DOC)
            .replace("{metric}", METRIC_DOC)
        )
    return cls


class GlobalStep(RegistrationStep):
    """Base of the global steps: the descriptor they match with and their matches.

    A global step ignores the incoming transformation. Its descriptor is its own
    ``descriptor`` parameter, else the context's (the pipeline's), else
    :func:`~o3d_rpointhop.registration.defaults.default_descriptor`; descriptors are
    computed once per registration and descriptor (``context.features``).
    """

    kind = "global"

    def _descriptors(self) -> tuple:
        return ((self.descriptor, self._n_turns()),)

    def _n_turns(self) -> int:
        """Turns of the local frames the step matches over (``frame_turns``; 1: none)."""
        return int(getattr(self, "frame_turns", 1))

    def _check_params(self) -> None:
        if self._n_turns() > 1 and (
            self.mutual_filter or self.max_ratio is not None or getattr(self, "n_nearest", 1) > 1
        ):
            raise ValueError(
                f"{type(self).__name__}: frame_turns={self.frame_turns} cannot be "
                "combined with mutual_filter, max_ratio or n_nearest > 1 (matches over "
                "turns take each point's nearest turned descriptor alone)"
            )

    def _turned(self, context: RegistrationContext) -> tuple[np.ndarray, np.ndarray]:
        """Both clouds' descriptors under every turn, ``(frame_turns, n, width)`` each
        (computed before the plain ones, which are their turn 0)."""
        n_turns, unit = self._n_turns(), self._unit()
        return (
            context.features(self.descriptor, "source", n_turns, unit),
            context.features(self.descriptor, "target", n_turns, unit),
        )

    def _describe(self, context: RegistrationContext) -> tuple[np.ndarray, np.ndarray]:
        # None: the context's descriptors (prepared, or its descriptor's).
        unit = self._unit()
        return (
            context.features(self.descriptor, "source", unit=unit),
            context.features(self.descriptor, "target", unit=unit),
        )

    def _unit(self) -> bool:
        """Whether the step compares its descriptors scaled to unit length (``metric=
        "cosine"``; the context scales them once per registration)."""
        return getattr(self, "metric", "euclidean") == "cosine"

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
    ) -> tuple[np.ndarray, dict]:
        """The estimate the step returns, and what its choice reports: with several
        hypotheses (best first, ``estimate`` the first), the winner of their
        verification (:func:`~._hypotheses.verify`, against the step's matches
        ``corr``) as the step estimated it (the short ICP only scores it: the steps
        after it refine; the step's own choice, kept, is the result ``n_hypotheses=1``
        gives); else ``estimate``."""
        if len(hypotheses) < 2:
            return estimate, {}
        check = verify(context, hypotheses, distance, GlobalStep._matched(context, corr))
        info = {
            "hypothesis_scores": [round(float(s), 6) for s in check.scores],
            "chosen_hypothesis": check.best,
            "margin": check.margin,
        }
        return hypotheses[check.best], info

    def _result_of(
        self,
        context: RegistrationContext,
        found,
        distance: float,
        corr: Correspondences,
        **info,
    ) -> StepResult:
        """The step's result from what its estimator ``found`` (``hypotheses`` best first,
        ``transformation``, the matches' ``inliers``): the choice among the hypotheses
        (:meth:`_chosen`), measured (:meth:`_measured`) with the step's own ``info``."""
        estimate, chosen = self._chosen(
            context, found.hypotheses, found.transformation, distance, corr
        )
        return self._measured(
            context,
            self.name,
            estimate,
            distance,
            corr,
            inlier_matches=int(found.inliers.sum()),
            **info,
            **chosen,
        )

    def _correspond(self, context: RegistrationContext, **filters) -> Correspondences:
        """Every source point's nearest target descriptor, filtered (``filters``), or
        over every turn of the target's frames (``frame_turns``)."""
        if self._n_turns() > 1:
            src_turns, tgt_turns = self._turned(context)
            corr = turned_correspondences(src_turns[0], tgt_turns)
        else:
            src, tgt = self._describe(context)
            corr = find_correspondences(src, tgt, **filters)
        return self._filters_left_enough(corr)

    def _filters_left_enough(self, corr: Correspondences) -> Correspondences:
        """``corr``, refused (:meth:`_enough`) when the filters left fewer than 3."""
        self._enough(
            len(corr),
            "correspondences survived the filters",
            "relax mutual_filter / max_ratio / top_k",
        )
        return corr

    def _enough(self, count: int, what: str, remedy: str) -> None:
        """Refuse fewer than 3 matches (a rigid motion needs 3), naming the step, what
        was counted and what to relax."""
        if count < 3:
            raise ValueError(
                f"{type(self).__name__}: only {count} {what}; at least 3 are needed ({remedy})"
            )

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
