"""ICP refinements: point-to-point, point-to-plane, generalized and multi-scale.

Each starts from the incoming transformation and runs Open3D's ICP, repeatably (one
thread), or, for point-to-plane without a robust loss, the same iteration compiled on
every core (:mod:`._point_to_plane`), with correspondence distances from the step's
parameters or, when they are ``None``, from ``context.settings`` (``icp_distances``: 2
then 0.5 resolutions).

A narrower pass is kept only if it does not lose coverage: when its result brings
:data:`COVERAGE_DROP` or more of the source fewer points within the previous pass's
distance than the previous result did, the previous result stands (and is reported at
that distance). Coverage is counted on the global step's clouds when the clouds were
downsampled for it, so only the last pass and the flags touch the whole clouds. On
sparse clouds a
pass narrower than the point spacing finds few correspondences and can walk away from
an exact start (ModelNet40 resampled pairs: from 0.2-0.4 deg to 6-26 deg).
"""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any

import numpy as np
import open3d as o3d

from ..._utils.cells import CellGrid
from ..._utils.params import Interval, StrOptions
from ..._utils.threads import kernel_threads, repeatable_open3d
from ..context import RegistrationContext
from ..result import StepResult
from ._base import RegistrationStep
from ._point_to_plane import point_to_plane_icp

__all__ = ["PointToPointICP", "PointToPlaneICP", "GeneralizedICP", "MultiScaleICP"]

reg = o3d.pipelines.registration

_KERNELS = {
    "huber": reg.HuberLoss,
    "tukey": reg.TukeyLoss,
    "cauchy": reg.CauchyLoss,
    "gm": reg.GMLoss,
}
_KERNEL = [None, StrOptions({*_KERNELS, "l1"})]
_POSITIVE = Interval(Real, 0, None, closed="neither")
_ITERATIONS = [Interval(Integral, 1, None, closed="left")]
_TOLERANCE = [Interval(Real, 0, None, closed="left")]
_SCHEDULE = [None, _POSITIVE, "array-like"]

#: A narrower ICP pass whose result covers this share of the source less (within the
#: previous pass's distance) than the previous result is undone. Chosen on pairs of
#: ModelNet40 *training* shapes (seed 7, success of register() with the ModelNet40 model
#: / FPFH; no guard, then thresholds 0.01 / 0.05 / 0.1): resampled 69.4 / 70.1 / 70.1 /
#: 70.1 % and 63.9 / 64.6 / 63.9 / 63.9 %, resampled-partial 43.8 / 44.4 / 44.4 / 44.4 %
#: and 36.8 / 37.5 / 38.2 / 38.2 %, paper-partial 77.8 / 75.7 / 77.1 / 77.8 % and 85.4 /
#: 84.0 / 84.7 / 85.4 %: at 0.1 no protocol loses a pair (a legitimate fine pass on a
#: partial overlap drops up to 9 % of the source), three gain.
COVERAGE_DROP = 0.1


#: The L1 kernel's weights ``1 / |r|`` are capped at ``1 / (L1_CAP * distance)``.
L1_CAP = 1e-6


def _robust_kernel(kernel: str | None, scale: float | None, distance: float):
    if kernel is None:
        return None
    if kernel == "l1":
        # Open3D's L1Loss weighs a residual by 1 / |r| and returns NaN as soon as one
        # residual is exactly zero (clouds that share points, a cloud registered to
        # itself). Huber's weights are k / max(|r|, k): the same weights up to a common
        # factor, which a weighted fit ignores, capped where |r| < k.
        return reg.HuberLoss(L1_CAP * float(distance))
    return _KERNELS[kernel](float(distance / 2.0 if scale is None else scale))


def _check_schedule(value: Any) -> None:
    """A distance schedule: None, a positive number or a non-empty sequence of them."""
    if value is None:
        return
    values = [value] if isinstance(value, Real) else list(value)
    if not values or not all(
        isinstance(v, Real) and not isinstance(v, bool) and np.isfinite(v) and v > 0 for v in values
    ):
        raise ValueError(
            "max_correspondence_distance must be None, a positive number or a non-empty "
            f"sequence of positive numbers, got {value!r}"
        )


def _distances(value: Any, context: RegistrationContext) -> list[float]:
    """A checked distance schedule (:func:`_check_schedule`) in the context's units: one
    pass per distance, coarse to fine."""
    if value is None:
        return list(context.settings.icp_distances)
    return [float(v) for v in ([value] if isinstance(value, Real) else value)]


