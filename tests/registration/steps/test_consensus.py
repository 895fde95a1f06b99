"""The correspondence-graph consensus: exact recovery among overwhelming outliers,
determinism, bounded memory, flags on planar and symmetric input."""

from __future__ import annotations

import tracemalloc
import warnings

import numpy as np
import pytest
from helpers import motion_matrix, random_motion

from o3d_rpointhop import ConsensusGlobal, Matcher, RegistrationWarning, register
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration.steps._consensus import compatibility, consensus
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg, translation_error


def synthetic_matches(n_matches: int, outlier_share: float, seed: int, noise: float = 0.002):
    """Matches between two clouds of a 2 m room-sized box: a share of them true (the
    source point moved by the motion, plus noise), the rest pairing random points."""
    rng = np.random.default_rng(seed)
    rot, shift = random_motion(seed, 1.0)
    truth = motion_matrix(rot, shift)  # maps source into target
    source = rng.uniform(-1.0, 1.0, (n_matches, 3))
    target = apply_transform(source, truth) + rng.normal(scale=noise, size=(n_matches, 3))
    n_out = int(round(outlier_share * n_matches))
    wrong = rng.choice(n_matches, n_out, replace=False)
    target[wrong] = apply_transform(rng.uniform(-1.0, 1.0, (n_out, 3)), truth)
    return source, target, truth, np.isin(np.arange(n_matches), wrong, invert=True)


@pytest.mark.parametrize("outlier_share", [0.95, 0.98, 0.99])
def test_recovers_the_motion_among_overwhelming_outliers(outlier_share):
    source, target, truth, _ = synthetic_matches(2000, outlier_share, seed=3)
    found = consensus(
        source,
        target,
        compatibility_threshold=0.02,
        inlier_threshold=0.02,
        score_threshold=0.03,
    )
    assert rotation_error_deg(found.transformation, truth) < 0.2
    assert translation_error(found.transformation, truth) < 0.005
    true_matches = int(round((1 - outlier_share) * 2000))
    assert true_matches <= found.inliers.sum() <= true_matches + 5  # chance inliers only


def test_the_same_matches_give_the_same_bytes():
    source, target, _, _ = synthetic_matches(1500, 0.97, seed=5)
    kwargs = dict(compatibility_threshold=0.02, inlier_threshold=0.02, score_threshold=0.03)
    a = consensus(source, target, **kwargs)
    b = consensus(source.copy(), target.copy(), **kwargs)
    assert a.transformation.tobytes() == b.transformation.tobytes()
    np.testing.assert_array_equal(a.inliers, b.inliers)


def test_an_up_prior_that_refuses_every_hypothesis_leaves_no_estimate():
    """Hypotheses the up prior rejects cannot win: when it rejects them all, the step
    has no estimate (the identity, no hypotheses) rather than a refused pose."""
    source, target, truth, _ = synthetic_matches(800, 0.9, seed=4)
    kwargs = dict(compatibility_threshold=0.02, inlier_threshold=0.02, score_threshold=0.03)
    free = consensus(source, target, **kwargs)
    assert rotation_error_deg(free.transformation, truth) < 0.2
    seen = []

    def refuse_all(rotations):
        seen.append(len(rotations))
        return np.zeros(len(rotations), dtype=bool)

    none = consensus(source, target, upright=refuse_all, n_hypotheses=3, **kwargs)
    assert seen and seen[0] == none.n_hypotheses > 0  # every seed's fit was asked
    np.testing.assert_array_equal(none.transformation, np.eye(4))
    assert none.hypotheses.shape == (0, 4, 4)


def test_the_thread_count_does_not_change_a_byte():
    source, target, _, _ = synthetic_matches(1500, 0.97, seed=6)
    kwargs = dict(compatibility_threshold=0.02, inlier_threshold=0.02, score_threshold=0.03)
    one = consensus(source, target, n_threads=1, **kwargs)
    two = consensus(source, target, n_threads=2, **kwargs)
    assert one.transformation.tobytes() == two.transformation.tobytes()
    np.testing.assert_array_equal(one.seeds, two.seeds)


