"""A correspondence-graph consensus: rigid motions from the matches that agree with each
other, after SC2-PCR (Chen et al., CVPR 2022).

Two correct matches ``(s_i, t_i)`` and ``(s_j, t_j)`` keep their length under a rigid
motion: ``| |s_i - s_j| - |t_i - t_j| |`` is below the noise. So the matches form a
graph whose edges join length-compatible pairs, and the correct matches form its
largest, densest cluster. The kernel

1. builds the compatibility graph as a bit matrix (row ``i`` holds one bit per match,
   set for the matches compatible with ``i``): ``m^2 / 8`` bytes, 3 MB at 5000 matches;
2. picks seeds: the ``n_seeds`` matches compatible with the most others (every match
   when there are fewer);
3. grows each seed ``i`` into a consensus set by second-order compatibility,
   ``SC2[i, j] = C[i, j] * |N(i) & N(j)|``, the number of matches compatible with both
   (a popcount of two rows), which separates a true cluster from matches that agree
   with the seed by chance; the set is the seed and its ``set_size`` best partners;
4. fits one rigid motion per set by a weighted SVD (weights: the SC2 scores);
5. scores every hypothesis on all matches, as the published estimators do, rather than
   on the whole clouds: a truncated quadratic, ``sum(max(0, 1 - r^2 / tau^2))`` over the
   residuals ``r`` of the matches;
6. refits the winner on its inliers while that gathers more of them.

Steps 1, 3 and 5 are compiled (numba, :mod:`o3d_rpointhop._utils.compiled`); the
scoring runs on ``n_threads`` threads, each hypothesis summed in one fixed order, so the
result does not depend on the thread count. Deterministic: no random draw; ties go to
the lower index.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._utils.compiled import kernel, prange, threads
from ...transforms import rigid_transform, rigid_transforms

__all__ = ["ConsensusResult", "compatibility", "consensus"]


@dataclass
class ConsensusResult:
    """Outcome of :func:`consensus`.

    Attributes
    ----------
    transformation : ndarray of shape (4, 4)
    inliers : ndarray of bool, shape (m,)
        Matches within the inlier distance under ``transformation``.
    n_hypotheses : int
    seeds : ndarray of int
        The seed matches the hypotheses grew from.
    """

    transformation: np.ndarray
    inliers: np.ndarray
    n_hypotheses: int
    seeds: np.ndarray


@kernel()
def _compatibility_bits(
    source, target, threshold, second_threshold, min_span, source_index, target_index
):  # pragma: no cover - compiled
    """The compatibility graphs as bit rows: bit ``j`` of row ``i`` set when matches
    ``i != j`` keep their length to within ``threshold`` (first order) or
    ``second_threshold`` (the graph whose common neighbours are counted), unless the
    pair is masked: its lengths sum to less than ``min_span`` (too close on both sides
    to say anything about a rotation) or the two matches share a source or a target
    point. Returns both graphs ``(m, ceil(m / 64))`` uint64 (the same array when the
    thresholds are equal) and the first graph's degrees."""
    m = source.shape[0]
    words = (m + 63) // 64
    bits = np.zeros((m, words), dtype=np.uint64)
    same = second_threshold == threshold
    second = bits if same else np.zeros((m, words), dtype=np.uint64)
    degree = np.zeros(m, dtype=np.int64)
    one = np.uint64(1)
    for i in range(m):
        for j in range(i + 1, m):
            if source_index[i] == source_index[j] or target_index[i] == target_index[j]:
                continue
            dx = source[i, 0] - source[j, 0]
            dy = source[i, 1] - source[j, 1]
            dz = source[i, 2] - source[j, 2]
            ds = np.sqrt(dx * dx + dy * dy + dz * dz)
            dx = target[i, 0] - target[j, 0]
            dy = target[i, 1] - target[j, 1]
            dz = target[i, 2] - target[j, 2]
            dt = np.sqrt(dx * dx + dy * dy + dz * dz)
            if ds + dt < min_span:
                continue
            gap = abs(ds - dt)
            if gap < threshold:
                bits[i, j >> 6] |= one << np.uint64(j & 63)
                bits[j, i >> 6] |= one << np.uint64(i & 63)
                degree[i] += 1
                degree[j] += 1
            if not same and gap < second_threshold:
                second[i, j >> 6] |= one << np.uint64(j & 63)
                second[j, i >> 6] |= one << np.uint64(i & 63)
    return bits, second, degree


