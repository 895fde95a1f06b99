"""Scoring registrations against known transformations, for ``GridSearchCV`` and friends.

A registration "dataset" is a list of ``(source, target)`` pairs ``X`` with their true
source-to-target transformations ``y``; :func:`registration_scorer` turns a
:class:`~o3d_rpointhop.RegistrationPipeline` into a number scikit-learn can maximise:
the share of pairs registered within a rotation and a translation tolerance
(registration recall).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..transforms import rotation_error_deg, translation_error

__all__ = ["check_pairs", "registration_recall", "registration_scorer"]


def check_pairs(X: Any) -> list[tuple[Any, Any]]:
    """``X`` as a list of ``(source, target)`` pairs.

    Raises
    ------
    ValueError
        If ``X`` is not a non-empty sequence of two-element items.
    """
    try:
        pairs = [tuple(pair) for pair in X]
    except TypeError:
        pairs = None
    if not pairs or any(len(pair) != 2 for pair in pairs):
        raise ValueError(
            "X must be a non-empty list of (source, target) pairs of point clouds, got "
            f"{type(X).__name__}"
        )
    return pairs


def registration_recall(
    results: list,
    y: Any,
    max_rotation_deg: float = 5.0,
    max_translation: float | None = None,
) -> float:
    """The share of ``results`` within tolerance of the true transformations ``y``.

    Parameters
    ----------
    results : list of RegistrationResult
    y : array-like of shape (n_pairs, 4, 4)
    max_rotation_deg : float, default=5.0
    max_translation : float, default=None
        In the clouds' units; ``None`` is two resolutions of each registration
        (``2 x result.voxel_size``), so that one scorer fits objects and scenes.

    Returns
    -------
    float
    """
    truth = np.asarray(y, dtype=np.float64)
    if truth.shape != (len(results), 4, 4):
        raise ValueError(
            f"y must hold one 4x4 transformation per pair, shape ({len(results)}, 4, 4); "
            f"got {truth.shape}"
        )
    hits = [
        rotation_error_deg(r.transformation, t) <= max_rotation_deg
        and translation_error(r.transformation, t)
        <= (2.0 * r.voxel_size if max_translation is None else max_translation)
        for r, t in zip(results, truth, strict=True)
    ]
    return float(np.mean(hits))


def registration_scorer(
    max_rotation_deg: float = 5.0, max_translation: float | None = None
) -> Callable[[Any, Any, Any], float]:
    """A scikit-learn scorer ``scorer(pipeline, X, y)``: registration recall.

    Pass it as ``scoring=`` to ``GridSearchCV`` or ``cross_val_score`` with a
    :class:`~o3d_rpointhop.RegistrationPipeline`, ``X`` a list of ``(source, target)``
    pairs and ``y`` their true transformations. Higher is better.

    Parameters
    ----------
    max_rotation_deg : float, default=5.0
    max_translation : float, default=None
        ``None`` is two resolutions of each registration.

    Examples
    --------
    >>> from o3d_rpointhop.registration import registration_scorer
    >>> scorer = registration_scorer(max_rotation_deg=2.0)
    """

    def scorer(estimator: Any, X: Any, y: Any) -> float:
        results = estimator.register_pairs(X)
        return registration_recall(results, y, max_rotation_deg, max_translation)

    return scorer
