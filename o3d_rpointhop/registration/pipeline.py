"""Registration chains (global first, then local) and the one-call ``register``."""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Any

import numpy as np
from sklearn.base import clone
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions
from sklearn.utils.metaestimators import _BaseComposition
from sklearn.utils.validation import check_is_fitted

from .context import RegistrationContext, RegistrationWarning
from .global_estimators import FGRGlobal, RANSACGlobal, SVDGlobal
from .icp import GeneralizedICP, MultiScaleICP, PointToPlaneICP, PointToPointICP
from .scoring import check_pairs, registration_scorer
from .settings import RegistrationSettings
from .steps import RegistrationStep, StepResult, evaluate
from .symmetry import SymmetryCheck, twin_transformations

__all__ = [
    "RegistrationResult",
    "RegistrationPipeline",
    "register",
    "GLOBAL_METHODS",
    "REFINE_METHODS",
]

GLOBAL_METHODS = {"ransac": RANSACGlobal, "fgr": FGRGlobal, "svd": SVDGlobal}
REFINE_METHODS = {
    "point_to_point": PointToPointICP,
    "point_to_plane": PointToPlaneICP,
    "generalized": GeneralizedICP,
    "multiscale": MultiScaleICP,
    "symmetry_check": SymmetryCheck,
}


@dataclass
class RegistrationResult:
    """The outcome of a registration.

    Attributes
    ----------
    transformation : ndarray of shape (4, 4)
        Maps source points into the target frame: ``target ~ source @ R.T + t``, as in
        Open3D.
    fitness : float
        Open3D's fitness: the share of the (full-resolution) source points that have a
        target point within ``distance`` (the last step's correspondence distance)
        after the transformation. The last step reports the same number when it ran on
        the full clouds; every step's own numbers are in ``steps``.
    inlier_rmse : float
        RMS distance of those inliers.
    correspondence_set : ndarray of shape (m, 2)
        Those inlier pairs ``(source index, target index)``, as in Open3D.
    steps : list of StepResult
        Every step's transformation, fitness, inliers and timing, in order.
    voxel_size : float
        The resolution the thresholds were derived from.
    seconds : float
        Wall time of the whole registration.
    distance : float
        The correspondence distance ``fitness`` was measured at.
    converged : bool
        False when fewer than 2 % of the source points found a partner (``fitness <
        0.02``), or when, measured within three times the resolution, the partners' RMS
        distance exceeds 0.47 of it: distances spread over the whole threshold are the
        mark of a chance alignment. Measured on training data: unrelated objects
        registered to each other 0.53-0.58; true poses of two different samples of an
        object, whole or cropped, 0.24-0.40. Wrong poses that align a scene's floors and
        walls can fit like right ones and are not always caught: the flag says "surely
        unreliable", not "surely right".
    ambiguous : bool
        True when the result turned by 180 degrees about one of the aligned source's
        principal axes fits about as well (fitness within three resolutions at least
        90 % of the result's, on the global clouds; the twins are not refined, so they
        are judged at that wider distance): a symmetric shape, or a featureless plane,
        whose pose the data cannot decide. A :class:`RegistrationWarning` is issued
        with either flag.
    """

    transformation: np.ndarray
    fitness: float
    inlier_rmse: float
    correspondence_set: np.ndarray
    steps: list[StepResult] = field(default_factory=list)
    voxel_size: float = 0.0
    seconds: float = 0.0
    distance: float = 0.0
    converged: bool = True
    ambiguous: bool = False

    def to_open3d(self):
        """This result as an ``open3d.pipelines.registration.RegistrationResult``
        (transformation, fitness, inlier RMSE and correspondence set)."""
        import open3d as o3d

        out = o3d.pipelines.registration.RegistrationResult()
        out.transformation = np.asarray(self.transformation, dtype=np.float64)
        out.fitness = float(self.fitness)
        out.inlier_rmse = float(self.inlier_rmse)
        out.correspondence_set = o3d.utility.Vector2iVector(
            np.asarray(self.correspondence_set, dtype=np.int32).reshape(-1, 2)
        )
        return out

    def as_dict(self) -> dict:
        """JSON-ready summary (the CLI's ``--json`` output)."""
        return {
            "transformation": self.transformation.tolist(),
            "fitness": self.fitness,
            "inlier_rmse": self.inlier_rmse,
            "n_correspondences": int(len(self.correspondence_set)),
            "voxel_size": self.voxel_size,
            "distance": self.distance,
            "converged": self.converged,
            "ambiguous": self.ambiguous,
            "seconds": self.seconds,
            "steps": [s.as_dict() for s in self.steps],
        }


