"""The base of every registration step: :class:`RegistrationStep`.

Every step is a scikit-learn estimator (``get_params``/``set_params``/``clone`` work,
parameters are checked declaratively from ``_parameter_constraints``) with one method,
:meth:`RegistrationStep.run`, that takes the shared
:class:`~o3d_rpointhop.registration.context.RegistrationContext` and the current
source-to-target transformation and returns a
:class:`~o3d_rpointhop.registration.result.StepResult`.

Distances a step leaves as ``None`` come from ``context.settings``
(:class:`~o3d_rpointhop.registration.settings.RegistrationSettings`): named multiples of
the resolution, so the same step works on a unit-sphere object and on a scan in metres.
"""

from __future__ import annotations

import time
from numbers import Real

import numpy as np
from sklearn.base import BaseEstimator

from ..._utils.params import Interval
from ..context import RegistrationContext
from ..result import StepResult

__all__ = ["OPTIONAL_DISTANCE", "RegistrationStep"]

#: The constraint of an optional distance: ``None`` (from the settings) or positive.
OPTIONAL_DISTANCE = [None, Interval(Real, 0, None, closed="neither")]


class RegistrationStep(BaseEstimator):
    """Base class of registration steps.

    Subclasses declare their parameters in ``_parameter_constraints`` (scikit-learn's
    declarative validation), may add the checks that relate parameters to each other in
    :meth:`_check_params`, and implement :meth:`_run`; :meth:`run` validates the
    parameters, times the step and returns its
    :class:`~o3d_rpointhop.registration.result.StepResult`. A caller that validated a
    step once (:class:`~o3d_rpointhop.RegistrationPipeline` validates every step before
    the first runs) runs it through :meth:`_run_timed`, which does not check again.
    """

    #: ``"global"`` steps ignore the incoming transformation; ``"refine"`` steps start from it.
    kind = "refine"
    #: The step's one name: its key in the pipeline's tables (``GLOBAL_METHODS``,
    #: ``REFINE_METHODS``), its section in a config file, and its results' name when it
    #: runs alone.
    name = "step"
    _parameter_constraints: dict = {}

    def validate(self) -> None:
        """Check every parameter (declaratively, then :meth:`_check_params`) without
        running the step.

        Raises
        ------
        ValueError
            Naming the first bad parameter (scikit-learn's ``InvalidParameterError`` for
            the declarative part).
        """
        self._validate_params()
        self._check_params()

    def _check_params(self) -> None:
        """Checks beyond the declarative constraints; nothing by default."""

    def _descriptors(self) -> tuple:
        """The descriptors whose features the step will read, as ``(descriptor,
        n_turns)`` (``None``: the context's own; ``n_turns`` as
        :meth:`~o3d_rpointhop.registration.context.RegistrationContext.features`
        takes it): what the pipeline's preparation stage computes before the first
        step. None by default."""
        return ()

    def run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        """Validate the parameters, then run the step; return its result (its
        transformation is absolute, in the context's centred frame).

        Raises
        ------
        ValueError
            For a parameter outside its constraints.
        """
        self.validate()
        return self._run_timed(context, transformation)

    def _run_timed(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        """:meth:`run` without the validation, for a caller that validated the step."""
        start = time.perf_counter()
        result = self._run(context, np.asarray(transformation, dtype=np.float64))
        result.seconds = time.perf_counter() - start
        return result

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        raise NotImplementedError
