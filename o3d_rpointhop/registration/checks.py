"""Input a registration refuses or warns about: coincident and collinear clouds, planar
ones, and float32 coordinates too coarse for the cloud's size; and the warning class
every registration warning uses."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from .._utils.validation import coarse_float32

__all__ = ["RegistrationWarning", "check_geometry"]


class RegistrationWarning(UserWarning):
    """A registration result to treat with care: degenerate input, or a flagged result."""


# A cloud whose second principal extent is below this share of its first is a line, and
# whose third is below it, a plane (relative standard deviations).
_COLLINEAR = 1e-6
_PLANAR = 1e-4


def _raw_float32(cloud: Any) -> np.ndarray | None:
    """The caller's coordinates when they are float32 (numpy or tensor Open3D)."""
    if isinstance(cloud, np.ndarray) and cloud.dtype == np.float32:
        return cloud
    point = getattr(cloud, "point", None)
    if point is not None and "positions" in point:
        positions = point.positions
        if "Float32" in str(positions.dtype):
            return positions.cpu().numpy()
    return None


def check_geometry(points: np.ndarray, name: str, raw: Any = None) -> None:
    """Refuse clouds a rigid registration cannot be defined on, warn about risky ones.

    Raises
    ------
    ValueError
        If every point coincides, or the points lie on one line (a rotation about it
        cannot be recovered).

    Warns
    -----
    RegistrationWarning
        For a planar cloud (in-plane turns and flips may be undetermined; see
        ``RegistrationResult.ambiguous``), and for float32 coordinates whose rounding
        step is coarse for the cloud's size (survey coordinates: pass float64).
    """
    if not np.any(points != points[0]):
        raise ValueError(f"{name} has no spatial extent: all its points coincide")
    spread = np.sqrt(np.clip(np.linalg.eigvalsh(np.cov(points.T)), 0.0, None))[::-1]
    if spread[1] <= _COLLINEAR * spread[0]:
        raise ValueError(
            f"{name} is collinear (its points lie on one line): a rotation about that line "
            "cannot be recovered, so there is no rigid registration to find"
        )
    if spread[2] <= _PLANAR * spread[0]:
        warnings.warn(
            f"{name} is planar (flat to {spread[2] / spread[0]:.1e} of its size): turns "
            "within the plane and flips may be undetermined; check result.ambiguous",
            RegistrationWarning,
            stacklevel=4,
        )
    raw32 = _raw_float32(raw)
    problem = None if raw32 is None else coarse_float32(raw32, name)
    if problem is not None:
        warnings.warn(problem, RegistrationWarning, stacklevel=4)