def _check_steps(steps: Any) -> list[tuple[str, RegistrationStep]]:
    if not isinstance(steps, (list, tuple)) or not steps:
        raise ValueError("steps must be a non-empty list of (name, step) pairs")
    names = set()
    for item in steps:
        if not (isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str)):
            raise ValueError(f"each step must be a (name, step) pair, got {item!r}")
        name, step = item
        if "__" in name or name in names:
            raise ValueError(f"step names must be unique and free of '__', got {name!r}")
        if not isinstance(step, RegistrationStep):
            raise ValueError(f"step {name!r} is not a RegistrationStep: {step!r}")
        names.add(name)
    return list(steps)


class RegistrationPipeline(_BaseComposition):
    """A chain of registration steps, run in order: a global estimate, then refinements.

    Built on scikit-learn's composition machinery, like ``sklearn.pipeline.Pipeline``:
    its steps are named, and every parameter of the steps and of the descriptor is
    reachable as ``<step>__<parameter>`` or ``descriptor__<parameter>`` through
    :meth:`get_params` / :meth:`set_params`, so ``clone`` and ``GridSearchCV`` work.
    :meth:`register` aligns one pair; :meth:`fit`, :meth:`predict` and :meth:`score`
    take a list of ``(source, target)`` pairs (and, for scoring, their true
    transformations) so that the pipeline can be cross-validated.

    Parameters
    ----------
    steps : list of (str, RegistrationStep)
    descriptor : transformer, default=None
        Descriptor for global steps that do not name their own; ``None`` is the
        pretrained R-PointHop model. :meth:`fit` fits a clone of it on the pairs' clouds
        (wrap a pretrained model in ``sklearn.frozen.FrozenEstimator`` to keep it as it
        is); :meth:`register` uses the fitted clone after :meth:`fit`, the descriptor as
        given before.
    voxel_size : float or "auto", default="auto"
        Resolution of the registration. ``"auto"``: clouds of up to ``n_global_points``
        points are used as they are, with their point spacing as the resolution; larger
        clouds are voxel-downsampled for the global step to about ``n_global_points``
        points. ICP steps always use the full clouds.
    n_global_points : int or "auto", default="auto"
        ``"auto"``: what the descriptor states in its ``registration_points_`` (4096
        for ``RPointHopTransformer.pretrained("scene")``), else 2048.
    seed : int, default=0
        Seeds the random parts (RANSAC, FGR): results are repeatable.
    settings : RegistrationSettings, default=None
        The multiples of the resolution that distances the steps leave unset are
        derived from; ``None`` is ``RegistrationSettings()``.

    Attributes
    ----------
    descriptor_ : transformer
        After :meth:`fit`: the descriptor fitted on the pairs' clouds (the pretrained
        model when ``descriptor`` is None).

    Examples
    --------
    >>> from o3d_rpointhop import RegistrationPipeline, RANSACGlobal, PointToPlaneICP
    >>> pipe = RegistrationPipeline([("global", RANSACGlobal()), ("icp", PointToPlaneICP())])
    >>> pipe.set_params(icp__max_iteration=100).named_steps["icp"].max_iteration
    100
    """

    _parameter_constraints = {
        "steps": [list, tuple],
        "descriptor": [None, HasMethods(["transform"])],
        "voxel_size": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "n_global_points": [Interval(Integral, 3, None, closed="left"), StrOptions({"auto"})],
        "seed": [Interval(Integral, 0, None, closed="left")],
        "settings": [None, RegistrationSettings],
    }

    def __init__(
        self,
        steps: list[tuple[str, RegistrationStep]],
        descriptor: Any = None,
        voxel_size: float | str = "auto",
        n_global_points: int | str = "auto",
        seed: int = 0,
        settings: RegistrationSettings | None = None,
    ) -> None:
        self.steps = steps
        self.descriptor = descriptor
        self.voxel_size = voxel_size
        self.n_global_points = n_global_points
        self.seed = seed
        self.settings = settings

    @property
    def named_steps(self) -> dict[str, RegistrationStep]:
        return dict(_check_steps(self.steps))

    def get_params(self, deep: bool = True) -> dict:
        """Parameters of the pipeline, and with ``deep`` those of its steps
        (``<step>__<parameter>``) and of the descriptor (``descriptor__<parameter>``)."""
        return self._get_params("steps", deep=deep)

    def set_params(self, **params) -> RegistrationPipeline:
        """Set parameters, including ``<step>__<parameter>`` and whole steps by name."""
        names = [name for name, _ in _check_steps(self.steps)]
        for key in params:
            head = key.split("__", 1)[0]
            if "__" in key and head not in names and head not in self._parameter_constraints:
                raise ValueError(f"no step named {head!r} (steps: {names})")
        self._set_params("steps", **params)
        return self

    def _check(self) -> list[tuple[str, RegistrationStep]]:
        self._validate_params()
        return _check_steps(self.steps)

    def fit(self, X: Any, y: Any = None) -> RegistrationPipeline:
        """Fit a clone of the descriptor on the clouds of the pairs ``X``.

        Parameters
        ----------
        X : list of (source, target)
            Pairs of clouds (arrays or Open3D clouds).
        y : ignored
            The true transformations are only needed by :meth:`score`.

        Returns
        -------
        self : RegistrationPipeline
        """
        self._check()
        pairs = check_pairs(X)
        if self.descriptor is None:
            from ..rpointhop import default_descriptor

            self.descriptor_ = default_descriptor()
        else:
            clouds = [cloud for pair in pairs for cloud in pair]
            self.descriptor_ = clone(self.descriptor).fit(clouds, None)
        return self

    def predict(self, X: Any) -> np.ndarray:
        """The source-to-target transformation of every pair.

        Parameters
        ----------
        X : list of (source, target)

        Returns
        -------
        ndarray of shape (n_pairs, 4, 4)
        """
        check_is_fitted(self, "descriptor_")
        return np.stack([result.transformation for result in self.register_pairs(X)])

    def register_pairs(self, X: Any) -> list[RegistrationResult]:
        """:meth:`register` for every ``(source, target)`` pair of ``X``, in order."""
        with warnings.catch_warnings():  # the flags are on the results
            warnings.simplefilter("ignore", RegistrationWarning)
            return [self.register(source, target) for source, target in check_pairs(X)]

    def score(self, X: Any, y: Any) -> float:
        """Registration recall: the share of pairs registered within 5 deg and two
        resolutions of their true transformation (:func:`registration_scorer`'s defaults).

        Parameters
        ----------
        X : list of (source, target)
        y : array-like of shape (n_pairs, 4, 4)
            True source-to-target transformations.

        Returns
        -------
        float
        """
        return registration_scorer()(self, X, y)

    def register(self, source: Any, target: Any, init: np.ndarray | None = None):
        """Align ``source`` to ``target``.

        Parameters
        ----------
        source, target : array-like (n, 3) or Open3D point cloud
            Not modified.
        init : ndarray of shape (4, 4), default=None
            Starting transformation for refinement steps that come before any global
            step (e.g. ICP alone); global steps start from scratch. ``None`` is the
            identity.

        Returns
        -------
        RegistrationResult
        """
        steps = self._check()
        start = time.perf_counter()
        context = RegistrationContext(
            source,
            target,
            voxel_size=self.voxel_size,
            n_global_points=self.n_global_points,
            seed=self.seed,
            descriptor=getattr(self, "descriptor_", self.descriptor),
            settings=self.settings,
        )
        current = np.eye(4) if init is None else context.to_local(_check_transformation(init))
        results = []
        for name, step in steps:
            outcome = step.run(context, current)
            outcome.name = name
            if not np.isfinite(outcome.transformation).all():
                raise ValueError(
                    f"step {name!r} found no finite transformation: the clouds are too "
                    "degenerate to register (nearly all points coincide, or too few distinct "
                    "points for the neighbourhoods)"
                )
            current = outcome.transformation  # in the context's centred frame
            outcome.transformation = context.to_world(current)
            results.append(outcome)
        distance = results[-1].distance
        final = evaluate(context, current, distance)
        wide = max(distance, context.settings.spread_distance)
        spread = evaluate(context, current, wide).inlier_rmse / wide
        converged = final.fitness >= MIN_FITNESS and spread <= MAX_SPREAD
        ambiguous = converged and _ambiguous(context, current, wide)
        if not converged:
            warnings.warn(
                f"the registration did not converge: {final.fitness:.1%} of the source "
                f"points have a target point within {distance:.4g}, and within {wide:.4g} "
                f"their RMS distance is {spread:.2f} of it (no overlap, or a chance "
                "alignment); result.converged is False",
                RegistrationWarning,
                stacklevel=3,
            )
        elif ambiguous:
            warnings.warn(
                "the registration is ambiguous: the result turned by 180 degrees fits about "
                "as well (a symmetric shape or a featureless plane); result.ambiguous is True",
                RegistrationWarning,
                stacklevel=3,
            )
        return RegistrationResult(
            transformation=context.to_world(current),
            fitness=final.fitness,
            inlier_rmse=final.inlier_rmse,
            correspondence_set=final.correspondence_set,
            steps=results,
            voxel_size=context.voxel_size,
            seconds=time.perf_counter() - start,
            distance=distance,
            converged=converged,
            ambiguous=ambiguous,
        )