@kernel(parallel=True)
def _consensus_sets(bits, second, seeds, set_size):  # pragma: no cover - compiled
    """For every seed, its ``set_size`` partners (compatible with it in ``bits``) with
    the highest second-order compatibility, the number of matches compatible with both
    in ``second`` (ties: the lower index), and those scores; a seed with fewer
    compatible matches is padded with itself at score 0."""
    m, words = bits.shape
    n = seeds.shape[0]
    members = np.empty((n, set_size), dtype=np.int64)
    scores = np.zeros((n, set_size), dtype=np.float64)
    one = np.uint64(1)
    # Population count of a word (the SWAR sum of its bits).
    m1, m2 = np.uint64(0x5555555555555555), np.uint64(0x3333333333333333)
    m4, h01 = np.uint64(0x0F0F0F0F0F0F0F0F), np.uint64(0x0101010101010101)
    for s in prange(n):
        i = seeds[s]
        count = 0
        for w in range(words):
            x = bits[i, w]
            x = x - ((x >> one) & m1)
            x = (x & m2) + ((x >> np.uint64(2)) & m2)
            count += ((x + (x >> np.uint64(4))) & m4) * h01 >> np.uint64(56)
        partners = np.empty(count, dtype=np.int64)
        values = np.empty(count, dtype=np.int64)
        c = 0
        for j in range(m):
            if (bits[i, j >> 6] >> np.uint64(j & 63)) & one:
                shared = 0
                for w in range(words):
                    x = second[i, w] & second[j, w]
                    x = x - ((x >> one) & m1)
                    x = (x & m2) + ((x >> np.uint64(2)) & m2)
                    shared += ((x + (x >> np.uint64(4))) & m4) * h01 >> np.uint64(56)
                partners[c] = j
                values[c] = shared
                c += 1
        # Highest first; mergesort is stable, so equal scores keep the lower index first.
        order = np.argsort(-values, kind="mergesort")
        k = min(set_size, count)
        for r in range(set_size):
            if r < k:
                members[s, r] = partners[order[r]]
                scores[s, r] = values[order[r]]
            else:
                members[s, r] = i
    return members, scores


@kernel(parallel=True)
def _truncated_scores(rot, shift, source, target, sq_threshold):  # pragma: no cover
    """Every hypothesis's ``sum(max(0, 1 - r^2 / tau^2))`` over all matches."""
    n = rot.shape[0]
    m = source.shape[0]
    out = np.zeros(n)
    for h in prange(n):
        total = 0.0
        for i in range(m):
            r2 = 0.0
            for a in range(3):
                x = (
                    rot[h, a, 0] * source[i, 0]
                    + rot[h, a, 1] * source[i, 1]
                    + rot[h, a, 2] * source[i, 2]
                    + shift[h, a]
                    - target[i, a]
                )
                r2 += x * x
            if r2 < sq_threshold:
                total += 1.0 - r2 / sq_threshold
        out[h] = total
    return out


def _bits(source, target, threshold, second_threshold, min_span, endpoints):
    """Both compatibility graphs and the first's degrees (see
    :func:`_compatibility_bits`); ``endpoints`` None masks no shared endpoint."""
    m = len(source)
    if endpoints is None:
        # Distinct ids on both sides: no pair shares an endpoint.
        source_index = target_index = np.arange(m, dtype=np.int64)
    else:
        source_index, target_index = (np.asarray(e, dtype=np.int64) for e in endpoints)
    second = threshold if second_threshold is None else second_threshold
    return _compatibility_bits(
        np.ascontiguousarray(source, dtype=np.float64),
        np.ascontiguousarray(target, dtype=np.float64),
        float(threshold),
        float(second),
        float(min_span),
        np.ascontiguousarray(source_index),
        np.ascontiguousarray(target_index),
    )