_DISTANCE_DOC = """max_correspondence_distance : float, sequence of float or None, default=None
        Correspondence distance; a sequence runs one ICP pass per distance, each from
        the previous result. ``None`` is the settings' ``icp_distances``: two passes,
        at 2 and at 0.5 x ``voxel_size``. A pass wider than ``voxel_size`` runs on the
        global step's clouds, which have that resolution (when they are downsampled),
        the others on the full clouds."""

_FULL_DOC = """full_resolution : bool, default=True
        ``False`` runs every pass on the global step's clouds: several times faster on
        large clouds, with the accuracy of their resolution (``register_multiway``
        screens its candidate pairs so, before refining the kept ones in full)."""


def _estimation(method: str, kernel, epsilon: float = 1e-3):
    """Open3D's estimation object for an ICP variant, with an optional robust kernel."""
    if method == "point_to_point":
        return reg.TransformationEstimationPointToPoint(False)
    extra = [kernel] if kernel is not None else []
    if method == "point_to_plane":
        return reg.TransformationEstimationPointToPlane(*extra)
    return reg.TransformationEstimationForGeneralizedICP(float(epsilon), *extra)


def _icp(method: str, source, target, distance: float, init, estimation, criteria):
    """One Open3D ICP run (generalized ICP has its own entry point), repeatably."""
    run = reg.registration_generalized_icp if method == "generalized" else reg.registration_icp
    with repeatable_open3d():
        return run(source, target, distance, init, estimation, criteria)


class _ICPStep(RegistrationStep):
    """Shared parameters, schedule and checks of the single-scale ICP steps."""

    name = "icp"
    #: The robust kernel a result reports; the steps that take one set it as a parameter.
    kernel: str | None = None
    _parameter_constraints = {
        "max_correspondence_distance": _SCHEDULE,
        "max_iteration": _ITERATIONS,
        "relative_fitness": _TOLERANCE,
        "relative_rmse": _TOLERANCE,
        "full_resolution": ["boolean"],
    }

    def _check_params(self) -> None:
        _check_schedule(self.max_correspondence_distance)

    def criteria(self) -> o3d.pipelines.registration.ICPConvergenceCriteria:
        """Open3D's convergence criteria of one pass."""
        return reg.ICPConvergenceCriteria(
            relative_fitness=float(self.relative_fitness),
            relative_rmse=float(self.relative_rmse),
            max_iteration=int(self.max_iteration),
        )

    def _solve(self, context: RegistrationContext, which: str, distance: float, init):
        """One pass on the ``"full"`` or the ``"global"`` clouds."""
        raise NotImplementedError

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        distances = _distances(self.max_correspondence_distance, context)
        current = transformation
        undone = []
        for k, distance in enumerate(distances):
            # Wide passes on the global clouds: at their resolution they see the same
            # correspondences for far less work. The last pass is on the full ones,
            # unless full_resolution is False.
            coarse = context.downsampled and distance > context.voxel_size
            last = k == len(distances) - 1
            which = "global" if (coarse and not last) or not self.full_resolution else "full"
            result = self._solve(context, which, distance, current)
            moved = np.array(result.transformation)
            if k and distance < distances[k - 1]:
                # Coverage within the previous pass's distance, before and after this one,
                # on the global clouds when there are any: the guard then costs what the
                # global step costs, and the whole clouds are searched once, for the flags.
                guard = "global" if context.downsampled else which
                before = context.evaluate(current, distances[k - 1], guard)
                after = context.evaluate(moved, distances[k - 1], guard)
                if after.fitness < before.fitness - COVERAGE_DROP:
                    # Undone; the result is reported where it was found, on this pass's
                    # clouds.
                    undone.append(k)
                    result = context.evaluate(current, distances[k - 1], which)
                    continue
            current = moved
        info = {
            "max_correspondence_distance": distances,
            "kernel": self.kernel,
            "passes_undone": undone,
        }
        if isinstance(result, StepResult):
            result.name, result.info = self.name, info
            return result
        return StepResult.from_open3d(self.name, result, 0.0, info, distances[-1])


