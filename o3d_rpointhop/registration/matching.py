"""Matching as a stage of its own: :class:`Matcher`, the one owner of every option that
decides which descriptor pairs a global step sees.

A global step composes a matcher the way scikit-learn's ``RANSACRegressor`` composes
its ``estimator``: ``ConsensusGlobal(matcher=Matcher(frame_turns=4))``. The step keeps
only its own parameters (thresholds, iterations, hypotheses); ``matcher=None`` is the
step's default matcher (:meth:`GlobalStep.default_matcher
<o3d_rpointhop.registration.steps.GlobalStep.default_matcher>`). The search engine
(exact nearest descriptors, both ways, over turns) is
:mod:`~o3d_rpointhop.registration.correspondences`; this module is the policy on top.
"""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator

from .._utils.params import Interval, Options, StrOptions
from ..descriptors import FPFHTransformer
from ..descriptors.pointhop import N_TURNS_ALLOWED
from .correspondences import (
    Correspondences,
    as_features,
    correspondences_both_ways,
    find_correspondences,
    k_best_correspondences,
    salient,
    spread_indices,
    turned_correspondences,
    unit_rows,
)
from .defaults import FALLBACK_SUPPORT

__all__ = ["Matcher", "PooledMatcher"]


class Matcher(BaseEstimator):
    """Which descriptor pairs a global step registers: the nearest descriptors, filtered.

    Every source point is matched to the target point with the nearest descriptor (and,
    with ``both_directions``, every target point to its nearest source descriptor), then
    filtered (mutual, ratio test, salient points) and capped.

    Parameters
    ----------
    metric : {"euclidean", "cosine"}, default="euclidean"
        How descriptors are compared (as in scikit-learn's ``NearestNeighbors``).
        ``"cosine"``: by the angle between them (the Euclidean distance of the
        descriptors scaled to unit length,
        :func:`~o3d_rpointhop.registration.correspondences.unit_rows`), so that two
        descriptors pointing the same way match whatever their lengths; distances,
        ratios and salient points are then those of the unit descriptors
        (docs/registration.md, "Matches by cosine distance").
    mutual_filter : bool, default=False
        Keep only mutual nearest descriptors (Open3D's name for the filter).
    both_directions : bool, default=False
        Also match every target point to its nearest source descriptor (ignored with
        ``mutual_filter``, where both directions agree by definition); a pair found
        both ways is kept once.
    max_ratio : float, default=None
        Ratio-test threshold: keep a match when its descriptor distance is at most this
        share of the distance to the nearest descriptor of another point.
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
    frame_turns : {1, 2, 4}, default=1
        Match each point's descriptor against the other cloud's descriptors under
        every turn of their local frames about the normal (a half turn for 2, every
        quarter turn for 4; ``RPointHopTransformer.transform_turns``): a true
        correspondence whose frames agree only up to such a turn (on walls, floors and
        other flat parts the in-plane axes are a matter of sampling) then matches too.
        Needs a descriptor with local frames (R-PointHop); above 1 it cannot be
        combined with ``mutual_filter``, ``max_ratio`` or ``n_nearest``. Costs a Saab
        projection per turn when describing and ``frame_turns`` times the matching
        (docs/registration.md, "Frames that agree up to a turn").
    max_matches : int, default=None
        Most matches kept (``None``: all). The correspondence graph of
        :class:`~o3d_rpointhop.ConsensusGlobal` grows with the square of its matches.
    cap : {"index", "distance"}, default="index"
        Which matches stay when there are more than ``max_matches``: evenly spread by
        index (no region favoured), or the smallest descriptor distances (which favours
        flat, repeated regions, whose descriptors are the most alike).
    max_queries : int, default=None
        With ``both_directions``: each direction searches from at most this many of
        its cloud's points, spread evenly by index, each against every point of the
        other cloud (``None``: from every point). For clouds several times larger than
        the matches kept (``max_matches``), the search then costs what the kept
        matches need; the matches differ, and on rooms' screenings that moved which
        pairs were found (docs/multiway.md, "Searching from half the cap").

    See Also
    --------
    o3d_rpointhop.find_correspondences : The nearest descriptors with filters, as a function.

    Examples
    --------
    >>> import numpy as np
    >>> from o3d_rpointhop.registration import Matcher
    >>> a = np.eye(4)
    >>> Matcher(mutual_filter=True).match(a, a[::-1]).pairs[:, 1].tolist()
    [3, 2, 1, 0]
    """

    _parameter_constraints = {
        "metric": [StrOptions({"euclidean", "cosine"})],
        "mutual_filter": ["boolean"],
        "both_directions": ["boolean"],
        "max_ratio": [None, Interval(Real, 0, None, closed="neither")],
        "n_nearest": [Interval(Integral, 1, None, closed="left")],
        "salient_share": [None, Interval(Real, 0, 1, closed="right")],
        "frame_turns": [Options(Integral, set(N_TURNS_ALLOWED))],
        "max_matches": [None, Interval(Integral, 3, None, closed="left")],
        "cap": [StrOptions({"index", "distance"})],
        "max_queries": [None, Interval(Integral, 3, None, closed="left")],
    }

    def __init__(
        self,
        *,
        metric: str = "euclidean",
        mutual_filter: bool = False,
        both_directions: bool = False,
        max_ratio: float | None = None,
        n_nearest: int = 1,
        salient_share: float | None = None,
        frame_turns: int = 1,
        max_matches: int | None = None,
        cap: str = "index",
        max_queries: int | None = None,
    ) -> None:
        self.metric = metric
        self.mutual_filter = mutual_filter
        self.both_directions = both_directions
        self.max_ratio = max_ratio
        self.n_nearest = n_nearest
        self.salient_share = salient_share
        self.frame_turns = frame_turns
        self.max_matches = max_matches
        self.cap = cap
        self.max_queries = max_queries

    @property
    def unit(self) -> bool:
        """Whether descriptors are compared scaled to unit length (``metric="cosine"``)."""
        return self.metric == "cosine"

    def validate(self) -> None:
        """Check every parameter and how they combine.

        Raises
        ------
        ValueError
            Naming the first bad parameter or combination.
        """
        self._validate_params()
        exclusive = self.mutual_filter or self.max_ratio is not None
        if self.n_nearest > 1 and exclusive:
            raise ValueError(
                f"Matcher: n_nearest={self.n_nearest} cannot be combined with "
                "mutual_filter or max_ratio (both are defined on the nearest descriptor "
                "alone)"
            )
        if self.max_queries is not None and not (
            self.both_directions and not self.mutual_filter and self.frame_turns == 1
        ):
            raise ValueError(
                "Matcher: max_queries needs both_directions=True, without mutual_filter "
                "or frame_turns (it thins the queries of the one pass that matches both "
                "ways)"
            )
        if self.frame_turns > 1 and (exclusive or self.n_nearest > 1):
            raise ValueError(
                f"Matcher: frame_turns={self.frame_turns} cannot be combined with "
                "mutual_filter, max_ratio or n_nearest > 1 (matches over turns take each "
                "point's nearest turned descriptor alone)"
            )

    def match(self, source_features, target_features) -> Correspondences:
        """The matches between two clouds' descriptors.

        Parameters
        ----------
        source_features, target_features : array-like
            One row per point, ``(n, d)`` and ``(m, d)`` (or Open3D ``Feature``); with
            ``frame_turns`` above 1 the descriptors under every turn, ``(frame_turns, n,
            d)`` and ``(frame_turns, m, d)`` (``RPointHopTransformer.transform_turns``),
            turn 0 being the plain descriptors.

        Returns
        -------
        Correspondences
            ``(source index, target index)`` rows with their descriptor distances and
            ratios.

        Raises
        ------
        ValueError
            For bad parameters, descriptors of the wrong shape, or fewer than 3 matches
            left by the filters.
        """
        self.validate()
        dims = 2 if self.frame_turns == 1 else 3
        arrays = []
        for name, value in (("source", source_features), ("target", target_features)):
            if dims == 2:  # shape, type and finiteness as every match function checks them
                array = as_features(value, f"{name}_features")
            else:
                array = np.asarray(value)
                if array.ndim != 3 or array.shape[0] != self.frame_turns:
                    raise ValueError(
                        f"{name}_features must be ({self.frame_turns}, n, d) for "
                        f"frame_turns={self.frame_turns}, got shape {array.shape}"
                    )
                if not np.issubdtype(array.dtype, np.floating):
                    array = array.astype(np.float64)
                if not np.isfinite(array).all():
                    raise ValueError(f"{name}_features hold NaN or infinite values")
            arrays.append(unit_rows(array) if self.unit else array)
        return self._match(*arrays)

    def _match(self, src: np.ndarray, tgt: np.ndarray, who: str = "Matcher") -> Correspondences:
        """:meth:`match` on checked descriptors already scaled for the metric (what a
        global step passes: the context caches them once per registration); ``who``
        names the caller in the errors."""
        turned = self.frame_turns > 1
        plain_src, plain_tgt = (src[0], tgt[0]) if turned else (src, tgt)
        both_ways = self.both_directions and not self.mutual_filter
        back = None
        if both_ways and not turned:
            # Both directions from one pass over the descriptors' distances.
            corr, back = correspondences_both_ways(
                src, tgt, max_ratio=self.max_ratio, k=self.n_nearest, max_queries=self.max_queries
            )
            if self.n_nearest == 1:
                _enough(who, len(corr), "correspondences survived the filters", _RELAX)
        elif self.n_nearest > 1:
            corr = k_best_correspondences(src, tgt, self.n_nearest)
        elif turned:
            corr = turned_correspondences(plain_src, tgt)
            _enough(who, len(corr), "correspondences survived the filters", _RELAX)
            if both_ways:
                back = turned_correspondences(plain_tgt, src)
        else:
            corr = find_correspondences(
                src, tgt, mutual_filter=self.mutual_filter, max_ratio=self.max_ratio
            )
            _enough(who, len(corr), "correspondences survived the filters", _RELAX)
        if back is not None:
            both = Correspondences(
                np.concatenate([corr.pairs, back.pairs[:, ::-1]]),
                np.concatenate([corr.distances, back.distances]),
                np.concatenate([corr.ratios, back.ratios]),
            )
            _, first = np.unique(both.pairs, axis=0, return_index=True)
            corr = both.rows(np.sort(first))
        if self.salient_share is not None:
            share = float(self.salient_share)
            keep = (
                salient(plain_src, share)[corr.pairs[:, 0]]
                & salient(plain_tgt, share)[corr.pairs[:, 1]]
            )
            _enough(
                who,
                int(keep.sum()),
                "matches join two salient points",
                f"raise the matcher's salient_share={share}",
            )
            corr = corr.rows(keep)
        if self.max_matches is not None and len(corr) > self.max_matches:
            if self.cap == "distance":
                keep = np.sort(np.argsort(corr.distances, kind="stable")[: self.max_matches])
            else:  # evenly by index: no region is favoured for its similar descriptors
                keep = spread_indices(len(corr), self.max_matches)
            corr = corr.rows(keep)
        return corr


