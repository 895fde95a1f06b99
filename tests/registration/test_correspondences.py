"""Descriptor matches: nearest, mutual, ratio test, top-k."""

from __future__ import annotations

import numpy as np
import pytest

from o3d_rpointhop import (
    find_correspondences,
)


# ----------------------------------------------------------------------------- correspondences
def test_nearest_and_mutual_matches():
    rng = np.random.default_rng(0)
    feats = rng.normal(size=(100, 16))
    perm = rng.permutation(100)
    corr = find_correspondences(feats[perm], feats)
    np.testing.assert_array_equal(corr.pairs[:, 1], perm)  # exact descriptors: exact matches
    np.testing.assert_array_equal(corr.pairs[:, 0], np.arange(100))
    np.testing.assert_allclose(corr.distances, 0.0, atol=1e-5)

    # A target with one extra near-duplicate: only one of the two can be mutual.
    tgt = np.r_[feats, feats[:1] + 1e-3]
    src = np.r_[feats, feats[:1] + 2e-3]
    mutual = find_correspondences(src, tgt, mutual_filter=True)
    assert len(mutual) == 100 and len(find_correspondences(src, tgt)) == 101


@pytest.mark.parametrize("n_refs, k", [(300, 1), (300, 2), (300, 3), (4, 2), (2, 2)])
def test_nearest_descriptors_are_the_exact_neighbours(n_refs, k):
    from scipy.spatial.distance import cdist

    from o3d_rpointhop.registration.correspondences import nearest_descriptors

    rng = np.random.default_rng(n_refs + k)
    refs = rng.normal(size=(n_refs, 24)).astype(np.float32)
    queries = np.r_[rng.normal(size=(150, 24)), refs[:5]].astype(np.float32)
    indices, distances = nearest_descriptors(queries, refs, k=k)
    exact = cdist(queries.astype(np.float64), refs.astype(np.float64))
    expected = np.sort(exact, axis=1)[:, :k]
    assert indices.shape == (len(queries), min(k, n_refs))
    np.testing.assert_allclose(distances, expected[:, : indices.shape[1]], atol=1e-5)
    np.testing.assert_allclose(
        np.take_along_axis(exact, indices, axis=1), distances, atol=1e-5
    )  # each index is at its distance


def test_ratio_and_top_k_filters_follow_the_paper():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(200, 8))
    tgt = src + rng.normal(scale=0.3, size=src.shape)
    full = find_correspondences(src, tgt)
    best = find_correspondences(src, tgt, top_k=50)
    assert len(best) == 50
    assert best.distances.max() <= np.sort(full.distances)[49] + 1e-12
    both = find_correspondences(src, tgt, top_k=50, top_k_ratio=20)
    assert len(both) == 20
    assert set(map(tuple, both.pairs)) <= set(map(tuple, best.pairs))
    assert both.ratios.max() <= np.sort(best.ratios)[19] + 1e-12
    thresholded = find_correspondences(src, tgt, max_distance=1.0, max_ratio=0.8)
    assert np.all(thresholded.distances <= 1.0) and np.all(thresholded.ratios <= 0.8)
    assert np.array_equal(np.asarray(full), full.pairs)
    assert len(full.to_open3d()) == 200


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(source_features=np.zeros((3, 4)), target_features=np.zeros((3, 5))), "differ"),
        (dict(source_features=np.full((3, 4), np.nan), target_features=np.zeros((3, 4))), "NaN"),
        (dict(source_features=np.zeros((0, 4)), target_features=np.zeros((3, 4))), "non-empty"),
        (dict(source_features=np.eye(3), target_features=np.eye(3), top_k=0), "top_k"),
        (dict(source_features=np.eye(3), target_features=np.eye(3), max_ratio=-1), "max_ratio"),
    ],
)
def test_correspondence_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        find_correspondences(**kwargs)


