"""The matcher as a stage of its own: the same matches as the search functions it wraps,
its checks, and the global steps composing it (their own parameters only)."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import numpy as np
import pytest
from sklearn.base import BaseEstimator, TransformerMixin, clone

from o3d_rpointhop import (
    ConsensusGlobal,
    FGRGlobal,
    FPFHTransformer,
    Matcher,
    PooledMatcher,
    RANSACGlobal,
    SVDGlobal,
    find_correspondences,
    register,
)
from o3d_rpointhop.registration.correspondences import (
    Correspondences,
    correspondences_both_ways,
    turned_correspondences,
    unit_rows,
)


def _codes(seed=0, n=200, m=240, d=6):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, d)), rng.normal(size=(m, d))


def test_plain_and_filtered_matches_are_find_correspondences():
    a, b = _codes()
    for params in ({}, {"mutual_filter": True}, {"max_ratio": 0.9}):
        got = Matcher(**params).match(a, b)
        want = find_correspondences(a, b, **params)
        np.testing.assert_array_equal(got.pairs, want.pairs)
        np.testing.assert_array_equal(got.distances, want.distances)


def test_both_directions_keep_a_pair_found_both_ways_once():
    a, b = _codes(1)
    got = Matcher(both_directions=True).match(a, b)
    forward, back = correspondences_both_ways(a, b)
    expected = np.unique(np.r_[forward.pairs, back.pairs[:, ::-1]], axis=0)
    assert len(expected) < len(forward) + len(back)  # some pairs are mutual
    np.testing.assert_array_equal(np.unique(got.pairs, axis=0), expected)
    assert len(got) == len(expected)


def test_cosine_matches_are_those_of_unit_rows():
    a, b = _codes(2)
    lengths = np.random.default_rng(3).uniform(0.1, 10, size=(len(b), 1))
    got = Matcher(metric="cosine").match(a, b * lengths)
    np.testing.assert_array_equal(got.pairs, find_correspondences(unit_rows(a), unit_rows(b)).pairs)


def test_turned_matches_and_their_shape_check():
    rng = np.random.default_rng(4)
    a, b = rng.normal(size=(4, 50, 5)), rng.normal(size=(4, 60, 5))
    got = Matcher(frame_turns=4).match(a, b)
    np.testing.assert_array_equal(got.pairs, turned_correspondences(a[0], b).pairs)
    with pytest.raises(ValueError, match=r"\(4, n, d\) for frame_turns=4"):
        Matcher(frame_turns=4).match(a[0], b[0])
    with pytest.raises(ValueError, match=r"\(n_points, n_features\) array"):
        Matcher().match(a, b)


def test_the_cap_and_salient_points_bound_the_matches():
    a, b = _codes(5, n=400, m=400)
    everything = Matcher(both_directions=True).match(a, b)
    capped = Matcher(both_directions=True, max_matches=100).match(a, b)
    assert len(everything) > 400 and len(capped) == 100
    assert all(tuple(p) in set(map(tuple, everything.pairs)) for p in capped.pairs)
    salient = Matcher(salient_share=0.5).match(a, b)
    assert 3 <= len(salient) < len(Matcher().match(a, b))
    # Searching from 50 spread points each way: every match has one of them at the
    # searching end (the source's rows forward, the target's backward).
    thinned = Matcher(both_directions=True, max_queries=50).match(a, b)
    rows = set(np.unique(np.linspace(0, 399, 50).astype(np.int64)).tolist())
    assert 50 < len(thinned) <= 100
    assert all(p[0] in rows or p[1] in rows for p in thinned.pairs.tolist())


@pytest.mark.parametrize(
    "params, message",
    [
        ({"metric": "manhattan"}, "metric"),
        ({"n_nearest": 2, "mutual_filter": True}, "n_nearest=2 cannot be combined"),
        ({"frame_turns": 4, "max_ratio": 0.8}, "frame_turns=4 cannot be combined"),
        ({"frame_turns": 3}, "frame_turns"),
        ({"max_matches": 2}, "max_matches"),
        ({"max_queries": 100}, "max_queries needs both_directions"),
        ({"max_queries": 100, "both_directions": True, "mutual_filter": True}, "max_queries"),
    ],
)
def test_bad_parameters_are_refused(params, message):
    a, b = _codes()
    with pytest.raises(ValueError, match=message):
        Matcher(**params).match(a, b)
    with pytest.raises(ValueError, match=message):  # and by the step, before it runs
        ConsensusGlobal(matcher=Matcher(**params)).run(None, np.eye(4))


def test_bad_descriptors_are_refused():
    a, b = _codes()
    a[3, 2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        Matcher().match(a, b)
    with pytest.raises(ValueError, match="differ in length"):
        Matcher().match(b[:, :4], b)
    with pytest.raises(ValueError, match="survived the filters"):
        Matcher(max_ratio=1e-9).match(*_codes())


@pytest.mark.parametrize("step", [ConsensusGlobal, RANSACGlobal, FGRGlobal, SVDGlobal])
def test_steps_compose_a_matcher_and_keep_their_own_parameters(step):
    params = step().get_params(deep=False)
    assert params["matcher"] is None
    assert not set(params) & set(Matcher().get_params())  # no matching option on a step
    assert len(params) <= 10  # the consensus: its graph, seeds, threads and verification
    chosen = step(matcher=Matcher(metric="cosine"))
    assert chosen.get_params(deep=True)["matcher__metric"] == "cosine"
    copy = clone(chosen)
    assert copy.matcher is not chosen.matcher and copy.matcher.metric == "cosine"
    assert isinstance(step.default_matcher(), Matcher)


def test_no_step_probes_attributes_it_may_not_have():
    steps = Path(inspect.getfile(ConsensusGlobal)).parent
    for path in steps.glob("*.py"):
        assert not re.search(r"getattr\(self,", path.read_text()), path.name


def _both(cap):
    return Matcher(both_directions=True, max_matches=cap)


@pytest.mark.parametrize(
    "parts, message",
    [
        ([], "non-empty"),
        ([("a", None)], "each part is"),
        ([("a", None, _both(10)), ("a", None, _both(20))], "distinct"),
        ([("a", object(), _both(10))], "no transform"),
        ([("a", None, {"max_matches": 10})], "not a Matcher"),
        ([("a", None, Matcher(n_nearest=2, mutual_filter=True))], "n_nearest"),
    ],
)
def test_a_pooled_matcher_refuses_bad_parts(parts, message):
    with pytest.raises(ValueError, match=message):
        PooledMatcher(parts).validate()
    with pytest.raises(ValueError, match=message):  # checked when the step runs, too
        register(
            np.random.default_rng(0).normal(size=(300, 3)),
            np.random.default_rng(1).normal(size=(300, 3)),
            FPFHTransformer(),
            global_method=ConsensusGlobal(matcher=PooledMatcher(parts)),
        )


def test_pooling_keeps_each_pair_once_where_it_first_appears():
    first = Correspondences(np.array([[0, 1], [2, 3]]), np.array([0.1, 0.2]), np.ones(2))
    second = Correspondences(
        np.array([[5, 6], [2, 3], [0, 0]]), np.array([1.0, 2.0, 3.0]), np.ones(3)
    )
    pooled = PooledMatcher.pool([first, second])
    assert pooled.pairs.tolist() == [[0, 1], [2, 3], [5, 6], [0, 0]]
    assert pooled.distances.tolist() == [0.1, 0.2, 1.0, 3.0]


def test_a_pooled_step_matches_with_every_part_and_registers():
    from helpers import assert_close_pose, moved_copy

    from o3d_rpointhop.datasets import make_object

    target = make_object(2500, shape_seed=3, sample_seed=1)
    source, truth = moved_copy(target, seed=2)
    fpfh = FPFHTransformer()
    one = register(source, target, fpfh, global_method=ConsensusGlobal(matcher=_both(300)))
    # the same descriptor twice, once under another name: the pool is the first part's
    twice = PooledMatcher([("a", None, _both(300)), ("b", None, _both(300))])
    same = register(source, target, fpfh, global_method=ConsensusGlobal(matcher=twice))
    assert same.transformation.tobytes() == one.transformation.tobytes()
    # FPFH at two widths: more matches than either part alone, and the right pose
    other = FPFHTransformer(radius=0.3)
    pooled = PooledMatcher([("narrow", None, _both(300)), ("wide", other, _both(300))])
    step = ConsensusGlobal(matcher=pooled)
    result = register(source, target, fpfh, global_method=step)
    matches = result.steps[0].info["candidate_matches"]
    assert 300 < matches <= 600
    assert_close_pose(result.transformation, truth, 2.0, 0.02)
    copy = clone(step)
    assert copy.matcher is not pooled and copy.matcher.parts[1][1].radius == 0.3


class _Noise(TransformerMixin, BaseEstimator):
    """Descriptors that say nothing: every point's row is noise."""

    def fit(self, X, y=None):
        return self

    def transform(self, X):
        n = len(np.asarray(X.points))  # given an Open3D cloud
        return np.random.default_rng(n).normal(size=(n, 8))