#: Fitness below which a result is flagged as not converged.
MIN_FITNESS = 0.02
#: Inlier RMSE within the settings' ``spread_distance`` (3 resolutions), as a share of
#: that distance, above which a result is flagged as not converged (a chance alignment).
MAX_SPREAD = 0.47
#: A 180-degree twin with at least this share of the result's fitness makes it ambiguous.
AMBIGUITY_RATIO = 0.9


def _ambiguous(context: RegistrationContext, transformation: np.ndarray, distance: float) -> bool:
    """Whether a 180-degree twin of ``transformation`` fits about as well, measured on
    the global clouds (cheap: about ``n_global_points`` points)."""
    source = np.asarray(context.global_cloud("source").points)
    base = evaluate(context, transformation, distance, which="global").fitness
    if base <= 0.0:
        return False
    twins = twin_transformations(source, transformation)
    best = max(evaluate(context, t, distance, which="global").fitness for t in twins)
    return best >= AMBIGUITY_RATIO * base


def _check_transformation(value: Any) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (4, 4) or not np.isfinite(arr).all():
        raise ValueError(f"init must be a finite 4x4 matrix, got shape {arr.shape}")
    rot = arr[:3, :3]
    if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
        raise ValueError("init's upper-left 3x3 block must be a rotation matrix")
    return arr


