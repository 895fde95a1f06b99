"""SC2-PCR (Chen, Sun, Yang, Tao, CVPR 2022), written from its paper and its published
3DMatch settings, as a benchmark peer of :class:`~o3d_rpointhop.ConsensusGlobal`: given
the same matches on the same pairs, does this library's consensus choose as well as a
published estimator?

The estimator, in the paper's steps, with its 3DMatch settings (metres):

1. **First-order compatibility** of two matches from the difference ``d`` of their
   lengths in the source and the target: soft ``max(0, 1 - d^2 / 0.1^2)``, hard
   ``d < 0.1``, and tight ``d < 0.05``.
2. **Seeds**: every match's confidence is its entry of the soft matrix's leading
   eigenvector (10 power iterations); a match seeds if no match within 0.1 m of its
   source point is more confident (non-maximum suppression); the 20 % most confident.
3. **Second-order compatibility** of a seed ``s`` and a match ``j``: hard-compatible,
   times the number of matches tight-compatible with both (the diagonal counts).
4. **Two-stage consensus sets**: the 30 matches of highest second-order compatibility
   with the seed; among them, the 20 with the most matches hard-compatible with both
   them and the set's first (the seed).
5. **Local spectral matching**: weights from the leading eigenvector of the set's soft
   compatibility (zero diagonal), a weighted SVD per set.
6. **Selection**: the hypothesis with the most matches within 0.1 m.
7. **Post-refinement**: up to 20 weighted refits on the matches within 0.1 m, each
   weighted ``1 / (1 + (r / 0.1)^2)``, until the inlier count stops changing.
"""

from __future__ import annotations

from numbers import Integral, Real
from typing import Any

import numpy as np

from .._utils.compiled import kernel, prange, threads
from .._utils.params import Interval
from .._utils.threads import kernel_threads
from ..registration import ConsensusGlobal, Matcher
from ..registration.context import RegistrationContext
from ..registration.result import StepResult
from ..registration.steps import (
    DESCRIPTOR,
    MATCHER,
    GlobalStep,
    compatibility_graphs,
    consensus_sets,
)
from ..transforms import from_centred, rigid_transforms

__all__ = ["SC2PCRGlobal", "sc2pcr"]

_POSITIVE = Interval(Real, 0, None, closed="neither")


@kernel(parallel=True)
def _soft_leading_vector(bits, source, target, threshold, iterations):  # pragma: no cover
    """The leading eigenvector of the soft compatibility matrix (diagonal included), by
    power iteration from ones, each step normalised, stopped early when it settles. The
    soft value is positive exactly where the hard bit is set, so each row visits only
    those matches."""
    m, words = bits.shape
    sq = threshold * threshold
    one = np.uint64(1)
    x = np.ones(m)
    for _ in range(iterations):
        y = np.zeros(m)
        for i in prange(m):
            total = x[i]  # the diagonal: a match is fully compatible with itself
            for w in range(words):
                word = bits[i, w]
                if word == 0:
                    continue
                for b in range(64):
                    if (word >> np.uint64(b)) & one:
                        j = w * 64 + b
                        dx = source[i, 0] - source[j, 0]
                        dy = source[i, 1] - source[j, 1]
                        dz = source[i, 2] - source[j, 2]
                        ds = np.sqrt(dx * dx + dy * dy + dz * dz)
                        dx = target[i, 0] - target[j, 0]
                        dy = target[i, 1] - target[j, 1]
                        dz = target[i, 2] - target[j, 2]
                        gap = ds - np.sqrt(dx * dx + dy * dy + dz * dz)
                        total += (1.0 - gap * gap / sq) * x[j]
            y[i] = total
        y /= np.sqrt((y * y).sum()) + 1e-6
        settled = np.all(np.abs(y - x) <= 1e-8 + 1e-5 * np.abs(x))
        x = y
        if settled:
            break
    return x


def _with_diagonal(bits: np.ndarray) -> np.ndarray:
    """A compatibility bit matrix with every match compatible with itself."""
    out = bits.copy()
    rows = np.arange(len(out))
    out[rows, rows >> 6] |= np.left_shift(np.uint64(1), (rows & 63).astype(np.uint64))
    return out


