"""The one import of scikit-learn's parameter validation.

``Interval``, ``StrOptions``, ``HasMethods`` and ``validate_params`` are what every
scikit-learn estimator checks its parameters with, and what makes ours answer a bad
value as scikit-learn's do (``InvalidParameterError``, a ``ValueError``). They live in
the private ``sklearn.utils._param_validation``; importing them here, and only here,
keeps a move in a future scikit-learn to one line.
"""

from sklearn.utils._param_validation import (
    HasMethods,
    Interval,
    InvalidParameterError,
    StrOptions,
    validate_params,
)

__all__ = ["HasMethods", "Interval", "InvalidParameterError", "StrOptions", "validate_params"]
