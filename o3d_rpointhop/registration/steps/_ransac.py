"""RANSAC over putative correspondences, vectorised: hypotheses are drawn, checked and
scored in batches.

Open3D's ``registration_ransac_based_on_correspondence`` costs about 85 us per iteration
on one thread (it transforms and scores the whole source cloud for every hypothesis
that passes its checkers), and it is only repeatable on one thread. Here a batch of
hypotheses costs a few array operations and two compiled passes: triples are drawn
with a seeded numpy generator, filtered by Open3D's two checkers (edge-length
similarity, in one compiled pass with the distinctness check; then the distance of
the triple's own points after the fit), fitted by a batched Kabsch solve,
and ranked by the number of correspondences they carry within the distance threshold
(which also sets when to stop). The best-ranked ones are then verified as Open3D
scores every hypothesis: by fitness (share of all source points with a target point
within the threshold), then inlier RMSE, on the whole clouds. The winner is refitted on
its inlier correspondences while that gathers more of them. Results depend only on
the seed, not on the number of threads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._utils.cells import CellGrid
from ..._utils.compiled import kernel
from ...transforms import from_centred, rigid_transform, rigid_transforms
from ._edges import consistent_edges
from ._hypotheses import pick_distinct
from ._refit import refit_while_growing

__all__ = ["RansacResult", "ransac"]

# Correspondence-hypothesis pairs scored at once (bounds the scoring's temporaries).
_SCORE_ELEMENTS = 1 << 21
_FIRST_BATCH = 256
_MAX_BATCH = 8192
# Best-ranked hypotheses verified on the whole clouds.
_VERIFIED = 64


@dataclass
class RansacResult:
    """Outcome of :func:`ransac`.

    Attributes
    ----------
    transformation : ndarray of shape (4, 4)
    inliers : ndarray of bool, shape (m,)
        Correspondences within the threshold under ``transformation``.
    iterations : int
        Hypotheses drawn.
    hypotheses : ndarray of shape (k, 4, 4)
        The best ``n_hypotheses`` distinct hypotheses, best first (``transformation``
        is the first, refitted; with ``clouds`` the others are as drawn, without them
        refitted on the matches); empty when no sample passed the checkers.
    """

    transformation: np.ndarray
    inliers: np.ndarray
    iterations: int
    hypotheses: np.ndarray


@kernel()
def _moved_clouds(rot, shift, points):  # pragma: no cover - compiled
    """``points`` moved by every hypothesis, ``(b, n, 3)``: ``rot[b] @ p + shift[b]``.

    Each coordinate is summed ``(r0 x + r2 z) + r1 y``, the order numpy 2's ``einsum``
    takes for ``"bij,nj->bni"`` (measured bit for bit on 346k points), so the kernel
    moves the clouds as the einsum it replaced did, at a tenth of its time.
    """
    b, n = rot.shape[0], points.shape[0]
    out = np.empty((b, n, 3))
    for h in range(b):
        for k in range(n):
            x, y, z = points[k, 0], points[k, 1], points[k, 2]
            for i in range(3):
                turned = (rot[h, i, 0] * x + rot[h, i, 2] * z) + rot[h, i, 1] * y
                out[h, k, i] = turned + shift[h, i]
    return out


def _residuals(rot, shift, src, tgt) -> np.ndarray:
    """Squared distances ``(b, m)`` between moved ``src`` and ``tgt`` (coordinate planes,
    ``(3, m)``) for every hypothesis, in the precision of ``src``. Elementwise passes over
    the planes: the same arithmetic for every entry whatever the thread count, and 11x
    faster than an ``einsum``."""
    dtype = src.dtype
    rot, shift = rot.astype(dtype), shift.astype(dtype)
    out = None
    for i in range(3):
        d = rot[:, i, 0:1] * src[0]
        d += rot[:, i, 1:2] * src[1]
        d += rot[:, i, 2:3] * src[2]
        d += shift[:, i : i + 1] - tgt[i]
        d *= d
        out = d if out is None else out + d
    return out


def _needed(ratio: float, confidence: float, sample: int) -> float:
    """Draws needed to see one all-inlier sample with probability ``confidence``."""
    good = ratio**sample
    if good >= 1.0:
        return 0.0
    if good <= 0.0:
        return np.inf
    return np.log(1.0 - confidence) / np.log1p(-good)


def _verify(rot, shift, clouds, grid: CellGrid) -> np.ndarray:
    """The hypotheses ranked by fitness, then inlier RMSE, on whole clouds (the first
    drawn on a tie)."""
    source = clouds[0]
    moved = _moved_clouds(rot, shift, source)
    dist, _ = grid.nearest(moved.reshape(-1, 3))
    dist = dist.reshape(len(rot), len(source))
    inside = np.isfinite(dist)
    fitness = inside.mean(axis=1)
    squares = np.where(inside, dist, 0.0) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        rmse = np.sqrt(squares.sum(axis=1) / inside.sum(axis=1))
    rmse[~inside.any(axis=1)] = np.inf
    return np.lexsort((rmse, -fitness))


def _refit_on_clouds(transformation, clouds, grid: CellGrid, rounds: int = 5):
    """Refit on the clouds' nearest-neighbour pairs within the grid's radius (as
    Open3D's RANSAC finishes), while that gathers more pairs; the last refit is kept
    (Open3D's rule), even one that lost a pair."""
    source, target = clouds
    partners = {}  # each inlier mask (by identity) -> its points' nearest target points

    def within(t):
        dist, idx = grid.nearest(source @ t[:3, :3].T + t[:3, 3])
        inside = np.isfinite(dist)
        partners[id(inside)] = idx
        return inside

    def fit(t, inside):
        return rigid_transform(source[inside], target[partners[id(inside)][inside]])

    return refit_while_growing(transformation, within, fit, rounds, keep_losing=True)[0]


def _refit_on_matches(transformation, planes, sq_threshold, source, target, rounds: int = 5):
    """Refit on the inlier matches while that gathers more of them."""

    def within(t):
        return _residuals(t[None, :3, :3], t[None, :3, 3], *planes)[0] < sq_threshold

    def fit(t, inliers):
        return rigid_transform(source[inliers], target[inliers])

    return refit_while_growing(transformation, within, fit, rounds)[0]


def ransac(
    source: np.ndarray,
    target: np.ndarray,
    threshold: float,
    *,
    max_iteration: int,
    confidence: float,
    edge_length: float,
    seed: int,
    ransac_n: int = 3,
    clouds: tuple[np.ndarray, np.ndarray] | None = None,
    upright=None,
    n_hypotheses: int = 1,
) -> RansacResult:
    """Robust rigid fit to putative matches ``source[i] <-> target[i]``.

    Parameters
    ----------
    source, target : ndarray of shape (m, 3)
        Matched points, ``m >= 3``.
    threshold : float
        Inlier distance.
    max_iteration : int
        Most hypotheses drawn; drawing stops earlier once the best hypothesis's inlier
        ratio ``w`` says that ``log(1 - confidence) / log(1 - w^3)`` draws suffice.
    confidence : float
        In (0, 1).
    edge_length : float
        Edge-length checker similarity in [0, 1): the three edges of a triple must agree
        within this ratio (0 disables the checker).
    seed : int
    ransac_n : int, default=3
        Correspondences per hypothesis.
    clouds : (ndarray, ndarray), default=None
        The whole source and target clouds, to verify the best-ranked hypotheses by
        fitness; ``None`` keeps the hypothesis with the most inlier correspondences.
    upright : callable, default=None
        ``upright(rotations) -> bool mask``: hypotheses it rejects are dropped (an
        up-axis prior); ``None`` keeps all.
    n_hypotheses : int, default=1
        How many of the best-ranked distinct hypotheses to return
        (:func:`~._hypotheses.distinct`); see ``hypotheses`` in :class:`RansacResult`.

    Returns
    -------
    RansacResult
    """
    # Work about the matches' centre: coordinates stay small wherever the clouds are, so
    # hypotheses can be scored in float32 (half the memory traffic of float64).
    centre = np.asarray(target, dtype=np.float64).mean(axis=0)
    source = np.asarray(source, dtype=np.float64) - centre
    target = np.asarray(target, dtype=np.float64) - centre
    planes = np.ascontiguousarray(source.T), np.ascontiguousarray(target.T)
    planes32 = planes[0].astype(np.float32), planes[1].astype(np.float32)
    if clouds is not None:
        clouds = (clouds[0] - centre, clouds[1] - centre)
    m = len(source)
    if m < max(3, ransac_n):
        raise ValueError(f"RANSAC needs at least {max(3, ransac_n)} correspondences, got {m}")
    rng = np.random.default_rng(seed)
    sq_threshold = threshold * threshold
    # The pool of best-ranked hypotheses: rotation, translation, inlier count, cost.
    pool_rot, pool_shift = np.empty((0, 3, 3)), np.empty((0, 3))
    pool_count, pool_cost = np.empty(0, dtype=np.int64), np.empty(0)
    drawn, needed, batch = 0, float(max_iteration), _FIRST_BATCH
    while drawn < min(max_iteration, needed):
        size = int(min(batch, max_iteration - drawn))
        drawn += size
        batch = min(2 * batch, _MAX_BATCH)
        samples = rng.integers(0, m, size=(size, ransac_n))
        samples = samples[consistent_edges(samples, source, target, float(edge_length))]
        src, tgt = source[samples], target[samples]  # (b, ransac_n, 3)
        if not len(src):
            continue
        rot, shift = rigid_transforms(src, tgt)
        moved = np.einsum("bij,bkj->bki", rot, src) + shift[:, None, :]
        ok = (((moved - tgt) ** 2).sum(axis=2) < sq_threshold).all(axis=1)
        if upright is not None:
            ok &= upright(rot)
        rot, shift = rot[ok], shift[ok]
        step = max(1, _SCORE_ELEMENTS // m)
        for lo in range(0, len(rot), step):
            sq = _residuals(rot[lo : lo + step], shift[lo : lo + step], *planes32)
            inside = sq < sq_threshold
            pool_rot = np.concatenate([pool_rot, rot[lo : lo + step]])
            pool_shift = np.concatenate([pool_shift, shift[lo : lo + step]])
            pool_count = np.concatenate([pool_count, inside.sum(axis=1)])
            pool_cost = np.concatenate(
                [pool_cost, np.where(inside, sq, 0.0).sum(axis=1, dtype=np.float64)]
            )
            # Most inliers, then the smallest sum of their squared residuals, then the
            # first drawn: a seed gives one answer.
            keep = np.lexsort((pool_cost, -pool_count))[:_VERIFIED]
            pool_rot, pool_shift = pool_rot[keep], pool_shift[keep]
            pool_count, pool_cost = pool_count[keep], pool_cost[keep]
        if len(pool_count):
            needed = _needed(pool_count[0] / m, confidence, ransac_n)
    transformation = np.eye(4)
    hypotheses = np.empty((0, 4, 4))
    if len(pool_count):
        if clouds is not None:
            grid = CellGrid(clouds[1], threshold)
            order = _verify(pool_rot, pool_shift, clouds, grid)
            pool_rot, pool_shift = pool_rot[order], pool_shift[order]
        picked = pick_distinct(pool_rot, pool_shift, n_hypotheses, source.mean(axis=0), threshold)
        if clouds is not None:
            # Only the step's own choice is refitted: the others are refined by the
            # verification's short ICP before they are scored (a rival that wins is
            # returned as drawn, and the steps after the global one refine it).
            first = _refit_on_clouds(picked[0], clouds, grid)
            hypotheses = np.concatenate([first[None], picked[1:]])
        else:
            hypotheses = np.stack(
                [_refit_on_matches(t, planes, sq_threshold, source, target) for t in picked]
            )
        transformation = hypotheses[0]
    # else: no sample passed the checkers, no estimate
    inliers = (
        _residuals(transformation[None, :3, :3], transformation[None, :3, 3], *planes)[0]
        < sq_threshold
    )
    transformation = from_centred(transformation, centre)  # back from the centred frame
    hypotheses = from_centred(hypotheses, centre)
    return RansacResult(
        transformation=transformation, inliers=inliers, iterations=drawn, hypotheses=hypotheses
    )