def _seeds(source, confidence, radius: float, ratio: float) -> np.ndarray:
    """The most confident matches after non-maximum suppression within ``radius`` of
    the source points (matches beaten nearby rank after every local maximum, by
    confidence then index), ``ratio`` of all matches."""
    from scipy.spatial import cKDTree

    near = cKDTree(source).query_pairs(radius, output_type="ndarray")
    local_max = np.ones(len(source), dtype=bool)
    if len(near):
        a, b = near[:, 0], near[:, 1]
        local_max[a[confidence[a] < confidence[b]]] = False
        local_max[b[confidence[b] < confidence[a]]] = False
    score = confidence * local_max
    count = max(1, int(len(source) * ratio))
    return np.argsort(-score, kind="stable")[:count]


def _pairwise(points: np.ndarray) -> np.ndarray:
    """Distances within each set, ``(s, k, 3) -> (s, k, k)``."""
    return np.linalg.norm(points[:, :, None, :] - points[:, None, :, :], axis=-1)


def _power(matrix: np.ndarray, iterations: int) -> np.ndarray:
    """Leading eigenvectors of a batch of symmetric matrices ``(s, k, k)``."""
    x = np.ones(matrix.shape[:2])
    for _ in range(iterations):
        y = np.einsum("sij,sj->si", matrix, x)
        y /= np.linalg.norm(y, axis=1, keepdims=True) + 1e-6
        settled = np.allclose(y, x)
        x = y
        if settled:
            break
    return x


@kernel(parallel=True)
def _inlier_counts(rot, shift, source, target, sq_threshold):  # pragma: no cover
    """Matches within the threshold under every hypothesis."""
    n = rot.shape[0]
    m = source.shape[0]
    out = np.zeros(n, dtype=np.int64)
    for h in prange(n):
        count = 0
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
                count += 1
        out[h] = count
    return out


def _refined(transformation, source, target, threshold: float, rounds: int) -> np.ndarray:
    """The paper's post-refinement: weighted refits on the inliers until their number
    stops changing."""
    best = transformation
    previous = 0
    for _ in range(rounds):
        residual = np.linalg.norm(source @ best[:3, :3].T + best[:3, 3] - target, axis=1)
        inside = residual < threshold
        count = int(inside.sum())
        if count == previous or count < 3:
            break
        previous = count
        weight = 1.0 / (1.0 + (residual[inside] / threshold) ** 2)
        rot, shift = rigid_transforms(source[inside][None], target[inside][None], weight[None])
        best = np.eye(4)
        best[:3, :3], best[:3, 3] = rot[0], shift[0]
    return best


