"""The kernels of hypotheses verified by overlap: distinct hypotheses, the overlap score
of a pose on both clouds and the support of its matches (the verification itself, which
refines each hypothesis by a short ICP, is the step-level :mod:`._verification`).

A global step ranks its hypotheses by what it sees, the matches (or, for RANSAC, the
source's fitness). On a pair that overlaps little, a wrong hypothesis can carry more
matches than the right one: matches from parts the other cloud never saw agree by
chance on a repeated structure. Refining each of a few distinct hypotheses and scoring
the refined poses on the clouds themselves, in both directions, lets the right one win
once it fits better; the winner's margin over the runner-up says how sure the choice
was.
"""

from __future__ import annotations

import numpy as np

from ..._utils.cells import CellGrid

__all__ = [
    "DISTINCT_ANGLE_DEG",
    "DISTINCT_SHIFT",
    "apart_from",
    "distinct",
    "match_support",
    "overlap_score",
    "pick_distinct",
]

#: Two hypotheses are distinct when their rotations differ by more than this, or their
#: motions of the source's centre by more than the step's inlier distance times
#: :data:`DISTINCT_SHIFT`.
DISTINCT_ANGLE_DEG = 10.0
DISTINCT_SHIFT = 3.0
#: Two points overlap only when their normals agree within this angle.
NORMAL_ANGLE_DEG = 30.0


def apart_from(many: np.ndarray, one: np.ndarray, centre: np.ndarray, shift: float) -> np.ndarray:
    """Which of the motions ``many`` (b, 4, 4) differ from ``one`` by more than
    :data:`DISTINCT_ANGLE_DEG` or move ``centre`` more than ``shift`` apart from it."""
    cos = (np.einsum("bji,ji->b", many[:, :3, :3], one[:3, :3]) - 1.0) / 2.0
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    moved = (many[:, :3, :3] - one[:3, :3]) @ centre + many[:, :3, 3] - one[:3, 3]
    return (angle > DISTINCT_ANGLE_DEG) | (np.linalg.norm(moved, axis=1) > shift)


def distinct(transformations: np.ndarray, k: int, centre: np.ndarray, shift: float) -> np.ndarray:
    """Indices of the first ``k`` of ``transformations`` (b, 4, 4; best first) that are
    distinct from every one taken before them (their rotations more than
    :data:`DISTINCT_ANGLE_DEG` apart, or ``centre`` moved more than ``shift`` apart)."""
    taken: list[int] = []
    open_ = np.ones(len(transformations), dtype=bool)
    while len(taken) < k and open_.any():
        i = int(np.argmax(open_))
        taken.append(i)
        if len(taken) < k:  # only a next pick needs the others compared with this one
            open_ &= apart_from(transformations, transformations[i], centre, shift)
    return np.asarray(taken, dtype=np.int64)


def pick_distinct(
    rotations: np.ndarray, shifts: np.ndarray, k: int, centre: np.ndarray, threshold: float
) -> np.ndarray:
    """The first ``k`` distinct of the motions ``rotations`` (b, 3, 3) and ``shifts``
    (b, 3), best first, as ``(k', 4, 4)`` matrices: what RANSAC and the consensus hand
    on for verification. Distinct as :func:`distinct` says, ``centre`` moved more than
    :data:`DISTINCT_SHIFT` times the step's inlier distance ``threshold`` apart."""
    pool = np.tile(np.eye(4), (len(rotations), 1, 1))
    pool[:, :3, :3], pool[:, :3, 3] = rotations, shifts
    return pool[distinct(pool, k, centre, DISTINCT_SHIFT * threshold)]


def overlap_score(
    source: np.ndarray,
    target: np.ndarray,
    transformation: np.ndarray,
    distance: float,
    normals: tuple[np.ndarray, np.ndarray] | None = None,
    grids: tuple[CellGrid, CellGrid] | None = None,
) -> float:
    """How well ``transformation`` brings the two clouds together where they can meet:
    every source point within ``distance`` of the target, and every target point within
    ``distance`` of the moved source, each counted by the truncated quadratic ``1 -
    (r / distance)^2`` of its distance ``r`` (with ``normals``, only where the two
    points' normals agree within :data:`NORMAL_ANGLE_DEG`, either sign: surfaces that
    cross are not an overlap); the sum over both clouds, divided by the smaller cloud's
    size (the most points the overlap can hold on one side). ``grids``: the
    :class:`~o3d_rpointhop._utils.cells.CellGrid` of ``source`` and of ``target`` with
    radius ``distance``, built once for many transformations (the target is moved back
    onto the source for the second direction: distances are the same)."""
    if grids is None:
        grids = (CellGrid(source, distance), CellGrid(target, distance))
    rot, shift = transformation[:3, :3], transformation[:3, 3]
    # Each side's queries in the other cloud's frame, and the rotation between them.
    sides = (
        (source @ rot.T + shift, grids[1], rot),
        ((target - shift) @ rot, grids[0], rot.T),
    )
    total = 0.0
    cos = np.cos(np.radians(NORMAL_ANGLE_DEG))
    for side, (queries, grid, turn) in enumerate(sides):
        r, idx = grid.nearest(queries)
        inside = np.isfinite(r)
        weight = 1.0 - (r[inside] / distance) ** 2
        if normals is not None:
            own, other = normals[side], normals[1 - side]
            turned = own[inside] @ turn.T
            agree = np.abs(np.einsum("ij,ij->i", turned, other[idx[inside]])) >= cos
            weight = weight[agree]
        total += float(np.sum(weight))
    return total / min(len(source), len(target))


def match_support(
    matched: tuple[np.ndarray, np.ndarray], transformation: np.ndarray, distance: float
) -> float:
    """The step's matches ``(source points, target points)`` that ``transformation``
    explains, each counted by the truncated quadratic of its residual within
    ``distance``: what the step itself ranks by."""
    a, b = matched
    r2 = ((a @ transformation[:3, :3].T + transformation[:3, 3] - b) ** 2).sum(axis=1)
    return float(np.clip(1.0 - r2 / (distance * distance), 0.0, None).sum())
