"""Global estimators: a transformation from descriptor matches, with no starting guess.

:class:`SVDGlobal` is the R-PointHop paper's one-shot estimate, :class:`RANSACGlobal`
a vectorised, seeded RANSAC, :class:`FGRGlobal` Open3D's Fast Global Registration on
the matches (with FGR's tuple test, :func:`tuple_test`). Each works on the context's
global clouds and their descriptors.
"""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any

import numpy as np
import open3d as o3d
from sklearn.utils._param_validation import HasMethods, Interval

from ..correspondences import Correspondences, count_of, find_correspondences
from ..transforms import rigid_transform
from ._ransac import ransac
from .context import RegistrationContext
from .steps import OPTIONAL_DISTANCE, RegistrationStep, StepResult, evaluate, repeatable_open3d

__all__ = ["SVDGlobal", "RANSACGlobal", "FGRGlobal", "tuple_test"]

reg = o3d.pipelines.registration

_DESCRIPTOR = [None, HasMethods(["transform"])]
_COUNT = [Interval(Integral, 3, None, closed="left"), Interval(Real, 0, 1, closed="right")]


class _GlobalStep(RegistrationStep):
    kind = "global"

    def _describe(self, context: RegistrationContext) -> tuple[np.ndarray, np.ndarray]:
        descriptor = self.descriptor if self.descriptor is not None else context.descriptor
        if descriptor is None:
            from ..rpointhop import default_descriptor

            descriptor = context.descriptor = default_descriptor()
        return context.features(descriptor, "source"), context.features(descriptor, "target")

    def _correspond(self, context: RegistrationContext, **filters) -> Correspondences:
        src, tgt = self._describe(context)
        corr = find_correspondences(src, tgt, **filters)
        if len(corr) < 3:
            raise ValueError(
                f"{type(self).__name__}: only {len(corr)} correspondences survived the "
                "filters; at least 3 are needed (relax mutual_filter / max_ratio / top_k)"
            )
        return corr


