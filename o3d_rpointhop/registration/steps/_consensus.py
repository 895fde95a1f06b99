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
   (a popcount of two rows, taken once for two seeds: ``SC2`` is symmetric), which
   separates a true cluster from matches that agree with the seed by chance; the set
   is the seed and its ``set_size`` best partners;
4. fits one rigid motion per set by a weighted SVD (weights: the SC2 scores);
5. scores every hypothesis on the matches, as the published estimators do, rather than
   on the whole clouds: a truncated quadratic, ``sum(max(0, 1 - r^2 / tau^2))`` over the
   residuals ``r`` of the matches; preemptively when there are many (every hypothesis
   on an eighth of the matches, the best few hundred of that on all of them);
6. refits the winner on its inliers while that gathers more of them.

Steps 1, 3 and 5 are compiled (numba, :mod:`o3d_rpointhop._utils.compiled`) and run
on ``n_threads`` threads: the graph's rows, the seeds and the hypotheses' blocks
are shared out, each row, set and sum computed in one fixed order, so the
result does not depend on the thread count. Deterministic: no random draw; ties go to
the lower index.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._utils.compiled import kernel, popcount
from ..._utils.threads import run_blocks
from ...transforms import from_centred, rigid_transform, rigid_transforms
from ._hypotheses import pick_distinct
from ._refit import refit_while_growing

__all__ = [
    "PREEMPT_KEEP",
    "PREEMPT_STRIDE",
    "ConsensusResult",
    "compatibility",
    "compatibility_graphs",
    "consensus",
    "consensus_sets",
    "pooled",
    "truncated_scores",
]


