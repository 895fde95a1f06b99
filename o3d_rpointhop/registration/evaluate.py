"""Scoring a transformation obtained elsewhere: Open3D's ``evaluate_registration`` with
this library's resolution and flags."""

from __future__ import annotations

import time
from numbers import Real
from typing import Any

from .._utils.params import Interval, StrOptions, validate_params
from .._utils.validation import check_rigid_transformation
from .context import RegistrationContext
from .flags import assess
from .result import RegistrationResult, StepResult
from .settings import RegistrationSettings

__all__ = ["evaluate"]


@validate_params(
    {
        "source": "no_validation",
        "target": "no_validation",
        "transformation": "no_validation",  # checked as a rigid motion, below
        "distance": [None, Interval(Real, 0, None, closed="neither")],
        "voxel_size": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "settings": [None, RegistrationSettings],
        "assess_ambiguity": ["boolean"],
    },
    prefer_skip_nested_validation=True,
)
def evaluate(
    source: Any,
    target: Any,
    transformation: Any,
    *,
    distance: float | None = None,
    voxel_size: float | str = "auto",
    settings: RegistrationSettings | None = None,
    assess_ambiguity: bool = True,
) -> RegistrationResult:
    """Measure how well ``transformation`` maps ``source`` onto ``target``.

    What :func:`~o3d_rpointhop.register` reports about its own estimate, for a
    transformation from anywhere (another tool, a pose file, a hand-made guess): the
    fitness and inlier RMSE at ``distance`` (as Open3D's ``evaluate_registration``),
    the inlier pairs, and the ``converged`` / ``ambiguous`` flags. No step runs and no
    warning is issued: the flags are in the result.

    Parameters
    ----------
    source, target : array-like (n, 3) or Open3D point cloud
    transformation : array-like of shape (4, 4)
        Maps source points into the target frame (Open3D's convention).
    distance : float, default=None
        Correspondence distance of the fitness; ``None`` is the settings'
        ``fitness_distance`` (the last ICP pass's, 0.5 resolution by default), where
        :func:`~o3d_rpointhop.register` measures its own result: the same
        transformation gets the same fitness from both.
    voxel_size : float or "auto", default="auto"
        The resolution, as in :func:`~o3d_rpointhop.register`.
    settings : RegistrationSettings, default=None
    assess_ambiguity : bool, default=True
        Measure ``ambiguous`` (three more evaluations).

    Returns
    -------
    RegistrationResult
        With one step, ``"evaluate"``, holding the same numbers.

    Examples
    --------
    >>> import numpy as np
    >>> from o3d_rpointhop.datasets import make_object
    >>> from o3d_rpointhop.registration import evaluate
    >>> cloud = make_object(1500, shape_seed=2)
    >>> shift = np.eye(4); shift[0, 3] = -0.1
    >>> evaluate(cloud + [0.1, 0.0, 0.0], cloud, shift).fitness
    1.0
    """
    start = time.perf_counter()
    if isinstance(distance, bool):  # a Real to the declaration above, not a distance
        raise ValueError(
            f"The 'distance' parameter of evaluate must be None or a float in the range "
            f"(0.0, inf). Got {distance!r} instead."
        )
    matrix = check_rigid_transformation(transformation, "transformation")
    context = RegistrationContext(source, target, voxel_size=voxel_size, settings=settings)
    distance = float(distance or context.settings.fitness_distance)
    local = context.to_local(matrix)
    quality = assess(context, local, distance, assess_ambiguity)
    seconds = time.perf_counter() - start
    step = StepResult(
        name="evaluate",
        transformation=matrix,
        fitness=quality.final.fitness,
        inlier_rmse=quality.final.inlier_rmse,
        correspondence_set=quality.final.correspondence_set,
        seconds=seconds,
        distance=distance,
    )
    return RegistrationResult.from_quality(
        quality, matrix, [step], voxel_size=context.voxel_size, seconds=seconds, distance=distance
    )