class SVDGlobal(_GlobalStep):
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
    mutual_filter : bool, default=False
    """

    _parameter_constraints = {
        "descriptor": _DESCRIPTOR,
        "top_k": _COUNT,
        "top_k_ratio": _COUNT,
        "mutual_filter": ["boolean"],
    }

    def __init__(
        self,
        descriptor: Any = None,
        top_k: int | float = 0.25,
        top_k_ratio: int | float = 0.125,
        mutual_filter: bool = False,
    ) -> None:
        self.descriptor = descriptor
        self.top_k = top_k
        self.top_k_ratio = top_k_ratio
        self.mutual_filter = mutual_filter

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        n = len(context.global_cloud("source").points)
        top_k = count_of(self.top_k, n, minimum=3)
        top_k_ratio = min(top_k, count_of(self.top_k_ratio, n, minimum=3))
        corr = self._correspond(
            context, mutual_filter=self.mutual_filter, top_k=top_k, top_k_ratio=top_k_ratio
        )
        src = np.asarray(context.global_cloud("source").points)[corr.pairs[:, 0]]
        tgt = np.asarray(context.global_cloud("target").points)[corr.pairs[:, 1]]
        estimate = rigid_transform(src, tgt)
        distance = context.settings.evaluation_distance
        check = evaluate(context, estimate, distance, which="global")
        return StepResult(
            name="svd",
            transformation=estimate,
            fitness=check.fitness,
            inlier_rmse=check.inlier_rmse,
            correspondence_set=corr.pairs,
            info={"matches_used": len(corr), "max_correspondence_distance": distance},
            distance=distance,
        )


class RANSACGlobal(_GlobalStep):
    """RANSAC on descriptor matches.

    Correspondences come from :func:`~o3d_rpointhop.find_correspondences` (nearest
    descriptor, optionally mutual and ratio-filtered). Hypotheses are drawn, checked
    with Open3D's two checkers (edge-length similarity, then the distance of the
    sample's own points) and scored on the correspondences in vectorised batches, and
    the best one is refitted on its inliers (``o3d_rpointhop.registration._ransac``):
    the same semantics as Open3D's ``registration_ransac_based_on_correspondence``
    at a fraction of its cost per iteration, repeatable on any number of threads.
    Seeded from the pipeline's ``seed``: the same input gives the same result.

    Parameters
    ----------
    descriptor : transformer, default=None
        ``None`` uses the pipeline's descriptor.
    max_correspondence_distance : float, default=None
        Inlier distance; ``None`` is the settings' ``ransac_distance`` (1.5 x
        ``voxel_size``, Open3D's tutorial ratio).
    mutual_filter : bool, default=False
        Keep only mutual nearest descriptors.
    max_ratio : float, default=None
        Ratio-test threshold on the matches.
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
    """

    _parameter_constraints = {
        "descriptor": _DESCRIPTOR,
        "max_correspondence_distance": OPTIONAL_DISTANCE,
        "mutual_filter": ["boolean"],
        "max_ratio": [None, Interval(Real, 0, None, closed="neither")],
        "max_iteration": [Interval(Integral, 1, None, closed="left")],
        "confidence": [Interval(Real, 0, 1, closed="neither")],
        "ransac_n": [Interval(Integral, 3, None, closed="left")],
        "edge_length": [Interval(Real, 0, 1, closed="left")],
    }

    def __init__(
        self,
        descriptor: Any = None,
        max_correspondence_distance: float | None = None,
        mutual_filter: bool = False,
        max_ratio: float | None = None,
        max_iteration: int = 1_000_000,
        confidence: float = 0.999,
        ransac_n: int = 3,
        edge_length: float = 0.9,
    ) -> None:
        self.descriptor = descriptor
        self.max_correspondence_distance = max_correspondence_distance
        self.mutual_filter = mutual_filter
        self.max_ratio = max_ratio
        self.max_iteration = max_iteration
        self.confidence = confidence
        self.ransac_n = ransac_n
        self.edge_length = edge_length

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        distance = self.max_correspondence_distance or context.settings.ransac_distance
        corr = self._correspond(context, mutual_filter=self.mutual_filter, max_ratio=self.max_ratio)
        src = np.asarray(context.global_cloud("source").points)
        tgt = np.asarray(context.global_cloud("target").points)
        found = ransac(
            src[corr.pairs[:, 0]],
            tgt[corr.pairs[:, 1]],
            distance,
            max_iteration=int(self.max_iteration),
            confidence=float(self.confidence),
            edge_length=float(self.edge_length),
            seed=context.seed,
            ransac_n=int(self.ransac_n),
            clouds=(src, tgt),
        )
        check = evaluate(context, found.transformation, distance, which="global")
        check.name = "ransac"
        check.info = {
            "candidate_matches": len(corr),
            "inlier_matches": int(found.inliers.sum()),
            "iterations": found.iterations,
            "max_correspondence_distance": distance,
        }
        return check


class FGRGlobal(_GlobalStep):
    """Fast Global Registration (Zhou et al., 2016) on descriptor matches, run by Open3D.

    Matches are mutual nearest descriptors by default (FGR's own filter); with
    ``tuple_test`` they also pass FGR's tuple test, here vectorised and seeded: random
    triples of matches are kept when their source and target triangles have edge
    lengths within ``tuple_scale`` of each other. The surviving matches go to Open3D's
    ``registration_fgr_based_on_correspondence``.

    Parameters
    ----------
    descriptor : transformer, default=None
    max_correspondence_distance : float, default=None
        Open3D's ``maximum_correspondence_distance``; ``None`` is the settings'
        ``fgr_distance`` (1.0 x ``voxel_size``).
    mutual_filter : bool, default=True
    tuple_test : bool, default=True
    tuple_scale : float, default=0.95
    max_iteration : int, default=64
        Open3D's ``iteration_number``.
    """

    _parameter_constraints = {
        "descriptor": _DESCRIPTOR,
        "max_correspondence_distance": OPTIONAL_DISTANCE,
        "mutual_filter": ["boolean"],
        "tuple_test": ["boolean"],
        "tuple_scale": [Interval(Real, 0, 1, closed="neither")],
        "max_iteration": [Interval(Integral, 1, None, closed="left")],
    }

    def __init__(
        self,
        descriptor: Any = None,
        max_correspondence_distance: float | None = None,
        mutual_filter: bool = True,
        tuple_test: bool = True,
        tuple_scale: float = 0.95,
        max_iteration: int = 64,
    ) -> None:
        self.descriptor = descriptor
        self.max_correspondence_distance = max_correspondence_distance
        self.mutual_filter = mutual_filter
        self.tuple_test = tuple_test
        self.tuple_scale = tuple_scale
        self.max_iteration = max_iteration

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        distance = self.max_correspondence_distance or context.settings.fgr_distance
        corr = self._correspond(context, mutual_filter=self.mutual_filter)
        pairs = corr.pairs
        if self.tuple_test:
            pairs = tuple_test(
                np.asarray(context.global_cloud("source").points),
                np.asarray(context.global_cloud("target").points),
                pairs,
                scale=float(self.tuple_scale),
                seed=context.seed,
            )
        option = reg.FastGlobalRegistrationOption(
            maximum_correspondence_distance=distance, iteration_number=int(self.max_iteration)
        )
        with repeatable_open3d():
            o3d.utility.random.seed(context.seed)
            result = reg.registration_fgr_based_on_correspondence(
                context.global_cloud("source"),
                context.global_cloud("target"),
                o3d.utility.Vector2iVector(pairs.astype(np.int32)),
                option,
            )
        # FGR reports no inliers of its own: measure them like every other step.
        check = evaluate(context, np.array(result.transformation), distance, which="global")
        check.name = "fgr"
        check.info = {
            "candidate_matches": len(corr),
            "after_tuple_test": len(pairs),
            "max_correspondence_distance": distance,
        }
        return check


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
    triples = triples[
        (triples[:, 0] != triples[:, 1])
        & (triples[:, 1] != triples[:, 2])
        & (triples[:, 0] != triples[:, 2])
    ]
    s = source[pairs[triples, 0]]  # (t, 3, 3)
    t = target[pairs[triples, 1]]
    ok = np.ones(len(triples), dtype=bool)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        ls = np.linalg.norm(s[:, a] - s[:, b], axis=1)
        lt = np.linalg.norm(t[:, a] - t[:, b], axis=1)
        ok &= (ls > scale * lt) & (lt > scale * ls)
    keep = np.unique(triples[ok])
    return pairs[keep] if keep.size >= 3 else pairs