def test_pooled_hypotheses_let_the_part_that_sees_the_pose_win():
    """One consensus per part, every part's hypotheses verified together: a part whose
    matches are noise gives the first hypotheses, the FPFH part's right one wins."""
    from helpers import assert_close_pose, moved_copy

    from o3d_rpointhop.datasets import make_object

    target = make_object(2500, shape_seed=3, sample_seed=1)
    source, truth = moved_copy(target, seed=2)
    parts = [("noise", _Noise(), _both(300)), ("fpfh", FPFHTransformer(), _both(300))]
    step = ConsensusGlobal(matcher=PooledMatcher(parts, combine="hypotheses"), n_hypotheses=3)
    result = register(source, target, FPFHTransformer(), global_method=step)
    assert_close_pose(result.transformation, truth, 2.0, 0.02)
    info = result.steps[0].info
    assert 4 <= len(info["hypothesis_scores"]) <= 6  # both parts' hypotheses
    parts_of = info["hypothesis_parts"]
    assert len(parts_of) == len(info["hypothesis_scores"]) and parts_of[0] == "noise"
    assert parts_of[info["chosen_hypothesis"]] == "fpfh"
    assert 300 < info["candidate_matches"] <= 600  # scored against the pooled matches
    noise_only = ConsensusGlobal(matcher=_both(300), n_hypotheses=3)
    with pytest.warns(Warning, match="did not converge"):
        wrong = register(source, target, _Noise(), global_method=noise_only)
    assert not np.allclose(wrong.transformation, truth, atol=0.05)


