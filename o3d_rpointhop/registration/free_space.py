"""Free-space violations: how much of one scan a pose puts where the other scan's
sensor saw through.

A sensor at a known position sees, along each ray, the first surface and nothing in
front of it. A right pose of two scans keeps each scan's points on or behind the surfaces
the other sensor saw; a wrong pose that still fits (a floor and a wall aligned with
another floor and wall, a repeated piece of furniture) puts many of them in front, in
space that sensor saw empty. The share of such points tells wrong edges of a room's pose
graph from right ones that fit no better (docs/multiway.md, "Scans of rooms").
"""

from __future__ import annotations

import numpy as np

from .._utils.threads import map_threads

__all__ = [
    "ANGULAR_RESOLUTION",
    "RANGE_MARGIN",
    "SeenSpace",
    "free_space_violation",
    "free_space_violations",
    "violation_share",
]

#: Width of a ray bin of the depth images, in radians (1 degree).
ANGULAR_RESOLUTION = np.radians(1.0)
#: A point violates free space when it lies nearer to the sensor than the seen surface
#: by more than this share of that surface's range (plus the absolute margin given).
RANGE_MARGIN = 0.05


def _equator(seen: np.ndarray) -> np.ndarray:
    """A rotation taking the mean viewing direction of ``seen`` to the x axis: the rays
    then lie about the equator of the azimuth / elevation grid, where its bins are all
    about as wide, and not about a pole, where they narrow to nothing."""
    mean = seen.mean(axis=0)
    norm = np.linalg.norm(mean)
    x = mean / norm if norm > 0 else np.array([1.0, 0.0, 0.0])
    helper = np.eye(3)[int(np.argmin(np.abs(x)))]
    z = np.cross(x, helper)
    z /= np.linalg.norm(z)
    return np.stack([x, np.cross(z, x), z])  # rows: the new axes


def _rays(points: np.ndarray, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """Each point's range from the origin and the key of its ray bin (azimuth,
    elevation)."""
    ranges = np.linalg.norm(points, axis=1)
    safe = np.where(ranges > 0, ranges, 1.0)
    azimuth = np.floor(np.arctan2(points[:, 1], points[:, 0]) / resolution).astype(np.int64)
    elevation = np.arcsin(np.clip(points[:, 2] / safe, -1.0, 1.0))
    keys = azimuth * (1 << 20) + np.floor(elevation / resolution).astype(np.int64)
    return ranges, keys


class SeenSpace:
    """What a sensor at the origin saw of a cloud: the nearest range along each ray bin,
    built once and asked about any number of points.

    Parameters
    ----------
    seen : ndarray of shape (m, 3)
        In the frame of the sensor that saw it, which stands at the origin.
    resolution : float, default=ANGULAR_RESOLUTION
        Width of a ray bin, in radians.
    """

    def __init__(self, seen: np.ndarray, resolution: float = ANGULAR_RESOLUTION) -> None:
        self.resolution = resolution
        self.turn = _equator(seen)
        seen_range, seen_key = _rays(seen @ self.turn.T, resolution)
        order = np.lexsort((seen_range, seen_key))
        self.keys, first = np.unique(seen_key[order], return_index=True)
        self.nearest = seen_range[order][first]

    def violation_share(self, points: np.ndarray, margin: float) -> float:
        """The share of ``points`` (same frame) nearer to the sensor than what it saw
        along their rays, of those whose rays it covers (0 when none do); ``margin``:
        see :func:`violation_share`."""
        ranges, point_keys = _rays(points @ self.turn.T, self.resolution)
        at = np.minimum(np.searchsorted(self.keys, point_keys), len(self.keys) - 1)
        covered = self.keys[at] == point_keys
        if not covered.any():
            return 0.0
        limit = self.nearest[at[covered]] * (1.0 - RANGE_MARGIN) - margin
        return float(np.mean(ranges[covered] < limit))


def violation_share(
    points: np.ndarray,
    seen: np.ndarray,
    margin: float,
    resolution: float = ANGULAR_RESOLUTION,
) -> float:
    """The share of ``points`` nearer to the origin than what ``seen`` shows along
    their rays, of those whose rays ``seen`` covers (0 when none do).

    Parameters
    ----------
    points, seen : ndarray of shape (n, 3), (m, 3)
        In the frame of the sensor that saw ``seen``, which stands at the origin.
    margin : float
        Absolute margin (the clouds' units): a point counts when it is nearer than the
        seen surface's range times ``1 - RANGE_MARGIN``, minus ``margin``.
    resolution : float, default=ANGULAR_RESOLUTION
        Width of a ray bin, in radians.

    Returns
    -------
    float
    """
    return SeenSpace(seen, resolution).violation_share(points, margin)


def free_space_violations(
    source: np.ndarray,
    target: np.ndarray,
    transformations: np.ndarray,
    source_view: np.ndarray,
    target_view: np.ndarray,
    margin: float,
    n_threads: int = 1,
) -> np.ndarray:
    """For each transformation, the larger share of either scan it puts in the other
    sensor's seen free space (:func:`violation_share`, both ways): the same whichever
    scan is the source. What each sensor saw is binned once for all of them; the
    transformations are shared out over ``n_threads`` threads (each measured alone).

    Parameters
    ----------
    source, target : ndarray of shape (n, 3), (m, 3)
        Each in its own coordinates.
    transformations : ndarray of shape (k, 4, 4)
        Each maps ``source`` into ``target``'s coordinates.
    source_view, target_view : ndarray of shape (3,)
        Where each scan's sensor stood, in that scan's coordinates.
    margin : float
        Absolute range margin (see :func:`violation_share`).
    n_threads : int, default=1

    Returns
    -------
    ndarray of shape (k,)
        From 0 (nothing in front of what either sensor saw) to 1.
    """
    seen_by_target = SeenSpace(target - target_view)
    seen_by_source = SeenSpace(source - source_view)
    shares = np.empty(len(transformations), dtype=np.float64)

    def measure(k: int) -> None:
        rotation, shift = transformations[k][:3, :3], transformations[k][:3, 3]
        moved = source @ rotation.T + shift - target_view
        back = (target - shift) @ rotation - source_view  # target into source's coordinates
        shares[k] = max(
            seen_by_target.violation_share(moved, margin),
            seen_by_source.violation_share(back, margin),
        )

    map_threads(measure, [(k,) for k in range(len(transformations))], n_threads)
    return shares


def free_space_violation(
    source: np.ndarray,
    target: np.ndarray,
    transformation: np.ndarray,
    source_view: np.ndarray,
    target_view: np.ndarray,
    margin: float,
) -> float:
    """:func:`free_space_violations` of one transformation (4, 4)."""
    stack = np.asarray(transformation, dtype=np.float64)[None]
    return float(free_space_violations(source, target, stack, source_view, target_view, margin)[0])