def test_compatibility_joins_exact_matches_and_rarely_random_ones():
    source, target, _, true = synthetic_matches(400, 0.5, seed=1, noise=0.0)
    comp = compatibility(source, target, 1e-6)
    np.testing.assert_array_equal(comp, comp.T)
    assert comp.dtype == bool and not comp.diagonal().any()
    exact = comp[np.ix_(true, true)]
    assert exact.sum() == true.sum() * (true.sum() - 1)  # every pair of exact matches
    assert comp[np.ix_(true, ~true)].mean() < 1e-3


def test_memory_stays_bounded_at_the_match_cap():
    """5000 matches (the cap) stay within a few megabytes: the compatibility graph is a
    bit matrix (3 MB), the sets and scores are built per seed."""
    source, target, truth, _ = synthetic_matches(5000, 0.98, seed=7)
    tracemalloc.start()
    found = consensus(
        source, target, compatibility_threshold=0.02, inlier_threshold=0.02, score_threshold=0.03
    )
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert rotation_error_deg(found.transformation, truth) < 0.2
    assert peak < 40 * 1024**2


def test_the_step_caps_its_matches_and_registers_an_object(object_model):
    target = make_object(3000, shape_seed=12, sample_seed=1)
    rot, shift = random_motion(4, 0.3)
    source = make_object(3000, shape_seed=12, sample_seed=2) @ rot.T + shift
    truth = np.linalg.inv(motion_matrix(rot, shift))
    capped = ConsensusGlobal(matcher=Matcher(both_directions=True, max_matches=1000))
    result = register(source, target, object_model, global_method=capped, n_global_points=1500)
    assert result.steps[0].info["candidate_matches"] == 1000
    assert rotation_error_deg(result.transformation, truth) < 2.0
    assert translation_error(result.transformation, truth) < 0.02
    by_name = register(source, target, object_model, global_method="consensus", random_state=0)
    assert by_name.steps[0].name == "global" and "hypotheses" in by_name.steps[0].info


def test_planar_and_symmetric_input_is_flagged(pretrained32):
    rng = np.random.default_rng(0)
    plane = np.c_[rng.uniform(-1, 1, (1500, 2)), np.zeros(1500)]
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.warns(RegistrationWarning):
        flat = register(plane, plane @ turn.T, pretrained32, global_method="consensus")
    assert flat.ambiguous or not flat.converged
    # A box is symmetric under half-turns about its axes.
    box = rng.uniform(-1, 1, (3000, 3))
    box[np.arange(3000), rng.integers(0, 3, 3000)] = np.sign(rng.normal(size=3000))
    box *= [1.0, 0.6, 0.3]  # the surface of a 2 x 1.2 x 0.6 box
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RegistrationWarning)
        symmetric = register(box, box @ turn.T, pretrained32, global_method="consensus")
    assert symmetric.ambiguous


def test_parameters_are_checked_with_the_step_named(object_model):
    cloud = make_object(800)
    with pytest.raises(ValueError, match="step 'global'.*'set_size' parameter"):
        register(cloud, cloud, object_model, global_method=ConsensusGlobal(set_size=1))


