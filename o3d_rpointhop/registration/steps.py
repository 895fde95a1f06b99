"""Registration steps: global estimators (SVD, RANSAC, FGR) and ICP refinements.

Every step is a scikit-learn style estimator (``get_params``/``set_params``/``clone``
work) with one method, :meth:`RegistrationStep.run`, that takes the shared
:class:`~o3d_rpointhop.registration.context.RegistrationContext` and the current
source-to-target transformation and returns a :class:`StepResult`.

Distances (RANSAC inlier threshold, ICP correspondence distance, ...) left as ``None``
are multiples of the context's ``voxel_size`` (the factors are given per parameter), so
the same step works on a unit-sphere object and on a scan in metres.
"""

from __future__ import annotations

import numbers
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import open3d as o3d
from sklearn.base import BaseEstimator

from ..correspondences import Correspondences, find_correspondences
from ..transforms import rigid_transform
from ._ransac import ransac
from .context import RegistrationContext

__all__ = [
    "evaluate",
    "repeatable_open3d",
    "StepResult",
    "RegistrationStep",
    "SVDGlobal",
    "RANSACGlobal",
    "FGRGlobal",
    "PointToPointICP",
    "PointToPlaneICP",
    "GeneralizedICP",
    "MultiScaleICP",
]

reg = o3d.pipelines.registration


@dataclass
class StepResult:
    """What one step produced.

    Attributes
    ----------
    name : str
    transformation : ndarray of shape (4, 4)
        Source-to-target transformation after this step.
    fitness : float
        Share of (global-step or full-resolution) source points with a target point
        within the step's distance threshold, as Open3D reports it.
    inlier_rmse : float
        RMS distance of those inliers.
    correspondences : ndarray of shape (m, 2)
        The step's inlier pairs ``(source index, target index)``; indices refer to the
        clouds the step worked on (global steps: the downsampled clouds).
    seconds : float
    info : dict
        Step-specific numbers (thresholds used, number of candidate matches, ...).
    distance : float
        The correspondence distance ``fitness`` and ``inlier_rmse`` were measured at.
    """

    name: str
    transformation: np.ndarray
    fitness: float
    inlier_rmse: float
    correspondences: np.ndarray
    seconds: float = 0.0
    info: dict = field(default_factory=dict)
    distance: float = 0.0

    def as_dict(self) -> dict:
        return {
            "name": self.name,
            "transformation": self.transformation.tolist(),
            "fitness": self.fitness,
            "inlier_rmse": self.inlier_rmse,
            "n_correspondences": int(len(self.correspondences)),
            "seconds": self.seconds,
            "distance": self.distance,
            "info": self.info,
        }


def _distance(value: float | None, factor: float, context: RegistrationContext, name: str):
    if value is None:
        return factor * context.voxel_size
    if not (isinstance(value, numbers.Real) and np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be None or a positive number, got {value!r}")
    return float(value)


def _positive_int(value: Any, name: str) -> int:
    if not (isinstance(value, numbers.Integral) and not isinstance(value, bool) and value >= 1):
        raise ValueError(f"{name} must be a positive int, got {value!r}")
    return int(value)


@contextmanager
def repeatable_open3d():
    """Run Open3D's registration code on one thread, so a seeded run repeats bit for bit.

    With several threads, Open3D's RANSAC draws from one shared random generator in an
    order set by thread timing (different results from one seed: 3 of 53 ModelNet40
    pairs), and ICP sums its residuals in a timing-dependent order (last-digit
    differences). One thread costs about 10 % on RANSAC and ICP over 40k points takes
    50 ms instead of 30 ms.
    """
    if not hasattr(o3d.utility, "set_max_threads"):  # Open3D < 0.20: no thread control
        yield
        return
    previous = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(1)
    try:
        yield
    finally:
        o3d.utility.set_max_threads(previous)


def _from_open3d(name: str, result, seconds: float, info: dict, distance: float) -> StepResult:
    return StepResult(
        name=name,
        transformation=np.array(result.transformation),
        fitness=float(result.fitness),
        inlier_rmse=float(result.inlier_rmse),
        correspondences=np.asarray(result.correspondence_set, dtype=np.int64).reshape(-1, 2),
        seconds=seconds,
        info=info,
        distance=float(distance),
    )


def evaluate(
    context: RegistrationContext, transformation: np.ndarray, threshold: float, which="full"
) -> StepResult:
    """Fitness, inlier RMSE and inlier pairs of ``transformation`` at ``threshold``, on the
    full-resolution clouds (``which="full"``) or the global step's (``"global"``)."""
    source, target = (
        (context.source, context.target)
        if which == "full"
        else (context.global_cloud("source"), context.global_cloud("target"))
    )
    with repeatable_open3d():
        result = reg.evaluate_registration(source, target, threshold, transformation)
    return _from_open3d("evaluation", result, 0.0, {"threshold": threshold}, threshold)


class RegistrationStep(BaseEstimator):
    """Base class of registration steps."""

    #: ``"global"`` steps ignore the incoming transformation; ``"refine"`` steps start from it.
    kind = "refine"

    def run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        """Run the step; return its result (its transformation is absolute)."""
        raise NotImplementedError


# --------------------------------------------------------------------------- global
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
                "filters; at least 3 are needed (relax mutual / max_ratio / top_k)"
            )
        return corr


