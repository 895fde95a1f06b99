"""What the steps of one registration share: the clouds, their resolution, and caches.

The context works in a frame centred on the target's centroid: survey, LiDAR and
photogrammetry clouds sit millions of units from the origin, where ICP's normal
equations and float32 scoring lose every digit that matters. The steps see centred
clouds; :meth:`RegistrationContext.to_world` maps their transformations back.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np
import open3d as o3d

from .._utils.geometry import point_spacing, vectors
from .._utils.validation import as_viewpoints, renamed_seed
from ..open3d_interop import to_point_cloud
from ..transforms import from_centred
from .checks import check_geometry
from .correspondences import unit_rows
from .defaults import DEFAULT_GLOBAL_POINTS, default_descriptor, resolve_global_points
from .fitness import FitnessEvaluator
from .prepared import PreparedCloud, describe_global, estimate_normals, prepare_cloud
from .result import StepResult
from .settings import RegistrationSettings, resolve_voxel_size

__all__ = ["CloudKey", "RegistrationContext", "global_points"]


#: The key of the context's own descriptor's features.
_OWN = "own"
#: The origin of clouds that are centred already.
_ZERO = np.zeros(3)


class CloudKey(NamedTuple):
    """What a cached cloud of a context is: ``which`` (``"source"`` or ``"target"``), its
    ``level`` (``"full"`` or ``"global"``) and ``scale`` (resolutions it is downsampled
    at, and its normals' radius in ``normal_radius``)."""

    which: str
    level: str
    scale: float


class RegistrationContext:
    """Source, target, resolution and per-registration caches shared by the steps.

    Parameters
    ----------
    source, target : array-like (n, 3) or Open3D point cloud
        Copied: the caller's objects are never modified.
    voxel_size : float or "auto"
        See :func:`~o3d_rpointhop.registration.settings.resolve_voxel_size`; with
        ``prepared``, ``"auto"`` is the larger of their point spacings.
    n_global_points : int or "auto"
        Size the global step aims for when it downsamples; see
        :func:`~o3d_rpointhop.registration.defaults.resolve_global_points`.
    random_state : int
        Seeds every random choice (RANSAC, FGR). ``seed``: its former name, deprecated.
    descriptor : transformer or None
        Descriptor used by global steps that do not name their own; ``None``:
        :func:`~o3d_rpointhop.registration.defaults.default_descriptor`, loaded when a
        step first needs it.
    check : bool, default=True
        Refuse clouds without extent or on one line, and warn about planar ones
        (:func:`~o3d_rpointhop.registration.checks.check_geometry`).
    settings : RegistrationSettings or None
        The multiples of the resolution; ``None`` is ``RegistrationSettings()``.
    prepared : (PreparedCloud, PreparedCloud), default=None
        The clouds the global step works on, already prepared
        (:func:`~o3d_rpointhop.registration.prepared.prepare_cloud`, in the caller's
        coordinates, like ``source`` and ``target``), instead of voxel-downsampling
        ``source`` and ``target``: a caller that registers one scan to many prepares it
        once. Their descriptors, when they carry them, are the ones a global step
        without a descriptor of its own matches (the context's ``descriptor`` is then
        not used for them).
    viewpoints : None, "origin" or (array-like, array-like), default=None
        Where the sensors that saw the source and the target stood, in the caller's
        coordinates of each cloud; ``"origin"``: each cloud is in its sensor's frame.
        Passed to the descriptor's ``transform`` (``viewpoints=``), so that normals and
        local frames face the sensor.
    up : None, array-like of shape (3,), or (array-like, array-like), default=None
        Which way is up in the source and the target (one vector for both, or one
        each): the global steps that can (RANSAC, the consensus) then reject
        hypotheses that turn the source's up more than 90 degrees away from the
        target's (upside down). ``None``: no prior.
    origin : array-like of shape (3,), default=None
        Where the centred frame's origin is, in the caller's coordinates; ``None``: the
        target's centroid. Zero for clouds that are centred already.

    Attributes
    ----------
    settings : RegistrationSettings
        Bound to this registration's resolution: every distance a step is not given.
    voxel_size : float
        The resolution (``settings.voxel_size``).
    n_global_points : int
        The size the global step aims for, resolved.
    downsampled : bool
        Whether the global step works on other clouds than the full ones (downsampled,
        or given as ``global_clouds``).
    origin : ndarray of shape (3,)
        The caller's coordinates of the centred frame's origin (the target's centroid);
        ``source`` and ``target`` are in the centred frame.
    viewpoints : dict or None
        ``{"source": ..., "target": ...}``: the sensor positions in the centred frame,
        or None when no viewpoints were given.
    up : tuple of ndarray or None
        The source's and the target's unit up vectors, or None.
    random_state : int
        The seed of every random choice.
    fitness : FitnessEvaluator
        Measures transformations of this pair (:meth:`evaluate`), its searches kept
        for the next measurement of the same transformation.
    """

    def __init__(
        self,
        source: Any,
        target: Any,
        *,
        voxel_size: float | str = "auto",
        n_global_points: int | str = "auto",
        random_state: int = 0,
        descriptor: Any = None,
        check: bool = True,
        settings: RegistrationSettings | None = None,
        prepared: tuple[PreparedCloud, PreparedCloud] | None = None,
        viewpoints: Any = None,
        up: Any = None,
        origin: Any = None,
        seed: int | None = None,
    ) -> None:
        self.source = to_point_cloud(source, "source")
        self.target = to_point_cloud(target, "target")
        if origin is None:
            origin = self.target.get_center()
        try:
            self.origin = np.array(origin, dtype=np.float64)
        except (TypeError, ValueError):
            self.origin = np.full(3, np.nan)
        if self.origin.shape != (3,) or not np.isfinite(self.origin).all():
            raise ValueError(f"origin must be a finite point (3,), got {origin!r}")
        self.up = _up_vectors(up)
        self.viewpoints = None
        if viewpoints is not None:
            views = as_viewpoints(viewpoints, 2)
            self.viewpoints = {
                which: view - self.origin
                for which, view in zip(("source", "target"), views, strict=True)
            }
        if self.origin.any():
            self.source.translate(-self.origin)
            self.target.translate(-self.origin)
        if check:
            check_geometry(np.asarray(self.source.points), "source", source)
            check_geometry(np.asarray(self.target.points), "target", target)
        self.n_global_points = resolve_global_points(n_global_points, descriptor)
        self._global: dict[str, o3d.geometry.PointCloud] = {}
        self.descriptor = descriptor
        # Descriptors by (descriptor id, or _OWN for the context's own, which).
        self._features: dict[tuple[Any, str], np.ndarray] = {}
        if prepared is None:
            voxel, self.downsampled = resolve_voxel_size(
                self.source, self.target, voxel_size, self.n_global_points
            )
        else:
            for which, scan in zip(("source", "target"), prepared, strict=True):
                if not isinstance(scan, PreparedCloud):
                    raise TypeError(f"prepared clouds must be PreparedCloud, got {type(scan)}")
                self._global[which] = _as_open3d(scan, f"prepared {which}").translate(-self.origin)
                if scan.features is not None:
                    self._features[(_OWN, which, 1)] = scan.features
            voxel, self.downsampled = voxel_size, True
            if voxel == "auto":
                voxel = max(point_spacing(np.asarray(c.points)) for c in self._global.values())
        self.settings = (settings or RegistrationSettings()).at(voxel)
        self.random_state = int(renamed_seed(random_state, seed, "RegistrationContext"))
        self._normals: dict[CloudKey, o3d.geometry.PointCloud] = {}
        self._downsampled: dict[CloudKey, o3d.geometry.PointCloud] = {}
        self._coarse: RegistrationContext | None = None
        self.fitness = FitnessEvaluator(self.clouds, self.settings.spread_distance)

    @property
    def voxel_size(self) -> float:
        return self.settings.voxel_size

    def to_world(self, transformation: np.ndarray) -> np.ndarray:
        """A centred-frame transformation in the caller's coordinates."""
        return from_centred(transformation, self.origin)

    def to_local(self, transformation: np.ndarray) -> np.ndarray:
        """A caller's transformation in the centred frame (inverse of :meth:`to_world`)."""
        return from_centred(transformation, -self.origin)

    def cloud(self, which: str) -> o3d.geometry.PointCloud:
        """The full-resolution ``"source"`` or ``"target"``."""
        return self.source if which == "source" else self.target

    def global_cloud(self, which: str) -> o3d.geometry.PointCloud:
        """The cloud the global step works on (downsampled when the clouds are large),
        prepared on first use (:meth:`prepare` prepares both up front)."""
        if which not in self._global:
            prepared = prepare_cloud(
                self.cloud(which), self.voxel_size, downsample=self.downsampled, centre=_ZERO
            )
            self._global[which] = _as_open3d(prepared, f"prepared {which}")
        return self._global[which]

    def prepare(self, descriptors: Any = ()) -> float:
        """Prepare what the steps will share, before the first runs: both global clouds
        (:func:`~o3d_rpointhop.registration.prepared.prepare_cloud`) and their
        descriptors by each of ``descriptors``: a descriptor (``None``: the context's
        own), or ``(descriptor, n_turns)`` for its descriptors under turns of the local
        frames (see :meth:`features`). Idempotent.

        Returns
        -------
        float
            The seconds it took (0 for what was prepared already).
        """
        start = time.perf_counter()
        for which in ("source", "target"):
            self.global_cloud(which)
        for entry in descriptors:
            descriptor, n_turns = entry if isinstance(entry, tuple) else (entry, 1)
            for which in ("source", "target"):
                self.features(descriptor, which, n_turns)
        return time.perf_counter() - start

    def clouds(
        self, which: str = "full"
    ) -> tuple[o3d.geometry.PointCloud, o3d.geometry.PointCloud]:
        """The source and target at full resolution (``which="full"``) or as the global
        step sees them (``"global"``)."""
        if which == "full":
            return self.source, self.target
        return self.global_cloud("source"), self.global_cloud("target")

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
                random_state=self.random_state,
                descriptor=self.descriptor,
                check=False,
                settings=self.settings,
                origin=_ZERO,  # this context's frame: transformations carry over
            )
            self._coarse.viewpoints, self._coarse.up = self.viewpoints, self.up
        return self._coarse

    def features(
        self, descriptor: Any, which: str, n_turns: int = 1, unit: bool = False
    ) -> np.ndarray:
        """Descriptors of the global cloud, computed once per descriptor object, with the
        distances it leaves to the registration at its resolution (``at_resolution``)
        and with the viewpoints, if any. ``descriptor`` None (or the context's own) is
        the context's: its prepared descriptors when it was given them, else the
        context's ``descriptor`` (the default one when that is None). ``n_turns`` above
        1: ``(n_turns, n_points, width)``, the descriptors under each turn of the local
        frames about their normals (the first, turn 0, is then also what ``n_turns=1``
        answers). ``unit``: every descriptor scaled to unit length
        (:func:`~o3d_rpointhop.registration.correspondences.unit_rows`, for matching by
        cosine distance), also computed once."""
        own = descriptor is None or descriptor is self.descriptor
        key = (_OWN if own else id(descriptor), which, n_turns)
        if unit:
            unit_key = key + ("unit",)
            if unit_key not in self._features:
                self._features[unit_key] = unit_rows(self.features(descriptor, which, n_turns))
            return self._features[unit_key]
        if key not in self._features:
            if own:
                if self.descriptor is None:
                    self.descriptor = default_descriptor()
                descriptor = self.descriptor
            cloud = self.global_cloud(which)
            view = None if self.viewpoints is None else self.viewpoints[which]
            try:
                self._features[key] = describe_global(
                    descriptor,
                    cloud,
                    self.voxel_size,
                    self.settings,
                    view,
                    n_turns,
                    with_normals=lambda: self.with_normals(which, "global"),
                )
            except ValueError as exc:
                detail = (
                    f" (after voxel downsampling at {self.voxel_size:.6g})"
                    if self.downsampled
                    else ""
                )
                raise ValueError(
                    f"cannot describe the {which} cloud, {len(cloud.points)} points{detail}: {exc}"
                ) from exc
            if n_turns > 1:
                self._features.setdefault(key[:2] + (1,), self._features[key][0])
        return self._features[key]

    def cloud_at(self, which: str, level: str = "full", scale: float = 1.0):
        """The source or target (``which``) at a level of detail: as given (``"full"``;
        with ``scale`` above 1 downsampled at ``scale`` resolutions, computed once) or as
        the global step sees it (``"global"``)."""
        if level == "global":
            return self.global_cloud(which)
        if scale <= 1.0:
            return self.cloud(which)
        key = CloudKey(which, level, float(scale))
        if key not in self._downsampled:
            self._downsampled[key] = self.cloud(which).voxel_down_sample(scale * self.voxel_size)
        return self._downsampled[key]

    def with_normals(self, which: str, level: str = "full", scale: float = 1.0):
        """:meth:`cloud_at` with normals: its own if it has them, else estimated within
        ``scale`` times the settings' ``normal_radius``, once per cloud and level (every
        step that asks for the same cloud shares them)."""
        cloud = self.cloud_at(which, level, scale)
        if cloud.has_normals():
            return cloud
        key = CloudKey(which, level, float(scale))
        if key not in self._normals:
            copy = o3d.geometry.PointCloud(cloud)
            estimate_normals(copy, scale * self.settings.normal_radius)
            self._normals[key] = copy
        return self._normals[key]

    def upright(self, rotations: np.ndarray) -> np.ndarray:
        """Which of the rotations ``(b, 3, 3)`` keep the source's up within 90 degrees
        of the target's (all of them without an up prior)."""
        if self.up is None:
            return np.ones(len(rotations), dtype=bool)
        source_up, target_up = self.up
        return np.einsum("bij,j,i->b", rotations, source_up, target_up) > 0.0

    def evaluate(
        self, transformation: np.ndarray, max_correspondence_distance: float, which: str = "full"
    ) -> StepResult:
        """Fitness, inlier RMSE and inlier pairs of ``transformation`` (centred frame)
        within ``max_correspondence_distance``, on the full-resolution clouds
        (``which="full"``) or the global step's (``"global"``): Open3D's
        ``evaluate_registration``, measured by the context's
        :class:`~o3d_rpointhop.registration.fitness.FitnessEvaluator`."""
        return self.fitness.evaluate(transformation, max_correspondence_distance, which)


