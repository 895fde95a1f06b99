"""What both descriptors share: the transform over one or many clouds, the output
width and the scikit-learn tags (in the manner of scikit-learn's ``_BasePCA``)."""

from __future__ import annotations

import inspect
from abc import ABCMeta, abstractmethod
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator, ClassNamePrefixFeaturesOutMixin, TransformerMixin

from .._utils.parallel import map_clouds
from .._utils.validation import as_cloud_list, as_viewpoints

__all__ = ["BaseDescriptor", "call_with_viewpoints"]


def call_with_viewpoints(method: Any, X: Any, viewpoints: Any, *args: Any) -> Any:
    """``method(X, *args)`` (a descriptor's ``transform`` or ``transform_turns``), with
    ``viewpoints`` when given.

    Raises
    ------
    TypeError
        If viewpoints are given and ``method`` takes none (a transformer from outside
        this library).
    """
    if viewpoints is None:
        return method(X, *args)
    if "viewpoints" not in inspect.signature(method).parameters:
        owner = type(method.__self__).__name__
        raise TypeError(
            f"viewpoints were given, but {owner}.{method.__name__} takes none: use a "
            "descriptor of this library, or leave viewpoints out"
        )
    return method(X, *args, viewpoints=viewpoints)


class BaseDescriptor(
    ClassNamePrefixFeaturesOutMixin, TransformerMixin, BaseEstimator, metaclass=ABCMeta
):
    """Base class of the point descriptors: one row per input point, in input order.

    Subclasses implement :meth:`_check_transform` (validate the parameters, once per
    call, and return what the call needs of them), :meth:`_per_cloud` (check the clouds
    and return the per-cloud arguments of :meth:`_describe`) and :meth:`_describe` (the
    descriptors of one validated cloud). The input forms, the parallel map over clouds
    and the form of the answer are handled here once.
    """

    @abstractmethod
    def _check_transform(self) -> Any:
        """Validate the parameters (and the fitted state) before any work; return the
        checked settings :meth:`_per_cloud` needs."""

    @abstractmethod
    def _per_cloud(self, X: Any, clouds: list[np.ndarray], kind: str, settings: Any) -> list:
        """Check the clouds; return the per-cloud argument of :meth:`_describe`, one
        per cloud."""

    @abstractmethod
    def _describe(self, points: np.ndarray, extra: Any, viewpoint: Any) -> np.ndarray:
        """Descriptors ``(n_points, n_features_out_)`` of one validated cloud, with its
        per-cloud argument from :meth:`_per_cloud` and its sensor position (or None)."""

    def transform(self, X: Any, viewpoints: Any = None) -> np.ndarray | list[np.ndarray]:
        """Describe every point of one or several clouds.

        Parameters
        ----------
        X : array-like of shape (n_points, 3) or (n_clouds, n_points, 3), \
                open3d.geometry.PointCloud, or list of those
            Clouds of any size, in any position and metric scale.
        viewpoints : None, "origin", array-like of shape (3,) or (n_clouds, 3), \
                default=None
            Where the sensor that saw each cloud stood, in that cloud's coordinates:
            surface normals (and, for R-PointHop, every local frame's normal axis)
            then face the sensor, as a scanned surface does. ``"origin"``: every cloud
            is in its sensor's frame (a 3DMatch fragment, a LiDAR sweep, a depth
            image's points). ``None``: no sensor is known, and the descriptor's own
            rule orients them. The descriptors are exactly invariant to a rigid motion
            that moves the viewpoint with the cloud.

        Returns
        -------
        descriptors : ndarray of shape (n_points, n_features_out_), or a list of such
            arrays for a list input, or an ndarray of shape
            (n_clouds, n_points, n_features_out_) for a 3-D array input. Row ``i``
            describes input point ``i``. Several clouds are described as ``n_jobs``
            parallel joblib tasks.
        """
        settings = self._check_transform()
        clouds, kind = as_cloud_list(X)
        views = as_viewpoints(viewpoints, len(clouds))
        extras = self._per_cloud(X, clouds, kind, settings)
        return map_clouds(self._describe, clouds, kind, self.n_jobs, extras, views)

    def fit_transform(self, X: Any, y: Any = None, viewpoints: Any = None) -> Any:
        """:meth:`fit` then :meth:`transform`, with the same ``viewpoints``.

        Parameters
        ----------
        X : point cloud(s)
        y : None
            Ignored.
        viewpoints : None, "origin" or positions, default=None
            As in :meth:`transform`.

        Returns
        -------
        descriptors : as :meth:`transform` returns them
        """
        return self.fit(X, y, viewpoints=viewpoints).transform(X, viewpoints=viewpoints)

    def validate(self) -> None:
        """Check every parameter against its constraints without fitting or describing.

        Raises
        ------
        ValueError
            Naming the first bad parameter (scikit-learn's ``InvalidParameterError``).
        """
        self._validate_params()

    def at_resolution(self, voxel_size: float, settings: Any = None) -> BaseDescriptor:
        """The descriptor a registration at resolution ``voxel_size`` describes with:
        this one, unless it has distances left to the registration (FPFH's ``"auto"``
        radii). ``settings``: the registration's
        :class:`~o3d_rpointhop.registration.RegistrationSettings`, bound to the
        resolution, whose multiples such distances follow."""
        return self

    @property
    def _n_features_out(self) -> int:
        return self.n_features_out_

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.three_d_array = True
        return tags
