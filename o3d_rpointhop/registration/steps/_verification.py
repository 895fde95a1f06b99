"""Hypotheses verified by overlap: a global step's best few distinct estimates, each
refined by a short point-to-plane ICP on the global clouds and scored by how much of
both clouds it brings together (:func:`verify`; its kernels are in :mod:`._hypotheses`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._utils.cells import CellGrid
from ..._utils.threads import map_threads
from ..free_space import free_space_violations
from ._hypotheses import DISTINCT_SHIFT, apart_from, match_support, overlap_score
from ._point_to_plane import refine_point_to_plane
from .icp import PointToPlaneICP

__all__ = ["REFINE_ITERATIONS", "SWITCH_MARGIN", "Verification", "verify"]

#: A hypothesis ranked below the step's own first replaces it only when it scores more
#: than this share higher: where two poses fit alike (a symmetric shape), the step's
#: own ranking keeps the say.
SWITCH_MARGIN = 0.3
#: ICP iterations a hypothesis is refined by before it is scored.
REFINE_ITERATIONS = 15


@dataclass
class Verification:
    """The outcome of :func:`verify`.

    Attributes
    ----------
    best : int
        Index of the winning hypothesis.
    scores : ndarray of shape (k,)
        Every hypothesis's overlap score after its refinement, in the order given.
    refined : ndarray of shape (k, 4, 4)
        The refined hypotheses.
    margin : float
        ``1 - rival / winner``, the rival being the best-scored hypothesis that did not
        refine into the winner (1 when there is none): 0 is a tie, and below 0 a rival
        scored higher without beating the step's own choice by :data:`SWITCH_MARGIN`.
    overlaps : ndarray of shape (k,)
        Every refined hypothesis's :func:`overlap_score` (free of the matches).
    free : ndarray of shape (k,) of bool
        Whether each passed the free-space check (all True without one).
    """

    best: int
    scores: np.ndarray
    refined: np.ndarray
    margin: float
    overlaps: np.ndarray
    free: np.ndarray


def verify(
    context,
    hypotheses: np.ndarray,
    distance: float,
    matched: tuple[np.ndarray, np.ndarray],
    max_violation: float | None = None,
    n_threads: int = 1,
    known: Verification | None = None,
) -> Verification:
    """Refine every hypothesis (centred frame) by a short point-to-plane ICP on the
    global clouds within ``distance`` and score it by its :func:`overlap_score` (with
    normals) times its :func:`match_support`: the clouds must meet where the pose puts
    them, and the matches must agree with it. The best score wins if it beats the first
    hypothesis's (the step's own choice) by more than :data:`SWITCH_MARGIN`; else the
    first stays.

    Parameters
    ----------
    context : RegistrationContext
    hypotheses : ndarray of shape (k, 4, 4)
        Best first, as the global step ranked them.
    distance : float
        The step's inlier distance: the ICP's correspondence distance and the score's.
    matched : (ndarray, ndarray)
        The step's matched source and target points (centred frame), row by row.
    max_violation : float, default=None
        With the sensors known (the context's viewpoints), a hypothesis that puts more
        than this share of either cloud where the other's sensor saw empty space
        (:func:`~o3d_rpointhop.registration.free_space.free_space_violations`) scores 0.
    n_threads : int, default=1
        Threads the hypotheses are shared out over (each is refined and scored alone:
        the result does not depend on it).
    known : Verification, default=None
        A verification of the first hypotheses on the same context and distance (with
        other matches): their refinement, overlap and free-space check are taken from
        it, only their match support is measured again; the result is the same.

    Returns
    -------
    Verification
    """
    coarse = context.coarse()
    source = np.asarray(coarse.source.points)
    target = np.asarray(coarse.target.points)
    # The coarse clouds' normals: with downsampled clouds, the context's own normals of
    # its global clouds, which the wide passes of a point-to-plane ICP share.
    level = "global" if context.downsampled else "full"
    normals = tuple(
        np.asarray(context.with_normals(w, level).normals) for w in ("source", "target")
    )
    grids = (CellGrid(source, distance), CellGrid(target, distance))
    done = 0 if known is None else len(known.refined)
    new = hypotheses[done:]
    if not len(new):
        refined = np.empty((0, 4, 4))
    elif grids[1].on_cells:
        refined = refine_point_to_plane(
            source, grids[1], normals[1], new, REFINE_ITERATIONS, n_threads
        )
    else:  # a cloud too wide for a grid at this distance: Open3D's ICP
        icp = PointToPlaneICP(distance, max_iteration=REFINE_ITERATIONS, full_resolution=False)
        refined = np.stack([icp._run_timed(coarse, h).transformation for h in new])
    overlaps = np.empty(len(refined))

    def overlap(k: int) -> None:
        overlaps[k] = overlap_score(source, target, refined[k], distance, normals, grids)

    map_threads(overlap, [(k,) for k in range(len(refined))], n_threads)
    free = np.ones(len(refined), dtype=bool)
    views, limit = context.viewpoints, max_violation
    if views is not None and limit is not None and len(refined):
        # A pose that puts more than ``limit`` of a cloud where the other sensor saw
        # empty space is wrong however well it fits (free_space.py).
        seen = free_space_violations(
            source,
            target,
            refined,
            views["source"],
            views["target"],
            context.voxel_size,
            n_threads=n_threads,
        )
        free = seen <= limit
    if known is not None:
        refined = np.concatenate([known.refined, refined])
        overlaps = np.concatenate([known.overlaps, overlaps])
        free = np.concatenate([known.free, free])
    support = np.array([match_support(matched, t, distance) for t in refined])
    scores = np.where(free, overlaps * support, 0.0)
    best = int(np.argmax(scores))
    if scores[best] <= (1.0 + SWITCH_MARGIN) * scores[0]:
        best = 0
    centre = source.mean(axis=0)
    rivals = scores[apart_from(refined, refined[best], centre, DISTINCT_SHIFT * distance)]
    margin = 1.0 if not len(rivals) or scores[best] <= 0 else 1.0 - rivals.max() / scores[best]
    return Verification(
        best=best,
        scores=scores,
        refined=refined,
        margin=float(margin),
        overlaps=overlaps,
        free=free,
    )
