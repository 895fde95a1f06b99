"""Open3D's FPFH descriptor behind the same fit/transform interface as R-PointHop."""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any

import numpy as np
import open3d as o3d
from sklearn.base import _fit_context, clone

from .._utils.geometry import point_spacing, vectors
from .._utils.params import Interval, StrOptions
from .._utils.validation import as_cloud_list, as_viewpoints, is_open3d_cloud
from ._base import BaseDescriptor

__all__ = ["FPFHTransformer", "FEATURE_RADIUS_FACTOR", "NORMAL_RADIUS_FACTOR"]

N_FPFH_FEATURES = 33
#: ``radius="auto"``: this many median point spacings (Open3D's global registration
#: tutorial: FPFH at 5 voxels of a voxel-downsampled cloud).
FEATURE_RADIUS_FACTOR = 5.0
#: ``normal_radius="auto"``: this many median point spacings (the tutorial: 2 voxels).
NORMAL_RADIUS_FACTOR = 2.0


def _open3d_normals(item: Any) -> np.ndarray | None:
    if not is_open3d_cloud(item):
        return None
    if hasattr(item, "has_normals"):  # legacy PointCloud
        return np.asarray(item.normals) if item.has_normals() else None
    return item.point.normals.cpu().numpy() if "normals" in item.point else None