def _tied_descriptors(dtype, n, m, seed):
    """Two descriptor sets with exact partners, duplicated rows and many ties (values
    on a half-integer grid)."""
    rng = np.random.default_rng(seed)
    a = np.round(rng.normal(size=(n, 6)) * 2) / 2
    b = np.round(rng.normal(size=(m, 6)) * 2) / 2
    b[: min(n, m) // 2] = a[: min(n, m) // 2]
    a[1] = a[0]
    b[3] = b[2]
    return a.astype(dtype), b.astype(dtype)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize(
    "n, m, k, k_back",
    [(200, 260, 2, 2), (200, 260, 2, 1), (260, 200, 1, 3), (5, 4, 3, 2), (300, 1400, 2, 2)],
)
@pytest.mark.parametrize("chunk", [None, 3000])
def test_both_ways_are_the_two_one_way_searches(dtype, n, m, k, k_back, chunk, monkeypatch):
    """One pass over the distances gives both directions' neighbours, bit for bit as
    two calls give them (ties included, over several blocks of rows, where every row is
    a candidate, and with rows longer than the sample that bounds their candidates)."""
    from o3d_rpointhop.registration import correspondences as module

    if chunk is not None:
        monkeypatch.setattr(module, "_CHUNK_ELEMENTS", chunk)
    a, b = _tied_descriptors(dtype, n, m, seed=n + k)
    (idx, dist), (back_idx, back_dist) = module.nearest_both_ways(a, b, k, k_back)
    one_idx, one_dist = module.nearest_descriptors(a, b, k)
    two_idx, two_dist = module.nearest_descriptors(b, a, k_back)
    np.testing.assert_array_equal(idx, one_idx)
    np.testing.assert_array_equal(dist, one_dist)
    np.testing.assert_array_equal(back_idx, two_idx)
    np.testing.assert_array_equal(back_dist, two_dist)
    assert back_idx.shape == (m, min(k_back, n))


def test_matches_both_ways_are_the_two_calls_matches():
    from o3d_rpointhop.registration.correspondences import (
        correspondences_both_ways,
        k_best_correspondences,
    )

    a, b = _tied_descriptors(np.float32, 300, 250, seed=3)
    for ratio in (None, 0.9):
        forward, backward = correspondences_both_ways(a, b, max_ratio=ratio)
        for got, want in (
            (forward, find_correspondences(a, b, max_ratio=ratio)),
            (backward, find_correspondences(b, a, max_ratio=ratio)),
        ):
            np.testing.assert_array_equal(got.pairs, want.pairs)
            np.testing.assert_array_equal(got.distances, want.distances)
            np.testing.assert_array_equal(got.ratios, want.ratios)
    assert len(correspondences_both_ways(a, b, max_ratio=0.9)[0]) < 300
    for k in (2, 3):  # k-best both ways: the two directions' k_best_correspondences
        forward, backward = correspondences_both_ways(a, b, k=k)
        for got, want in (
            (forward, k_best_correspondences(a, b, k)),
            (backward, k_best_correspondences(b, a, k)),
        ):
            np.testing.assert_array_equal(got.pairs, want.pairs)
            np.testing.assert_array_equal(got.distances, want.distances)
            np.testing.assert_array_equal(got.ratios, want.ratios)
    with pytest.raises(ValueError, match="max_ratio"):
        correspondences_both_ways(a, b, max_ratio=0.9, k=2)
    with pytest.raises(ValueError, match="k must be an int"):
        correspondences_both_ways(a, b, k=0)


def test_matches_both_ways_from_a_spread_of_queries():
    """With ``max_queries``, each direction searches from that many of its points,
    spread evenly by index, against every point of the other cloud: the matches of
    those rows as a plain search of them finds, indexed in the whole cloud; a cloud no
    larger than ``max_queries`` searches from every point."""
    from o3d_rpointhop.registration.correspondences import (
        correspondences_both_ways,
        k_best_correspondences,
    )

    a, b = _tied_descriptors(np.float32, 300, 250, seed=5)
    rows = np.unique(np.linspace(0, 299, 100).astype(np.int64))
    columns = np.unique(np.linspace(0, 249, 100).astype(np.int64))
    for ratio in (None, 0.9):
        forward, backward = correspondences_both_ways(a, b, max_ratio=ratio, max_queries=100)
        for got, (queries, refs, chosen) in (
            (forward, (a, b, rows)),
            (backward, (b, a, columns)),
        ):
            want = find_correspondences(queries[chosen], refs, max_ratio=ratio)
            np.testing.assert_array_equal(got.pairs[:, 0], chosen[want.pairs[:, 0]])
            np.testing.assert_array_equal(got.pairs[:, 1], want.pairs[:, 1])
            np.testing.assert_array_equal(got.distances, want.distances)
            np.testing.assert_array_equal(got.ratios, want.ratios)
    forward, _ = correspondences_both_ways(a, b, k=2, max_queries=100)
    want = k_best_correspondences(a[rows], b, 2)
    np.testing.assert_array_equal(forward.pairs[:, 0], rows[want.pairs[:, 0]])
    np.testing.assert_array_equal(forward.pairs[:, 1], want.pairs[:, 1])
    # Only the larger cloud is thinned; at or above both sizes nothing is.
    forward, backward = correspondences_both_ways(a, b, max_queries=260)
    assert len(np.unique(forward.pairs[:, 0])) <= 260 < 300
    np.testing.assert_array_equal(backward.pairs, find_correspondences(b, a).pairs)
    for bad in (0, 2.5, True):
        with pytest.raises(ValueError, match="max_queries must be an int"):
            correspondences_both_ways(a, b, max_queries=bad)
    every = correspondences_both_ways(a, b, max_queries=300)
    plain = correspondences_both_ways(a, b)
    for got, want in zip(every, plain, strict=True):
        np.testing.assert_array_equal(got.pairs, want.pairs)
        np.testing.assert_array_equal(got.distances, want.distances)


def test_shared_matches_answer_the_other_way_round_as_computing_it(monkeypatch):
    """Inside shared_matches(), matching two arrays the other way round reuses the
    first matching, swapped, and gives what computing it gives, to the bit; outside,
    and for other arrays or options, it computes."""
    from o3d_rpointhop.registration import correspondences as module

    a, b = _tied_descriptors(np.float32, 300, 250, seed=5)
    computed = []
    real = module._both_ways
    monkeypatch.setattr(module, "_both_ways", lambda *args: computed.append(1) or real(*args))
    for ratio, k in ((None, 1), (0.9, 1), (None, 2)):
        want = module.correspondences_both_ways(b, a, max_ratio=ratio, k=k)
        computed.clear()
        with module.shared_matches():
            module.correspondences_both_ways(a, b, max_ratio=ratio, k=k)
            got = module.correspondences_both_ways(b, a, max_ratio=ratio, k=k)
            assert len(computed) == 1  # the other way round came from the first
            module.correspondences_both_ways(b, a.copy(), max_ratio=ratio, k=k)
            assert len(computed) == 2  # another array is matched anew
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g.pairs, w.pairs)
            np.testing.assert_array_equal(g.distances, w.distances)
            np.testing.assert_array_equal(g.ratios, w.ratios)
    computed.clear()
    module.correspondences_both_ways(a, b)
    module.correspondences_both_ways(b, a)
    assert len(computed) == 2  # nothing is shared outside


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_compiled_candidates_are_the_argmin_passes(dtype, monkeypatch):
    """Large distance blocks take their candidates from one compiled pass per row: the
    same columns, in the same order (value, then index), as the argmin passes."""
    from o3d_rpointhop.registration import correspondences as module

    rng = np.random.default_rng(1)
    values = rng.normal(size=(120, 333)).astype(dtype)
    values[:, 7] = values[:, 2]  # ties go to the lower index
    values[5] = 1.0  # a row of ties
    monkeypatch.setattr(module, "COMPILED_FROM", 1 << 60)
    passes = module._smallest(values.copy(), 4)
    monkeypatch.setattr(module, "COMPILED_FROM", 0)
    np.testing.assert_array_equal(module._smallest(values.copy(), 4), passes)
    np.testing.assert_array_equal(passes[5], [0, 1, 2, 3])