def compatibility(
    source: np.ndarray,
    target: np.ndarray,
    threshold: float,
    *,
    min_span: float = 0.0,
    endpoints: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Pairwise length compatibility of matches as a dense ``(m, m)`` bool matrix (for
    inspection and tests; the kernel keeps the bits packed).

    ``C[i, j]`` is True when ``| |s_i - s_j| - |t_i - t_j| | < threshold`` (``i != j``),
    the two lengths sum to at least ``min_span``, and (with ``endpoints``, the matches'
    source and target point ids) the matches share neither point.
    """
    bits, _, _ = _bits(source, target, threshold, None, min_span, endpoints)
    m = len(source)
    dense = np.unpackbits(bits.view(np.uint8), axis=1, bitorder="little")
    return dense[:, :m].astype(bool)


def _within(transformation, source, target, sq_threshold) -> np.ndarray:
    """Matches whose residual under ``transformation`` is below the threshold."""
    moved = source @ transformation[:3, :3].T + transformation[:3, 3]
    return ((moved - target) ** 2).sum(axis=1) < sq_threshold


def _weighted_fit(source, target, transformation, sq_threshold) -> np.ndarray:
    """A rigid fit on the matches within the threshold of ``transformation``, each
    weighted by its truncated quadratic score ``1 - r^2 / tau^2``."""
    moved = source @ transformation[:3, :3].T + transformation[:3, 3]
    r2 = ((moved - target) ** 2).sum(axis=1)
    weight = np.clip(1.0 - r2 / sq_threshold, 0.0, None)
    inside = weight > 0
    rot, shift = rigid_transforms(source[inside][None], target[inside][None], weight[inside][None])
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot[0], shift[0]
    return out


def _refit(transformation, source, target, sq_threshold, rounds: int = 20, weighted=False):
    """Refit on the inlier matches while that gathers more of them (each weighted by
    its truncated quadratic score with ``weighted``); returns the fit and its inliers."""
    best = transformation
    inside = _within(best, source, target, sq_threshold)
    for _ in range(rounds):
        if inside.sum() < 3:
            break
        try:
            if weighted:
                refit = _weighted_fit(source, target, best, sq_threshold)
            else:
                refit = rigid_transform(source[inside], target[inside])
        except ValueError:  # collinear inliers: keep what there is
            break
        more = _within(refit, source, target, sq_threshold)
        if more.sum() < inside.sum():
            break
        grew = more.sum() > inside.sum()
        best, inside = refit, more
        if not grew:
            break
    return best, inside


def _seeds(source, degree, n_seeds: int, seed_radius: float | None) -> np.ndarray:
    """The matches that seed hypotheses: with ``seed_radius``, only those with the
    highest degree among the matches whose source points lie within that distance
    (non-maximum suppression, ties to the lower index); then the ``n_seeds`` of
    highest degree, with at least two compatible matches; sorted by index."""
    order = np.argsort(-degree, kind="stable")
    candidates = degree >= 2  # a seed needs partners to fit a motion
    if seed_radius is not None and seed_radius > 0:
        from scipy.spatial import cKDTree

        rank = np.empty(len(order), dtype=np.int64)
        rank[order] = np.arange(len(order))
        near = cKDTree(source).query_pairs(float(seed_radius), output_type="ndarray")
        if len(near):
            a, b = near[:, 0], near[:, 1]
            beaten = np.where(rank[a] < rank[b], b, a)
            candidates[beaten] = False
    order = order[candidates[order]]
    return np.sort(order[:n_seeds])


def consensus(
    source: np.ndarray,
    target: np.ndarray,
    *,
    compatibility_threshold: float,
    inlier_threshold: float,
    score_threshold: float,
    second_order_threshold: float | None = None,
    min_span: float = 0.0,
    endpoints: tuple[np.ndarray, np.ndarray] | None = None,
    n_seeds: int = 1000,
    seed_radius: float | None = None,
    set_size: int = 30,
    weighted_refit: bool = False,
    upright=None,
    n_threads: int = 1,
) -> ConsensusResult:
    """A rigid motion from putative matches ``source[i] <-> target[i]`` by consensus.

    Parameters
    ----------
    source, target : ndarray of shape (m, 3)
        Matched points, ``m >= 3``.
    compatibility_threshold : float
        Largest length difference of two compatible matches (the first-order graph: a
        seed's set is drawn from the matches compatible with it).
    inlier_threshold : float
        Residual within which a match is an inlier of the winner (its refit).
    score_threshold : float
        Truncation of the hypotheses' score.
    second_order_threshold : float, default=None
        Largest length difference in the graph whose common neighbours rank a seed's
        partners (second-order compatibility); ``None``: ``compatibility_threshold``.
    min_span : float, default=0.0
        Two matches whose lengths sum to less than this are not compatible: points
        that close on both sides fix no rotation and agree with any hypothesis.
    endpoints : (ndarray, ndarray), default=None
        Each match's source and target point ids: two matches that share a point are
        not compatible (one of them is wrong). ``None``: not checked.
    n_seeds : int, default=1000
        Most hypotheses: the matches compatible with the most others seed them.
    seed_radius : float, default=None
        Non-maximum suppression of the seeds: among matches whose source points lie
        within this distance only the best-connected one seeds (``None``: every match
        may).
    set_size : int, default=30
        Partners of a seed in its consensus set.
    weighted_refit : bool, default=False
        Weigh every match of the winner's refit by its truncated quadratic score
        within ``inlier_threshold``, rather than all inliers alike.
    upright : callable, default=None
        ``upright(rotations) -> bool mask``: hypotheses it rejects cannot win (an
        up-axis prior); ``None`` keeps all.
    n_threads : int, default=1
        Threads of the compiled set building and scoring (the result does not depend
        on it).

    Returns
    -------
    ConsensusResult
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    m = len(source)
    if m < 3:
        raise ValueError(f"the consensus needs at least 3 matches, got {m}")
    # About the matches' centre: coordinates stay small wherever the clouds are.
    centre = target.mean(axis=0)
    source = np.ascontiguousarray(source - centre)
    target = np.ascontiguousarray(target - centre)
    bits, second, degree = _bits(
        source, target, compatibility_threshold, second_order_threshold, min_span, endpoints
    )
    seeds = _seeds(source, degree, n_seeds, seed_radius)
    transformation = np.eye(4)
    sq_inlier = inlier_threshold**2
    if len(seeds):
        k = min(set_size, m - 1)
        with threads(n_threads):
            partners, weights = _consensus_sets(bits, second, seeds, k)
            members = np.concatenate([seeds[:, None], partners], axis=1)
            weights = np.concatenate([weights.max(axis=1, keepdims=True), weights], axis=1)
            rot, shift = rigid_transforms(source[members], target[members], weights)
            rot, shift = np.ascontiguousarray(rot), np.ascontiguousarray(shift)
            sq_score = float(score_threshold) ** 2
            score = _truncated_scores(rot, shift, source, target, sq_score)
        allowed = np.ones(len(score), dtype=bool) if upright is None else upright(rot)
        best = int(np.argmax(np.where(allowed, score, -1.0)))  # the first of equal scores
    if len(seeds) and allowed[best]:
        transformation[:3, :3], transformation[:3, 3] = rot[best], shift[best]
        transformation, inliers = _refit(
            transformation, source, target, sq_inlier, weighted=weighted_refit
        )
    else:  # no hypothesis, or none the up prior allows: no estimate
        inliers = _within(transformation, source, target, sq_inlier)
    # Back from the centred frame: x -> R (x - c) + t + c.
    transformation[:3, 3] += centre - transformation[:3, :3] @ centre
    return ConsensusResult(
        transformation=transformation, inliers=inliers, n_hypotheses=len(seeds), seeds=seeds
    )
