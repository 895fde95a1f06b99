"""Hypotheses verified by overlap (``n_hypotheses``): a planted pair whose best-supported
hypothesis is wrong and whose runner-up is right."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from helpers import CodesBySize, consensus_matcher
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from o3d_rpointhop import (
    ConsensusGlobal,
    Matcher,
    RANSACGlobal,
    RegistrationPipeline,
    RegistrationWarning,
)
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.registration.context import RegistrationContext
from o3d_rpointhop.registration.steps._hypotheses import (
    distinct,
    match_support,
    overlap_score,
)
from o3d_rpointhop.registration.steps._verification import verify
from o3d_rpointhop.transforms import rotation_error_deg


def _planted_pair():
    """A partial source of an object, its truth, and planted matches: 25 right ones
    spread over the overlap, and 40 that agree on a wrong motion (the truth, then a
    half-turn of the target)."""
    rng = np.random.default_rng(0)
    target = make_object(700, shape_seed=11, sample_seed=1)
    whole = make_object(900, shape_seed=11, sample_seed=2)
    part = whole[whole[:, 0] < 0.35]  # a crop: the source sees part of the object
    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_euler("xyz", [20, -35, 50], degrees=True).as_matrix()
    truth[:3, 3] = [0.2, -0.1, 0.3]
    source = (part - truth[:3, 3]) @ truth[:3, :3]  # truth maps source onto target
    flip = np.eye(4)  # a half-turn of the target: a sixth of the crop lands on it again
    flip[:3, :3] = Rotation.from_euler("x", 180, degrees=True).as_matrix()
    wrong = flip @ truth

    tree = cKDTree(target)

    def partners(motion):
        """Every source point whose moved copy lands on the target, and its partner."""
        dist, idx = tree.query(source @ motion[:3, :3].T + motion[:3, 3])
        near = np.flatnonzero(dist < 0.03)
        return near, idx[near]

    wrong_src, wrong_tgt = partners(wrong)
    pick = rng.permutation(len(wrong_src))[:40]
    wrong_src, wrong_tgt = wrong_src[pick], wrong_tgt[pick]
    right_src, right_tgt = partners(truth)
    free = ~np.isin(right_src, wrong_src) & ~np.isin(right_tgt, wrong_tgt)
    pick = rng.permutation(np.flatnonzero(free))[:25]
    right_src, right_tgt = right_src[pick], right_tgt[pick]
    assert len(wrong_src) == 40 and len(right_src) == 25
    dim = 16
    src_codes = rng.normal(size=(len(source), dim)) * 100.0
    tgt_codes = rng.normal(size=(len(target), dim)) * 100.0 + 1000.0
    for s, t in zip(np.r_[right_src, wrong_src], np.r_[right_tgt, wrong_tgt], strict=True):
        code = rng.normal(size=dim)
        src_codes[s], tgt_codes[t] = code, code
    assert len(source) != len(target)
    descriptor = CodesBySize({len(source): src_codes, len(target): tgt_codes})
    planted = (np.r_[right_src, wrong_src], np.r_[right_tgt, wrong_tgt])
    return source, target, truth, wrong, descriptor, planted


@pytest.mark.parametrize(
    "step",
    [
        ConsensusGlobal(matcher=consensus_matcher(mutual_filter=True)),
        RANSACGlobal(matcher=Matcher(mutual_filter=True), selection="matches"),
    ],
    ids=["consensus", "ransac"],
)
def test_the_runner_up_wins_when_it_overlaps_better(step):
    """The step's own ranking takes the motion most matches agree on (wrong); verifying
    three hypotheses by overlap takes the right one, and says by how much it won."""
    source, target, truth, wrong, descriptor, _ = _planted_pair()

    def run(n):
        pipe = RegistrationPipeline(
            [("global", step.set_params(n_hypotheses=n))], descriptor=descriptor
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RegistrationWarning)
            return pipe.register(source, target)

    alone = run(1)
    assert rotation_error_deg(alone.transformation, wrong) < 5.0  # the planted trap
    assert alone.margin is None and "hypothesis_scores" not in alone.steps[0].info
    verified = run(3)
    assert rotation_error_deg(verified.transformation, truth) < 5.0
    info = verified.steps[0].info
    assert len(info["hypothesis_scores"]) >= 2 and info["chosen_hypothesis"] > 0
    assert verified.margin == info["margin"] and 0.2 < verified.margin <= 1.0
    # The matches the chosen pose explains, not those of the step's own choice.
    assert info["inlier_matches"] == int(verified.steps[0].match_inliers.sum())
    assert info["inlier_matches"] < alone.steps[0].info["inlier_matches"]


def test_a_small_margin_makes_the_result_ambiguous():
    """Two distinct hypotheses that overlap alike leave the winner no margin: the
    result is flagged ambiguous, as a symmetric shape's is."""
    from o3d_rpointhop.registration.flags import AMBIGUITY_RATIO, assess

    cloud = make_object(800, shape_seed=1)  # no half-turn symmetry: not ambiguous alone
    context = RegistrationContext(cloud, cloud)
    sure = assess(context, np.eye(4), 0.05, margin=1.0)
    close = assess(context, np.eye(4), 0.05, margin=0.5 * (1.0 - AMBIGUITY_RATIO))
    assert sure.converged and close.converged
    assert close.ambiguous and not sure.ambiguous
    assert assess(context, np.eye(4), 0.05, ambiguity=False, margin=0.0).ambiguous is False