def sc2pcr(
    source: np.ndarray,
    target: np.ndarray,
    *,
    threshold: float = 0.1,
    inlier_threshold: float = 0.1,
    seed_radius: float = 0.1,
    seed_ratio: float = 0.2,
    first_stage: int = 30,
    second_stage: int = 20,
    iterations: int = 10,
    refinements: int = 20,
    n_threads: int = 1,
) -> tuple[np.ndarray, int]:
    """SC2-PCR on matches ``source[i] <-> target[i]`` (see the module's docstring).

    Returns
    -------
    transformation : ndarray of shape (4, 4)
    n_hypotheses : int
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    centre = target.mean(axis=0)  # small coordinates wherever the clouds are
    source = np.ascontiguousarray(source - centre)
    target = np.ascontiguousarray(target - centre)
    hard, tight, _ = compatibility_graphs(
        source, target, threshold, threshold / 2, 0.0, None, n_threads
    )
    with threads(n_threads):
        confidence = _soft_leading_vector(hard, source, target, float(threshold), iterations)
    seeds = _seeds(source, confidence, seed_radius, seed_ratio)
    k1 = min(first_stage, len(source))
    members, _ = consensus_sets(_with_diagonal(hard), _with_diagonal(tight), seeds, k1, n_threads)
    # Second stage: within each first-stage set, the matches hard-compatible with the
    # most of those compatible with the set's first (the seed).
    src, tgt = source[members], target[members]
    gap = np.abs(_pairwise(src) - _pairwise(tgt))
    local = (gap < threshold).astype(np.float64)
    shared = np.einsum("sk,skj->sj", local[:, 0, :], local)
    k2 = min(second_stage, k1)
    keep = np.argsort(-shared, axis=1, kind="stable")[:, :k2]
    src = np.take_along_axis(src, keep[:, :, None], axis=1)
    tgt = np.take_along_axis(tgt, keep[:, :, None], axis=1)
    gap = np.abs(_pairwise(src) - _pairwise(tgt))
    soft = np.clip(1.0 - gap**2 / threshold**2, 0.0, None)
    soft[:, np.arange(k2), np.arange(k2)] = 0.0
    weights = _power(soft, iterations)
    weights /= weights.sum(axis=1, keepdims=True) + 1e-6
    rot, shift = rigid_transforms(src, tgt, weights)
    with threads(n_threads):
        counts = _inlier_counts(
            np.ascontiguousarray(rot),
            np.ascontiguousarray(shift),
            source,
            target,
            float(inlier_threshold) ** 2,
        )
    best = int(np.argmax(counts))
    transformation = np.eye(4)
    transformation[:3, :3], transformation[:3, 3] = rot[best], shift[best]
    transformation = _refined(transformation, source, target, inlier_threshold, refinements)
    return from_centred(transformation, centre), len(seeds)


class SC2PCRGlobal(GlobalStep):
    """SC2-PCR as a global step, on the matches its matcher gives (by default those of
    :class:`~o3d_rpointhop.ConsensusGlobal`; a benchmark peer, the distances are the
    paper's 3DMatch settings, in metres).

    Parameters
    ----------
    descriptor : transformer, default=None
    matcher : Matcher, default=None
        ``None``: :meth:`ConsensusGlobal.default_matcher
        <o3d_rpointhop.ConsensusGlobal.default_matcher>`.
    threshold, inlier_threshold, seed_radius : float, default=0.1
        The compatibility threshold (the tight one is half of it), the inlier distance
        of selection and refinement, and the seeds' suppression radius.
    seed_ratio : float, default=0.2
    first_stage, second_stage : int, default=30, 20
    n_jobs : int, default=None
        Threads of the compiled kernels (``None``: every core, as the consensus's; see
        :class:`~o3d_rpointhop.ConsensusGlobal`); the result does not depend on it.
    """

    name = "sc2pcr"

    _parameter_constraints = {
        "descriptor": DESCRIPTOR,
        "matcher": MATCHER,
        "threshold": [_POSITIVE],
        "inlier_threshold": [_POSITIVE],
        "seed_radius": [_POSITIVE],
        "seed_ratio": [Interval(Real, 0, 1, closed="right")],
        "first_stage": [Interval(Integral, 3, None, closed="left")],
        "second_stage": [Interval(Integral, 3, None, closed="left")],
        "n_jobs": [None, Integral],
    }

    def __init__(
        self,
        descriptor: Any = None,
        *,
        matcher: Matcher | None = None,
        threshold: float = 0.1,
        inlier_threshold: float = 0.1,
        seed_radius: float = 0.1,
        seed_ratio: float = 0.2,
        first_stage: int = 30,
        second_stage: int = 20,
        n_jobs: int | None = None,
    ) -> None:
        self.descriptor = descriptor
        self.matcher = matcher
        self.threshold = threshold
        self.inlier_threshold = inlier_threshold
        self.seed_radius = seed_radius
        self.seed_ratio = seed_ratio
        self.first_stage = first_stage
        self.second_stage = second_stage
        self.n_jobs = n_jobs

    @classmethod
    def default_matcher(cls) -> Matcher:
        """:class:`~o3d_rpointhop.ConsensusGlobal`'s matcher."""
        return ConsensusGlobal.default_matcher()

    def _run(self, context: RegistrationContext, transformation: np.ndarray) -> StepResult:
        corr = self._matches(context)
        src, tgt = self._matched(context, corr)
        found, hypotheses = sc2pcr(
            src,
            tgt,
            threshold=self.threshold,
            inlier_threshold=self.inlier_threshold,
            seed_radius=self.seed_radius,
            seed_ratio=self.seed_ratio,
            first_stage=self.first_stage,
            second_stage=self.second_stage,
            n_threads=kernel_threads(self.n_jobs),
        )
        return self._measured(
            context, self.name, found, self.inlier_threshold, corr, hypotheses=hypotheses
        )