def test_counts_and_shares_at_their_boundaries():
    """An int count from 1, a share in (0, 1] of n (at least ``minimum``); a bool, 0, a
    share above 1 or a negative number refused, with the rule in the message."""
    from o3d_rpointhop.registration.correspondences import count_of

    assert count_of(1, 10) == 1 and count_of(7, 10) == 7
    assert count_of(1.0, 10) == 10 and count_of(0.5, 10) == 5
    assert count_of(0.01, 10) == 1  # rounds to 0: the minimum
    assert count_of(0.01, 10, minimum=3) == 3
    for bad in (0, 0.0, -1, 1.5, 2.0, True):
        with pytest.raises(ValueError, match=r"an int >= 1 or a share in \(0, 1\]"):
            count_of(bad, 10)


def test_integer_descriptors_are_matched_as_their_float_values():
    from o3d_rpointhop.registration.correspondences import as_features, find_correspondences

    rng = np.random.default_rng(4)
    ints = rng.integers(0, 50, (60, 5))
    assert as_features(ints, "x").dtype == np.float64
    assert as_features(ints.astype(np.float32), "x").dtype == np.float32  # floats kept
    got = find_correspondences(ints, ints[::-1])
    want = find_correspondences(ints.astype(np.float64), ints[::-1].astype(np.float64))
    np.testing.assert_array_equal(np.asarray(got), np.asarray(want))


