"""The shipped model a registration describes with when told ``"auto"``: the object or
the scene model, and whether to orient by the sensor, chosen from the clouds themselves.

The scene model serves scans of rooms taken from a sensor (3DMatch fragments, depth
frames), oriented by that sensor; the object model serves everything else it was chosen
on (whole shapes, scans of objects, outdoor LiDAR sweeps). What tells them apart, for a
cloud in its sensor's frame, is where the origin sits and how large the cloud is:

* **seen from the origin**: every point lies on one side of the origin, inside a cone
  about the mean viewing direction (the mean unit vector from the origin to the points
  is long), and the origin keeps clear of the points, but not far off: a sensor at the
  origin looked at them. A shape centred on the origin, a 360-degree LiDAR sweep around
  it, or a scan in survey coordinates (kilometres from its origin) is not.
* **room-sized**: the cloud spans between 1 and 30 units across, read as metres, the
  unit of RGB-D and laser scans. Scans of objects (the Stanford bunny: 0.25 m) are
  smaller, outdoor sweeps larger.

The thresholds were chosen on training data only (``benchmarks/model_choice.py``: the
ModelNet40 training shapes as the pair protocols present them and every fragment of the
four 3DMatch training scenes); the held-out check is in docs/registration.md.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from .._utils.validation import as_points
from ..descriptors import RPointHopTransformer

__all__ = [
    "MAX_CUE_POINTS",
    "MODELS",
    "ROOM_SIZE",
    "SENSOR_CLEARANCE",
    "SENSOR_CONE",
    "SENSOR_FRONT",
    "CloudCues",
    "ModelChoice",
    "choose_model",
    "cloud_cues",
    "resolve_model",
]

#: The shipped models the choice is between.
MODELS = ("object", "scene")
#: Sizes (in the clouds' units, read as metres) of a room-sized cloud: the span across
#: its points (twice the 99th percentile of their distances from their centroid).
ROOM_SIZE = (1.0, 30.0)
#: The least length of the mean unit vector from the origin to the points of a cloud
#: seen from the origin (1: all along one ray; 0: all around).
SENSOR_CONE = 0.85
#: The least share of the points in front of the origin (a positive projection on the
#: mean viewing direction) of a cloud seen from the origin.
SENSOR_FRONT = 0.99
#: The clearance between the origin and the points (the 1st percentile of their
#: distances from it) of a cloud seen from the origin, as a share of its size: at least
#: the first (a sensor keeps its distance), at most the second (a sensor that far sees
#: little: clouds in survey coordinates lie far from their origin).
SENSOR_CLEARANCE = (0.1, 2.0)
#: The cues are measured on at most this many points of a cloud (an even stride).
MAX_CUE_POINTS = 20_000


@dataclass(frozen=True)
class CloudCues:
    """What the automatic model choice reads from one cloud.

    Attributes
    ----------
    size : float
        Span across the points: twice the 99th percentile of their distances from their
        centroid (a stray point does not count).
    cone : float
        Length of the mean unit vector from the origin to the points.
    front : float
        Share of the points in front of the origin (along the mean viewing direction).
    clearance : float
        The 1st percentile of the points' distances from the origin, over ``size``.
    """

    size: float
    cone: float
    front: float
    clearance: float

    @property
    def seen_from_origin(self) -> bool:
        """Whether a sensor at the origin could have seen these points."""
        return bool(
            self.cone >= SENSOR_CONE
            and self.front >= SENSOR_FRONT
            and SENSOR_CLEARANCE[0] <= self.clearance <= SENSOR_CLEARANCE[1]
        )

    @property
    def room_sized(self) -> bool:
        """Whether the cloud spans a room (:data:`ROOM_SIZE`, read as metres)."""
        return bool(ROOM_SIZE[0] <= self.size <= ROOM_SIZE[1])

    @property
    def room_scan(self) -> bool:
        """A room scanned from a sensor at the origin: what the scene model serves."""
        return self.seen_from_origin and self.room_sized


@dataclass(frozen=True)
class ModelChoice:
    """The model ``"auto"`` chose for some clouds, and why.

    Attributes
    ----------
    model : {"object", "scene"}
        The shipped model (``RPointHopTransformer.pretrained(model)``).
    viewpoints : "origin", None or "given"
        Where the sensors stood, as chosen with the model ("given": positions the
        caller gave).
    reason : str
        What in the clouds decided it, in words.
    room_scans : int
        How many of the clouds read as room scans.
    n_clouds : int
    axes : int or None, default=None
        The leading principal axes the model describes on when a rebuild narrows it
        (:func:`~o3d_rpointhop.registration.multiway.chosen_model`); None: the model's
        own.
    """

    model: str
    viewpoints: str | None
    reason: str
    room_scans: int
    n_clouds: int
    axes: int | None = None

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready, with ``"chosen": "auto"``: what results and records store."""
        return {"chosen": "auto", **asdict(self)}