class PointToPointICP(_ICPStep):
    """Point-to-point ICP (Besl and McKay, 1992) on the full-resolution clouds.

    Parameters
    ----------
    {distance}
    max_iteration : int, default=50
        Per pass.
    relative_fitness, relative_rmse : float, default=1e-6
        Convergence thresholds.
    {full}
    """

    name = "point_to_point"

    def __init__(
        self,
        max_correspondence_distance: float | list[float] | None = None,
        *,
        max_iteration: int = 50,
        relative_fitness: float = 1e-6,
        relative_rmse: float = 1e-6,
        full_resolution: bool = True,
    ) -> None:
        self.max_correspondence_distance = max_correspondence_distance
        self.max_iteration = max_iteration
        self.relative_fitness = relative_fitness
        self.relative_rmse = relative_rmse
        self.full_resolution = full_resolution

    def _solve(self, context, which, distance, init):
        source, target = context.clouds(which)
        estimation = _estimation(self.name, None)
        return _icp(self.name, source, target, distance, init, estimation, self.criteria())


class PointToPlaneICP(_ICPStep):
    """Point-to-plane ICP (Chen and Medioni, 1992) on the full-resolution clouds.

    Target normals are estimated (radius: the settings' ``normal_radius``, 2 x
    ``voxel_size``) when the target has none. Without a robust ``kernel`` each pass is
    Open3D's iteration compiled and shared out over every core, with the same result
    on any thread count (a target too wide for a grid of cells as wide as the distance
    falls back to Open3D's ICP on one thread).

    Parameters
    ----------
    {distance}
    max_iteration : int, default=50
        Per pass.
    kernel : {{None, "huber", "tukey", "cauchy", "gm", "l1"}}, default=None
        Robust loss on the point-to-plane residuals. ``"l1"`` weighs each residual by
        ``1 / |r|``, capped for residuals under a millionth of the pass's distance (so
        points the two clouds share exactly do not divide by zero).
    kernel_scale : float, default=None
        The loss's scale (not ``"l1"``'s); ``None`` is half the pass's correspondence
        distance.
    relative_fitness, relative_rmse : float, default=1e-6
    {full}
    """

    name = "point_to_plane"
    _parameter_constraints = {
        **_ICPStep._parameter_constraints,
        "kernel": _KERNEL,
        "kernel_scale": [None, _POSITIVE],
    }

    def __init__(
        self,
        max_correspondence_distance: float | list[float] | None = None,
        *,
        max_iteration: int = 50,
        kernel: str | None = None,
        kernel_scale: float | None = None,
        relative_fitness: float = 1e-6,
        relative_rmse: float = 1e-6,
        full_resolution: bool = True,
    ) -> None:
        self.max_correspondence_distance = max_correspondence_distance
        self.max_iteration = max_iteration
        self.kernel = kernel
        self.kernel_scale = kernel_scale
        self.relative_fitness = relative_fitness
        self.relative_rmse = relative_rmse
        self.full_resolution = full_resolution

    def _solve(self, context, which, distance, init):
        kernel = _robust_kernel(self.kernel, self.kernel_scale, distance)
        source = context.cloud_at("source", which)
        target = context.with_normals("target", which)
        if kernel is None:
            # Without a robust loss: the compiled ICP, on every core with the same
            # result (_point_to_plane.py), unless the target is too wide for its grid.
            grid = CellGrid(np.asarray(target.points), distance)
            if grid.on_cells:
                return point_to_plane_icp(
                    np.asarray(source.points),
                    grid,
                    np.asarray(target.normals),
                    np.asarray(init, dtype=np.float64),
                    int(self.max_iteration),
                    float(self.relative_fitness),
                    float(self.relative_rmse),
                    kernel_threads(None),
                )
        return _icp(
            self.name,
            source,
            target,
            distance,
            init,
            _estimation(self.name, kernel),
            self.criteria(),
        )


class GeneralizedICP(_ICPStep):
    """Generalized ICP (Segal et al., 2009; plane-to-plane) on the full-resolution clouds.

    Parameters
    ----------
    {distance}
    max_iteration : int, default=50
        Per pass.
    epsilon : float, default=1e-3
        Covariance regulariser of the local planes.
    kernel : {{None, "huber", "tukey", "cauchy", "gm", "l1"}}, default=None
    kernel_scale : float, default=None
    relative_fitness, relative_rmse : float, default=1e-6
    {full}
    """

    name = "generalized"
    _parameter_constraints = {
        **PointToPlaneICP._parameter_constraints,
        "epsilon": [_POSITIVE],
    }

    def __init__(
        self,
        max_correspondence_distance: float | list[float] | None = None,
        *,
        max_iteration: int = 50,
        epsilon: float = 1e-3,
        kernel: str | None = None,
        kernel_scale: float | None = None,
        relative_fitness: float = 1e-6,
        relative_rmse: float = 1e-6,
        full_resolution: bool = True,
    ) -> None:
        self.max_correspondence_distance = max_correspondence_distance
        self.max_iteration = max_iteration
        self.epsilon = epsilon
        self.kernel = kernel
        self.kernel_scale = kernel_scale
        self.relative_fitness = relative_fitness
        self.relative_rmse = relative_rmse
        self.full_resolution = full_resolution

    def _solve(self, context, which, distance, init):
        kernel = _robust_kernel(self.kernel, self.kernel_scale, distance)
        source, target = context.clouds(which)
        estimation = _estimation(self.name, kernel, self.epsilon)
        return _icp(self.name, source, target, distance, init, estimation, self.criteria())