class FPFHTransformer(BaseDescriptor):
    """Fast Point Feature Histograms (Rusu et al., 2009), computed by Open3D.

    A drop-in peer of :class:`~o3d_rpointhop.RPointHopTransformer`: same inputs (arrays,
    Open3D point clouds, lists of either), one 33-D row per input point in input order,
    and a :meth:`fit` that learns nothing, so pipelines, tests and benchmarks can swap
    descriptors.

    Parameters
    ----------
    radius : float or "auto", default="auto"
        Search radius of the histograms, in the cloud's units. ``"auto"``: in a
        registration, :data:`FEATURE_RADIUS_FACTOR` (5) times its resolution (the voxel
        of its downsampled clouds: Open3D's tutorial, and the published pipelines at 5
        cm voxels, 0.25 m); described alone, 5 times the cloud's median
        nearest-neighbour spacing.
    max_nn : int, default=100
        Most neighbours used per histogram.
    normal_radius : float or "auto", default="auto"
        Search radius for normal estimation; ``"auto"``: :data:`NORMAL_RADIUS_FACTOR`
        (2) times the registration's resolution, or alone, the median spacing.
    normal_max_nn : int, default=30
    use_existing_normals : bool, default=True
        Keep the normals of an Open3D point cloud that has them instead of re-estimating.
    normalize : bool, default=False
        Scale every histogram to unit length, as the published correspondence-graph
        pipelines do before matching (PointDSC's features). On the training scenes of
        3DMatch it registered fewer pairs (docs/benchmarks.md), so it is off.
    n_jobs : int, default=None
        Cores to use. ``None``: every core, clouds one after another, each on Open3D's
        threads; an int ``k``: ``k`` joblib processes of one thread each over a list of
        clouds (one cloud runs on Open3D's threads); ``-1``: every core.

    Attributes
    ----------
    n_features_in_ : int
        Always 3.
    n_features_out_ : int
        Always 33.

    Notes
    -----
    Normals come from Open3D's ``estimate_normals``, whose orientation is arbitrary, so
    FPFH is not exactly rotation-invariant the way R-PointHop is. That is the behaviour
    of Open3D's own registration pipeline, which this class stands for.

    Examples
    --------
    >>> from o3d_rpointhop import FPFHTransformer
    >>> from o3d_rpointhop.datasets import make_blob
    >>> FPFHTransformer().fit_transform(make_blob(500)).shape
    (500, 33)
    """

    _RADIUS = [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})]
    _parameter_constraints = {
        "radius": _RADIUS,
        "max_nn": [Interval(Integral, 1, None, closed="left")],
        "normal_radius": _RADIUS,
        "normal_max_nn": [Interval(Integral, 1, None, closed="left")],
        "use_existing_normals": ["boolean"],
        "normalize": ["boolean"],
        "n_jobs": [None, Integral],
    }

    def __init__(
        self,
        radius: float | str = "auto",
        *,
        max_nn: int = 100,
        normal_radius: float | str = "auto",
        normal_max_nn: int = 30,
        use_existing_normals: bool = True,
        normalize: bool = False,
        n_jobs: int | None = None,
    ) -> None:
        self.radius = radius
        self.max_nn = max_nn
        self.normal_radius = normal_radius
        self.normal_max_nn = normal_max_nn
        self.use_existing_normals = use_existing_normals
        self.normalize = normalize
        self.n_jobs = n_jobs

    def _check_radii(self) -> None:
        """Finite radii (the declarative constraints admit infinity)."""
        for name in ("radius", "normal_radius"):
            value = getattr(self, name)
            if value != "auto" and not np.isfinite(value):
                raise ValueError(f"{name} must be finite, got {value!r}")

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X: Any = None, y: Any = None, viewpoints: Any = None) -> FPFHTransformer:
        """Check the parameters (and ``X`` if given); FPFH has nothing to learn, and
        :meth:`transform` works without fitting.

        Parameters
        ----------
        X : point cloud(s), optional
            Validated like in :meth:`transform`, then ignored.
        y : None
            Ignored.
        viewpoints : None, "origin" or positions, default=None
            Validated like in :meth:`transform` (with ``X``), then ignored.

        Returns
        -------
        self : FPFHTransformer
        """
        self._check_radii()
        if X is not None:
            as_viewpoints(viewpoints, len(as_cloud_list(X)[0]))
        self.n_features_in_ = 3
        self.n_features_out_ = N_FPFH_FEATURES
        return self

    def at_resolution(self, voxel_size: float, settings: Any = None) -> FPFHTransformer:
        """A copy whose ``"auto"`` radii are those of a registration at ``voxel_size``:
        ``settings.feature_radius`` and ``settings.normal_radius`` (5 and 2
        resolutions by default), or with no settings :data:`FEATURE_RADIUS_FACTOR` and
        :data:`NORMAL_RADIUS_FACTOR` times ``voxel_size``; itself when no radius is
        ``"auto"``."""
        if "auto" not in (self.radius, self.normal_radius):
            return self
        if settings is None:
            feature = FEATURE_RADIUS_FACTOR * voxel_size
            normal = NORMAL_RADIUS_FACTOR * voxel_size
        else:
            feature, normal = settings.feature_radius, settings.normal_radius
        return clone(self).set_params(
            radius=feature if self.radius == "auto" else self.radius,
            normal_radius=normal if self.normal_radius == "auto" else self.normal_radius,
        )

    def _describe(
        self, points: np.ndarray, normals: np.ndarray | None, viewpoint: np.ndarray | None
    ) -> np.ndarray:
        radius, normal_radius = self.radius, self.normal_radius
        if "auto" in (radius, normal_radius):
            spacing = point_spacing(points)
            radius = FEATURE_RADIUS_FACTOR * spacing if radius == "auto" else radius
            if normal_radius == "auto":
                normal_radius = NORMAL_RADIUS_FACTOR * spacing
        cloud = o3d.geometry.PointCloud(vectors(points))
        if normals is not None:
            cloud.normals = vectors(normals)
        else:
            cloud.estimate_normals(
                o3d.geometry.KDTreeSearchParamHybrid(
                    radius=normal_radius, max_nn=int(self.normal_max_nn)
                )
            )
        if viewpoint is not None:
            cloud.orient_normals_towards_camera_location(viewpoint)
        feature = o3d.pipelines.registration.compute_fpfh_feature(
            cloud, o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=int(self.max_nn))
        )
        out = np.asarray(feature.data).T
        if self.normalize:
            # A point without neighbours has an all-zero histogram: it stays zero.
            length = np.linalg.norm(out, axis=1, keepdims=True)
            out = out / np.where(length > 0.0, length, 1.0)
        return out

    def _normals_of(self, X: Any, n_clouds: int) -> list[np.ndarray | None]:
        """Normals carried by the Open3D clouds in ``X`` (None where there are none)."""
        items = [X] if is_open3d_cloud(X) else X if isinstance(X, (list, tuple)) else []
        if not self.use_existing_normals or len(items) != n_clouds:
            return [None] * n_clouds
        return [_open3d_normals(item) for item in items]

    def _check_transform(self) -> None:
        self._validate_params()
        self._check_radii()

    def _per_cloud(self, X: Any, clouds: list[np.ndarray], kind: str, settings: None) -> list:
        return self._normals_of(X, len(clouds))

    @property
    def _n_features_out(self) -> int:
        return N_FPFH_FEATURES

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.requires_fit = False
        return tags
