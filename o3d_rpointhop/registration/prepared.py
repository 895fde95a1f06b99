"""Clouds prepared once for many registrations: the global step's cloud of a scan at a
given resolution, and its descriptors.

:func:`prepare_cloud` is the one way a cloud becomes a prepared cloud. A single
registration prepares its two clouds as the first stage of its pipeline
(:meth:`RegistrationContext.prepare`); a caller that registers one scan to many (scan
sets: :func:`~o3d_rpointhop.register_multiway`) prepares every scan once, at one
resolution for all of them (:func:`~.settings.common_voxel`), and gives the context
the prepared scans.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import open3d as o3d

from .._utils.geometry import vectors
from ..descriptors import call_with_viewpoints

__all__ = [
    "NORMAL_NEIGHBOURS",
    "PreparedCloud",
    "describe_global",
    "estimate_normals",
    "prepare_cloud",
]

#: Most neighbours a normal is fitted to (within the settings' normal radius).
NORMAL_NEIGHBOURS = 30


@dataclass
class PreparedCloud:
    """A scan as the global step sees it.

    Attributes
    ----------
    points : ndarray of shape (n, 3)
        The global cloud, in the scan's own coordinates.
    features : ndarray of shape (n, d) or None
        The descriptors of ``points``, one row per point (``None``: not described; a
        global step then describes ``points`` itself).
    normals : ndarray of shape (n, 3) or None
        Normals of ``points`` for point-to-plane ICP on the global cloud (``None``: the
        context estimates them when a step needs them).
    """

    points: np.ndarray
    features: np.ndarray | None = None
    normals: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.points = np.asarray(self.points, dtype=np.float64)
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise ValueError(f"prepared points must be (n, 3), got {self.points.shape}")
        if self.features is not None:
            self.features = np.asarray(self.features)
            if self.features.ndim != 2 or len(self.features) != len(self.points):
                raise ValueError(
                    f"prepared features must be one row per point: {self.features.shape} "
                    f"for {len(self.points)} points"
                )
        if self.normals is not None:
            self.normals = np.asarray(self.normals, dtype=np.float64)
            if self.normals.shape != self.points.shape:
                raise ValueError(
                    f"prepared normals must be one per point: {self.normals.shape} for "
                    f"{len(self.points)} points"
                )


def estimate_normals(cloud: o3d.geometry.PointCloud, radius: float) -> None:
    """``cloud``'s normals, in place, as every registration estimates them: within
    ``radius``, at most :data:`NORMAL_NEIGHBOURS` neighbours (each point's own fit, the
    same on any thread count)."""
    search = o3d.geometry.KDTreeSearchParamHybrid(radius=float(radius), max_nn=NORMAL_NEIGHBOURS)
    cloud.estimate_normals(search)


def describe_global(
    descriptor: Any,
    cloud: Any,
    voxel: float,
    settings: Any = None,
    viewpoint: Any = None,
    n_turns: int = 1,
    with_normals: Callable[[], o3d.geometry.PointCloud] | None = None,
) -> np.ndarray:
    """A global cloud's descriptors as every registration computes them: with the
    distances the descriptor leaves to the registration bound to its resolution
    (``descriptor.at_resolution(voxel, settings)``: FPFH's ``"auto"`` radii), seen from
    ``viewpoint`` (the sensor position, in the cloud's coordinates) when given. The one
    route for a pair's context and for scans prepared once for many pairs.

    With ``n_turns`` above 1, the descriptors under each turn of the local frames about
    their normals (``transform_turns``), ``(n_turns, n_points, width)``.

    ``with_normals``: the same cloud with the normals :func:`estimate_normals` gives it
    at ``settings.normal_radius`` (a pair's context estimates them once); a descriptor
    that would estimate exactly those and takes a cloud's own (:func:`_same_normals`:
    FPFH at its ``"auto"`` radius) describes that cloud instead, to the same bits.

    Raises
    ------
    TypeError
        If a viewpoint is given to a descriptor whose ``transform`` takes none, or turns
        to one without local frames.
    """
    at = getattr(descriptor, "at_resolution", None)
    bound = descriptor if at is None else at(voxel, settings)
    if with_normals is not None and _same_normals(bound, settings):
        cloud = with_normals()
    if n_turns > 1:
        if not hasattr(bound, "transform_turns"):
            raise TypeError(
                f"frame turns were asked for, but {type(bound).__name__} has no local "
                "frames to turn (no transform_turns): use RPointHopTransformer, or "
                "Matcher(frame_turns=1)"
            )
        return np.asarray(call_with_viewpoints(bound.transform_turns, cloud, viewpoint, n_turns))
    return np.asarray(call_with_viewpoints(bound.transform, cloud, viewpoint))


def _same_normals(descriptor: Any, settings: Any) -> bool:
    """Whether ``descriptor`` (bound to the registration's resolution) takes a cloud's
    own normals and, for a cloud without, estimates them as :func:`estimate_normals`
    does at ``settings.normal_radius``: the same radius and neighbours, so the same
    normals."""
    return (
        settings is not None
        and getattr(descriptor, "use_existing_normals", False) is True
        and getattr(descriptor, "normal_max_nn", None) == NORMAL_NEIGHBOURS
        and getattr(descriptor, "normal_radius", None) == settings.normal_radius
    )


def prepare_cloud(
    points: Any,
    voxel: float,
    descriptor: Any = None,
    viewpoint: Any = None,
    normal_radius: float | None = None,
    settings: Any = None,
    *,
    downsample: bool = True,
    centre: Any = None,
) -> PreparedCloud:
    """A scan as the global step sees it at resolution ``voxel``: voxel-downsampled
    (unless ``downsample`` is False); with ``descriptor``, described as every
    registration describes its global clouds (:func:`describe_global`, with
    ``settings``, the registration's settings at ``voxel``; seen from ``viewpoint``, the
    scan's sensor position in its own coordinates, when given); with
    ``normal_radius``, with normals estimated within that radius
    (:func:`estimate_normals`); without it, an Open3D cloud's own normals are kept
    (averaged per voxel).

    The one way a cloud becomes a prepared cloud: a pair's
    :class:`~o3d_rpointhop.registration.context.RegistrationContext` prepares its two
    clouds here, :func:`~o3d_rpointhop.register_multiway` every scan once.

    Parameters
    ----------
    points : ndarray of shape (n, 3) or open3d.geometry.PointCloud
        Not modified.
    voxel : float
        The resolution: the voxel size, and the resolution the descriptor is bound to.
    descriptor, viewpoint, normal_radius, settings
        See above.
    downsample : bool, default=True
        False keeps the points as they are (a cloud already at the resolution).
    centre : array-like of shape (3,), default=None
        Where the grid's coordinates are measured from while downsampling, so that
        nothing is lost far from the origin; ``None``: the scan's own centroid. The
        points come back in the scan's coordinates either way.

    Returns
    -------
    PreparedCloud
    """
    if isinstance(points, o3d.geometry.PointCloud):
        cloud = o3d.geometry.PointCloud(points)
    else:
        cloud = o3d.geometry.PointCloud(vectors(np.asarray(points)))
    origin = np.zeros(3)
    if downsample:
        origin = np.asarray(cloud.points).mean(axis=0) if centre is None else np.asarray(centre)
        if origin.any():
            cloud.translate(-origin)
        cloud = cloud.voxel_down_sample(voxel)
    if normal_radius is not None:
        estimate_normals(cloud, normal_radius)
    normals = np.asarray(cloud.normals).copy() if cloud.has_normals() else None
    kept = np.asarray(cloud.points).copy()
    if origin.any():
        kept += origin
    features = None
    if descriptor is not None:
        features = describe_global(descriptor, kept, voxel, settings, viewpoint)
    return PreparedCloud(kept, features, normals)