def test_masks_drop_close_pairs_and_shared_endpoints():
    """Exact matches are all compatible, until a pair lies too close on both sides (the
    span mask) or shares a source or target point (the endpoint mask)."""
    source, target, _, _ = synthetic_matches(300, 0.0, seed=2, noise=0.0)
    span = np.linalg.norm(source[:, None] - source[None], axis=2) * 2  # both sides equal
    plain = compatibility(source, target, 1e-6)
    masked = compatibility(source, target, 1e-6, min_span=0.8)
    off_diagonal = ~np.eye(300, dtype=bool)
    np.testing.assert_array_equal(plain, off_diagonal)
    np.testing.assert_array_equal(masked, off_diagonal & (span >= 0.8))
    assert 0 < masked.sum() < plain.sum()
    ids = np.arange(300)
    shared = ids.copy()
    shared[1] = 0  # matches 0 and 1 start at the same source point
    ends = compatibility(source, target, 1e-6, endpoints=(shared, ids))
    assert not ends[0, 1] and not ends[1, 0]
    assert ends[0, 2] and ends[1, 2] and ends.sum() == plain.sum() - 2
    back = compatibility(source, target, 1e-6, endpoints=(ids, np.where(ids == 5, 7, ids)))
    assert not back[5, 7] and back.sum() == plain.sum() - 2


def test_the_second_order_graph_is_the_tighter_threshold():
    """With a second-order threshold below the first, the second graph holds exactly
    the pairs whose length difference is below it."""
    from o3d_rpointhop.registration.steps._consensus import compatibility_graphs

    source, target, _, _ = synthetic_matches(200, 0.5, seed=4, noise=0.01)
    ds = np.linalg.norm(source[:, None] - source[None], axis=2)
    dt = np.linalg.norm(target[:, None] - target[None], axis=2)
    gap = np.abs(ds - dt)
    first, second, degree = compatibility_graphs(source, target, 0.05, 0.02, 0.0, None)

    def dense(bits):
        return np.unpackbits(bits.view(np.uint8), axis=1, bitorder="little")[:, :200] > 0

    off = ~np.eye(200, dtype=bool)
    np.testing.assert_array_equal(dense(first), off & (gap < 0.05))
    np.testing.assert_array_equal(dense(second), off & (gap < 0.02))
    np.testing.assert_array_equal(degree, (off & (gap < 0.05)).sum(axis=1))


def test_seed_suppression_keeps_the_best_seed_of_a_neighbourhood():
    from o3d_rpointhop.registration.steps._consensus import _seeds

    source = np.array([[0.0, 0, 0], [0.01, 0, 0], [1.0, 0, 0], [1.0, 0.01, 0], [3.0, 0, 0]])
    degree = np.array([5, 9, 4, 4, 1])
    np.testing.assert_array_equal(_seeds(source, degree, 10, None), [0, 1, 2, 3])  # degree >= 2
    # Within 5 cm: 1 beats 0 (higher degree), 2 beats 3 (a tie goes to the lower index).
    np.testing.assert_array_equal(_seeds(source, degree, 10, 0.05), [1, 2])
    np.testing.assert_array_equal(_seeds(source, degree, 1, 0.0), [1])


@pytest.mark.parametrize("cap", ["index", "distance"])
def test_the_cap_keeps_matches_spread_by_index_or_the_closest_descriptors(cap):
    from o3d_rpointhop.registration.context import RegistrationContext
    from o3d_rpointhop.registration.prepared import PreparedCloud

    rng = np.random.default_rng(0)
    cloud = rng.uniform(-1, 1, (400, 3))
    features = rng.normal(size=(400, 8))
    step = ConsensusGlobal(matcher=Matcher(both_directions=False, max_matches=100, cap=cap))
    noisy = features + rng.normal(scale=0.5, size=features.shape)
    context = RegistrationContext(
        cloud,
        cloud,
        voxel_size=0.05,
        prepared=(PreparedCloud(cloud, features), PreparedCloud(cloud, noisy)),
    )
    everything = ConsensusGlobal(matcher=Matcher(both_directions=False, max_matches=400))._matches(
        context
    )
    kept = step._matches(context)
    assert len(everything) == 400 and len(kept) == 100
    if cap == "index":
        np.testing.assert_array_equal(kept.pairs[:, 0], np.linspace(0, 399, 100).astype(int))
    else:
        assert kept.distances.max() <= np.sort(everything.distances)[99]