for _cls in (PointToPointICP, PointToPlaneICP, GeneralizedICP):
    if _cls.__doc__:  # None under python -OO
        _cls.__doc__ = _cls.__doc__.format(distance=_DISTANCE_DOC, full=_FULL_DOC)


class MultiScaleICP(RegistrationStep):
    """ICP from coarse to fine: each scale downsamples both clouds and widens the search.

    At scale ``s`` both clouds are voxel-downsampled to ``s x voxel_size`` (the finest
    scale, ``s <= 1``, uses the full clouds) and ICP runs with a correspondence distance
    of ``distance_factor x s x voxel_size``. Coarse scales pull in a poor start cheaply;
    the fine scale gives the accuracy.

    Parameters
    ----------
    scales : sequence of float, default=(4.0, 2.0, 1.0)
        Coarse to fine, in units of ``voxel_size``.
    max_iteration : sequence of int, default=(50, 30, 20)
        One per scale.
    method : {"point_to_plane", "point_to_point", "generalized"}, default="point_to_plane"
    distance_factor : float, default=2.0
    kernel : {None, "huber", "tukey", "cauchy", "gm", "l1"}, default=None
        Ignored by ``"point_to_point"`` (Open3D has no robust point-to-point solver).
    """

    name = "multiscale"

    _parameter_constraints = {
        "scales": ["array-like"],
        "max_iteration": ["array-like"],
        "method": [StrOptions({"point_to_plane", "point_to_point", "generalized"})],
        "distance_factor": [_POSITIVE],
        "kernel": _KERNEL,
    }

    def __init__(
        self,
        scales=(4.0, 2.0, 1.0),
        *,
        max_iteration=(50, 30, 20),
        method: str = "point_to_plane",
        distance_factor: float = 2.0,
        kernel: str | None = None,
    ) -> None:
        self.scales = scales
        self.max_iteration = max_iteration
        self.method = method
        self.distance_factor = distance_factor
        self.kernel = kernel

    def _check_params(self) -> None:
        scales, iterations = list(self.scales), list(self.max_iteration)
        if (
            len(scales) != len(iterations)
            or not scales
            or not all(isinstance(s, Real) and s > 0 for s in scales)
            or not all(isinstance(i, Integral) and i >= 1 for i in iterations)
        ):
            raise ValueError(
                "scales and max_iteration must be non-empty and as long, with positive "
                f"scales and iteration counts, got {self.scales!r} and {self.max_iteration!r}"
            )

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        scales = [float(s) for s in self.scales]
        iterations = list(self.max_iteration)
        current = transformation
        result = None
        for scale, iters in zip(scales, iterations, strict=True):
            result = self._run_scale(context, current, scale, int(iters))
            current = np.array(result.transformation)
        info = {"scales": scales, "method": self.method}
        last = self.distance_factor * scales[-1] * context.voxel_size
        return StepResult.from_open3d("multiscale", result, 0.0, info, last)

    def _run_scale(self, context: RegistrationContext, current, scale: float, iters: int):
        """One ICP pass at ``scale`` x ``voxel_size``."""
        voxel = scale * context.voxel_size
        src = context.cloud_at("source", "full", scale)  # as given at scale <= 1
        tgt = context.cloud_at("target", "full", scale)
        distance = self.distance_factor * voxel
        criteria = reg.ICPConvergenceCriteria(1e-6, 1e-6, iters)
        kernel = (
            None if self.method == "point_to_point" else _robust_kernel(self.kernel, None, distance)
        )
        if self.method == "point_to_plane":
            tgt = context.with_normals("target", "full", scale)
        estimation = _estimation(self.method, kernel)
        return _icp(self.method, src, tgt, distance, current, estimation, criteria)
