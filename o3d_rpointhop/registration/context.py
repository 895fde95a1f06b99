"""What the steps of one registration share: the clouds, their resolution, and caches.

The context works in a frame centred on the target's centroid: survey, LiDAR and
photogrammetry clouds sit millions of units from the origin, where ICP's normal
equations and float32 scoring lose every digit that matters. The steps see centred
clouds; :meth:`RegistrationContext.to_world` maps their transformations back.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import open3d as o3d

from ..open3d_interop import to_point_cloud
from .settings import (
    DEFAULT_GLOBAL_POINTS,
    RegistrationSettings,
    resolve_global_points,
    resolve_voxel_size,
)

__all__ = ["RegistrationContext", "RegistrationWarning", "check_geometry", "global_points"]

# A cloud whose second principal extent is below this share of its first is a line, and
# whose third is below it, a plane (relative standard deviations).
_COLLINEAR = 1e-6
_PLANAR = 1e-4
# float32 coordinates whose rounding step exceeds this share of the cloud's extent.
_FLOAT32_RESOLUTION = 1e-5


class RegistrationWarning(UserWarning):
    """A registration result to treat with care: degenerate input, or a flagged result."""


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
    if raw32 is not None:
        step = float(np.spacing(np.float32(np.abs(raw32).max())))
        extent = float(points.max(axis=0).max() - points.min(axis=0).min())
        if step > _FLOAT32_RESOLUTION * extent:
            warnings.warn(
                f"{name} holds float32 coordinates up to {np.abs(raw32).max():.6g}, where "
                f"float32 resolves only {step:.3g}, coarse for a cloud {extent:.3g} across: "
                "its points were already rounded before registration; pass float64 "
                "(or coordinates relative to a local origin) for full precision",
                RegistrationWarning,
                stacklevel=4,
            )


class RegistrationContext:
    """Source, target, resolution and per-registration caches shared by the steps.

    Parameters
    ----------
    source, target : array-like (n, 3) or Open3D point cloud
        Copied: the caller's objects are never modified.
    voxel_size : float or "auto"
        See :func:`~o3d_rpointhop.registration.settings.resolve_voxel_size`.
    n_global_points : int or "auto"
        Size the global step aims for when it downsamples; see
        :func:`~o3d_rpointhop.registration.settings.resolve_global_points`.
    seed : int
        Seeds every random choice (Open3D's RANSAC and FGR).
    descriptor : transformer or None
        Descriptor used by global steps that do not name their own.
    settings : RegistrationSettings or None
        The multiples of the resolution; ``None`` is ``RegistrationSettings()``.

    Attributes
    ----------
    settings : RegistrationSettings
        Bound to this registration's resolution: every distance a step is not given.
    voxel_size : float
        The resolution (``settings.voxel_size``).
    n_global_points : int
        The size the global step aims for, resolved.
    downsampled : bool
        Whether the global step works on voxel-downsampled clouds.
    origin : ndarray of shape (3,)
        The caller's coordinates of the centred frame's origin (the target's centroid);
        ``source`` and ``target`` are in the centred frame.
    """

    def __init__(
        self,
        source: Any,
        target: Any,
        voxel_size: float | str = "auto",
        n_global_points: int | str = "auto",
        seed: int = 0,
        descriptor: Any = None,
        check: bool = True,
        settings: RegistrationSettings | None = None,
    ) -> None:
        self.source = to_point_cloud(source, "source")
        self.target = to_point_cloud(target, "target")
        self.origin = np.asarray(self.target.get_center(), dtype=np.float64)
        self.source.translate(-self.origin)
        self.target.translate(-self.origin)
        if check:
            check_geometry(np.asarray(self.source.points), "source", source)
            check_geometry(np.asarray(self.target.points), "target", target)
        self.n_global_points = resolve_global_points(n_global_points, descriptor)
        voxel, self.downsampled = resolve_voxel_size(
            self.source, self.target, voxel_size, self.n_global_points
        )
        if settings is not None and not isinstance(settings, RegistrationSettings):
            raise ValueError(f"settings must be a RegistrationSettings, got {settings!r}")
        self.settings = (settings or RegistrationSettings()).at(voxel)
        self.seed = int(seed)
        self.descriptor = descriptor
        self._global: dict[str, o3d.geometry.PointCloud] = {}
        self._features: dict[tuple[int, str], np.ndarray] = {}
        self._normals: dict[tuple, o3d.geometry.PointCloud] = {}
        self._coarse: RegistrationContext | None = None

    @property
    def voxel_size(self) -> float:
        return self.settings.voxel_size

    def to_world(self, transformation: np.ndarray) -> np.ndarray:
        """A centred-frame transformation in the caller's coordinates."""
        out = np.array(transformation, dtype=np.float64)
        out[:3, 3] += self.origin - out[:3, :3] @ self.origin
        return out

    def to_local(self, transformation: np.ndarray) -> np.ndarray:
        """A caller's transformation in the centred frame (inverse of :meth:`to_world`)."""
        out = np.array(transformation, dtype=np.float64)
        out[:3, 3] -= self.origin - out[:3, :3] @ self.origin
        return out

    def cloud(self, which: str) -> o3d.geometry.PointCloud:
        """The full-resolution ``"source"`` or ``"target"``."""
        return self.source if which == "source" else self.target

    def global_cloud(self, which: str) -> o3d.geometry.PointCloud:
        """The cloud the global step works on (downsampled when the clouds are large)."""
        if which not in self._global:
            full = self.cloud(which)
            self._global[which] = (
                full.voxel_down_sample(self.voxel_size) if self.downsampled else full
            )
        return self._global[which]

    def coarse(self) -> RegistrationContext:
        """A context whose clouds are this one's global clouds, at the same resolution
        (for cheap trial refinements); ``self`` when the global step does not downsample."""
        if not self.downsampled:
            return self
        if self._coarse is None:
            self._coarse = RegistrationContext(
                self.global_cloud("source"),
                self.global_cloud("target"),
                voxel_size=self.voxel_size,
                n_global_points=self.n_global_points,
                seed=self.seed,
                descriptor=self.descriptor,
                check=False,
                settings=self.settings,
            )
            # The same frame as this context (its clouds are centred already, but their
            # own centroid may differ slightly): transformations carry over unchanged.
            self._coarse.source.translate(self._coarse.origin)
            self._coarse.target.translate(self._coarse.origin)
            self._coarse.origin = np.zeros(3)
        return self._coarse

    def features(self, descriptor: Any, which: str) -> np.ndarray:
        """Descriptors of the global cloud, computed once per descriptor object."""
        key = (id(descriptor), which)
        if key not in self._features:
            cloud = self.global_cloud(which)
            try:
                self._features[key] = np.asarray(descriptor.transform(cloud))
            except ValueError as exc:
                detail = (
                    f" (after voxel downsampling at {self.voxel_size:.6g})"
                    if self.downsampled
                    else ""
                )
                raise ValueError(
                    f"cannot describe the {which} cloud, {len(cloud.points)} points{detail}: {exc}"
                ) from exc
        return self._features[key]

    def with_normals(self, cloud: o3d.geometry.PointCloud, which: str, radius: float):
        """``cloud`` with normals: its own if it has them, else estimated (and cached)."""
        if cloud.has_normals():
            return cloud
        key = (which, round(radius, 12), len(cloud.points))
        if key not in self._normals:
            copy = o3d.geometry.PointCloud(cloud)
            copy.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=30))
            self._normals[key] = copy
        return self._normals[key]


def global_points(points: Any, n_global_points: int = DEFAULT_GLOBAL_POINTS) -> np.ndarray:
    """A cloud as ``register()``'s global step sees it when registered to itself:
    voxel-downsampled to about ``n_global_points`` points (as it is, if smaller), in the
    cloud's own coordinates. What a model for ``register()`` should be fitted on."""
    context = RegistrationContext(points, points, n_global_points=n_global_points)
    return np.asarray(context.global_cloud("source").points) + context.origin