def test_the_weighted_refit_weights_each_match_by_its_truncated_quadratic():
    """``weighted_refit``: every match within the threshold is weighted 1 - r^2 / tau^2
    (outside: 0), and the fit is the weighted Kabsch fit with those weights."""
    from o3d_rpointhop.registration.steps._consensus import _weighted_fit
    from o3d_rpointhop.transforms import rigid_transforms

    source, target, truth, true = synthetic_matches(300, 0.5, seed=11, noise=0.004)
    tau2 = 0.01**2
    moved = apply_transform(source, truth)
    r2 = ((moved - target) ** 2).sum(axis=1)
    weight = np.clip(1 - r2 / tau2, 0, None)
    inside = weight > 0
    rot, shift = rigid_transforms(source[inside][None], target[inside][None], weight[inside][None])
    found = _weighted_fit(source, target, truth, tau2)
    np.testing.assert_allclose(found[:3, :3], rot[0], atol=1e-12)
    np.testing.assert_allclose(found[:3, 3], shift[0], atol=1e-12)
    plain = rigid_transforms(source[inside][None], target[inside][None])
    assert not np.allclose(found[:3, 3], plain[1][0], atol=1e-9)  # the weights matter
    both = [
        consensus(
            source,
            target,
            compatibility_threshold=0.02,
            inlier_threshold=0.01,
            score_threshold=0.015,
            weighted_refit=w,
        ).transformation
        for w in (False, True)
    ]
    assert all(rotation_error_deg(t, truth) < 0.5 for t in both)
    assert not np.array_equal(both[0], both[1])


def _reference_graphs(source, target, threshold, second, min_span, ends):
    """The two compatibility graphs, dense, in numpy."""
    ds = np.linalg.norm(source[:, None] - source[None], axis=2)
    dt = np.linalg.norm(target[:, None] - target[None], axis=2)
    keep = (ds + dt >= min_span) & (ends[0][:, None] != ends[0][None])
    keep &= ends[1][:, None] != ends[1][None]
    gap = np.abs(ds - dt)
    return keep & (gap < threshold), keep & (gap < second)


def _assert_best_partners(members, scores, first, second, seeds, k):
    """Each seed's ``k`` partners in ``first`` with the most common neighbours in
    ``second`` (dense bool matrices), most first, of equal ones the lower index, padded
    with the seed itself at score 0."""
    shared = second.astype(np.int64) @ second.T.astype(np.int64)
    for s, i in enumerate(seeds):
        partners = np.flatnonzero(first[i])
        order = partners[np.argsort(-shared[i, partners], kind="stable")][:k]
        padded = np.r_[order, np.full(k - len(order), i)]
        np.testing.assert_array_equal(members[s], padded)
        np.testing.assert_array_equal(scores[s][: len(order)], shared[i, order])
        assert not scores[s][len(order) :].any()


@pytest.mark.parametrize("symmetric", [True, False])
def test_best_partners_on_any_graph_and_seed_list(symmetric):
    """consensus_sets counts two seeds' common neighbours once and copies the count
    across; on graphs with a diagonal (SC2-PCR's), one-way edges, seeds out of order
    and repeated, and many tied counts, it still gives every seed the dense reference's
    partners, on any number of threads."""
    from o3d_rpointhop.registration.steps._consensus import consensus_sets

    rng = np.random.default_rng(3 + symmetric)
    m = 200
    first = rng.random((m, m)) < 0.2
    second = first & (rng.random((m, m)) < 0.6)
    if symmetric:
        first, second = np.triu(first), np.triu(second)
        first, second = first | first.T, second | second.T
    first[np.arange(m), np.arange(m)] = True  # every match compatible with itself

    def pack(dense):
        words = np.zeros((m, 8), dtype=np.uint64)  # padded beyond the 200 matches
        packed = np.packbits(dense, axis=1, bitorder="little")
        words.view(np.uint8)[:, : packed.shape[1]] = packed
        return words

    seeds = np.r_[rng.permutation(m)[:90], [7, 7, 150]]
    k = 12
    members, scores = consensus_sets(pack(first), pack(second), seeds, k)
    _assert_best_partners(members, scores, first, second, seeds, k)
    for n_threads in (2, 3):
        again = consensus_sets(pack(first), pack(second), seeds, k, n_threads)
        np.testing.assert_array_equal(again[0], members)
        np.testing.assert_array_equal(again[1], scores)


