"""Conversions between numpy arrays and Open3D objects."""

from __future__ import annotations

from typing import Any

import numpy as np
import open3d as o3d

from ._utils.geometry import vectors
from ._utils.validation import as_points, is_open3d_cloud

__all__ = ["to_open3d_feature", "to_point_cloud"]


def to_open3d_feature(descriptors: Any) -> o3d.pipelines.registration.Feature:
    """Wrap per-point descriptors as an Open3D registration ``Feature``.

    Parameters
    ----------
    descriptors : array-like of shape (n_points, n_features)
        E.g. the output of ``RPointHopTransformer.transform`` or ``FPFHTransformer``.

    Returns
    -------
    open3d.pipelines.registration.Feature
        ``feature.data`` has shape ``(n_features, n_points)``, as Open3D expects; it can
        go straight into ``registration_ransac_based_on_feature_matching`` or
        ``registration_fgr_based_on_feature_matching``.
    """
    arr = np.asarray(descriptors)
    if arr.ndim != 2:
        raise ValueError(f"descriptors must be a 2-D (n_points, n_features) array, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError("descriptors hold NaN or infinite values")
    feature = o3d.pipelines.registration.Feature()
    feature.data = np.ascontiguousarray(arr.T, dtype=np.float64)  # Open3D: float64 (dim, n)
    return feature


def to_point_cloud(cloud: Any, name: str = "cloud") -> o3d.geometry.PointCloud:
    """A legacy Open3D ``PointCloud`` from an array or any Open3D point cloud.

    A legacy cloud is copied (with its normals and colours), so the caller's object is
    never modified; a tensor cloud is converted; an array is validated like every input.
    """
    if isinstance(cloud, o3d.geometry.PointCloud):
        as_points(cloud, name)
        return o3d.geometry.PointCloud(cloud)
    if is_open3d_cloud(cloud):  # tensor PointCloud
        legacy = cloud.to_legacy()
        as_points(legacy, name)
        return legacy
    return o3d.geometry.PointCloud(vectors(as_points(cloud, name)))