def _make_step(spec: Any, table: dict, what: str, descriptor: Any = None):
    if isinstance(spec, RegistrationStep):
        return spec
    if isinstance(spec, str) and spec in table:
        return table[spec]()
    raise ValueError(
        f"{what} must be one of {sorted(table)}, None or a RegistrationStep, got {spec!r}"
    )


def register(
    source: Any,
    target: Any,
    descriptor: Any = None,
    *,
    global_method: str | RegistrationStep | None = "ransac",
    refine: str | RegistrationStep | list | None = "point_to_plane",
    voxel_size: float | str = "auto",
    n_global_points: int | str = "auto",
    init: np.ndarray | None = None,
    seed: int = 0,
    settings: RegistrationSettings | None = None,
) -> RegistrationResult:
    """Register ``source`` to ``target``: a global estimate from descriptors, then ICP.

    Parameters
    ----------
    source, target : array-like (n, 3) or Open3D point cloud
        Any size and metric scale; not modified.
    descriptor : transformer, default=None
        Fitted ``RPointHopTransformer`` or an ``FPFHTransformer``; ``None`` is the
        pretrained R-PointHop model.
    global_method : {"ransac", "fgr", "svd"}, RegistrationStep or None, default="ransac"
        ``"svd"`` is the paper's one-shot estimate; ``None`` skips the global step (ICP
        from ``init``).
    refine : {"point_to_plane", "point_to_point", "generalized", "multiscale", \
            "symmetry_check"}, step, list of those, or None, default="point_to_plane"
        Run in order. ``"symmetry_check"`` (:class:`SymmetryCheck`) after an ICP step
        also tries the estimate's 180-degree twins, refined by a copy of that step, and
        takes one that fits better on every count: it corrects near-symmetric objects
        registered turned over, at the cost of four more ICP runs on the global clouds.
    voxel_size : float or "auto", default="auto"
        See :class:`RegistrationPipeline`.
    n_global_points : int or "auto", default="auto"
        Size of the global step's clouds. ``"auto"``: the descriptor's
        ``registration_points_`` if it states one (the shipped scene model: 4096, so
        ``register(source, target, RPointHopTransformer.pretrained("scene"))`` is the
        3DMatch benchmark's setting), else 2048.
    init : ndarray of shape (4, 4), default=None
        Start for ICP when there is no global step.
    seed : int, default=0
    settings : RegistrationSettings, default=None
        The multiples of the resolution every unset distance is derived from (RANSAC's
        inlier distance, ICP's passes, the normals' radius, ...); ``None`` is
        ``RegistrationSettings()``.

    Returns
    -------
    RegistrationResult
        ``result.transformation`` maps the source into the target frame.

    Examples
    --------
    >>> from o3d_rpointhop import register
    >>> from o3d_rpointhop.datasets import make_object
    >>> cloud = make_object(1024)
    >>> result = register(cloud + [0.1, 0.0, 0.0], cloud)
    >>> bool(abs(result.transformation[0, 3] + 0.1) < 1e-3)
    True
    """
    steps: list[tuple[str, RegistrationStep]] = []
    if global_method is not None:
        steps.append(("global", _make_step(global_method, GLOBAL_METHODS, "global_method")))
    refinements = refine if isinstance(refine, (list, tuple)) else [refine]
    previous = None
    for i, spec in enumerate(r for r in refinements if r is not None and r != "none"):
        if spec == "symmetry_check":  # twins are refined like the estimate was
            step = SymmetryCheck(refine=None if previous is None else clone(previous))
            steps.append(("symmetry_check", step))
            continue
        previous = _make_step(spec, REFINE_METHODS, "refine")
        steps.append((f"refine{i}" if i else "refine", previous))
    if not steps:
        raise ValueError("nothing to do: global_method and refine are both None")
    pipeline = RegistrationPipeline(
        steps,
        descriptor=descriptor,
        voxel_size=voxel_size,
        n_global_points=n_global_points,
        seed=seed,
        settings=settings,
    )
    return pipeline.register(source, target, init=init)
