"""Fitness of transformations of one pair of clouds: Open3D's ``evaluate_registration``
numbers (fitness, inlier RMSE, inlier pairs), each transformation searched once however
many distances it is measured at.

A registration measures a few transformations at several distances (the flags' final
and spread distances, ICP's guard, the symmetry check), multiway one per edge; the
searches run on the target's cell grid (:class:`~o3d_rpointhop._utils.cells.CellGrid`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import open3d as o3d

from .._utils.cells import CellGrid
from .result import StepResult

__all__ = ["FitnessEvaluator"]

#: Transformations whose nearest target points an evaluator keeps (the last ones
#: measured: a registration measures a few, multiway one per edge), and target grids.
_KEPT = 8
#: Source clouds from this many points share one search between a transformation's
#: evaluations; smaller ones are searched at each distance (on a 1000-point object
#: pair sharing cost 1-4 % more time per registration, on a scene pair it saves 20 ms).
_SHARED_FROM = 5000

Clouds = Callable[[str], tuple[o3d.geometry.PointCloud, o3d.geometry.PointCloud]]


class FitnessEvaluator:
    """Fitness, inlier RMSE and inlier pairs of transformations of one source onto one
    target, at the levels of detail ``clouds(which)`` gives (``"full"``, ``"global"``).

    Parameters
    ----------
    clouds : callable
        ``clouds(which) -> (source, target)``, the Open3D clouds of a level; called
        when a level is first measured.
    spread_distance : float
        The widest distance the flags measure at: each transformation is searched
        once at this distance (or a wider one asked), and nearer ones read from it.
    """

    def __init__(self, clouds: Clouds, spread_distance: float) -> None:
        self.clouds = clouds
        self.spread_distance = float(spread_distance)
        # Nearest target points of moved sources, by (which, transformation).
        self._nearest: dict[tuple[str, bytes], tuple[float, np.ndarray, np.ndarray]] = {}
        self._grids: dict[tuple[str, float], CellGrid] = {}

    def evaluate(
        self, transformation: np.ndarray, max_correspondence_distance: float, which: str = "full"
    ) -> StepResult:
        """Open3D's ``evaluate_registration`` of ``transformation`` within
        ``max_correspondence_distance`` on the ``which`` clouds, to the bit but for exact
        ties between two nearest points (sources under :data:`_SHARED_FROM` points are
        searched at each distance)."""
        distance = float(max_correspondence_distance)
        transformation = np.array(transformation, dtype=np.float64)
        source, _ = self.clouds(which)
        if len(source.points) < _SHARED_FROM:
            # A small cloud's search costs less than reading distances from a wider one.
            pairs, squared = self._grid(which, distance).moved_pairs(source.points, transformation)
        else:
            pairs, squared = self._inliers_within(transformation, distance, which)
        inside = squared < distance * distance  # strictly, as Open3D's search
        count = int(inside.sum())
        # Open3D's numbers: the share of source points, and the RMS of the squared
        # distances summed in source order.
        rmse = float(np.sqrt(np.cumsum(squared[inside])[-1] / count)) if count else 0.0
        return StepResult(
            name="evaluation",
            # Column-major, as Open3D's own result hands it over: products with it round
            # as they did.
            transformation=np.asfortranarray(transformation),
            fitness=count / len(source.points) if count else 0.0,
            inlier_rmse=rmse,
            correspondence_set=pairs[inside],
            info={"max_correspondence_distance": distance},
            distance=distance,
        )

    def _grid(self, which: str, distance: float) -> CellGrid:
        """The target cloud's cell grid at ``distance`` (``which`` level), built once."""
        key = (which, float(distance))
        if key not in self._grids:
            target = np.asarray(self.clouds(which)[1].points)
            self._grids[key] = CellGrid(target, distance)
            _forget_oldest(self._grids)
        return self._grids[key]

    def _inliers_within(
        self, transformation: np.ndarray, distance: float, which: str
    ) -> tuple[np.ndarray, np.ndarray]:
        """Every source point with a target point within ``distance`` after
        ``transformation``: ``(source, nearest target)`` pairs and their squared
        distances. Each transformation is searched once, at the widest distance asked
        of it or ``spread_distance``, and nearer distances are read from that: the
        points with a neighbour within ``d`` have their nearest within the wider
        distance there too, at the same distance, so each evaluation reports what
        Open3D's own at ``d`` reports."""
        key = (which, transformation.tobytes())
        kept = self._nearest.get(key)
        if kept is None or kept[0] < distance:
            wide = max(distance, self.spread_distance)
            points = self.clouds(which)[0].points
            kept = (wide, *self._grid(which, wide).moved_pairs(points, transformation))
            self._nearest[key] = kept
            _forget_oldest(self._nearest)
        return kept[1], kept[2]


def _forget_oldest(cache: dict) -> None:
    """Drop the oldest entries of ``cache`` beyond :data:`_KEPT`."""
    while len(cache) > _KEPT:
        del cache[next(iter(cache))]
