"""Fast Global Registration on descriptor matches, with FGR's tuple test."""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any

import numpy as np
import open3d as o3d

from ..._utils.params import Interval
from ..._utils.threads import repeatable_open3d
from ..context import RegistrationContext
from ..matching import Matcher
from ..result import StepResult
from ._base import OPTIONAL_DISTANCE
from ._edges import consistent_edges
from ._global import DESCRIPTOR, MATCHER, GlobalStep, with_shared_docs

__all__ = ["FGRGlobal", "tuple_test"]

reg = o3d.pipelines.registration


@with_shared_docs
class FGRGlobal(GlobalStep):
    """Fast Global Registration (Zhou et al., 2016) on descriptor matches, run by Open3D.

    Matches are the matcher's, mutual nearest descriptors by default (FGR's own filter); with
    ``tuple_test`` they also pass FGR's tuple test, here vectorised and seeded: random
    triples of matches are kept when their source and target triangles have edge
    lengths within ``tuple_scale`` of each other. The surviving matches go to Open3D's
    ``registration_fgr_based_on_correspondence``.

    Parameters
    ----------
    descriptor : transformer, default=None
    {matcher}
    max_correspondence_distance : float, default=None
        Open3D's ``maximum_correspondence_distance``; ``None`` is the settings'
        ``fgr_distance`` (1.0 x ``voxel_size``).
    tuple_test : bool, default=True
    tuple_scale : float, default=0.95
    max_iteration : int, default=64
        Open3D's ``iteration_number``.
    """

    name = "fgr"

    _parameter_constraints = {
        "descriptor": DESCRIPTOR,
        "matcher": MATCHER,
        "max_correspondence_distance": OPTIONAL_DISTANCE,
        "tuple_test": ["boolean"],
        "tuple_scale": [Interval(Real, 0, 1, closed="neither")],
        "max_iteration": [Interval(Integral, 1, None, closed="left")],
    }

    def __init__(
        self,
        descriptor: Any = None,
        *,
        matcher: Matcher | None = None,
        max_correspondence_distance: float | None = None,
        tuple_test: bool = True,
        tuple_scale: float = 0.95,
        max_iteration: int = 64,
    ) -> None:
        self.descriptor = descriptor
        self.matcher = matcher
        self.max_correspondence_distance = max_correspondence_distance
        self.tuple_test = tuple_test
        self.tuple_scale = tuple_scale
        self.max_iteration = max_iteration

    @classmethod
    def default_matcher(cls) -> Matcher:
        """Mutual nearest descriptors (FGR's own filter)."""
        return Matcher(mutual_filter=True)

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        distance = self.max_correspondence_distance or context.settings.fgr_distance
        corr = self._matches(context)
        pairs = corr.pairs
        if self.tuple_test:
            pairs = tuple_test(
                np.asarray(context.global_cloud("source").points),
                np.asarray(context.global_cloud("target").points),
                pairs,
                scale=float(self.tuple_scale),
                seed=context.random_state,
            )
        option = reg.FastGlobalRegistrationOption(
            maximum_correspondence_distance=distance, iteration_number=int(self.max_iteration)
        )
        with repeatable_open3d():
            o3d.utility.random.seed(context.random_state)
            result = reg.registration_fgr_based_on_correspondence(
                context.global_cloud("source"),
                context.global_cloud("target"),
                o3d.utility.Vector2iVector(pairs.astype(np.int32)),
                option,
            )
        # FGR reports no inliers of its own: measure them like every other step.
        return self._measured(
            context,
            self.name,
            np.array(result.transformation),
            distance,
            corr,
            after_tuple_test=len(pairs),
        )


def tuple_test(
    source: np.ndarray,
    target: np.ndarray,
    pairs: np.ndarray,
    scale: float = 0.95,
    n_tuples: int | None = None,
    seed: int = 0,
) -> np.ndarray:
    """FGR's tuple test: keep matches that belong to a length-consistent random triple.

    Parameters
    ----------
    source, target : ndarray of shape (n, 3)
    pairs : ndarray of shape (m, 2)
    scale : float
        Each of a triple's three edges must satisfy ``scale < |s_i - s_j| / |t_i - t_j| <
        1 / scale``.
    n_tuples : int, default=None
        Triples drawn; ``None`` is ``100 * m`` (FGR: up to 100 per match).

    Returns
    -------
    pairs : ndarray of shape (m', 2)
        The matches in at least one consistent triple (all of them if fewer than 3).
    """
    m = len(pairs)
    if m < 3:
        return pairs
    rng = np.random.default_rng(seed)
    n_tuples = 100 * m if n_tuples is None else n_tuples
    triples = rng.integers(0, m, size=(n_tuples, 3))
    matched = np.ascontiguousarray(source[pairs[:, 0]], dtype=np.float64)
    partners = np.ascontiguousarray(target[pairs[:, 1]], dtype=np.float64)
    ok = consistent_edges(triples, matched, partners, float(scale))
    keep = np.unique(triples[ok])
    return pairs[keep] if keep.size >= 3 else pairs
