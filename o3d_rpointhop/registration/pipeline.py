"""Registration chains (global first, then local) and the one-call ``register``."""

from __future__ import annotations

import numbers
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, clone

from .context import RegistrationContext
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
from .symmetry import SymmetryCheck

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
        Share of the (full-resolution) source points that have a target point within
        ``voxel_size`` after the transformation; the same yardstick whatever the steps
        (each step's own numbers, at its own thresholds, are in ``steps``).
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
    """

    transformation: np.ndarray
    fitness: float
    inlier_rmse: float
    correspondences: np.ndarray
    steps: list[StepResult] = field(default_factory=list)
    voxel_size: float = 0.0
    seconds: float = 0.0

    def as_dict(self) -> dict:
        """JSON-ready summary (the CLI's ``--json`` output)."""
        return {
            "transformation": self.transformation.tolist(),
            "fitness": self.fitness,
            "inlier_rmse": self.inlier_rmse,
            "n_correspondences": int(len(self.correspondences)),
            "voxel_size": self.voxel_size,
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
        current = np.eye(4) if init is None else _check_transformation(init)
        results = []
        for name, step in steps:
            outcome = step.run(context, current)
            outcome.name = name
            results.append(outcome)
            current = outcome.transformation
        final = evaluate(context, current, context.voxel_size)
        return RegistrationResult(
            transformation=current,
            fitness=final.fitness,
            inlier_rmse=final.inlier_rmse,
            correspondences=final.correspondences,
            steps=results,
            voxel_size=context.voxel_size,
            seconds=time.perf_counter() - start,
        )


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