def test_verify_scores_the_right_pose_above_a_wrong_one():
    """More matches agree on the wrong pose, but the right one brings the clouds
    together: its overlap times its support wins."""
    source, target, truth, wrong, _, (si, ti) = _planted_pair()
    context = RegistrationContext(source, target)
    matched = (source[si] - context.origin, target[ti] - context.origin)
    local = np.stack([context.to_local(wrong), context.to_local(truth)])
    assert match_support(matched, local[0], 0.05) > match_support(matched, local[1], 0.05)
    check = verify(context, local, 0.05, matched)
    assert check.best == 1 and check.scores[1] > check.scores[0]
    assert check.refined.shape == (2, 4, 4)
    assert rotation_error_deg(context.to_world(check.refined[1]), truth) < 2.0
    # The same hypothesis twice: no distinct rival, the margin is whole.
    twice = verify(context, np.stack([local[1], local[1]]), 0.05, matched)
    assert twice.margin == 1.0


def test_overlap_score_counts_both_sides_and_agreeing_normals():
    """Each cloud's points near the other count once on each side; with normals, a
    crossing surface does not count."""
    grid = np.stack(np.meshgrid(np.linspace(0, 1, 11), np.linspace(0, 1, 11)), -1).reshape(-1, 2)
    plane = np.c_[grid, np.zeros(len(grid))]
    up = np.tile([0.0, 0.0, 1.0], (len(plane), 1))
    assert overlap_score(plane, plane, np.eye(4), 0.05) == pytest.approx(2.0)
    half = plane[plane[:, 0] <= 0.5]
    # Every point of the half has a partner, and as many of the plane's: 2 x 66 / 66.
    assert overlap_score(half, plane, np.eye(4), 0.05) == pytest.approx(2.0)
    assert overlap_score(plane, plane, np.eye(4), 0.05, (up, up)) == pytest.approx(2.0)
    sideways = np.tile([1.0, 0.0, 0.0], (len(plane), 1))
    assert overlap_score(plane, plane, np.eye(4), 0.05, (sideways, up)) == 0.0
    far = np.eye(4)
    far[2, 3] = 1.0
    assert overlap_score(plane, plane, far, 0.05) == 0.0


