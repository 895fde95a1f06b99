"""One resolution, and every distance of a registration derived from it in one place.

A registration has one length scale, its resolution (``voxel_size``): the voxel of the
global step's clouds, or their point spacing when they are used as they are. Every
distance a step needs and is not given (RANSAC's inlier distance, ICP's correspondence
distances, the radius of the normals, ...) is a named multiple of it, held by
:class:`RegistrationSettings`. Steps read ``context.settings``; nothing else multiplies
the resolution. The multiples follow Open3D's global registration tutorial where it
gives one (normals 2x, FPFH 5x, RANSAC 1.5x) and were measured on training data
otherwise (docs/registration.md, "Settings").

The two rules that choose a resolution live here too: :func:`resolve_voxel_size` for a
pair, :func:`common_voxel` for a set of scans registered together.
"""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass

import numpy as np

from .._utils.geometry import point_spacing
from .._utils.validation import is_positive_number
from ..descriptors import FEATURE_RADIUS_FACTOR, NORMAL_RADIUS_FACTOR

__all__ = ["RegistrationSettings", "common_voxel", "resolve_voxel_size"]

# Small clouds whose point spacings differ by more than this factor are downsampled.
_DENSITY_RATIO = 0.5


@dataclass(frozen=True)
class RegistrationSettings:
    """The multiples of the resolution that every registration distance is derived from.

    Unbound (``voxel_size=None``) it is a recipe; :meth:`at` binds it to a resolution,
    and the distance properties (``ransac_distance``, ``icp_distances``, ...) are then
    in the clouds' units. Every registration builds one per pair
    (``RegistrationContext.settings``); pass your own to :func:`~o3d_rpointhop.register`
    or :class:`~o3d_rpointhop.RegistrationPipeline` to change a multiple everywhere it
    is used.

    Parameters
    ----------
    voxel_size : float, default=None
        The resolution; ``None`` until :meth:`at` binds it.
    ransac_factor : float, default=1.5
        RANSAC's inlier distance (Open3D's tutorial: 1.5 voxels).
    fgr_factor : float, default=1.0
        FGR's ``maximum_correspondence_distance``.
    evaluation_factor : float, default=1.0
        Where the one-shot SVD estimate is scored.
    icp_factors : tuple of float, default=(2.0, 0.5)
        ICP's correspondence distances, one pass each, coarse to fine: the first pulls
        in the global estimate, the second leaves out points without a partner in a
        partial overlap (on the Stanford Bunny scans it cuts the worst pair's error from
        1.4 deg / 3 mm to 0.14 deg / 0.3 mm).
    normal_radius_factor : float, default=2.0
        Radius of estimated normals (point-to-plane ICP, FPFH; Open3D's tutorial).
    feature_radius_factor : float, default=5.0
        FPFH's histogram radius (Open3D's tutorial).
    symmetry_factor : float, default=2.0
        Truncation distance of :class:`~o3d_rpointhop.SymmetryCheck`'s score (ICP's
        first pass).
    spread_factor : float, default=3.0
        Where ``RegistrationResult.converged`` measures the spread of the inliers.
    edge_factor : float, default=1.5
        Multiway registration: edge fitness, information matrices and the pose graph's
        correspondence distance.
    consensus_factor : float, default=2.0
        :class:`~o3d_rpointhop.ConsensusGlobal`: the largest length difference of two
        compatible matches (SC2-PCR's 10 cm at 3DMatch's 5 cm voxels).
    second_order_factor : float, default=1.0
        :class:`~o3d_rpointhop.ConsensusGlobal`: the length difference of its
        second-order graph (SC2-PCR's 5 cm).
    score_factor : float, default=2.0
        :class:`~o3d_rpointhop.ConsensusGlobal`: the truncation of its hypotheses'
        score.
    span_factor : float, default=3.0
        :class:`~o3d_rpointhop.ConsensusGlobal`: the least sum of the two lengths (source
        side plus target side) of two compatible matches.
    seed_factor : float, default=2.0
        :class:`~o3d_rpointhop.ConsensusGlobal`: the seed suppression radius, when it is
        asked for (``seed_radius=None``).

    Examples
    --------
    >>> from o3d_rpointhop.registration import RegistrationSettings
    >>> settings = RegistrationSettings().at(0.01)
    >>> round(settings.ransac_distance, 6), settings.icp_distances
    (0.015, (0.02, 0.005))
    """

    voxel_size: float | None = None
    _: dataclasses.KW_ONLY
    ransac_factor: float = 1.5
    fgr_factor: float = 1.0
    evaluation_factor: float = 1.0
    icp_factors: tuple[float, ...] = (2.0, 0.5)
    normal_radius_factor: float = NORMAL_RADIUS_FACTOR
    feature_radius_factor: float = FEATURE_RADIUS_FACTOR
    symmetry_factor: float = 2.0
    spread_factor: float = 3.0
    edge_factor: float = 1.5
    consensus_factor: float = 2.0
    second_order_factor: float = 1.0
    score_factor: float = 2.0
    span_factor: float = 3.0
    seed_factor: float = 2.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "voxel_size" and value is None:
                continue
            values = value if f.name == "icp_factors" else (value,)
            if f.name == "icp_factors":
                if not isinstance(value, (tuple, list)) or not value:
                    raise ValueError(f"icp_factors must be a non-empty tuple, got {value!r}")
                object.__setattr__(self, f.name, tuple(float(v) for v in value))
            for v in values:
                if not is_positive_number(v):
                    raise ValueError(f"{f.name} must be a positive number, got {v!r}")

    def at(self, voxel_size: float) -> RegistrationSettings:
        """These multiples bound to the resolution ``voxel_size``."""
        return dataclasses.replace(self, voxel_size=float(voxel_size))

    def _times(self, factor: float) -> float:
        if self.voxel_size is None:
            raise ValueError("these settings have no resolution yet: use settings.at(voxel_size)")
        return factor * self.voxel_size

    @property
    def ransac_distance(self) -> float:
        """RANSAC's ``max_correspondence_distance``."""
        return self._times(self.ransac_factor)

    @property
    def fgr_distance(self) -> float:
        """FGR's ``max_correspondence_distance``."""
        return self._times(self.fgr_factor)

    @property
    def evaluation_distance(self) -> float:
        """Where the SVD estimate is scored."""
        return self._times(self.evaluation_factor)

    @property
    def icp_distances(self) -> tuple[float, ...]:
        """ICP's ``max_correspondence_distance`` per pass, coarse to fine."""
        return tuple(self._times(f) for f in self.icp_factors)

    @property
    def fitness_distance(self) -> float:
        """Where a result's fitness is measured: the last ICP pass's distance, at which
        ``register()``'s default chain ends and :func:`~o3d_rpointhop.evaluate` measures
        by default, so that both report the same fitness for the same transformation."""
        return self.icp_distances[-1]

    @property
    def normal_radius(self) -> float:
        return self._times(self.normal_radius_factor)

    @property
    def feature_radius(self) -> float:
        return self._times(self.feature_radius_factor)

    @property
    def symmetry_distance(self) -> float:
        return self._times(self.symmetry_factor)

    @property
    def spread_distance(self) -> float:
        return self._times(self.spread_factor)

    @property
    def edge_distance(self) -> float:
        return self._times(self.edge_factor)

    @property
    def consensus_distance(self) -> float:
        return self._times(self.consensus_factor)

    @property
    def second_order_distance(self) -> float:
        return self._times(self.second_order_factor)

    @property
    def score_distance(self) -> float:
        return self._times(self.score_factor)

    @property
    def span_distance(self) -> float:
        return self._times(self.span_factor)

    @property
    def seed_distance(self) -> float:
        return self._times(self.seed_factor)


