"""The base of every registration step: :class:`RegistrationStep` and :class:`StepResult`.

Every step is a scikit-learn estimator (``get_params``/``set_params``/``clone`` work,
parameters are checked declaratively from ``_parameter_constraints``) with one method,
:meth:`RegistrationStep.run`, that takes the shared
:class:`~o3d_rpointhop.registration.context.RegistrationContext` and the current
source-to-target transformation and returns a :class:`StepResult`. The concrete steps
live in :mod:`.global_estimators` (SVD, RANSAC, FGR) and :mod:`.icp` (the ICP
variants); this module imports neither.

Distances a step leaves as ``None`` come from ``context.settings``
(:class:`~o3d_rpointhop.registration.settings.RegistrationSettings`): named multiples of
the resolution, so the same step works on a unit-sphere object and on a scan in metres.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from numbers import Real

import numpy as np
import open3d as o3d
from sklearn.base import BaseEstimator
from sklearn.utils._param_validation import Interval

from .context import RegistrationContext

__all__ = ["evaluate", "repeatable_open3d", "StepResult", "RegistrationStep"]

reg = o3d.pipelines.registration

#: The constraint of an optional distance: ``None`` (from the settings) or positive.
OPTIONAL_DISTANCE = [None, Interval(Real, 0, None, closed="neither")]


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
        within ``distance``, as Open3D reports it.
    inlier_rmse : float
        RMS distance of those inliers.
    correspondence_set : ndarray of shape (m, 2)
        The step's inlier pairs ``(source index, target index)``; indices refer to the
        clouds the step worked on (global steps: the downsampled clouds).
    seconds : float
    info : dict
        Step-specific numbers (distances used, number of candidate matches, ...).
    distance : float
        The correspondence distance ``fitness`` and ``inlier_rmse`` were measured at.
    """

    name: str
    transformation: np.ndarray
    fitness: float
    inlier_rmse: float
    correspondence_set: np.ndarray
    seconds: float = 0.0
    info: dict = field(default_factory=dict)
    distance: float = 0.0

    def as_dict(self) -> dict:
        return {
            "name": self.name,
            "transformation": self.transformation.tolist(),
            "fitness": self.fitness,
            "inlier_rmse": self.inlier_rmse,
            "n_correspondences": int(len(self.correspondence_set)),
            "seconds": self.seconds,
            "distance": self.distance,
            "info": self.info,
        }


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


def from_open3d(name: str, result, seconds: float, info: dict, distance: float) -> StepResult:
    """A :class:`StepResult` from Open3D's ``RegistrationResult``."""
    return StepResult(
        name=name,
        transformation=np.array(result.transformation),
        fitness=float(result.fitness),
        inlier_rmse=float(result.inlier_rmse),
        correspondence_set=np.asarray(result.correspondence_set, dtype=np.int64).reshape(-1, 2),
        seconds=seconds,
        info=info,
        distance=float(distance),
    )


def evaluate(
    context: RegistrationContext,
    transformation: np.ndarray,
    max_correspondence_distance: float,
    which: str = "full",
) -> StepResult:
    """Fitness, inlier RMSE and inlier pairs of ``transformation`` within
    ``max_correspondence_distance``, on the full-resolution clouds (``which="full"``)
    or the global step's (``"global"``)."""
    source, target = (
        (context.source, context.target)
        if which == "full"
        else (context.global_cloud("source"), context.global_cloud("target"))
    )
    distance = max_correspondence_distance
    with repeatable_open3d():
        result = reg.evaluate_registration(source, target, distance, transformation)
    return from_open3d("evaluation", result, 0.0, {"max_correspondence_distance": distance},
                       distance)  # fmt: skip


class RegistrationStep(BaseEstimator):
    """Base class of registration steps.

    Subclasses declare their parameters in ``_parameter_constraints`` (scikit-learn's
    declarative validation) and implement :meth:`_run`; :meth:`run` validates the
    parameters, times the step and returns its :class:`StepResult`.
    """

    #: ``"global"`` steps ignore the incoming transformation; ``"refine"`` steps start from it.
    kind = "refine"
    _parameter_constraints: dict = {}

    def run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        """Run the step; return its result (its transformation is absolute).

        Raises
        ------
        ValueError
            For a parameter outside its constraints (scikit-learn's
            ``InvalidParameterError``, a ``ValueError``).
        """
        self._validate_params()
        start = time.perf_counter()
        result = self._run(context, np.asarray(transformation, dtype=np.float64))
        result.seconds = time.perf_counter() - start
        return result

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        raise NotImplementedError