def _as_open3d(scan: PreparedCloud, what: str) -> o3d.geometry.PointCloud:
    """A prepared cloud's points (and normals) as an Open3D cloud."""
    cloud = to_point_cloud(scan.points, what)
    if scan.normals is not None:
        cloud.normals = vectors(scan.normals)
    return cloud


def _up_vectors(up: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """``up`` as two unit vectors (source, target), or None; a clear error otherwise."""
    if up is None:
        return None
    try:
        arr = np.asarray(up, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"up must be a vector (3,) or two of them, got {up!r}: {exc}") from None
    if arr.shape == (3,):
        arr = np.stack([arr, arr])
    norms = np.linalg.norm(arr, axis=-1) if arr.ndim == 2 else None
    if arr.shape != (2, 3) or not np.isfinite(arr).all() or not (norms > 0).all():
        raise ValueError(
            f"up must be a non-zero vector (3,) or two of them (2, 3), got {arr.tolist()}"
        )
    return arr[0] / norms[0], arr[1] / norms[1]


def global_points(points: Any, n_global_points: int = DEFAULT_GLOBAL_POINTS) -> np.ndarray:
    """A cloud as ``register()``'s global step sees it when registered to itself:
    voxel-downsampled to about ``n_global_points`` points (as it is, if smaller), in the
    cloud's own coordinates. What a model for ``register()`` should be fitted on."""
    context = RegistrationContext(points, points, n_global_points=n_global_points)
    return np.asarray(context.global_cloud("source").points) + context.origin