def resolve_voxel_size(source, target, voxel_size: float | str, n_global_points: int):
    """The resolution of a registration, and whether the global step downsamples.

    Parameters
    ----------
    source, target : open3d.geometry.PointCloud
    voxel_size : float or "auto"
        ``"auto"``: clouds of at most ``n_global_points`` points are used as they are,
        and the resolution is their point spacing (the larger of the two median
        nearest-neighbour distances), unless one cloud is more than twice as dense as
        the other (near-duplicate points, uneven sampling): then both are
        voxel-downsampled at that resolution. Larger clouds are voxel-downsampled, with
        a voxel chosen so that the larger cloud keeps about ``n_global_points`` points.
        A number is used as the voxel size directly.
    n_global_points : int

    Returns
    -------
    voxel_size : float
    downsampled : bool
    """
    if isinstance(voxel_size, numbers.Real) and not isinstance(voxel_size, bool):
        if not is_positive_number(voxel_size):
            raise ValueError(f"voxel_size must be positive, got {voxel_size!r}")
        return float(voxel_size), True
    if voxel_size != "auto":
        raise ValueError(f"voxel_size must be 'auto' or a positive number, got {voxel_size!r}")
    src, tgt = np.asarray(source.points), np.asarray(target.points)
    spacings = point_spacing(src), point_spacing(tgt)
    spacing = max(spacings)
    largest = max(len(src), len(tgt))
    if largest <= n_global_points:
        # Descriptors compare neighbourhoods of k points: clouds of different density
        # (near-duplicate points, uneven sampling) are evened out at the resolution.
        return spacing, min(spacings) < _DENSITY_RATIO * spacing
    # Surfaces: the point count falls with the square of the voxel size.
    voxel = spacing * np.sqrt(largest / n_global_points)
    for _ in range(10):
        kept = max(len(c.voxel_down_sample(voxel).points) for c in (source, target))
        if kept <= 1.15 * n_global_points:
            break
        voxel *= np.sqrt(kept / n_global_points)
    return float(voxel), True


def common_voxel(clouds: list[np.ndarray], n_global_points: int) -> float:
    """One resolution for every scan: the largest that any scan needs, so that no scan
    is finer than it can be described. A scan needs its point spacing widened by the
    square root of its points over ``n_global_points`` (surfaces lose points with the
    square of the voxel size). Unlike a pair's (:func:`resolve_voxel_size`), the guess
    is not corrected by downsampling: on 3DMatch fragments it keeps 2-3x
    ``n_global_points`` of the scan that sets it, and the rooms need them (kept to
    about ``n_global_points``, the held-out rooms lost 70 of 354 ground-truth pairs,
    docs/multiway.md)."""
    return float(
        max(point_spacing(c) * max(1.0, np.sqrt(len(c) / n_global_points)) for c in clouds)
    )