def test_distinct_keeps_the_best_of_each_pose():
    base = np.eye(4)
    near = np.eye(4)
    near[:3, :3] = Rotation.from_euler("z", 3, degrees=True).as_matrix()
    turned = np.eye(4)
    turned[:3, :3] = Rotation.from_euler("z", 40, degrees=True).as_matrix()
    shifted = np.eye(4)
    shifted[0, 3] = 1.0
    poses = np.stack([base, near, turned, shifted, turned])
    centre = np.zeros(3)
    np.testing.assert_array_equal(distinct(poses, 5, centre, 0.1), [0, 2, 3])
    np.testing.assert_array_equal(distinct(poses, 2, centre, 0.1), [0, 2])
    np.testing.assert_array_equal(distinct(poses, 1, centre, 0.1), [0])


def test_n_hypotheses_is_checked():
    with pytest.raises(ValueError, match="n_hypotheses"):
        RANSACGlobal(n_hypotheses=0).validate()


def test_overlap_score_turns_the_normals_with_the_pose():
    """Under a turning pose each side's normals are compared in one frame: a turned
    copy of a plane, with its own turned normals, overlaps fully once turned back, and
    not at all with normals that stayed put."""
    grid = np.stack(np.meshgrid(np.linspace(0, 1, 11), np.linspace(0, 1, 11)), -1).reshape(-1, 2)
    plane = np.c_[grid, np.zeros(len(grid))]
    up = np.tile([0.0, 0.0, 1.0], (len(plane), 1))
    turn = Rotation.from_euler("xyz", [70, -40, 25], degrees=True).as_matrix()
    source = plane @ turn.T + [0.3, -0.2, 0.5]
    back = np.eye(4)  # maps the turned copy onto the plane
    back[:3, :3] = turn.T
    back[:3, 3] = -turn.T @ [0.3, -0.2, 0.5]
    assert overlap_score(source, plane, back, 0.05, (up @ turn.T, up)) == pytest.approx(2.0)
    assert overlap_score(source, plane, back, 0.05, (up, up)) == pytest.approx(0.0)


def test_verify_on_clouds_too_wide_for_a_grid_uses_open3d_icp(monkeypatch):
    """A cloud too wide for a cell grid at the verification's distance is refined by
    Open3D's ICP and scored through k-d trees: the same choice and nearly the same
    poses as on the grid."""
    from o3d_rpointhop._utils import cells

    source, target, truth, wrong, _, (si, ti) = _planted_pair()
    context = RegistrationContext(source, target)
    matched = (source[si] - context.origin, target[ti] - context.origin)
    local = np.stack([context.to_local(wrong), context.to_local(truth)])
    on_grid = verify(context, local, 0.05, matched)
    monkeypatch.setattr(cells, "MAX_CELLS", 1)
    on_trees = verify(RegistrationContext(source, target), local, 0.05, matched)
    assert on_trees.best == on_grid.best == 1
    np.testing.assert_allclose(on_trees.refined, on_grid.refined, atol=1e-6)
    np.testing.assert_allclose(on_trees.scores, on_grid.scores, rtol=1e-6)


def test_ransac_s_own_choice_does_not_depend_on_how_many_are_verified():
    """With whole clouds to rank by, the first hypothesis (the one refitted, the step's
    own choice) is the same bytes whether one or three are handed on, and the others
    are distinct from it."""
    from o3d_rpointhop.registration.steps._hypotheses import DISTINCT_ANGLE_DEG
    from o3d_rpointhop.registration.steps._ransac import ransac

    source, target, _, _, _, (src_rows, tgt_rows) = _planted_pair()
    common = dict(max_iteration=20000, confidence=0.999, edge_length=0.9, seed=3)
    one = ransac(source[src_rows], target[tgt_rows], 0.03, clouds=(source, target), **common)
    three = ransac(
        source[src_rows], target[tgt_rows], 0.03, clouds=(source, target), n_hypotheses=3,
        **common,
    )  # fmt: skip
    assert len(one.hypotheses) == 1 and len(three.hypotheses) >= 2
    np.testing.assert_array_equal(three.hypotheses[0], one.transformation)
    for other in three.hypotheses[1:]:
        moved = np.linalg.norm(other[:3, 3] - one.transformation[:3, 3])
        turned = rotation_error_deg(other, one.transformation)
        assert turned > DISTINCT_ANGLE_DEG or moved > 0.03