#: Preemptive scoring: with more than :data:`PREEMPT_KEEP` hypotheses and at least
#: ``PREEMPT_STRIDE * PREEMPT_MIN_SAMPLE`` matches, every hypothesis is scored on every
#: ``PREEMPT_STRIDE``-th match and only the ``PREEMPT_KEEP`` best of that on all of
#: them (Nister's preemptive RANSAC scores the same way). Set for time and checked on
#: every pair of the scene model's training scenes: the winner as full scoring's on 36
#: consecutive pairs, 1 pair lost and 2 traded on the rest (docs/benchmarks_3dmatch.md,
#: "Preemptive scoring").
PREEMPT_STRIDE = 8
PREEMPT_KEEP = 256
PREEMPT_MIN_SAMPLE = 64
#: The compatibility graphs' rows are whole multiples of this many 64-bit words (zero
#: beyond the matches): one 512-bit vector.
ROW_ALIGN = 8
#: Partners :func:`consensus_sets` lists at once (8 bytes each), about: further seeds
#: are taken in further runs.
SETS_ENTRIES = 1 << 23


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
    hypotheses : ndarray of shape (k, 4, 4)
        The best-scored ``n_hypotheses`` distinct hypotheses, each refitted, best first
        (``transformation`` is the first); empty without an estimate.
    """

    transformation: np.ndarray
    inliers: np.ndarray
    n_hypotheses: int
    seeds: np.ndarray
    hypotheses: np.ndarray


@kernel(nogil=True)
def _compatibility_bits(
    start,
    stop,
    source,
    target,
    threshold,
    second_threshold,
    min_span,
    source_index,
    target_index,
    bits,
    second,
):  # pragma: no cover - compiled
    """The compatibility graphs as bit rows: bit ``j`` of row ``i`` set when matches
    ``i != j`` keep their length to within ``threshold`` (first order) or
    ``second_threshold`` (the graph whose common neighbours are counted), unless the
    pair is masked: its lengths sum to less than ``min_span`` (too close on both sides
    to say anything about a rotation) or the two matches share a source or a target
    point. ``source`` and ``target`` come as ``(3, m)`` coordinate rows. Writes, for the
    blocks of 64 rows ``start:stop``, each row's words from its block's diagonal word
    on, of both graphs ``bits`` and ``second`` (uint64, ``m`` rows of at least
    ``ceil(m / 64)`` words, the same array when the thresholds are equal);
    :func:`_mirror_bits` fills the words before.

    A pair's bits are the same from either end (its differences only change sign), so
    each row is built from its block's first column on: its lengths first (one pass in
    SIMD lanes over views that start there, whose indices the compiler knows are not
    negative), then its words."""
    m = source.shape[1]
    words = (m + 63) // 64
    same = second_threshold == threshold
    ds = np.empty(m)
    dt = np.empty(m)
    x0, y0, z0 = source[0], source[1], source[2]
    x1, y1, z1 = target[0], target[1], target[2]
    for block in range(start, stop):
        first = block * 64
        sx, sy, sz = x0[first:], y0[first:], z0[first:]
        tx, ty, tz = x1[first:], y1[first:], z1[first:]
        near, far = ds[first:], dt[first:]
        ends_s, ends_t = source_index[first:], target_index[first:]
        for i in range(first, min(m, first + 64)):
            xi, yi, zi = x0[i], y0[i], z0[i]
            ui, vi, wi = x1[i], y1[i], z1[i]
            for j in range(sx.shape[0]):
                dx = xi - sx[j]
                dy = yi - sy[j]
                dz = zi - sz[j]
                near[j] = np.sqrt(dx * dx + dy * dy + dz * dz)
                dx = ui - tx[j]
                dy = vi - ty[j]
                dz = wi - tz[j]
                far[j] = np.sqrt(dx * dx + dy * dy + dz * dz)
            own_source, own_target = source_index[i], target_index[i]
            for w in range(words - block):  # from the block's diagonal word on
                word = np.uint64(0)
                word2 = np.uint64(0)
                for b in range(min(64, sx.shape[0] - w * 64)):
                    j = w * 64 + b
                    a, c = near[j], far[j]
                    keep = (
                        (a + c >= min_span) & (ends_s[j] != own_source) & (ends_t[j] != own_target)
                    )
                    gap = abs(a - c)
                    word |= np.uint64(keep & (gap < threshold)) << np.uint64(b)
                    word2 |= np.uint64(keep & (gap < second_threshold)) << np.uint64(b)
                bits[i, block + w] = word
                if not same:
                    second[i, block + w] = word2


@kernel(inline="always")
def _transpose_tile(tile):  # pragma: no cover - compiled
    """Transpose a 64 x 64 bit matrix in place (row ``c``'s bit ``r`` becomes row
    ``r``'s bit ``c``), swapping the off-diagonal halves of ever smaller blocks."""
    width = 32
    mask = np.uint64(0x00000000FFFFFFFF)
    while width:
        shift = np.uint64(width)
        for k in range(64):
            if k & width:
                continue
            t = ((tile[k] >> shift) ^ tile[k + width]) & mask
            tile[k] ^= t << shift
            tile[k + width] ^= t
        width //= 2
        mask ^= mask << np.uint64(width)


@kernel(nogil=True)
def _mirror_bits(start, stop, m, same, bits, second, degree):  # pragma: no cover - compiled
    """For the blocks of 64 rows ``start:stop``: each word left of the block's diagonal
    word, the transposed tile across the diagonal that :func:`_compatibility_bits`
    built (``second``'s too unless ``same``), and the first graph's degrees."""
    tile = np.zeros(64, dtype=np.uint64)
    for block in range(start, stop):
        first = block * 64
        rows = min(64, m - first)
        for graph in range(1 if same else 2):
            out = bits if graph == 0 else second
            for w in range(block):
                for c in range(64):
                    tile[c] = out[w * 64 + c, block]  # w < block: all 64 rows exist
                _transpose_tile(tile)
                for r in range(rows):
                    out[first + r, w] = tile[r]
        for i in range(first, first + rows):
            count = 0
            for w in range(bits.shape[1]):
                count += popcount(bits[i, w])
            degree[i] = count


@kernel(nogil=True)
def _row_starts(bits, seeds):  # pragma: no cover - compiled
    """Where each seed's compatible matches start in the flat lists of
    :func:`_shared_counts` (the seeds' degrees in ``bits``, summed), and their total."""
    out = np.zeros(seeds.shape[0] + 1, dtype=np.int64)
    for s in range(seeds.shape[0]):
        count = 0
        for w in range(bits.shape[1]):
            count += popcount(bits[seeds[s], w])
        out[s + 1] = out[s] + count
    return out


@kernel(nogil=True)
def _shared_counts(
    start, stop, bits, second, seeds, rank, starts, partners, shared
):  # pragma: no cover - compiled
    """For the seeds ``start:stop``: the matches compatible with each in ``bits``, in
    index order (``partners[starts[s]:starts[s + 1]]``), and for each the number of
    matches compatible with both in ``second`` (a popcount of the two rows). A pair of
    two seeds compatible both ways is counted once, from the lower index; the higher's
    entry is left at -1 for :func:`_mirror_counts` (``rank``: a match's place among the
    seeds, -1 for none)."""
    words = bits.shape[1]
    one = np.uint64(1)
    for s in range(start, stop):
        i = seeds[s]
        p = starts[s]
        for w in range(words):
            word = bits[i, w]
            while word:
                low = word & (~word + one)  # the lowest set bit
                j = w * 64 + popcount(low - one)
                word ^= low
                partners[p] = j
                if j < i and rank[j] >= 0 and (bits[j, i >> 6] >> np.uint64(i & 63)) & one:
                    shared[p] = -1
                else:
                    count = 0
                    for v in range(second.shape[1]):
                        count += popcount(second[i, v] & second[j, v])
                    shared[p] = count
                p += 1


@kernel(nogil=True)
def _mirror_counts(bits, seeds, rank, starts, partners, shared):  # pragma: no cover
    """Fill the entries :func:`_shared_counts` left at -1 from the lower seed's entry.
    The seeds come in increasing index order, so each seed's open entries are met in
    the order they are listed, and a cursor per seed finds them."""
    one = np.uint64(1)
    cursor = starts[:-1].copy()
    for s in range(seeds.shape[0]):
        i = seeds[s]
        for p in range(starts[s], starts[s + 1]):
            j = partners[p]
            if j <= i or rank[j] < 0 or not (bits[j, i >> 6] >> np.uint64(i & 63)) & one:
                continue
            t = rank[j]
            c = cursor[t]
            while c < starts[t + 1] and shared[c] != -1:
                c += 1
            shared[c] = shared[p]
            cursor[t] = c + 1


@kernel(nogil=True)
def _best_partners(
    start, stop, seeds, starts, partners, shared, set_size, members, scores
):  # pragma: no cover - compiled
    """For the seeds ``start:stop``: the ``set_size`` partners with the most common
    neighbours, most first, of equal ones the lower index (a stable sort's order),
    and their counts; a seed with fewer is padded with itself at score 0. The count
    that the last kept partner has is found from a histogram of the seed's counts, so
    one pass keeps those above it (at most ``set_size - 1``, placed by insertion) and
    one takes the first of those equal to it."""
    histogram = np.zeros(64, dtype=np.int64)
    kept_rows = np.empty(set_size, dtype=np.int64)
    kept_counts = np.empty(set_size, dtype=np.int64)
    for s in range(start, stop):
        # The seed's counts and partners as views from 0 (indices the compiler knows
        # are not negative).
        counts, rows = shared[starts[s] : starts[s + 1]], partners[starts[s] : starts[s + 1]]
        n = counts.shape[0]
        if n <= set_size:
            cut = -1  # every partner is kept
        else:
            top = 0
            for p in range(n):
                top = max(top, counts[p])
            if top >= histogram.shape[0]:
                histogram = np.zeros(2 * (top + 1), dtype=np.int64)
            histogram[: top + 1] = 0
            for p in range(n):
                histogram[counts[p]] += 1
            cut = top
            total = histogram[cut]
            while total < set_size:
                cut -= 1
                total += histogram[cut]
        kept = 0
        for p in range(n):
            value = counts[p]
            if value > cut:
                r = kept
                while r > 0 and kept_counts[r - 1] < value:
                    kept_rows[r] = kept_rows[r - 1]
                    kept_counts[r] = kept_counts[r - 1]
                    r -= 1
                kept_rows[r] = rows[p]
                kept_counts[r] = value
                kept += 1
        if cut >= 0:
            for p in range(n):
                if kept == set_size:
                    break
                if counts[p] == cut:
                    kept_rows[kept] = rows[p]
                    kept_counts[kept] = cut
                    kept += 1
        for r in range(set_size):
            if r < kept:
                members[s, r] = kept_rows[r]
                scores[s, r] = kept_counts[r]
            else:
                members[s, r] = seeds[s]


@kernel(nogil=True)
def _truncated_scores(
    start, stop, rot, shift, source, target, sq_threshold, out
):  # pragma: no cover - compiled
    """Every hypothesis's ``sum(max(0, 1 - r^2 / tau^2))`` over all matches.

    ``rot`` comes as ``(9, n)`` (row-major entries of each rotation), ``shift`` as
    ``(3, n)``. Writes the blocks of 64 hypotheses ``start:stop`` of ``out``; within a
    block the matches are the outer loop and the hypotheses the inner one, so SIMD lanes hold
    different hypotheses and each hypothesis is still summed match by match, in
    order."""
    n = rot.shape[1]
    m = source.shape[0]
    for block in range(start, stop):
        first = block * 64
        last = min(n, first + 64)
        # The block's lanes as views from 0: indices the compiler knows are not
        # negative, so the lanes vectorise.
        r0, r1, r2 = rot[0][first:last], rot[1][first:last], rot[2][first:last]
        r3, r4, r5 = rot[3][first:last], rot[4][first:last], rot[5][first:last]
        r6, r7, r8 = rot[6][first:last], rot[7][first:last], rot[8][first:last]
        t0, t1, t2 = shift[0][first:last], shift[1][first:last], shift[2][first:last]
        total = np.zeros(last - first)
        for i in range(m):
            x0, x1, x2 = source[i, 0], source[i, 1], source[i, 2]
            y0, y1, y2 = target[i, 0], target[i, 1], target[i, 2]
            for h in range(total.shape[0]):
                a = r0[h] * x0 + r1[h] * x1 + r2[h] * x2 + t0[h] - y0
                b = r3[h] * x0 + r4[h] * x1 + r5[h] * x2 + t1[h] - y1
                c = r6[h] * x0 + r7[h] * x1 + r8[h] * x2 + t2[h] - y2
                squared = a * a + b * b + c * c
                total[h] += (1.0 - squared / sq_threshold) if squared < sq_threshold else 0.0
        out[first:last] = total


def compatibility_graphs(
    source, target, threshold, second_threshold, min_span, endpoints, n_threads=1
):
    """Both compatibility graphs of the matches ``source[i] <-> target[i]``, packed 64
    matches to a word (``(m, w)`` uint64, ``w`` the words ``m`` bits take rounded up to
    a multiple of :data:`ROW_ALIGN`, the spare words zero; the same array twice when
    the thresholds are equal), and the first's degrees (see
    :func:`_compatibility_bits`); ``endpoints`` None masks no shared endpoint. The
    consensus step and the SC2-PCR peer build their graphs with it."""
    m = len(source)
    if endpoints is None:
        # Distinct ids on both sides: no pair shares an endpoint.
        source_index = target_index = np.arange(m, dtype=np.int64)
    else:
        source_index, target_index = (np.asarray(e, dtype=np.int64) for e in endpoints)
    second_threshold = threshold if second_threshold is None else second_threshold
    words = (m + 63) // 64
    # Rows padded with zero words to whole vectors of ROW_ALIGN words, which the
    # common-neighbour counts then read without a remainder loop.
    shape = (m, -(-words // ROW_ALIGN) * ROW_ALIGN)
    bits = np.zeros(shape, dtype=np.uint64)
    second = bits if second_threshold == threshold else np.zeros(shape, dtype=np.uint64)
    degree = np.zeros(m, dtype=np.int64)
    run_blocks(
        _compatibility_bits,
        words,
        n_threads,
        np.ascontiguousarray(np.asarray(source, dtype=np.float64).T),
        np.ascontiguousarray(np.asarray(target, dtype=np.float64).T),
        float(threshold),
        float(second_threshold),
        float(min_span),
        np.ascontiguousarray(source_index),
        np.ascontiguousarray(target_index),
        bits,
        second,
        per_thread=4,  # the blocks' rows shorten along the diagonal: smaller pieces
    )
    run_blocks(_mirror_bits, words, n_threads, m, second is bits, bits, second, degree)
    return bits, second, degree


def consensus_sets(
    bits: np.ndarray, second: np.ndarray, seeds: np.ndarray, set_size: int, n_threads: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Every seed's ``set_size`` best partners and their scores, ``(n_seeds, set_size)``
    each, on ``n_threads`` threads: the matches compatible with the seed in ``bits``
    with the most matches compatible with both in ``second`` (the second-order
    compatibility), most first, of equal ones the lower index; a seed with fewer
    compatible matches is padded with itself at score 0. Two seeds compatible both ways
    (every pair of :func:`compatibility_graphs`) have their common neighbours counted
    once (:func:`_shared_counts`, :func:`_mirror_counts`, :func:`_best_partners`)."""
    seeds = np.asarray(seeds, dtype=np.int64)
    unique, back = np.unique(seeds, return_inverse=True)
    members = np.empty((len(unique), set_size), dtype=np.int64)
    scores = np.zeros((len(unique), set_size), dtype=np.float64)
    starts = _row_starts(bits, unique)
    # Seeds in runs of about SETS_ENTRIES listed partners (one seed at least): memory
    # stays bounded on dense graphs; two seeds of different runs are counted from both.
    cuts = np.searchsorted(starts, np.arange(SETS_ENTRIES, starts[-1], SETS_ENTRIES), "right")
    bounds = np.unique(np.r_[0, np.maximum(cuts - 1, 1), len(unique)])
    rank = np.full(len(bits), -1, dtype=np.int64)
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        run = unique[a:b]
        rank[run] = np.arange(len(run))
        offsets = starts[a : b + 1] - starts[a]
        partners = np.empty(offsets[-1], dtype=np.int32)
        shared = np.empty(offsets[-1], dtype=np.int32)
        arrays = (bits, second, run, rank, offsets, partners, shared)
        run_blocks(_shared_counts, len(run), n_threads, *arrays)
        _mirror_counts(bits, run, rank, offsets, partners, shared)
        arrays = (run, offsets, partners, shared, int(set_size), members[a:b], scores[a:b])
        run_blocks(_best_partners, len(run), n_threads, *arrays)
        rank[run] = -1
    if len(unique) == len(seeds) and np.array_equal(unique, seeds):
        return members, scores
    return members[back], scores[back]


def truncated_scores(
    rot: np.ndarray,
    shift: np.ndarray,
    source: np.ndarray,
    target: np.ndarray,
    sq_threshold: float,
    n_threads: int = 1,
) -> np.ndarray:
    """Every hypothesis's truncated quadratic score over the matches (see
    :func:`_truncated_scores`; ``rot`` ``(9, n)``, ``shift`` ``(3, n)``)."""
    n = rot.shape[1]
    out = np.zeros(n)
    arrays = (rot, shift, source, target, float(sq_threshold), out)
    run_blocks(_truncated_scores, (n + 63) // 64, n_threads, *arrays)
    return out


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
    bits, _, _ = compatibility_graphs(source, target, threshold, None, min_span, endpoints)
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

    def within(t):
        return _within(t, source, target, sq_threshold)

    def fit(t, inliers):
        if weighted:
            return _weighted_fit(source, target, t, sq_threshold)
        return rigid_transform(source[inliers], target[inliers])

    return refit_while_growing(transformation, within, fit, rounds)


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


def _ranked(rot, shift, allowed, source, target, sq_threshold, n_threads) -> np.ndarray:
    """The hypotheses ``allowed`` lets win, best first by their truncated quadratic
    score over the matches (the first of equal ones). With many of both they are scored
    preemptively: all on every :data:`PREEMPT_STRIDE`-th match first, then the
    :data:`PREEMPT_KEEP` best of that on all matches. Those come first, by their exact
    scores; the others follow by their first scores, which only decide which runners-up
    are handed on for verification."""

    def scored(which, stride=1):
        return truncated_scores(
            np.ascontiguousarray(rot[which].reshape(-1, 9).T),
            np.ascontiguousarray(shift[which].T),
            np.ascontiguousarray(source[::stride]),
            np.ascontiguousarray(target[::stride]),
            sq_threshold,
            n_threads,
        )

    candidates = np.flatnonzero(allowed)
    if len(candidates) <= PREEMPT_KEEP or len(source) < PREEMPT_STRIDE * PREEMPT_MIN_SAMPLE:
        return candidates[np.argsort(-scored(candidates), kind="stable")]
    rough_order = candidates[np.argsort(-scored(candidates, PREEMPT_STRIDE), kind="stable")]
    kept = np.sort(rough_order[:PREEMPT_KEEP])
    return np.concatenate(
        [kept[np.argsort(-scored(kept), kind="stable")], rough_order[PREEMPT_KEEP:]]
    )


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
    n_hypotheses: int = 1,
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
    n_hypotheses : int, default=1
        How many of the best-scored distinct hypotheses to return, each refitted
        (:func:`~._hypotheses.distinct`).
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
    bits, second, degree = compatibility_graphs(
        source,
        target,
        compatibility_threshold,
        second_order_threshold,
        min_span,
        endpoints,
        n_threads,
    )
    seeds = _seeds(source, degree, n_seeds, seed_radius)
    transformation = np.eye(4)
    sq_inlier = inlier_threshold**2
    if len(seeds):
        k = min(set_size, m - 1)
        partners, weights = consensus_sets(bits, second, seeds, k, n_threads)
        members = np.concatenate([seeds[:, None], partners], axis=1)
        weights = np.concatenate([weights.max(axis=1, keepdims=True), weights], axis=1)
        rot, shift = rigid_transforms(source[members], target[members], weights)
        # Hypotheses the up prior rejects cannot win.
        allowed = np.ones(len(rot), dtype=bool) if upright is None else upright(rot)
        sq_score = float(score_threshold) ** 2
        order = _ranked(rot, shift, allowed, source, target, sq_score, n_threads)
    hypotheses = np.empty((0, 4, 4))
    if len(seeds) and len(order):
        centroid = source.mean(axis=0)
        picked = pick_distinct(rot[order], shift[order], n_hypotheses, centroid, inlier_threshold)
        refits = [_refit(t, source, target, sq_inlier, weighted=weighted_refit) for t in picked]
        hypotheses = np.stack([t for t, _ in refits])
        transformation, inliers = refits[0]
    else:  # no hypothesis, or none the up prior allows: no estimate
        inliers = _within(transformation, source, target, sq_inlier)
    transformation = from_centred(transformation, centre)  # back from the centred frame
    hypotheses = from_centred(hypotheses, centre)
    return ConsensusResult(
        transformation=transformation,
        inliers=inliers,
        n_hypotheses=len(seeds),
        seeds=seeds,
        hypotheses=hypotheses,
    )


def pooled(results: list[ConsensusResult]) -> ConsensusResult:
    """Several consensus runs' hypotheses as one result, each run's best first and the
    runs in order: the first run with an estimate gives the transformation (its
    ``inliers`` and ``seeds`` are about its own matches); ``n_hypotheses`` counts every
    run's."""
    first = next((r for r in results if len(r.hypotheses)), results[0])
    return ConsensusResult(
        transformation=first.transformation,
        inliers=first.inliers,
        n_hypotheses=sum(r.n_hypotheses for r in results),
        seeds=first.seeds,
        hypotheses=np.concatenate([r.hypotheses for r in results]),
    )