# ----------------------------------------------------------------------------- k-best matches
@pytest.mark.parametrize("k", [1, 2, 3])
def test_k_best_matches_are_each_points_k_nearest_in_order(k):
    from scipy.spatial.distance import cdist

    from o3d_rpointhop.registration.correspondences import k_best_correspondences

    rng = np.random.default_rng(k)
    src, tgt = rng.normal(size=(60, 8)), rng.normal(size=(45, 8))
    corr = k_best_correspondences(src, tgt, k)
    exact = cdist(src, tgt)
    order = np.argsort(exact, axis=1)
    assert len(corr) == 60 * k
    np.testing.assert_array_equal(corr.pairs[:, 0], np.repeat(np.arange(60), k))
    np.testing.assert_array_equal(corr.pairs[:, 1].reshape(60, k), order[:, :k])
    dist = np.sort(exact, axis=1)
    np.testing.assert_allclose(corr.distances.reshape(60, k), dist[:, :k], atol=1e-6)
    np.testing.assert_allclose(
        corr.ratios.reshape(60, k), dist[:, :k] / dist[:, 1 : k + 1], rtol=1e-6
    )
    if k == 1:  # the unfiltered nearest matches, ratios and all
        plain = find_correspondences(src, tgt)
        np.testing.assert_array_equal(corr.pairs, plain.pairs)
        np.testing.assert_allclose(corr.ratios, plain.ratios)


def test_k_best_is_capped_at_the_target_and_refuses_a_bad_k():
    from o3d_rpointhop.registration.correspondences import k_best_correspondences

    rng = np.random.default_rng(0)
    src, tgt = rng.normal(size=(5, 3)), rng.normal(size=(2, 3))
    corr = k_best_correspondences(src, tgt, 4)
    assert len(corr) == 10 and set(corr.pairs[:, 1]) == {0, 1}
    assert np.all(corr.ratios[1::2] == 1.0)  # the last match has no next nearest
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="k must be"):
            k_best_correspondences(src, tgt, bad)
    with pytest.raises(ValueError, match="differ in length"):
        k_best_correspondences(src, tgt[:, :2], 1)
