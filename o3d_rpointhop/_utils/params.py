"""The one import of scikit-learn's parameter validation.

``Interval``, ``Options``, ``StrOptions``, ``HasMethods`` and ``validate_params`` are what every
scikit-learn estimator checks its parameters with, and what makes ours answer a bad
value as scikit-learn's do (``InvalidParameterError``, a ``ValueError``). They live in
the private ``sklearn.utils._param_validation``; importing them here, and only here,
keeps a move in a future scikit-learn to one line.
"""

from collections.abc import Callable
from typing import Any, TypeVar

from sklearn.utils._param_validation import (
    HasMethods,
    Interval,
    InvalidParameterError,
    Options,
    StrOptions,
)
from sklearn.utils._param_validation import validate_params as _validate_params

__all__ = [
    "HasMethods",
    "Interval",
    "InvalidParameterError",
    "Options",
    "StrOptions",
    "validate_params",
]

_Function = TypeVar("_Function", bound=Callable[..., Any])


def validate_params(
    parameter_constraints: dict, *, prefer_skip_nested_validation: bool
) -> Callable[[_Function], _Function]:
    """scikit-learn's ``validate_params``, typed: the function it decorates keeps its
    signature and return type for type checkers (scikit-learn's own decorator is
    untyped, so ``register()`` would read as ``Any``)."""
    return _validate_params(
        parameter_constraints, prefer_skip_nested_validation=prefer_skip_nested_validation
    )