_RELAX = "relax the matcher's mutual_filter / max_ratio"


def _enough(who: str, count: int, what: str, remedy: str) -> None:
    """Refuse fewer than 3 matches (a rigid motion needs 3), naming the caller, what was
    counted and what to relax."""
    if count < 3:
        raise ValueError(f"{who}: only {count} {what}; at least 3 are needed ({remedy})")


class PooledMatcher(BaseEstimator):
    """The matches of several descriptors pooled into one set for one global step.

    Each part matches both clouds with its own descriptor and :class:`Matcher`; a pair
    of points found by several parts is kept once, as the first part found it. A true
    correspondence that one descriptor misses (R-PointHop's frames on a flat wall, an
    FPFH histogram that repeats) may be another's, so a consensus over the pool finds
    more pairs that overlap little than either part alone (docs/low_overlap.md,
    "Pooled matches").

    With ``combine="hypotheses"`` the parts are kept apart one step further: the
    consensus runs on each part's matches alone and its hypotheses, every part's, are
    verified together (:class:`~o3d_rpointhop.ConsensusGlobal` only). Each descriptor
    then finds what it would find alone, and the overlap and free-space checks choose:
    the first part's best hypothesis is the step's own choice, which another replaces
    only when it scores 30 % higher (docs/low_overlap.md, "Pooled hypotheses").

    With ``combine="fallback"`` the first part runs alone, as without the others, and
    the others are asked only when its estimate explains less than ``min_support`` of
    its matches (a pose its matches barely single out, near the results the command
    line would not trust): then their consensus runs too and every hypothesis is verified
    together, as with ``"hypotheses"``. Pairs that overlap well pay for one
    descriptor; the ones that overlap little get the second (docs/low_overlap.md,
    "FPFH as a fallback").

    Parameters
    ----------
    parts : list of (str, transformer or None, Matcher)
        Each part's name, descriptor (``None``: the step's own, else the pipeline's)
        and matcher. Names are distinct; two parts may share a descriptor.
    combine : {"matches", "hypotheses", "fallback"}, default="matches"
        What is pooled: the parts' matches, for one consensus (any global step), the
        hypotheses of one consensus per part (:class:`~o3d_rpointhop.ConsensusGlobal`),
        or those hypotheses only when the first part's own estimate is weak (also the
        consensus only).
    min_support : float, default=0.015
        With ``combine="fallback"``: the least share of the first part's matches its
        estimate must explain (within the step's inlier distance) for the others not
        to be asked (:data:`~o3d_rpointhop.registration.defaults.FALLBACK_SUPPORT`,
        chosen on the training scenes; the command line trusts a result from 0.01).

    Examples
    --------
    >>> from o3d_rpointhop import ConsensusGlobal, FPFHTransformer
    >>> from o3d_rpointhop.registration import Matcher, PooledMatcher
    >>> pooled = PooledMatcher(
    ...     [
    ...         ("model", None, Matcher(both_directions=True, max_matches=4000)),
    ...         ("fpfh", FPFHTransformer(), Matcher(both_directions=True, max_matches=2000)),
    ...     ]
    ... )
    >>> step = ConsensusGlobal(matcher=pooled)
    """

    def __init__(
        self, parts: list, combine: str = "matches", min_support: float = FALLBACK_SUPPORT
    ) -> None:
        self.parts = parts
        self.combine = combine
        self.min_support = min_support

    def validate(self) -> None:
        """Check the parts and each part's matcher.

        Raises
        ------
        ValueError
            Naming the first bad part.
        """
        if not isinstance(self.parts, (list, tuple)) or not self.parts:
            raise ValueError(f"PooledMatcher: parts must be a non-empty list, got {self.parts!r}")
        if self.combine not in ("matches", "hypotheses", "fallback"):
            raise ValueError(
                "PooledMatcher: combine must be 'matches', 'hypotheses' or 'fallback', "
                f"got {self.combine!r}"
            )
        support = self.min_support
        if isinstance(support, bool) or not isinstance(support, Real) or not 0 <= support <= 1:
            raise ValueError(f"PooledMatcher: min_support must be in [0, 1], got {support!r}")
        names = set()
        for part in self.parts:
            if not (isinstance(part, tuple) and len(part) == 3):
                raise ValueError(
                    f"PooledMatcher: each part is (name, descriptor or None, Matcher), got {part!r}"
                )
            name, descriptor, matcher = part
            if not isinstance(name, str) or name in names:
                raise ValueError(
                    f"PooledMatcher: part names must be distinct strings, got {name!r}"
                )
            names.add(name)
            if descriptor is not None and not hasattr(descriptor, "transform"):
                raise ValueError(
                    f"PooledMatcher: part {name!r}'s descriptor has no transform: {descriptor!r}"
                )
            if not isinstance(matcher, Matcher):
                raise ValueError(f"PooledMatcher: part {name!r}'s matcher is not a Matcher")
            matcher.validate()

    @classmethod
    def with_fpfh(
        cls,
        matcher: Matcher | None = None,
        fpfh: Any = None,
        fpfh_matcher: Matcher | None = None,
        combine: str = "hypotheses",
    ) -> PooledMatcher:
        """The step's own descriptor's matches beside FPFH's: the pooled hypotheses of
        docs/low_overlap.md ("Pooled hypotheses") with the defaults.

        Parameters
        ----------
        matcher : Matcher, default=None
            The own descriptor's matcher (the part named ``"model"``); ``None``:
            nearest descriptors both ways, at most 4000 matches (the consensus's
            default).
        fpfh : FPFHTransformer, default=None
            FPFH's descriptor (the part named ``"fpfh"``); ``None``: its defaults.
        fpfh_matcher : Matcher, default=None
            FPFH's matcher; ``None``: nearest both ways, at most 4000 matches.
        combine : {"matches", "hypotheses", "fallback"}, default="hypotheses"
            As :class:`PooledMatcher` takes it.

        Returns
        -------
        PooledMatcher
            Parts ``"model"`` and ``"fpfh"``.

        Examples
        --------
        >>> from o3d_rpointhop import ConsensusGlobal, PooledMatcher
        >>> step = ConsensusGlobal(matcher=PooledMatcher.with_fpfh())
        >>> [name for name, _, _ in step.matcher.parts]
        ['model', 'fpfh']
        """
        own = Matcher(both_directions=True, max_matches=4000) if matcher is None else matcher
        if fpfh_matcher is None:
            fpfh_matcher = Matcher(both_directions=True, max_matches=4000)
        fpfh = FPFHTransformer() if fpfh is None else fpfh
        return cls([("model", None, own), ("fpfh", fpfh, fpfh_matcher)], combine=combine)

    def descriptors(self, own: Any) -> list[tuple[Any, Matcher]]:
        """Each part's descriptor (``own`` for ``None``) and matcher, in order."""
        return [(own if d is None else d, m) for _, d, m in self.parts]

    @staticmethod
    def pool(found: list[Correspondences]) -> Correspondences:
        """Several parts' matches as one set: every pair once, where it first appears
        (parts in order, each part's rows in its order)."""
        both = Correspondences(
            np.concatenate([c.pairs for c in found]),
            np.concatenate([c.distances for c in found]),
            np.concatenate([c.ratios for c in found]),
        )
        _, first = np.unique(both.pairs, axis=0, return_index=True)
        return both.rows(np.sort(first))
