"""What the steps of one registration share: the clouds, their resolution, and caches."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np
import open3d as o3d

from ..fpfh import point_spacing
from ..open3d_interop import to_point_cloud

__all__ = ["RegistrationContext", "resolve_voxel_size"]


def resolve_voxel_size(
    source: o3d.geometry.PointCloud,
    target: o3d.geometry.PointCloud,
    voxel_size: float | str,
    n_global_points: int,
) -> tuple[float, bool]:
    """The resolution of a registration, and whether the global step downsamples.

    ``"auto"``: clouds of at most ``n_global_points`` points are used as they are, and
    the resolution is their point spacing (the larger of the two median
    nearest-neighbour distances); larger clouds are voxel-downsampled, with a voxel
    chosen so that the larger cloud keeps about ``n_global_points`` points. A number is
    used as the voxel size directly.
    """
    if isinstance(voxel_size, numbers.Real) and not isinstance(voxel_size, bool):
        if not (np.isfinite(voxel_size) and voxel_size > 0):
            raise ValueError(f"voxel_size must be positive, got {voxel_size!r}")
        return float(voxel_size), True
    if voxel_size != "auto":
        raise ValueError(f"voxel_size must be 'auto' or a positive number, got {voxel_size!r}")
    src, tgt = np.asarray(source.points), np.asarray(target.points)
    spacing = max(point_spacing(src), point_spacing(tgt))
    largest = max(len(src), len(tgt))
    if largest <= n_global_points:
        return spacing, False
    # Surfaces: the point count falls with the square of the voxel size.
    voxel = spacing * np.sqrt(largest / n_global_points)
    for _ in range(10):
        kept = max(len(c.voxel_down_sample(voxel).points) for c in (source, target))
        if kept <= 1.15 * n_global_points:
            break
        voxel *= np.sqrt(kept / n_global_points)
    return float(voxel), True


class RegistrationContext:
    """Source, target, resolution and per-registration caches shared by the steps.

    Parameters
    ----------
    source, target : array-like (n, 3) or Open3D point cloud
        Copied: the caller's objects are never modified.
    voxel_size : float or "auto"
        See :func:`resolve_voxel_size`.
    n_global_points : int
        Size the global step aims for when it downsamples.
    seed : int
        Seeds every random choice (Open3D's RANSAC and FGR).
    descriptor : transformer or None
        Descriptor used by global steps that do not name their own.

    Attributes
    ----------
    voxel_size : float
        The resolution: thresholds of the steps are multiples of it unless given.
    downsampled : bool
        Whether the global step works on voxel-downsampled clouds.
    """

    def __init__(
        self,
        source: Any,
        target: Any,
        voxel_size: float | str = "auto",
        n_global_points: int = 2048,
        seed: int = 0,
        descriptor: Any = None,
    ) -> None:
        self.source = to_point_cloud(source, "source")
        self.target = to_point_cloud(target, "target")
        self.voxel_size, self.downsampled = resolve_voxel_size(
            self.source, self.target, voxel_size, n_global_points
        )
        self.seed = int(seed)
        self.descriptor = descriptor
        self._global: dict[str, o3d.geometry.PointCloud] = {}
        self._features: dict[tuple[int, str], np.ndarray] = {}
        self._normals: dict[tuple, o3d.geometry.PointCloud] = {}
        self._coarse: RegistrationContext | None = None

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
                seed=self.seed,
                descriptor=self.descriptor,
            )
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