@pytest.mark.parametrize("m", [5, 64, 130])
def test_the_kernels_match_a_dense_numpy_reference(m):
    """Graph bits, degrees, the seeds' best partners by common neighbours (ties to the
    lower index) and the truncated scores, against plain numpy on dense matrices."""
    from o3d_rpointhop.registration.steps._consensus import (
        compatibility_graphs,
        consensus_sets,
        truncated_scores,
    )

    rng = np.random.default_rng(m)
    source, target, _, _ = synthetic_matches(m, 0.5, seed=m, noise=0.01)
    ends = (rng.integers(0, m, m), rng.integers(0, m, m))
    first, second = _reference_graphs(source, target, 0.1, 0.05, 0.2, ends)
    bits, bits2, degree = compatibility_graphs(source, target, 0.1, 0.05, 0.2, ends)
    unpack = lambda b: np.unpackbits(b.view(np.uint8), axis=1, bitorder="little")[:, :m]  # noqa: E731
    np.testing.assert_array_equal(unpack(bits).astype(bool), first)
    np.testing.assert_array_equal(unpack(bits2).astype(bool), second)
    np.testing.assert_array_equal(degree, first.sum(axis=1))

    seeds = np.arange(0, m, 2, dtype=np.int64)
    k = min(4, m - 1)
    members, scores = consensus_sets(bits, bits2, seeds, k)
    for n_threads in (2, 3):  # the same bytes on any number of threads
        again = consensus_sets(bits, bits2, seeds, k, n_threads)
        np.testing.assert_array_equal(again[0], members)
        np.testing.assert_array_equal(again[1], scores)
        threaded = compatibility_graphs(source, target, 0.1, 0.05, 0.2, ends, n_threads)
        np.testing.assert_array_equal(threaded[1], bits2)
    _assert_best_partners(members, scores, first, second, seeds, k)

    rot = np.stack([np.eye(3), np.diag([1.0, -1.0, -1.0])] * 40)[: m + 3]
    shift = rng.normal(scale=0.05, size=(len(rot), 3))
    found = truncated_scores(
        np.ascontiguousarray(rot.reshape(-1, 9).T),
        np.ascontiguousarray(shift.T),
        source,
        target,
        0.3**2,
    )
    r2 = (((source @ rot.transpose(0, 2, 1)) + shift[:, None] - target) ** 2).sum(axis=2)
    np.testing.assert_allclose(found, np.clip(1 - r2 / 0.3**2, 0, None).sum(axis=1), rtol=1e-12)