class _Unasked(_Noise):
    """A descriptor that must not be computed."""

    def transform(self, X):
        raise AssertionError("the fallback part was described though the first sufficed")


def test_the_fallback_asks_the_second_part_only_when_the_first_is_weak():
    """``combine="fallback"``: a first part whose estimate explains its matches is the
    step alone (the second part never described); one whose matches are noise hands
    over to the pooled hypotheses, with the same pose as ``combine="hypotheses"``."""
    from helpers import assert_close_pose, moved_copy

    from o3d_rpointhop.datasets import make_object

    target = make_object(2500, shape_seed=3, sample_seed=1)
    source, truth = moved_copy(target, seed=2)

    def run(parts, combine, **params):
        matcher = PooledMatcher(parts, combine=combine, **params)
        step = ConsensusGlobal(matcher=matcher, n_hypotheses=3)
        return register(source, target, FPFHTransformer(), global_method=step)

    strong = [("fpfh", None, _both(300)), ("later", _Unasked(), _both(300))]
    kept = run(strong, "fallback")
    alone = register(
        source,
        target,
        FPFHTransformer(),
        global_method=ConsensusGlobal(matcher=_both(300), n_hypotheses=3),
    )
    np.testing.assert_array_equal(kept.transformation, alone.transformation)
    assert kept.steps[0].info["fallback"] is False
    assert kept.support >= 0.01 and "hypothesis_parts" not in kept.steps[0].info
    with pytest.raises(AssertionError, match="fallback part was described"):
        run(strong, "fallback", min_support=1.0)  # nothing explains every match

    weak = [("noise", _Noise(), _both(300)), ("fpfh", FPFHTransformer(), _both(300))]
    rescued = run(weak, "fallback")
    assert_close_pose(rescued.transformation, truth, 2.0, 0.02)
    info = rescued.steps[0].info
    assert info["fallback"] is True and info["hypothesis_parts"][0] == "noise"
    np.testing.assert_array_equal(rescued.transformation, run(weak, "hypotheses").transformation)


def test_the_fallback_gives_the_same_bytes_on_any_thread_count():
    """register()'s default for the scene model where FPFH is asked (a room scan against
    noise): one thread and every core give the same transformation and scores."""
    from o3d_rpointhop.datasets import make_room

    room = make_room(3000, random_state=1) + [0.0, 0.0, 2.5]
    noise = np.random.default_rng(0).uniform(-1, 1, size=(3000, 3)) + [0.0, 0.0, 3.0]
    runs = [register(noise, room, "scene", viewpoints="origin", n_jobs=n_jobs) for n_jobs in (1, 2)]
    assert all(r.steps[0].info["fallback"] is True for r in runs)
    np.testing.assert_array_equal(runs[0].transformation, runs[1].transformation)
    assert runs[0].steps[0].info["hypothesis_scores"] == runs[1].steps[0].info["hypothesis_scores"]
    # Built on the first part's verification, the scores are the pooled hypotheses'
    # own (free-space checks included).
    step = ConsensusGlobal(matcher=PooledMatcher.with_fpfh(combine="hypotheses"))
    pooled = register(noise, room, "scene", viewpoints="origin", global_method=step)
    np.testing.assert_array_equal(pooled.transformation, runs[0].transformation)
    assert pooled.steps[0].info["hypothesis_scores"] == runs[0].steps[0].info["hypothesis_scores"]


@pytest.mark.parametrize("support", [-0.1, 1.5, True, "high"])
def test_min_support_is_a_share(support):
    with pytest.raises(ValueError, match="min_support must be in"):
        PooledMatcher([("a", None, _both(10))], min_support=support).validate()


@pytest.mark.parametrize("step", [RANSACGlobal, FGRGlobal, SVDGlobal])
def test_only_the_consensus_pools_hypotheses(step):
    pooled = PooledMatcher([("a", None, _both(10))], combine="hypotheses")
    with pytest.raises(ValueError, match="combine='hypotheses' needs ConsensusGlobal"):
        register(
            np.random.default_rng(0).normal(size=(300, 3)),
            np.random.default_rng(1).normal(size=(300, 3)),
            FPFHTransformer(),
            global_method=step(matcher=pooled),
        )
    with pytest.raises(ValueError, match="combine must be"):
        PooledMatcher([("a", None, _both(10))], combine="poses").validate()