def cloud_cues(cloud: Any, name: str = "cloud") -> CloudCues:
    """The cues of one cloud (see :class:`CloudCues`).

    Parameters
    ----------
    cloud : array-like of shape (n, 3) or Open3D point cloud
    name : str, default="cloud"
        What error messages call it.

    Returns
    -------
    CloudCues
    """
    points = as_points(cloud, name, min_points=1)
    if len(points) > MAX_CUE_POINTS:
        points = points[np.linspace(0, len(points) - 1, MAX_CUE_POINTS).astype(np.intp)]
    points = np.asarray(points, dtype=np.float64)
    spread = np.linalg.norm(points - points.mean(axis=0), axis=1)
    size = 2.0 * float(np.percentile(spread, 99))
    ranges = np.linalg.norm(points, axis=1)
    if size <= 0 or not np.all(ranges > 0):  # one point, or a point at the origin
        return CloudCues(size=size, cone=0.0, front=0.0, clearance=0.0)
    directions = points / ranges[:, None]
    mean = directions.mean(axis=0)
    cone = float(np.linalg.norm(mean))
    front = float(np.mean(directions @ mean > 0)) if cone > 0 else 0.0
    clearance = float(np.percentile(ranges, 1)) / size
    return CloudCues(size=size, cone=cone, front=front, clearance=clearance)


def choose_model(clouds: list[Any], names: list[str] | None = None) -> ModelChoice:
    """The shipped model for these clouds, and whether to orient by the sensor.

    The scene model, oriented by a sensor at each cloud's origin
    (``viewpoints="origin"``), when at least half of the clouds read as rooms scanned
    from their origin (:attr:`CloudCues.room_scan`; for a pair: both); else the object
    model, with no sensor.

    Parameters
    ----------
    clouds : list of array-like (n, 3) or Open3D point clouds
    names : list of str, default=None
        What error messages call them (default: ``cloud 0``, ``cloud 1``...).

    Returns
    -------
    ModelChoice
    """
    names = names or [f"cloud {k}" for k in range(len(clouds))]
    cues = [cloud_cues(cloud, name) for cloud, name in zip(clouds, names, strict=True)]
    rooms = sum(c.room_scan for c in cues)
    seen = sum(c.seen_from_origin for c in cues)
    sizes = [c.size for c in cues]
    span = f"{min(sizes):.3g}-{max(sizes):.3g}" if len(sizes) > 1 else f"{sizes[0]:.3g}"
    what = "both clouds" if len(cues) == 2 else f"{rooms} of {len(cues)} clouds"
    needed = len(cues) if len(cues) <= 2 else -(-len(cues) // 2)
    if rooms >= needed:
        return ModelChoice(
            "scene",
            "origin",
            f"{what} read as rooms scanned from their origin (seen from it, {span} "
            f"across, within {ROOM_SIZE[0]:g}-{ROOM_SIZE[1]:g})",
            rooms,
            len(cues),
        )
    if seen and not rooms:
        why = f"seen from their origin but {span} across, not room-sized"
    elif seen:
        why = f"only {rooms} of {len(cues)} clouds read as rooms scanned from their origin"
    else:
        why = "not seen from their origin by a sensor"
    return ModelChoice("object", None, f"the clouds are {why}", rooms, len(cues))


def resolve_model(
    descriptor: Any, viewpoints: Any, clouds: list[Any], names: list[str] | None = None
) -> tuple[Any, Any, ModelChoice | None]:
    """The descriptor and viewpoints a registration of ``clouds`` uses.

    Parameters
    ----------
    descriptor : "auto", a shipped model's name, transformer or None
        ``"auto"``: the shipped model :func:`choose_model` picks; a name of
        ``PRETRAINED_MODELS``: ``RPointHopTransformer.pretrained(name)``; a transformer
        or None (the object model) as given.
    viewpoints : "auto", None, "origin" or array-like
        ``"auto"``: what :func:`choose_model` picked with the model when the model was
        ``"auto"``, else None (no sensor known); anything else as given.
    clouds : list of array-like or Open3D point clouds
    names : list of str, default=None
        What error messages call the clouds.

    Returns
    -------
    descriptor, viewpoints, choice
        ``choice`` is None unless the model was chosen here.
    """
    auto_views = isinstance(viewpoints, str) and viewpoints == "auto"
    if isinstance(descriptor, str) and descriptor == "auto":
        choice = choose_model(clouds, names)
        chosen = RPointHopTransformer.pretrained(choice.model)
        if auto_views:
            return chosen, choice.viewpoints, choice
        given = viewpoints if viewpoints is None or isinstance(viewpoints, str) else "given"
        return chosen, viewpoints, replace(choice, viewpoints=given)
    if isinstance(descriptor, str):
        descriptor = RPointHopTransformer.pretrained(descriptor)
    return descriptor, (None if auto_views else viewpoints), None