def test_preemptive_scoring_keeps_the_winner_and_its_runners_up(monkeypatch):
    """With more seeds than :data:`PREEMPT_KEEP` and enough matches, hypotheses are
    scored on every PREEMPT_STRIDE-th match first; the winner and the distinct
    runners-up handed on for verification are those of full scoring here, and the
    preemption did run (the first pass saw an eighth of the matches)."""
    from o3d_rpointhop.registration.steps import _consensus

    source, target, truth, _ = synthetic_matches(2400, 0.9, seed=8)
    kwargs = dict(
        compatibility_threshold=0.02,
        inlier_threshold=0.02,
        score_threshold=0.03,
        n_seeds=2000,
        n_hypotheses=4,
    )
    sizes = []
    scores = _consensus.truncated_scores

    def counted(rot, shift, source, target, *args):
        sizes.append((rot.shape[1], len(source)))
        return scores(rot, shift, source, target, *args)

    monkeypatch.setattr(_consensus, "truncated_scores", counted)
    fast = consensus(source, target, **kwargs)
    assert sizes[0][1] == -(-2400 // _consensus.PREEMPT_STRIDE)  # every stride-th match
    assert sizes[1] == (_consensus.PREEMPT_KEEP, 2400)  # the kept ones on all of them
    keep = _consensus.PREEMPT_KEEP
    monkeypatch.setattr(_consensus, "PREEMPT_KEEP", 10**9)
    full = consensus(source, target, **kwargs)
    assert fast.n_hypotheses == full.n_hypotheses > keep
    np.testing.assert_array_equal(fast.transformation, full.transformation)
    np.testing.assert_array_equal(fast.hypotheses[0], full.hypotheses[0])
    assert rotation_error_deg(fast.transformation, truth) < 0.2


def test_ranking_puts_the_exactly_scored_first():
    """The kept hypotheses come first, by their exact scores, even when a rough
    estimate of another is higher; every allowed hypothesis is ranked once and the
    ones the up prior refuses not at all."""
    from o3d_rpointhop.registration.steps._consensus import PREEMPT_KEEP, _ranked

    rng = np.random.default_rng(0)
    n, m = PREEMPT_KEEP + 300, 2048
    source = rng.uniform(-1, 1, (m, 3))
    shifts = rng.normal(scale=0.01, size=(n, 3))
    target = source.copy()
    rot = np.tile(np.eye(3), (n, 1, 1))
    allowed = np.ones(n, dtype=bool)
    allowed[::7] = False
    order = _ranked(rot, shifts, allowed, source, target, 0.03**2, 1)
    assert sorted(order.tolist()) == np.flatnonzero(allowed).tolist()
    exact = [
        np.clip(1 - ((source + s - target) ** 2).sum(1) / 0.03**2, 0, None).sum()
        for s in shifts[order[:PREEMPT_KEEP]]
    ]
    assert np.all(np.diff(exact) <= 1e-9)  # the kept ones by exact score
    # The best hypothesis overall (the smallest shift) is ranked first.
    best = np.flatnonzero(allowed)[np.argmin(np.linalg.norm(shifts[allowed], axis=1))]
    assert order[0] == best


def test_best_partners_in_runs_of_seeds_are_the_same(monkeypatch):
    """With the partners listed a few seeds at a time (a dense graph's memory bound),
    every seed's partners and scores are those of one run."""
    from o3d_rpointhop.registration.steps import _consensus

    source, target, _, _ = synthetic_matches(300, 0.7, seed=5, noise=0.01)
    bits, second, _ = _consensus.compatibility_graphs(source, target, 0.1, 0.05, 0.0, None)
    seeds = np.arange(0, 300, 2)
    whole = _consensus.consensus_sets(bits, second, seeds, 10)
    monkeypatch.setattr(_consensus, "SETS_ENTRIES", 500)
    runs = _consensus.consensus_sets(bits, second, seeds, 10, 2)
    np.testing.assert_array_equal(runs[0], whole[0])
    np.testing.assert_array_equal(runs[1], whole[1])


def test_graph_rows_are_whole_vectors_with_zero_spare_words():
    """Rows are padded to ROW_ALIGN words; the spare words stay zero, so every reader
    that walks whole rows sees the same graph."""
    from o3d_rpointhop.registration.steps import _consensus

    source, target, _, _ = synthetic_matches(130, 0.9, seed=6, noise=0.0)
    bits, second, degree = _consensus.compatibility_graphs(source, target, 0.1, 0.05, 0.0, None)
    assert bits.shape == second.shape == (130, _consensus.ROW_ALIGN)
    assert not bits[:, 3:].any() and not second[:, 3:].any()  # 130 matches take 3 words
    assert bits[:, 2].any()  # the third word holds matches 128 and 129