def _count(value: int | float, n: int, name: str) -> int:
    """An int, or a fraction of ``n`` (at least 3)."""
    if isinstance(value, numbers.Integral) and not isinstance(value, bool) and value >= 3:
        return int(value)
    if isinstance(value, numbers.Real) and 0 < value <= 1:
        return max(3, int(round(value * n)))
    raise ValueError(f"{name} must be an int >= 3 or a fraction in (0, 1], got {value!r}")


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
        Matches kept by descriptor distance (the paper's M1: 256 of 1024 points); a
        fraction is relative to the source's point count.
    top_k_ratio : int or float, default=0.125
        Matches then kept by ratio (M2: 128 of 1024).
    mutual : bool, default=False
    """

    def __init__(
        self,
        descriptor: Any = None,
        top_k: int | float = 0.25,
        top_k_ratio: int | float = 0.125,
        mutual: bool = False,
    ) -> None:
        self.descriptor = descriptor
        self.top_k = top_k
        self.top_k_ratio = top_k_ratio
        self.mutual = mutual

    def run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        start = time.perf_counter()
        n = len(context.global_cloud("source").points)
        top_k = _count(self.top_k, n, "top_k")
        top_k_ratio = _count(self.top_k_ratio, n, "top_k_ratio")
        corr = self._correspond(
            context, mutual=self.mutual, top_k=top_k, top_k_ratio=min(top_k, top_k_ratio)
        )
        src = np.asarray(context.global_cloud("source").points)[corr.pairs[:, 0]]
        tgt = np.asarray(context.global_cloud("target").points)[corr.pairs[:, 1]]
        estimate = rigid_transform(src, tgt)
        check = evaluate(context, estimate, context.voxel_size, which="global")
        return StepResult(
            name="svd",
            transformation=estimate,
            fitness=check.fitness,
            inlier_rmse=check.inlier_rmse,
            correspondences=corr.pairs,
            seconds=time.perf_counter() - start,
            info={"matches_used": len(corr), "evaluation_threshold": context.voxel_size},
            distance=context.voxel_size,
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
    distance_threshold : float, default=None
        Inlier distance; ``None`` is 1.5 x ``voxel_size`` (Open3D's tutorial ratio).
    mutual : bool, default=False
        Keep only mutual nearest descriptors.
    max_ratio : float, default=None
        Ratio-test threshold on the matches.
    max_iterations : int, default=1000000
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

    def __init__(
        self,
        descriptor: Any = None,
        distance_threshold: float | None = None,
        mutual: bool = False,
        max_ratio: float | None = None,
        max_iterations: int = 1_000_000,
        confidence: float = 0.999,
        ransac_n: int = 3,
        edge_length: float = 0.9,
    ) -> None:
        self.descriptor = descriptor
        self.distance_threshold = distance_threshold
        self.mutual = mutual
        self.max_ratio = max_ratio
        self.max_iterations = max_iterations
        self.confidence = confidence
        self.ransac_n = ransac_n
        self.edge_length = edge_length

    def run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        start = time.perf_counter()
        threshold = _distance(self.distance_threshold, 1.5, context, "distance_threshold")
        max_iterations = _positive_int(self.max_iterations, "max_iterations")
        ransac_n = _positive_int(self.ransac_n, "ransac_n")
        if ransac_n < 3:
            raise ValueError(f"ransac_n must be at least 3, got {self.ransac_n!r}")
        if not 0 < self.confidence < 1:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence!r}")
        if not (isinstance(self.edge_length, numbers.Real) and 0 <= self.edge_length < 1):
            raise ValueError(f"edge_length must be in [0, 1), got {self.edge_length!r}")
        corr = self._correspond(context, mutual=self.mutual, max_ratio=self.max_ratio)
        src = np.asarray(context.global_cloud("source").points)
        tgt = np.asarray(context.global_cloud("target").points)
        found = ransac(
            src[corr.pairs[:, 0]],
            tgt[corr.pairs[:, 1]],
            threshold,
            max_iteration=max_iterations,
            confidence=float(self.confidence),
            edge_length=float(self.edge_length),
            seed=context.seed,
            ransac_n=ransac_n,
            clouds=(src, tgt),
        )
        check = evaluate(context, found.transformation, threshold, which="global")
        check.name = "ransac"
        check.seconds = time.perf_counter() - start
        check.info = {
            "candidate_matches": len(corr),
            "inlier_matches": int(found.inliers.sum()),
            "iterations": found.iterations,
            "distance_threshold": threshold,
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
    maximum_correspondence_distance : float, default=None
        ``None`` is 1.0 x ``voxel_size``.
    mutual : bool, default=True
    tuple_test : bool, default=True
    tuple_scale : float, default=0.95
    iteration_number : int, default=64
    """

    def __init__(
        self,
        descriptor: Any = None,
        maximum_correspondence_distance: float | None = None,
        mutual: bool = True,
        tuple_test: bool = True,
        tuple_scale: float = 0.95,
        iteration_number: int = 64,
    ) -> None:
        self.descriptor = descriptor
        self.maximum_correspondence_distance = maximum_correspondence_distance
        self.mutual = mutual
        self.tuple_test = tuple_test
        self.tuple_scale = tuple_scale
        self.iteration_number = iteration_number

    def run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        start = time.perf_counter()
        distance = _distance(
            self.maximum_correspondence_distance, 1.0, context, "maximum_correspondence_distance"
        )
        corr = self._correspond(context, mutual=self.mutual)
        pairs = corr.pairs
        if self.tuple_test:
            pairs = tuple_test(
                np.asarray(context.global_cloud("source").points),
                np.asarray(context.global_cloud("target").points),
                pairs,
                scale=self.tuple_scale,
                seed=context.seed,
            )
        option = reg.FastGlobalRegistrationOption(
            maximum_correspondence_distance=distance,
            iteration_number=_positive_int(self.iteration_number, "iteration_number"),
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
        check.seconds = time.perf_counter() - start
        check.info = {
            "candidate_matches": len(corr),
            "after_tuple_test": len(pairs),
            "maximum_correspondence_distance": distance,
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


# --------------------------------------------------------------------------- refine
_KERNELS = {
    "huber": reg.HuberLoss,
    "tukey": reg.TukeyLoss,
    "cauchy": reg.CauchyLoss,
    "gm": reg.GMLoss,
}


def _robust_kernel(kernel: str | None, scale: float | None, distance: float):
    if kernel is None:
        return None
    if kernel == "l1":
        return reg.L1Loss()
    if kernel not in _KERNELS:
        raise ValueError(
            f"kernel must be None or one of {sorted([*_KERNELS, 'l1'])}, got {kernel!r}"
        )
    k = distance / 2.0 if scale is None else scale
    if not (isinstance(k, numbers.Real) and k > 0):
        raise ValueError(f"kernel_scale must be a positive number, got {scale!r}")
    return _KERNELS[kernel](float(k))


def _distances(value: Any, factors: tuple[float, ...], context: RegistrationContext) -> list[float]:
    """A distance schedule: one pass per distance, coarse to fine."""
    if value is None:
        return [f * context.voxel_size for f in factors]
    values = [value] if isinstance(value, numbers.Real) else list(value)
    if not values:
        raise ValueError("max_correspondence_distance must not be an empty sequence")
    return [_distance(v, 1.0, context, "max_correspondence_distance") for v in values]


_DISTANCE_DOC = """max_correspondence_distance : float, sequence of float or None, default=None
        Correspondence distance; a sequence runs one ICP pass per distance, each from
        the previous result. ``None`` is two passes, at 2 and at 0.5 x ``voxel_size``:
        the first pulls in the global estimate, the second leaves out the points that
        have no partner in a partial overlap (on the Stanford Bunny scans it cuts the
        error from 1.4 deg / 3 mm to 0.14 deg / 0.3 mm on the worst pair). A pass wider
        than ``voxel_size`` runs on the global step's clouds, which have that
        resolution (when they are downsampled), the others on the full clouds."""


def _estimation(method: str, kernel, epsilon: float = 1e-3):
    """Open3D's estimation object for an ICP variant, with an optional robust kernel."""
    if method == "point_to_point":
        return reg.TransformationEstimationPointToPoint(False)
    extra = [kernel] if kernel is not None else []
    if method == "point_to_plane":
        return reg.TransformationEstimationPointToPlane(*extra)
    return reg.TransformationEstimationForGeneralizedICP(float(epsilon), *extra)


def _icp(method: str, source, target, distance: float, init, estimation, criteria):
    """One Open3D ICP run (generalized ICP has its own entry point), repeatably."""
    run = reg.registration_generalized_icp if method == "generalized" else reg.registration_icp
    with repeatable_open3d():
        return run(source, target, distance, init, estimation, criteria)


class _ICPStep(RegistrationStep):
    """Shared parameters, schedule and checks of the single-scale ICP steps."""

    #: default distance schedule, in units of voxel_size
    distance_factors = (2.0, 0.5)
    name = "icp"

    def _criteria(self):
        return reg.ICPConvergenceCriteria(
            relative_fitness=float(self.relative_fitness),
            relative_rmse=float(self.relative_rmse),
            max_iteration=_positive_int(self.max_iteration, "max_iteration"),
        )

    def _solve(self, context: RegistrationContext, which: str, distance: float, init):
        """One pass on the ``"full"`` or the ``"global"`` clouds."""
        raise NotImplementedError

    @staticmethod
    def _clouds(context: RegistrationContext, which: str):
        if which == "full":
            return context.source, context.target
        return context.global_cloud("source"), context.global_cloud("target")

    def run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        start = time.perf_counter()
        distances = _distances(self.max_correspondence_distance, self.distance_factors, context)
        current = np.asarray(transformation, dtype=np.float64)
        for k, distance in enumerate(distances):
            # Wide passes on the global clouds: at their resolution they see the same
            # correspondences for far less work. The last pass is always on the full ones.
            coarse = context.downsampled and distance > context.voxel_size
            which = "global" if coarse and k < len(distances) - 1 else "full"
            result = self._solve(context, which, distance, current)
            current = np.array(result.transformation)
        info = {"distances": distances, "kernel": getattr(self, "kernel", None)}
        return _from_open3d(self.name, result, time.perf_counter() - start, info, distances[-1])


class PointToPointICP(_ICPStep):
    """Point-to-point ICP (Besl and McKay, 1992) on the full-resolution clouds.

    Parameters
    ----------
    {distance}
    max_iteration : int, default=50
        Per pass.
    relative_fitness, relative_rmse : float, default=1e-6
        Convergence thresholds.
    """

    name = "point_to_point"

    def __init__(
        self,
        max_correspondence_distance: float | list[float] | None = None,
        max_iteration: int = 50,
        relative_fitness: float = 1e-6,
        relative_rmse: float = 1e-6,
    ) -> None:
        self.max_correspondence_distance = max_correspondence_distance
        self.max_iteration = max_iteration
        self.relative_fitness = relative_fitness
        self.relative_rmse = relative_rmse

    def _solve(self, context, which, distance, init):
        source, target = self._clouds(context, which)
        estimation = _estimation(self.name, None)
        return _icp(self.name, source, target, distance, init, estimation, self._criteria())


class PointToPlaneICP(_ICPStep):
    """Point-to-plane ICP (Chen and Medioni, 1992) on the full-resolution clouds.

    Target normals are estimated (radius 2 x ``voxel_size``) when the target has none.

    Parameters
    ----------
    {distance}
    max_iteration : int, default=50
        Per pass.
    kernel : {{None, "huber", "tukey", "cauchy", "gm", "l1"}}, default=None
        Robust loss on the point-to-plane residuals.
    kernel_scale : float, default=None
        The loss's scale; ``None`` is half the pass's correspondence distance.
    relative_fitness, relative_rmse : float, default=1e-6
    """

    name = "point_to_plane"

    def __init__(
        self,
        max_correspondence_distance: float | list[float] | None = None,
        max_iteration: int = 50,
        kernel: str | None = None,
        kernel_scale: float | None = None,
        relative_fitness: float = 1e-6,
        relative_rmse: float = 1e-6,
    ) -> None:
        self.max_correspondence_distance = max_correspondence_distance
        self.max_iteration = max_iteration
        self.kernel = kernel
        self.kernel_scale = kernel_scale
        self.relative_fitness = relative_fitness
        self.relative_rmse = relative_rmse

    def _solve(self, context, which, distance, init):
        kernel = _robust_kernel(self.kernel, self.kernel_scale, distance)
        source, target = self._clouds(context, which)
        target = context.with_normals(target, f"target-{which}", 2.0 * context.voxel_size)
        return _icp(self.name, source, target, distance, init,
                    _estimation(self.name, kernel), self._criteria())  # fmt: skip


class GeneralizedICP(_ICPStep):
    """Generalized ICP (Segal et al., 2009; plane-to-plane) on the full-resolution clouds.

    Parameters
    ----------
    {distance}
    max_iteration : int, default=50
        Per pass.
    epsilon : float, default=1e-3
        Covariance regulariser of the local planes.
    kernel : {{None, "huber", "tukey", "cauchy", "gm", "l1"}}, default=None
    kernel_scale : float, default=None
    relative_fitness, relative_rmse : float, default=1e-6
    """

    name = "generalized"

    def __init__(
        self,
        max_correspondence_distance: float | list[float] | None = None,
        max_iteration: int = 50,
        epsilon: float = 1e-3,
        kernel: str | None = None,
        kernel_scale: float | None = None,
        relative_fitness: float = 1e-6,
        relative_rmse: float = 1e-6,
    ) -> None:
        self.max_correspondence_distance = max_correspondence_distance
        self.max_iteration = max_iteration
        self.epsilon = epsilon
        self.kernel = kernel
        self.kernel_scale = kernel_scale
        self.relative_fitness = relative_fitness
        self.relative_rmse = relative_rmse

    def _solve(self, context, which, distance, init):
        kernel = _robust_kernel(self.kernel, self.kernel_scale, distance)
        source, target = self._clouds(context, which)
        estimation = _estimation(self.name, kernel, self.epsilon)
        return _icp(self.name, source, target, distance, init, estimation, self._criteria())


for _cls in (PointToPointICP, PointToPlaneICP, GeneralizedICP):
    if _cls.__doc__:  # None under python -OO
        _cls.__doc__ = _cls.__doc__.format(distance=_DISTANCE_DOC)


class MultiScaleICP(RegistrationStep):
    """ICP from coarse to fine: each scale downsamples both clouds and widens the search.

    At scale ``s`` both clouds are voxel-downsampled to ``s x voxel_size`` (the finest
    scale, ``s <= 1``, uses the full clouds) and ICP runs with a correspondence distance
    of ``distance_factor x s x voxel_size``. Coarse scales pull in a poor start cheaply;
    the fine scale gives the accuracy.

    Parameters
    ----------
    scales : sequence of float, default=(4.0, 2.0, 1.0)
        Coarse to fine, in units of ``voxel_size``.
    max_iterations : sequence of int, default=(50, 30, 20)
        One per scale.
    method : {"point_to_plane", "point_to_point", "generalized"}, default="point_to_plane"
    distance_factor : float, default=2.0
    kernel : {None, "huber", "tukey", "cauchy", "gm", "l1"}, default=None
        Ignored by ``"point_to_point"`` (Open3D has no robust point-to-point solver).
    """

    def __init__(
        self,
        scales=(4.0, 2.0, 1.0),
        max_iterations=(50, 30, 20),
        method: str = "point_to_plane",
        distance_factor: float = 2.0,
        kernel: str | None = None,
    ) -> None:
        self.scales = scales
        self.max_iterations = max_iterations
        self.method = method
        self.distance_factor = distance_factor
        self.kernel = kernel

    def run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        start = time.perf_counter()
        scales = [float(s) for s in self.scales]
        iterations = [_positive_int(i, "max_iterations") for i in self.max_iterations]
        if len(scales) != len(iterations) or not scales or min(scales) <= 0:
            raise ValueError("scales and max_iterations must be non-empty, positive, and as long")
        if self.method not in ("point_to_plane", "point_to_point", "generalized"):
            raise ValueError(f"unknown method {self.method!r}")
        current = np.asarray(transformation, dtype=np.float64)
        result = None
        for scale, iters in zip(scales, iterations, strict=True):
            result = self._run_scale(context, current, scale, iters)
            current = np.array(result.transformation)
        info = {"scales": scales, "method": self.method}
        last = self.distance_factor * scales[-1] * context.voxel_size
        return _from_open3d("multiscale", result, time.perf_counter() - start, info, last)

    def _run_scale(self, context: RegistrationContext, current, scale: float, iters: int):
        """One ICP pass at ``scale`` x ``voxel_size``."""
        voxel = scale * context.voxel_size
        if scale <= 1.0:
            src, tgt, tag = context.source, context.target, "full"
        else:
            src = context.source.voxel_down_sample(voxel)
            tgt = context.target.voxel_down_sample(voxel)
            tag = f"x{scale:g}"
        distance = self.distance_factor * voxel
        criteria = reg.ICPConvergenceCriteria(1e-6, 1e-6, iters)
        kernel = (
            None if self.method == "point_to_point" else _robust_kernel(self.kernel, None, distance)
        )
        if self.method == "point_to_plane":
            tgt = context.with_normals(tgt, f"target{tag}", 2.0 * voxel)
        estimation = _estimation(self.method, kernel)
        return _icp(self.method, src, tgt, distance, current, estimation, criteria)
