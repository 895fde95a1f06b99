"""Registration chains (global first, then local) and the one-call ``register``."""

from __future__ import annotations

import numbers
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, clone

from .context import RegistrationContext, RegistrationWarning
from .steps import (
    FGRGlobal,
    GeneralizedICP,
    MultiScaleICP,
    PointToPlaneICP,
    PointToPointICP,
    RANSACGlobal,
    RegistrationStep,
    StepResult,
    SVDGlobal,
    evaluate,
)
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
    correspondences : ndarray of shape (m, 2)
        Those inlier pairs ``(source index, target index)``.
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
    correspondences: np.ndarray
    steps: list[StepResult] = field(default_factory=list)
    voxel_size: float = 0.0
    seconds: float = 0.0
    distance: float = 0.0
    converged: bool = True
    ambiguous: bool = False

    @property
    def correspondence_set(self) -> np.ndarray:
        """Open3D's name for :attr:`correspondences`."""
        return self.correspondences

    def to_open3d(self):
        """This result as an ``open3d.pipelines.registration.RegistrationResult``
        (transformation, fitness, inlier RMSE and correspondence set)."""
        import open3d as o3d

        out = o3d.pipelines.registration.RegistrationResult()
        out.transformation = np.asarray(self.transformation, dtype=np.float64)
        out.fitness = float(self.fitness)
        out.inlier_rmse = float(self.inlier_rmse)
        out.correspondence_set = o3d.utility.Vector2iVector(
            np.asarray(self.correspondences, dtype=np.int32).reshape(-1, 2)
        )
        return out

    def as_dict(self) -> dict:
        """JSON-ready summary (the CLI's ``--json`` output)."""
        return {
            "transformation": self.transformation.tolist(),
            "fitness": self.fitness,
            "inlier_rmse": self.inlier_rmse,
            "n_correspondences": int(len(self.correspondences)),
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


class RegistrationPipeline(BaseEstimator):
    """A chain of registration steps, run in order: a global estimate, then refinements.

    Like a scikit-learn ``Pipeline``, its steps are named and their parameters are
    reachable as ``<step>__<parameter>`` through :meth:`get_params` / :meth:`set_params`;
    it can be cloned.

    Parameters
    ----------
    steps : list of (str, RegistrationStep)
    descriptor : transformer, default=None
        Descriptor for global steps that do not name their own; ``None`` is the
        pretrained R-PointHop model.
    voxel_size : float or "auto", default="auto"
        Resolution of the registration. ``"auto"``: clouds of up to ``n_global_points``
        points are used as they are, with their point spacing as the resolution; larger
        clouds are voxel-downsampled for the global step to about ``n_global_points``
        points. ICP steps always use the full clouds. Distances the steps leave unset
        are multiples of it.
    n_global_points : int, default=2048
    seed : int, default=0
        Seeds the random parts (RANSAC, FGR): results are repeatable.

    Examples
    --------
    >>> from o3d_rpointhop import RegistrationPipeline, RANSACGlobal, PointToPlaneICP
    >>> pipe = RegistrationPipeline([("global", RANSACGlobal()), ("icp", PointToPlaneICP())])
    >>> pipe.set_params(icp__max_iteration=100).named_steps["icp"].max_iteration
    100
    """

    def __init__(
        self,
        steps: list[tuple[str, RegistrationStep]],
        descriptor: Any = None,
        voxel_size: float | str = "auto",
        n_global_points: int = 2048,
        seed: int = 0,
    ) -> None:
        self.steps = steps
        self.descriptor = descriptor
        self.voxel_size = voxel_size
        self.n_global_points = n_global_points
        self.seed = seed

    @property
    def named_steps(self) -> dict[str, RegistrationStep]:
        return dict(_check_steps(self.steps))

    def get_params(self, deep: bool = True) -> dict:
        params = super().get_params(deep=False)
        if deep:
            for name, step in self.steps:
                params[name] = step
                for key, value in step.get_params(deep=True).items():
                    params[f"{name}__{key}"] = value
        return params

    def set_params(self, **params) -> RegistrationPipeline:
        steps = list(self.steps)
        names = [name for name, _ in steps]
        for name in [k for k in params if k in names]:
            steps[names.index(name)] = (name, params.pop(name))
        self.steps = steps
        nested: dict[str, dict] = {}
        for key in list(params):
            if "__" in key:
                name, sub = key.split("__", 1)
                if name not in names:
                    raise ValueError(f"no step named {name!r} (steps: {names})")
                nested.setdefault(name, {})[sub] = params.pop(key)
        super().set_params(**params)
        for name, sub in nested.items():
            dict(self.steps)[name].set_params(**sub)
        return self

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
        steps = _check_steps(self.steps)
        if not (isinstance(self.n_global_points, numbers.Integral) and self.n_global_points >= 3):
            raise ValueError(f"n_global_points must be an int >= 3, got {self.n_global_points!r}")
        start = time.perf_counter()
        context = RegistrationContext(
            source,
            target,
            voxel_size=self.voxel_size,
            n_global_points=self.n_global_points,
            seed=self.seed,
            descriptor=self.descriptor,
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
        wide = max(distance, SPREAD_DISTANCE * context.voxel_size)
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
            correspondences=final.correspondences,
            steps=results,
            voxel_size=context.voxel_size,
            seconds=time.perf_counter() - start,
            distance=distance,
            converged=converged,
            ambiguous=ambiguous,
        )


#: Fitness below which a result is flagged as not converged.
MIN_FITNESS = 0.02
#: Inlier RMSE within SPREAD_DISTANCE resolutions, as a share of that distance, above
#: which a result is flagged as not converged (a chance alignment).
SPREAD_DISTANCE = 3.0
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
    n_global_points: int = 2048,
    init: np.ndarray | None = None,
    seed: int = 0,
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
    n_global_points : int, default=2048
    init : ndarray of shape (4, 4), default=None
        Start for ICP when there is no global step.
    seed : int, default=0

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
    )
    return pipeline.register(source, target, init=init)
